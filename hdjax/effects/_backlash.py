r"""Lost motion (backlash): the joint twists freely by a small angle around zero torque.

Clearances between the flexspline and circular-spline teeth and in the wave-generator bearing
let the output move by a small angle $b$ (catalogue "lost motion", measured at $\pm 4\%$ of rated
torque, about 1 arcmin for size 40-50 units) before the teeth carry load. The plant adds the
smooth step $\frac{b}{2}\tanh(T/T_b)$ to the deflection in series with the flexspline (so the
budget is then inverted by Newton steps); the regression term is $\tanh(T/T_b)$ of the
torque, inverted by Newton steps as well; the loop scans $T_b$ on a grid of fractions of the
rated torque.

References: Song et al. 2019, Section II (lost motion of the harmonic drive); Harmonic Drive
CSG/CSF catalogue, "lost motion".
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Float, Pointwise, PointwiseOut
from ._base import AbstractMemorylessTerm, AbstractPlantEffect, AbstractTorqueScaleFamily
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, hyper, labels
from ._traced import opaque


class Backlash(AbstractMemorylessTerm):
    """Lost motion around zero torque: a smooth step $\\tanh(T/T_b)$ of width $T_b$."""

    width: float = hyper(1.0, positive=True)

    key, names = labels("backlash:torque", "tanh(T/{width})")

    def value_and_slope(self, torque: Pointwise) -> tuple[PointwiseOut, PointwiseOut]:
        w = opaque(self.width)  # a constant width rounds as a traced one
        v = jnp.tanh(torque / w)
        return v, (1.0 - v**2) / w

    def numpy_value(self, torque: Pointwise) -> Float[np.ndarray, "*shape"]:
        return np.tanh(np.asarray(torque) / self.width)

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """$\\tanh(T/T_b)$ and its slope for the exported estimator's Newton steps."""
        w = c.num(self.width)
        return CSnippet(
            value=f"{c.fn('tanh')}({c.torque} / {w})",
            slope=f"({c.num(1.0)} - {c.value} * {c.value}) / {w}",
        )


class LostMotion(AbstractPlantEffect):
    r"""Lost motion: the deflection gains $\frac{b}{2}\tanh(T/T_b)$ [rad].

    `width` $b$ [rad] is the lost motion, `torque_scale` $T_b$ [N·m] the torque over which the
    play closes (catalogues measure lost motion at $\pm 4\%$ of rated torque).
    """

    width: Float[Array, ""] = bound("nonneg")
    torque_scale: Float[Array, ""] = bound("positive", inverse=True)

    def deflection(self, torque: Pointwise, inv: dict | None = None) -> PointwiseOut:
        inv = self.reciprocals() if inv is None else inv
        return 0.5 * self.width * jnp.tanh(torque * inv["torque_scale"])

    def slope(self, torque: Pointwise, inv: dict | None = None) -> PointwiseOut:
        inv = self.reciprocals() if inv is None else inv
        th = jnp.tanh(torque * inv["torque_scale"])
        return 0.5 * self.width * (1.0 - th * th) * inv["torque_scale"]


_ARCMIN = np.pi / (180.0 * 60.0)


def _defaults(rated: float, k1: float, given) -> dict:
    """1 arcmin of lost motion (a size 40-50 unit's catalogue value), closing over 2 % of the
    rated torque."""
    return dict(width=1.0 * _ARCMIN, torque_scale=0.02 * rated)


class BacklashFamily(AbstractTorqueScaleFamily):
    """Lost motion: plant `backlash`; term `Backlash`; a grid of widths $T_b$, fractions of the
    rated torque."""

    name: ClassVar[str] = "backlash"
    terms: ClassVar[tuple] = (Backlash,)
    plant_effects: ClassVar[tuple] = (LostMotion.entry("backlash", "compliance", _defaults),)
    discover_families: ClassVar[tuple] = ("backlash:torque",)
    options: ClassVar[dict] = {"backlash_fractions": (0.005, 0.01, 0.02, 0.05)}
    scale_field: ClassVar[str] = "width"
    fractions_option: ClassVar[str] = "backlash_fractions"
