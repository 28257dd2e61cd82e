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

from types import ModuleType
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike, Float, Pointwise, PointwiseOut, SamplesLike
from ._base import AbstractFamily, AbstractFriction, AbstractSignalTerm, Candidate, CandidateContext
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, hyper, labels
from ._friction import friction_effects, velocity_candidates
from ._traced import opaque_in


class Coulomb(AbstractSignalTerm):
    """Coulomb-like friction signature, a smooth sign $\\tanh(\\omega/\\omega_s)$ of a velocity."""

    signal: str = eqx.field(default="omega_m", static=True)
    omega_s: float = hyper(1.0, positive=True)

    key, names = labels("coulomb:{signal}", "tanh({signal}/{omega_s})")

    def transform(self, x: SamplesLike, xp: ModuleType) -> Float[ArrayLike, " n"]:
        return xp.tanh(x / opaque_in(xp, self.omega_s))  # as a traced value rounds

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The smooth sign for the exported estimator."""
        return CSnippet(
            columns=(f"{c.fn('tanh')}({c.signal(self.signal)} / {c.num(self.omega_s)})",)
        )


class CoulombFriction(AbstractFriction):
    r"""Coulomb friction $F_c \tanh(\omega/\omega_s)$ [N·m] (`level` $F_c$, `smoothing`
    $\omega_s$)."""

    level: Float[Array, ""] = bound("nonneg")
    smoothing: Float[Array, ""] = bound("positive", inverse=True)

    def __call__(self, omega: Pointwise, inv: dict | None = None) -> PointwiseOut:
        inv = self.reciprocals() if inv is None else inv
        return self.level * jnp.tanh(omega * inv["smoothing"])

    def max_slope(self) -> Float[Array, ""]:
        return self.level / self.smoothing


class CoulombFamily(AbstractFamily):
    """Coulomb friction: plant `coulomb_m`, `coulomb_l`; term `Coulomb`; a grid of smoothing
    speeds $\\omega_s$, fractions of the velocity's RMS."""

    name: ClassVar[str] = "coulomb"
    terms: ClassVar[tuple] = (Coulomb,)
    plant_effects: ClassVar[tuple] = friction_effects(
        "coulomb",
        CoulombFriction.from_params,
        motor=lambda rated, k1, given: dict(level=0.1, smoothing=0.5),
        output=lambda rated, k1, given: dict(level=0.0075 * rated, smoothing=5e-3),
    )
    discover_families: ClassVar[tuple] = ("coulomb:omega_m", "coulomb:omega_l")
    options: ClassVar[dict] = {"smoothing_fractions": (0.003, 0.01, 0.03, 0.1, 0.3)}

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        return velocity_candidates(ctx, "coulomb", Coulomb, ctx.option(self, "smoothing_fractions"))
