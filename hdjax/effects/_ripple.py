r"""Compliance ripple: the joint's stiffness varies with the wave-generator or the output angle.

The elliptical wave generator pushes the flexspline's teeth into the circular spline at its two
lobes; as it turns, the number of teeth in contact and the flexspline's bending change twice per
revolution, so the torsional compliance is modulated at two per motor revolution (and its
harmonics). An eccentric output bearing or flexspline modulates it once per output revolution.
Unlike the kinematic error (a twist offset, [`hdjax.effects.Harmonics`][]), the ripple scales
with the load: at compliance $k(\theta) = k\,(1 + \varepsilon(\theta))$,
$\varepsilon(\theta) = \sum_j a_j \sin(K_j\theta + \varphi_j)$, the twist gains
$\varepsilon(\theta)\,k\,T$.

- **Plant** (`ripple_m`, `ripple_l`): the series compliance budget $G(T)$ of the joint (the
  flexspline, the wave generator, the lost motion) is scaled by $1 + \varepsilon(\theta)$ of the
  recorded motor or load angle, so the elastic torque solves $G(T_s) = d_{eff}/(1 + \varepsilon)$.
  The defaults are a 3 % ripple at 2 per motor revolution.
- **Term** (`Ripple`): the pair $T/\tau_0 \cdot \sin K\theta$, $T/\tau_0 \cdot \cos K\theta$,
  linear in torque and so inverted in closed form (the slope is
  $u(\theta) = (c_s \sin K\theta + c_c \cos K\theta)/\tau_0$).
- **Candidates** (`ripple:theta_m:K`, `ripple:theta_l:K`): the orders come from the order
  spectrum of residual $\div$ torque (samples with a small torque left out, where the ratio is
  noise), merged with the named orders (2 and 4 per motor revolution, 1 and 2 per output
  revolution). An order is offered only when the angle turns through at least
  `ripple_min_periods` (3) of its periods: over fewer, $T \sin K\theta$ is nearly a smooth
  function of the torque path (with the link held, the motor angle follows the twist) and
  stands in for compliance structure that is no ripple.

References: Tuttle and Seering, "A nonlinear model of a harmonic drive gear transmission",
IEEE Trans. Robotics and Automation 12(3), 1996 (the compliance and its variation with the
wave-generator angle); Song et al. 2019, eq. (7) (the compliance that the ripple modulates).
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .. import _trig
from .._custom_types import Array, Bool, Float, Pointwise, PointwiseOut, SamplesLike
from .._errors import ConfigError
from .._features import Signals
from .._trig import sincos
from ._base import (
    AbstractFamily,
    AbstractLinearTorqueTerm,
    AbstractPlantEffect,
    Candidate,
    CandidateContext,
    both_sides,
)
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, concrete, fmt, hyper
from ._traced import opaque

MAX_RIPPLE = 0.5
"""Largest total relative ripple $\\sum_j a_j$ the plant accepts (the compliance stays positive)."""


def ripple_key(signal: str, order: float) -> str:
    """The vocabulary key of a compliance ripple of one order of one angle."""
    return f"ripple:{signal}:{fmt(round(order, 6))}"


class Ripple(AbstractLinearTorqueTerm):
    r"""Compliance modulated by one harmonic of an angle: $T/\tau_0 \cdot (\sin K\theta,
    \cos K\theta)$, linear in torque.

    **Arguments:** `signal` (`"theta_m"` or `"theta_l"`), `order` $K$, `torque_scale` $\tau_0$
    (the rated torque, so the coefficients are twists at rated torque).
    """

    signal: str = hyper("theta_m")
    order: float = hyper(2.0, positive=True)
    torque_scale: float = hyper(1.0, positive=True)

    @property
    def key(self) -> str:
        return ripple_key(self.signal, self.order)

    def names(self) -> tuple[str, ...]:
        k, s, t = fmt(self.order), self.signal, fmt(self.torque_scale)
        return (f"T/{t}*sin({k}*{s})", f"T/{t}*cos({k}*{s})")

    def torque_slope(self, sig: Signals) -> Float[Array, "n 2"]:
        s, c = sincos(opaque(self.order) * sig.get(self.signal))  # as a traced order rounds
        return jnp.stack([s, c], axis=1) * opaque(1.0 / self.torque_scale)

    def numpy_torque_slope(self, sig: Signals) -> Float[np.ndarray, "n 2"]:
        th = self.order * np.asarray(sig.get(self.signal))
        return np.column_stack([np.sin(th), np.cos(th)]) / self.torque_scale

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The torque slopes $(\\sin K\\theta, \\cos K\\theta)/\\tau_0$ for the exported
        estimator."""
        s, co, inv = c.local("s"), c.local("c"), c.num(1.0 / self.torque_scale)
        arg = f"{c.dnum(self.order)} * {c.angle(self.signal)}"
        return CSnippet(columns=(f"{s} * {inv}", f"{co} * {inv}"), lines=(c.sincos(arg, s, co),))


class ComplianceRipple(AbstractPlantEffect):
    r"""Relative change of the joint's compliance, $\varepsilon(\theta) = \sum_j a_j
    \sin(K_j\theta + \varphi_j)$, of one recorded angle (motor for `ripple_m`, load for
    `ripple_l`); the plant scales the series compliance by $1 + \varepsilon$.

    **Arguments:** `orders` $K_j$, `amplitudes` $a_j$ (fractions of the compliance, e.g. 0.03;
    their sum below 0.5), `phases` $\varphi_j$ [rad], each of shape `(n,)`.
    """

    orders: Float[Array, " n"] = bound("positive")
    amplitudes: Float[Array, " n"] = bound("nonneg")
    phases: Float[Array, " n"]

    def __call__(self, angle: Pointwise, inv: dict | None = None) -> PointwiseOut:
        return _trig.harmonic_sum(self.orders, self.amplitudes, self.phases, angle)

    def max_change(self) -> Float[Array, ""]:
        """$\\sum_j |a_j|$, the largest relative change (the integrator's stiffness check)."""
        return jnp.sum(jnp.abs(self.amplitudes))


def _build(name: str, p: dict) -> ComplianceRipple:
    ripple = ComplianceRipple.from_params(name, p)
    total = concrete(ripple.amplitudes)
    if total is not None and not float(np.sum(total)) < MAX_RIPPLE:
        raise ConfigError(
            f"effect {name!r}: the amplitudes are fractions of the compliance and must sum to "
            f"less than {MAX_RIPPLE} (a compliance ripple is a few %), got {total.tolist()}"
        )
    return ripple


def torque_ratio(
    residual: SamplesLike, torque: SamplesLike, rated_torque: float
) -> tuple[Float[np.ndarray, " m"], Bool[np.ndarray, " n"]]:
    r"""Residual $\div$ torque where the torque is large enough for the ratio to mean something.

    Samples with $|T| < \max(0.05\,\tau_0, 0.3\,\mathrm{RMS}(T))$ are left out (near zero torque
    the ratio is noise over a small number). **Returns:** `(ratio, keep)`, `keep` the boolean
    mask of the samples used (`ratio` has `keep.sum()` entries).
    """
    t = np.asarray(torque, np.float64)
    guard = max(0.05 * float(rated_torque), 0.3 * float(np.sqrt(np.mean(t * t))))
    keep = np.abs(t) >= guard
    return np.asarray(residual, np.float64)[keep] / t[keep], keep


MIN_RATIO_SAMPLES = 200
"""Fewest samples with a usable torque for the residual ÷ torque spectrum (else named orders
only)."""


class RippleFamily(AbstractFamily):
    """Compliance ripple: plant `ripple_m`, `ripple_l`; term `Ripple`; orders from the spectrum
    of residual ÷ torque (`ripple:theta_m:ORDER`, `ripple:theta_l:ORDER`)."""

    name: ClassVar[str] = "ripple"
    terms: ClassVar[tuple] = (Ripple,)
    plant_effects: ClassVar[tuple] = both_sides(
        "ripple",
        "compliance_ripple",
        _build,
        motor=lambda rated, k1, given: dict(orders=[2.0], amplitudes=[0.03], phases=[0.4]),
        output=lambda rated, k1, given: dict(orders=[1.0], amplitudes=[0.03], phases=[0.0]),
    )
    discover_families: ClassVar[tuple] = ("ripple:theta_m", "ripple:theta_l")
    vocabulary: ClassVar[str] = "ripple:theta_m:ORDER, ripple:theta_l:ORDER"
    options: ClassVar[dict] = {
        "ripple_orders_m": (0.5, 8.0),
        # the output side's ripple sources (an eccentric bearing or flexspline) are low orders;
        # a high order of a partial swing under a gravity-like load is a function of the torque
        # path and stands in for compliance structure that is no ripple
        "ripple_orders_l": (0.5, 4.0),
        "ripple_named_orders_m": (2.0, 4.0),
        "ripple_named_orders_l": (1.0, 2.0),
        "ripple_n_peaks": 2,
        "ripple_min_periods": 3.0,
    }

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        existing = {"theta_m": [], "theta_l": []}
        for term in ctx.existing_terms:
            if isinstance(term, Ripple):
                existing[term.signal].append(term.order)
        ratio, keep = torque_ratio(ctx.residual, ctx.torque, ctx.rated_torque)
        out = []
        for signal, suffix in (("theta_m", "m"), ("theta_l", "l")):
            if f"ripple:{signal}" not in ctx.families:
                continue
            # too few samples with a usable torque: the named orders only
            enough = keep.sum() >= MIN_RATIO_SAMPLES
            lo, hi = ctx.option(self, f"ripple_orders_{suffix}")
            span = float(np.ptp(np.asarray(ctx.sig.get(signal))))
            periods = ctx.option(self, "ripple_min_periods")
            lo = max(lo, periods * 2.0 * math.pi / span) if span > 0.0 else math.inf
            if lo > hi:
                ctx.cannot_identify(
                    f"ripple:{signal}",
                    f"{signal} turns through {span:.3g} rad, fewer than {periods:g} periods of "
                    f"the highest order searched ({hi:g})",
                    f"record {periods * 2.0 * math.pi / hi:.3g} rad of {signal} or more",
                )
                continue
            orders = ctx.spectrum_orders(
                signal,
                (lo, hi),
                list(ctx.option(self, f"ripple_named_orders_{suffix}")),
                existing[signal],
                ctx.option(self, "ripple_n_peaks") if enough else 0,
                residual=ratio if enough else np.asarray(ctx.residual),
                where=keep if enough else None,
            )
            for k, origin in orders:
                term = Ripple(signal, float(round(k, 6)), float(ctx.rated_torque))
                out.append(Candidate(term.key, f"ripple:{signal}", term, origin))
        return out
