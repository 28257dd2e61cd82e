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

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

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
from ._coulomb import Coulomb, velocity_rms


class Stribeck(AbstractSignalTerm):
    r"""The Stribeck excess of a velocity, $e^{-(\omega/\omega_{st})^2}\tanh(\omega/\omega_s)$
    (`omega_st` the Stribeck speed, `omega_s` the smooth sign's speed)."""

    signal: str = eqx.field(default="omega_m", static=True)
    omega_s: float = eqx.field(default=1.0, static=True)
    omega_st: float = eqx.field(default=1.0, static=True)

    def __check_init__(self):
        check_positive("Stribeck", "omega_s", self.omega_s)
        check_positive("Stribeck", "omega_st", self.omega_st)

    @property
    def key(self) -> str:
        return f"stribeck:{self.signal}"

    def names(self) -> tuple[str, ...]:
        w, st, ws = self.signal, fmt(self.omega_st), fmt(self.omega_s)
        return (f"exp(-({w}/{st})^2)*tanh({w}/{ws})",)

    @property
    def signal_name(self) -> str:
        return self.signal

    def transform(self, x, xp):
        u = x / self.omega_st
        return xp.exp(-(u * u)) * xp.tanh(x / self.omega_s)


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
    """Stribeck friction: plant `stribeck_m`, `stribeck_l`; term `Stribeck`; a grid of Stribeck
    speeds, offered beside the Coulomb term of the same velocity."""

    name: ClassVar[str] = "stribeck"
    terms: ClassVar[tuple] = (Stribeck,)
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
    discover_families: ClassVar[tuple] = ("stribeck:omega_m", "stribeck:omega_l")
    vocabulary: ClassVar[str] = "stribeck:omega_m, stribeck:omega_l"
    options: ClassVar[dict] = {"stribeck_fractions": (0.1, 0.2, 0.35, 0.6, 1.0, 1.7)}

    def candidates(self, ctx):
        out = []
        for signal in ("omega_m", "omega_l"):
            coulomb = [
                t for t in ctx.existing_terms if isinstance(t, Coulomb) and t.signal == signal
            ]
            rms = velocity_rms(ctx.sig, signal)
            if not coulomb or rms == 0.0 or not ctx.wants(f"stribeck:{signal}"):
                continue
            omega_s = coulomb[0].omega_s
            for frac in ctx.option(self, "stribeck_fractions"):
                omega_st = float(f"{frac * rms:.4g}")
                if omega_st <= omega_s:
                    continue  # an excess narrower than the smooth sign is not a Stribeck curve
                term = Stribeck(signal=signal, omega_s=omega_s, omega_st=omega_st)
                out.append(Candidate(term.key, term.key, term))
        return out
