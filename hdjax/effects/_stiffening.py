r"""Stiffening: the joint gets stiffer with torque beyond what the piecewise segments describe.

The flexspline's contact area grows with load, so its stiffness rises smoothly with torque;
Song et al. approximate that by five linear segments (eq. (7)). What the segments miss is an
odd, smooth term. The plant adds a cubic spring $\kappa_3 d^3$ in parallel with the flexspline;
the regression term is $(T/\tau_0)^3$, inverted by Newton steps.

References: Song et al. 2019, eq. (7); Hashimoto et al. 1993, Section 2 (nonlinear stiffness).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from .._custom_types import Array, ArrayLike, Float, Pointwise, PointwiseOut
from ._base import AbstractMemorylessTerm, AbstractPlantEffect, AbstractTorqueScaleFamily
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, hyper, labels
from ._traced import opaque


class Stiffening(AbstractMemorylessTerm):
    """Nonlinear stiffness beyond the piecewise segments: $(T/\\tau_s)^3$ (odd, smooth)."""

    torque_scale: float = hyper(1.0, positive=True)

    key, names = labels("stiffness:torque", "(T/{torque_scale})^3")

    def value_and_slope(
        self, torque: Pointwise
    ) -> tuple[Float[ArrayLike, "*shape"], Float[ArrayLike, "*shape"]]:
        s = opaque(self.torque_scale)  # a constant scale rounds as a traced one
        u = torque / s
        return u**3, 3.0 * u**2 / s

    def numpy_value(self, torque: Pointwise) -> Float[np.ndarray, "*shape"]:
        return (np.asarray(torque) / self.torque_scale) ** 3

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """$(T/\\tau_s)^3$ and its slope for the exported estimator's Newton steps (the powers
        multiplied as JAX's `integer_pow` does)."""
        s, u = c.num(self.torque_scale), c.local("u")
        return CSnippet(
            value=f"{u} * ({u} * {u})",
            slope=f"{c.num(3.0)} * ({u} * {u}) / {s}",
            lines=(f"const {c.real} {u} = {c.torque} / {s};",),
        )


class CubicSpring(AbstractPlantEffect):
    r"""A cubic spring $\kappa_3 d^3$ [N·m] in parallel with the flexspline (`cubic` $\kappa_3$)."""

    cubic: Float[Array, ""] = bound("nonneg")

    def torque(self, d: Pointwise) -> PointwiseOut:
        return self.cubic * d * d * d


def _defaults(rated: float, k1: float, given) -> dict:
    """A cubic spring that carries 10 % of the rated torque at the rated deflection
    $\\tau_0 k_1$."""
    return dict(cubic=0.1 * rated / (rated * k1 * 1.0) ** 3)


class StiffeningFamily(AbstractTorqueScaleFamily):
    """Stiffening: plant `stiffening`; term `Stiffening`; one candidate, at the rated torque
    $\\tau_0$."""

    name: ClassVar[str] = "stiffening"
    terms: ClassVar[tuple] = (Stiffening,)
    plant_effects: ClassVar[tuple] = (CubicSpring.entry("stiffening", "spring", _defaults),)
    discover_families: ClassVar[tuple] = ("stiffness:torque",)
    scale_field: ClassVar[str] = "torque_scale"
