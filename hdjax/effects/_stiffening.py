r"""Stiffening: the joint gets stiffer with torque beyond what the piecewise segments describe.

The flexspline's contact area grows with load, so its stiffness rises smoothly with torque;
Song et al. approximate that by five linear segments (eq. (7)). What the segments miss is an
odd, smooth term. The plant adds a cubic spring $\kappa_3 d^3$ in parallel with the flexspline;
the regression term is $(T/\tau_0)^3$, inverted by Newton steps.

References: Song et al. 2019, eq. (7); Hashimoto et al. 1993, Section 2 (nonlinear stiffness).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import numpy as np

from .._custom_types import Array, Float
from ._base import (
    AbstractFamily,
    AbstractMemorylessTerm,
    AbstractPlantEffect,
    Candidate,
    PlantEffect,
    check_positive,
    f64,
    fmt,
    require,
)


class Stiffening(AbstractMemorylessTerm):
    """Nonlinear stiffness beyond the piecewise segments: $(T/\\tau_s)^3$ (odd, smooth)."""

    torque_scale: float = eqx.field(default=1.0, static=True)

    def __check_init__(self):
        check_positive("Stiffening", "torque_scale", self.torque_scale)

    @property
    def key(self) -> str:
        return "stiffness:torque"

    def names(self) -> tuple[str, ...]:
        return (f"(T/{fmt(self.torque_scale)})^3",)

    def value_and_slope(self, torque):
        u = torque / self.torque_scale
        return u**3, 3.0 * u**2 / self.torque_scale

    def numpy_value(self, torque) -> np.ndarray:
        return (np.asarray(torque) / self.torque_scale) ** 3


class CubicSpring(AbstractPlantEffect):
    r"""A cubic spring $\kappa_3 d^3$ [N·m] in parallel with the flexspline (`cubic` $\kappa_3$)."""

    cubic: Float[Array, ""]

    def reciprocals(self):
        return {}

    def torque(self, d):
        return self.cubic * d * d * d


def _build(name: str, p: dict) -> CubicSpring:
    require(name, "cubic", p["cubic"], nonneg=True, shape=())
    return CubicSpring(f64(p["cubic"]))


class StiffeningFamily(AbstractFamily):
    """Stiffening: plant `stiffening`; term `Stiffening`; one candidate at $\\tau_0$."""

    name: ClassVar[str] = "stiffening"
    terms: ClassVar[tuple] = (Stiffening,)
    plant_effects: ClassVar[tuple] = (
        PlantEffect(
            "stiffening",
            "spring",
            lambda rated, k1, given: dict(cubic=0.1 * rated / (rated * k1 * 1.0) ** 3),
            _build,
        ),
    )
    discover_families: ClassVar[tuple] = ("stiffness:torque",)
    vocabulary: ClassVar[str] = "stiffness:torque"
    options: ClassVar[dict] = {}

    def candidates(self, ctx):
        if not ctx.wants("stiffness:torque"):
            return []
        term = Stiffening(torque_scale=float(ctx.rated_torque))
        return [Candidate(term.key, term.key, term)]
