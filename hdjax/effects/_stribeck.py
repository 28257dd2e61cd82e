r"""Stribeck friction: breakaway friction above the Coulomb level at low speed.

At low sliding speed the lubricant film has not built up and friction rises above its Coulomb
level; the excess decays over a characteristic (Stribeck) speed, $F_s e^{-(\omega/\omega_{st})^2}
\tanh(\omega/\omega_s)$. The plant simulates it on the motor (`stribeck_m`) and output
(`stribeck_l`) sides; the residual loop does not propose it yet.

References: Armstrong-Hélouvry et al., Automatica 30(7), 1994, Section 2 (the Stribeck curve).
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from .._custom_types import Array, Float
from ._base import AbstractFamily, AbstractFriction, PlantEffect, f64, require


class StribeckFriction(AbstractFriction):
    r"""Stribeck bump $F_s e^{-(\omega/\omega_{st})^2} \tanh(\omega/\omega_s)$ [N·m].

    `peak` is the breakaway torque *above* the Coulomb level, `speed` the Stribeck speed.
    """

    peak: Float[Array, ""]
    speed: Float[Array, ""]
    smoothing: Float[Array, ""]

    def reciprocals(self):
        return {"speed": 1.0 / self.speed, "smoothing": 1.0 / self.smoothing}

    def __call__(self, omega, inv=None):
        inv = self.reciprocals() if inv is None else inv
        x = omega * inv["speed"]
        return self.peak * jnp.exp(-(x * x)) * jnp.tanh(omega * inv["smoothing"])

    def max_slope(self):
        return self.peak / self.smoothing


def _build(name: str, p: dict) -> StribeckFriction:
    require(name, "peak", p["peak"], nonneg=True, shape=())
    for f in ("speed", "smoothing"):
        require(name, f, p[f], positive=True, shape=())
    return StribeckFriction(f64(p["peak"]), f64(p["speed"]), f64(p["smoothing"]))


class StribeckFamily(AbstractFamily):
    """Stribeck friction: plant `stribeck_m`, `stribeck_l` (no regression term yet)."""

    name: ClassVar[str] = "stribeck"
    terms: ClassVar[tuple] = ()
    plant_effects: ClassVar[tuple] = (
        PlantEffect(
            "stribeck_m",
            "motor_friction",
            lambda rated, k1, given: dict(peak=0.05, speed=2.0, smoothing=0.5),
            _build,
        ),
        PlantEffect(
            "stribeck_l",
            "output_friction",
            lambda rated, k1, given: dict(peak=0.005 * rated, speed=0.02, smoothing=5e-3),
            _build,
        ),
    )
    discover_families: ClassVar[tuple] = ()
    vocabulary: ClassVar[str] = ""
    options: ClassVar[dict] = {}

    def candidates(self, ctx):
        return []
