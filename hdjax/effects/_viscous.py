r"""Viscous friction: a torque proportional to speed.

Lubricant shear in the wave-generator bearing, the teeth and the output bearing gives a
friction torque $F_v\omega$ that grows with speed (Song et al. Section IV.C list friction as the
main un-modelled effect). On the output side it acts between the flexspline and the torque
sensor, so the twist carries $F_v\omega_l$ that the sensor does not. The regression column is
the velocity divided by its RMS; the loop offers one candidate per velocity.

References: Song et al. 2019, Section IV.C; Armstrong-Hélouvry et al., Automatica 30(7), 1994.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

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
from ._coulomb import velocity_rms


class Viscous(AbstractSignalTerm):
    """Viscous friction signature: a velocity, divided by `scale`."""

    signal: str = eqx.field(default="omega_m", static=True)
    scale: float = eqx.field(default=1.0, static=True)

    def __check_init__(self):
        check_positive("Viscous", "scale", self.scale)

    @property
    def key(self) -> str:
        return f"viscous:{self.signal}"

    def names(self) -> tuple[str, ...]:
        return (f"{self.signal}/{fmt(self.scale)}",)

    @property
    def signal_name(self) -> str:
        return self.signal

    def transform(self, x, xp):
        return x / self.scale


class ViscousFriction(AbstractFriction):
    r"""Viscous friction $F_v \omega$ [N·m] (`coefficient` $F_v$)."""

    coefficient: Float[Array, ""]

    def reciprocals(self):
        return {}

    def __call__(self, omega, inv=None):
        return self.coefficient * omega

    def max_slope(self):
        return self.coefficient


def _build(name: str, p: dict) -> ViscousFriction:
    require(name, "coefficient", p["coefficient"], nonneg=True, shape=())
    return ViscousFriction(f64(p["coefficient"]))


class ViscousFamily(AbstractFamily):
    """Viscous friction: plant `viscous_m`, `viscous_l`; term `Viscous`; one candidate each."""

    name: ClassVar[str] = "viscous"
    terms: ClassVar[tuple] = (Viscous,)
    plant_effects: ClassVar[tuple] = (
        PlantEffect(
            "viscous_m", "motor_friction", lambda rated, k1, given: dict(coefficient=2.0e-4), _build
        ),
        PlantEffect(
            "viscous_l", "output_friction", lambda rated, k1, given: dict(coefficient=2.0), _build
        ),
    )
    discover_families: ClassVar[tuple] = ("viscous:omega_m", "viscous:omega_l")
    vocabulary: ClassVar[str] = "viscous:omega_m, viscous:omega_l"
    options: ClassVar[dict] = {}

    def candidates(self, ctx):
        out = []
        for signal in ("omega_m", "omega_l"):
            rms = velocity_rms(ctx.sig, signal)
            if rms == 0.0 or not ctx.wants(f"viscous:{signal}"):
                continue
            term = Viscous(signal=signal, scale=float(f"{rms:.4g}"))
            out.append(Candidate(term.key, term.key, term))
        return out
