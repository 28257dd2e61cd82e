r"""Coulomb friction: a torque of constant size opposing the motion.

Friction between the motor and the wave generator, and in the output bearing, has a level that
barely depends on speed once sliding (Coulomb); Song et al. name un-modelled friction as their
main error source (Section IV.C). The plant uses a smooth sign, $F_c\tanh(\omega/\omega_s)$, so
gradients exist everywhere; on the motor side it takes torque from the current before the
wave generator, on the output side it acts between the flexspline and the torque sensor, so
the twist sees $F_c\tanh(\omega_l/\omega_s)$ that the sensor does not. The regression column is
the smooth sign of a velocity; the residual loop scans $\omega_s$ on a grid of fractions of the
velocity's RMS.

References: Song et al. 2019, Section IV.C; Armstrong-Hélouvry, Dupont and Canudas de Wit,
"A survey of models, analysis tools and compensation methods for the control of machines with
friction", Automatica 30(7), 1994.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Float
from ._base import (
    AbstractFamily,
    AbstractFriction,
    AbstractSignalTerm,
    Candidate,
    PlantEffect,
    check_positive,
    f64,
    fmt,
    require,
)


class Coulomb(AbstractSignalTerm):
    """Coulomb-like friction signature, a smooth sign $\\tanh(\\omega/\\omega_s)$ of a velocity."""

    signal: str = eqx.field(default="omega_m", static=True)
    omega_s: float = eqx.field(default=1.0, static=True)

    def __check_init__(self):
        check_positive("Coulomb", "omega_s", self.omega_s)

    @property
    def key(self) -> str:
        return f"coulomb:{self.signal}"

    def names(self) -> tuple[str, ...]:
        return (f"tanh({self.signal}/{fmt(self.omega_s)})",)

    @property
    def signal_name(self) -> str:
        return self.signal

    def transform(self, x, xp):
        return xp.tanh(x / self.omega_s)


class CoulombFriction(AbstractFriction):
    r"""Coulomb friction $F_c \tanh(\omega/\omega_s)$ [N·m] (`level` $F_c$, `smoothing`
    $\omega_s$)."""

    level: Float[Array, ""]
    smoothing: Float[Array, ""]

    def reciprocals(self):
        return {"smoothing": 1.0 / self.smoothing}

    def __call__(self, omega, inv=None):
        inv = self.reciprocals() if inv is None else inv
        return self.level * jnp.tanh(omega * inv["smoothing"])

    def max_slope(self):
        return self.level / self.smoothing


def _build(name: str, p: dict) -> CoulombFriction:
    require(name, "level", p["level"], nonneg=True, shape=())
    require(name, "smoothing", p["smoothing"], positive=True, shape=())
    return CoulombFriction(f64(p["level"]), f64(p["smoothing"]))


def velocity_rms(sig, signal: str) -> float:
    """RMS of a velocity signal (the scale of friction grids)."""
    w = np.asarray(sig.get(signal))
    return float(np.sqrt(np.mean(w**2)))


class CoulombFamily(AbstractFamily):
    """Coulomb friction: plant `coulomb_m`, `coulomb_l`; term `Coulomb`; a grid of $\\omega_s$."""

    name: ClassVar[str] = "coulomb"
    terms: ClassVar[tuple] = (Coulomb,)
    plant_effects: ClassVar[tuple] = (
        PlantEffect(
            "coulomb_m",
            "motor_friction",
            lambda rated, k1, given: dict(level=0.1, smoothing=0.5),
            _build,
        ),
        PlantEffect(
            "coulomb_l",
            "output_friction",
            lambda rated, k1, given: dict(level=0.0075 * rated, smoothing=5e-3),
            _build,
        ),
    )
    discover_families: ClassVar[tuple] = ("coulomb:omega_m", "coulomb:omega_l")
    vocabulary: ClassVar[str] = "coulomb:omega_m, coulomb:omega_l"
    options: ClassVar[dict] = {"smoothing_fractions": (0.003, 0.01, 0.03, 0.1, 0.3)}

    def candidates(self, ctx):
        out = []
        for signal in ("omega_m", "omega_l"):
            rms = velocity_rms(ctx.sig, signal)
            if rms == 0.0 or not ctx.wants(f"coulomb:{signal}"):
                continue
            for frac in ctx.option(self, "smoothing_fractions"):
                term = Coulomb(signal=signal, omega_s=float(f"{frac * rms:.4g}"))
                out.append(Candidate(term.key, term.key, term))
        return out
