r"""Stribeck friction: breakaway friction above the Coulomb level at low speed.

At low sliding speed the lubricant film has not built up and friction rises above its Coulomb
level; the excess decays over a characteristic (Stribeck) speed $\omega_{st}$, so the friction is
$(F_c + F_s e^{-(\omega/\omega_{st})^2}) \tanh(\omega/\omega_s)$ (the Stribeck curve).

- **Plant** (`stribeck_m`, `stribeck_l`): the excess $F_s e^{-(\omega/\omega_{st})^2}
  \tanh(\omega/\omega_s)$ on the motor or output side (switch `coulomb_*` on for the level).
- **Term** (`Stribeck`): the column $e^{-(\omega/\omega_{st})^2}\tanh(\omega/\omega_s)$, the
  curve's low-speed excess; with the Coulomb column $\tanh(\omega/\omega_s)$ of the same velocity
  it spans the Stribeck curve of that side.
- **Candidates** (`stribeck:omega_m`, `stribeck:omega_l`): offered once the model holds the
  Coulomb term of that velocity (whose $\omega_s$ the column shares), with the Stribeck speed
  scanned on a grid of fractions of the velocity's RMS; the loop's cross-validation picks the
  member. A plain Coulomb joint leaves nothing for the excess to explain, so it is not added;
  a Stribeck joint is named as Coulomb plus the Stribeck excess of the same side, instead of
  Coulomb terms of both sides whose smoothings mimic the curve.

References: Armstrong-Hélouvry, Dupont and Canudas de Wit, "A survey of models, analysis tools
and compensation methods for the control of machines with friction", Automatica 30(7), 1994,
Section 2 (the Stribeck curve).
"""

from __future__ import annotations

from types import ModuleType
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike, Float, Pointwise, PointwiseOut, SamplesLike
from ._base import AbstractFamily, AbstractFriction, AbstractSignalTerm, Candidate, CandidateContext
from ._c import AbstractCEmitter, CSnippet
from ._coulomb import Coulomb
from ._fields import bound, hyper, labels
from ._friction import friction_effects, velocity_candidates
from ._traced import opaque_in


class Stribeck(AbstractSignalTerm):
    r"""The Stribeck excess of a velocity, $e^{-(\omega/\omega_{st})^2}\tanh(\omega/\omega_s)$
    (`omega_st` the Stribeck speed, `omega_s` the smooth sign's speed)."""

    signal: str = eqx.field(default="omega_m", static=True)
    omega_s: float = hyper(1.0, positive=True)
    omega_st: float = hyper(1.0, positive=True)

    key, names = labels(
        "stribeck:{signal}", "exp(-({signal}/{omega_st})^2)*tanh({signal}/{omega_s})"
    )

    def transform(self, x: SamplesLike, xp: ModuleType) -> Float[ArrayLike, " n"]:
        omega_st, omega_s = opaque_in(xp, self.omega_st, self.omega_s)  # as traced values
        u = x / omega_st
        return xp.exp(-(u * u)) * xp.tanh(x / omega_s)

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The Stribeck excess for the exported estimator."""
        x, u = c.signal(self.signal), c.local("u")
        return CSnippet(
            columns=(f"{c.fn('exp')}(-({u} * {u})) * {c.fn('tanh')}({x} / {c.num(self.omega_s)})",),
            lines=(f"const {c.real} {u} = {x} / {c.num(self.omega_st)};",),
        )


class StribeckFriction(AbstractFriction):
    r"""Stribeck bump $F_s e^{-(\omega/\omega_{st})^2} \tanh(\omega/\omega_s)$ [N·m].

    `peak` is the breakaway torque *above* the Coulomb level, `speed` the Stribeck speed.
    """

    peak: Float[Array, ""] = bound("nonneg")
    speed: Float[Array, ""] = bound("positive", inverse=True)
    smoothing: Float[Array, ""] = bound("positive", inverse=True)

    def __call__(self, omega: Pointwise, inv: dict | None = None) -> PointwiseOut:
        inv = self.reciprocals() if inv is None else inv
        x = omega * inv["speed"]
        return self.peak * jnp.exp(-(x * x)) * jnp.tanh(omega * inv["smoothing"])

    def max_slope(self) -> Float[Array, ""]:
        return self.peak / self.smoothing


class StribeckFamily(AbstractFamily):
    """Stribeck friction: plant `stribeck_m`, `stribeck_l`; term `Stribeck`; a grid of Stribeck
    speeds, offered beside the Coulomb term of the same velocity."""

    name: ClassVar[str] = "stribeck"
    terms: ClassVar[tuple] = (Stribeck,)
    plant_effects: ClassVar[tuple] = friction_effects(
        "stribeck",
        StribeckFriction.from_params,
        motor=lambda rated, k1, given: dict(peak=0.05, speed=2.0, smoothing=0.5),
        output=lambda rated, k1, given: dict(peak=0.005 * rated, speed=0.02, smoothing=5e-3),
    )
    discover_families: ClassVar[tuple] = ("stribeck:omega_m", "stribeck:omega_l")
    options: ClassVar[dict] = {"stribeck_fractions": (0.1, 0.2, 0.35, 0.6, 1.0, 1.7)}

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        # each side's Stribeck excess shares the smooth sign of that side's Coulomb term
        omega_s = {}
        for t in ctx.existing_terms:
            if isinstance(t, Coulomb):
                omega_s.setdefault(t.signal, t.omega_s)

        def beside_coulomb(signal, omega_st):
            ws = omega_s.get(signal)
            # an excess narrower than the smooth sign is not a Stribeck curve
            return Stribeck(signal, ws, omega_st) if ws is not None and omega_st > ws else None

        fractions = ctx.option(self, "stribeck_fractions")
        return velocity_candidates(ctx, "stribeck", beside_coulomb, fractions)
