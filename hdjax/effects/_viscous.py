r"""Viscous friction: a torque proportional to speed.

Lubricant shear in the wave-generator bearing, the teeth and the output bearing gives a
friction torque $F_v\omega$ that grows with speed (Song et al. Section IV.C list friction as the
main un-modelled effect). On the output side it acts between the flexspline and the torque
sensor, so the twist carries $F_v\omega_l$ that the sensor does not. The regression column is
the velocity divided by its RMS; the loop offers one candidate per velocity.

References: Song et al. 2019, Section IV.C; Armstrong-Hélouvry et al., Automatica 30(7), 1994.
"""

from __future__ import annotations

from types import ModuleType
from typing import ClassVar

import equinox as eqx

from .._custom_types import Array, ArrayLike, Float, Pointwise, PointwiseOut, SamplesLike
from ._base import AbstractFamily, AbstractFriction, AbstractSignalTerm, Candidate, CandidateContext
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, hyper, labels
from ._friction import friction_effects, velocity_candidates
from ._traced import opaque_in


class Viscous(AbstractSignalTerm):
    """Viscous friction signature: a velocity, divided by `scale`."""

    signal: str = eqx.field(default="omega_m", static=True)
    scale: float = hyper(1.0, positive=True)

    key, names = labels("viscous:{signal}", "{signal}/{scale}")

    def transform(self, x: SamplesLike, xp: ModuleType) -> Float[ArrayLike, " n"]:
        return x / opaque_in(xp, self.scale)  # a constant rounds as a traced value

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The scaled velocity for the exported estimator."""
        return CSnippet(columns=(f"{c.signal(self.signal)} / {c.num(self.scale)}",))


class ViscousFriction(AbstractFriction):
    r"""Viscous friction $F_v \omega$ [N·m] (`coefficient` $F_v$)."""

    coefficient: Float[Array, ""] = bound("nonneg")

    def __call__(self, omega: Pointwise, inv: dict | None = None) -> PointwiseOut:
        return self.coefficient * omega

    def max_slope(self) -> Float[Array, ""]:
        return self.coefficient


class ViscousFamily(AbstractFamily):
    """Viscous friction: plant `viscous_m`, `viscous_l`; term `Viscous`; one candidate per
    velocity, scaled by its RMS."""

    name: ClassVar[str] = "viscous"
    terms: ClassVar[tuple] = (Viscous,)
    plant_effects: ClassVar[tuple] = friction_effects(
        "viscous",
        ViscousFriction.from_params,
        motor=lambda rated, k1, given: dict(coefficient=2.0e-4),
        output=lambda rated, k1, given: dict(coefficient=2.0),
    )
    discover_families: ClassVar[tuple] = ("viscous:omega_m", "viscous:omega_l")

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        return velocity_candidates(ctx, "viscous", Viscous, (1.0,))
