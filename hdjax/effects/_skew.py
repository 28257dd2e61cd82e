r"""Encoder time skew: the motor and load encoders are not sampled at the same instant.

A drive that reads its two encoders over separate buses (or latches them at different points of
its cycle) records $\theta_l$ a little before or after $\theta_m$. With the load encoder read
$\delta$ after the motor encoder, the recorded twist is

$$\Delta\theta_{rec}(t) = s\,\big(\theta_l(t + \delta) - \theta_m(t)/N\big)
 = \Delta\theta(t) + s\,\big(\theta_l(t + \delta) - \theta_l(t)\big)
 \approx \Delta\theta(t) + \delta\, s\,\omega_l ,$$

a twist proportional to the link speed that a compliance model reads as torque: about 400 arcsec
per rad/s on a joint whose encoders are 2 ms apart, far more than the joint's viscous friction
explains. To first order it is the column of output-side viscous friction
([`hdjax.effects.Viscous`][] of `omega_l`); the residual loop screens it with that column,
then refits it exactly.

**Term** (`EncoderSkew`): the exact correction of a delay $\delta$ as one column whose
coefficient *is* the delay [s]:
$c_\delta(t) = s\,(x(t) - x(t - |\delta|))/|\delta|$, with $x = \theta_l$ for $\delta > 0$ and
$x = \theta_m/N$ for $\delta < 0$ (the encoder read earlier is interpolated back to the later
one's instant, so only recorded samples at or before $t$ are read: causal), linear
interpolation on the recording's own timestamps (jitter and dropped samples included, never
across a long gap: where `SEGMENT_START` marks a new segment, the column starts again as at
the record's start, see `delayed`). The twist then holds $\delta\,c_\delta$ exactly; a fit's
coefficient $\hat\delta$ differs from the term's $\delta$ only through the column's
curvature terms, and the loop refits at $\delta = \hat\delta$ until the two agree
([`EncoderSkew.refined`][]). When $|\delta|$ is below the sample period the column is the
backward-difference speed, for any $\delta$.

**Skew or friction.** Output-side friction between the flexspline and the reference sensor adds
$F_v\omega_l$ to the twist-derived torque; the motor current carries that friction and the
motor side's too, so a velocity term in the twist that, in N·m, exceeds the current's own
viscous slope is no friction: it is a skew (see [`velocity_reading`][]).

References: Song et al. 2019, eq. (5) (the twist of the two encoders); the encoder skew of a
real joint: the LARA8 logs of `shared/data/lara8` (about 2 ms).
"""

from __future__ import annotations

from types import ModuleType
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float, SamplesLike, Scalar
from .._errors import ConfigError
from .._features import Signals
from ._base import (
    SEGMENT_START,
    AbstractFamily,
    AbstractTorqueFreeTerm,
    Candidate,
    CandidateContext,
)
from ._c import AbstractCEmitter, CSnippet
from ._fields import fmt, hyper, rounded
from ._traced import opaque_in

BACK_SAMPLES = 16
"""How many samples back the delayed encoder value is searched (a delay of up to this many
sample periods; a longer one is held at the oldest)."""

SCREEN_DELAY = 1e-3
"""The delay [s] of the screening candidate (the column hardly depends on it)."""

SKEW_MARGIN = 1.5
"""A velocity term in the twist is read as a skew when, in N·m, it exceeds this many times the
current's viscous slope (with two standard errors): friction in the twist cannot exceed the
friction in the current, and the compliance that converts the twist to torque is known to
some tens of percent (it varies along the torque)."""

REFINE_RTOL = 1e-3
"""A fitted delay within this fraction of the term's own is taken as converged."""


def delayed(t, x, delay: Scalar, xp: ModuleType = np, reset=None):
    """`x` at the instants `t - delay` (`delay >= 0`), by linear interpolation between the
    recorded samples at or before each instant (up to `BACK_SAMPLES` back, the oldest of them
    beyond); an instant before the record starts keeps the sample's own value. Samples across
    a time reversal (joined recordings) are never read, nor across a sample where `reset`
    (1 at the first sample of a segment, the signal `SEGMENT_START`) is set: an instant
    before its segment starts is one before the record starts. Across shorter gaps (dropped
    samples, where memory states carry on too) the angle is interpolated; across a long
    one, where the joint may have done anything (the join of two recordings, the blocks of
    a split log), interpolation would read a speed the joint never had."""
    t, x = xp.asarray(t), xp.asarray(x)
    n = t.shape[0]
    reset = xp.zeros(n, bool) if reset is None else xp.asarray(reset) != 0

    def shift(a, m):  # a[k - m] at k, the first value repeated before the start
        m = min(m, n)
        return xp.concatenate([xp.repeat(a[:1], m), a[: n - m]])

    target = t - delay
    out, done = x, xp.zeros(n, bool)
    hi_t, hi_x, hi_r = t, x, reset
    for m in range(1, BACK_SAMPLES + 1):
        # the pair (k - m, k - m + 1) around the target, inside one increasing run of t
        lo_t, lo_x = shift(t, m), shift(x, m)
        edge = (lo_t >= hi_t) | hi_r  # the record's or a segment's start, a time reversal
        inside = ~done & ~edge & (lo_t <= target)
        frac = (target - lo_t) / xp.where(edge, 1.0, hi_t - lo_t)
        out = xp.where(inside, lo_x + frac * (hi_x - lo_x), out)
        done = done | inside | edge
        hi_t, hi_x, hi_r = lo_t, lo_x, shift(reset, m)
    return xp.where(done, out, hi_x)


def skew_column(sig: Signals, delay, ratio, sign, xp: ModuleType = np):
    """The column $c_\\delta$ of a delay `delay` $\\delta$ [s] (nonzero) between the load and
    the motor encoder (module docstring): $s\\,(x(t) - x(t - |\\delta|))/|\\delta|$, the
    encoder read earlier ($x = \\theta_l$ for $\\delta > 0$, $\\theta_m/N$ for
    $\\delta < 0$) interpolated back by [`delayed`][]. The recorded twist less
    $\\delta\\,c_\\delta$ is the twist of the two encoders read at one instant (Song et al.
    eq. (5)). Written for values that are traced too (a compiled column program serves every
    delay, see `split_hypers`): both encoders' angles, the later one selected."""
    d = xp.abs(delay)
    t = xp.asarray(sig.t)
    x = xp.where(delay > 0, xp.asarray(sig.theta_l), xp.asarray(sig.theta_m) / ratio)
    return sign * (x - delayed(t, x, d, xp, sig.extras.get(SEGMENT_START))) / d


class EncoderSkew(AbstractTorqueFreeTerm):
    r"""A time skew `delay` $\delta$ [s] between the load and motor encoders (positive: the load
    encoder is read after the motor encoder) as the exact twist it adds, one column
    $c_\delta$ whose coefficient is the delay (module docstring).

    **Arguments:** `delay` (the delay the column is built for, nonzero), `ratio` $N$, `sign`
    (the joint's twist sign).
    """

    delay: float = hyper(SCREEN_DELAY)
    ratio: float = hyper(1.0, positive=True)
    sign: float = hyper(1.0)

    coefficient_label: ClassVar[tuple[str, float]] = ("delay_ms", 1e3)
    """The coefficient is the delay: reported in ms, with its own interval."""

    @property
    def key(self) -> str:
        """The vocabulary key: skew:encoders."""
        return "skew:encoders"

    def names(self) -> tuple[str, ...]:
        """One column, named by the delay it is built for [ms]."""
        return (f"skew({fmt(round(self.delay * 1e3, 6))} ms)",)

    def __check_init__(self):
        if isinstance(self.delay, (int, float)) and not (np.isfinite(self.delay) and self.delay):
            raise ConfigError(f"EncoderSkew: delay must be finite and nonzero, got {self.delay!r}")

    def _column(self, sig: Signals, xp: ModuleType):
        # constants made opaque round as traced values do
        return skew_column(sig, *opaque_in(xp, self.delay, self.ratio, self.sign), xp)

    def columns(self, sig: Signals, torque: SamplesLike | None = None) -> Float[Array, "n 1"]:
        return self._column(sig, jnp)[:, None]

    def numpy_columns(
        self, sig: Signals, torque: SamplesLike | None = None
    ) -> Float[np.ndarray, "n 1"]:
        return self._column(sig, np)[:, None]

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The column for the exported estimator: the last `BACK_SAMPLES` samples of the
        encoder read earlier kept (double) in the state, and the interpolation of `delayed`
        over them, step for step (bounded: `BACK_SAMPLES` pairs per sample)."""
        m = BACK_SAMPLES + 1
        d = abs(float(self.delay))
        x_now = (
            c.angle("theta_l")
            if self.delay > 0
            else f"({c.angle('theta_m')} / {c.dnum(self.ratio)})"
        )
        ts = [c.state(f"t{j}") for j in range(m)]
        xs = [c.state(f"x{j}") for j in range(m)]
        tb, xb, xn, col = c.local("tb"), c.local("xb"), c.local("xnow"), c.local("col")
        update = [f"const double {xn} = {x_now};", f"if ({c.first}) {{"]
        update += [f"    {a} = {c.time()}; {b} = {xn};" for a, b in zip(ts, xs)]
        update += ["} else {"]
        update += [
            f"    {ts[j]} = {ts[j - 1]}; {xs[j]} = {xs[j - 1]};" for j in range(m - 1, 0, -1)
        ]
        update += [f"    {ts[0]} = {c.time()}; {xs[0]} = {xn};", "}"]
        update += [
            f"const double {tb}[{m}] = {{{', '.join(ts)}}};",
            f"const double {xb}[{m}] = {{{', '.join(xs)}}};",
            f"const {c.real} {col} = ({c.real})({c.dnum(self.sign)} * ({xn} - "
            f"hdjax_skew_delayed({tb}, {xb}, {c.time()} - {c.dnum(d)})) / {c.dnum(d)});",
        ]
        helper = f"""\
static double hdjax_skew_delayed(const double *tb, const double *xb, double target)
{{
    /* delayed() of the skew family: x at the instant target, by linear interpolation between the
       pairs of the last {m} samples (tb[0], xb[0] the present one) at or before it */
    double out = xb[0], hi_t = tb[0], hi_x = xb[0];
    int done = 0, j;
    for (j = 1; j < {m}; ++j) {{
        const double lo_t = tb[j], lo_x = xb[j];
        const int edge = lo_t >= hi_t;
        if (!done && !edge && lo_t <= target)
            out = lo_x + (target - lo_t) / (hi_t - lo_t) * (hi_x - lo_x);
        done = done || edge || lo_t <= target;
        hi_t = lo_t;
        hi_x = lo_x;
    }}
    return done ? out : hi_x;
}}"""
        state = tuple((f"t{j}", 0.0) for j in range(m)) + tuple((f"x{j}", 0.0) for j in range(m))
        return CSnippet(columns=(col,), double_state=state, update=tuple(update), helpers=(helper,))

    def refined(self, coef: Float[np.ndarray, " 1"]) -> EncoderSkew | None:
        """The term at the fitted delay `coef[0]` [s], or `None` when that agrees with this
        term's own delay (to `REFINE_RTOL`) or is zero: the fixed point at which the column is
        the exact interpolation of the delay the fit finds."""
        d = float(np.asarray(coef).reshape(-1)[0])
        if not np.isfinite(d) or d == 0.0 or abs(d - self.delay) <= REFINE_RTOL * abs(d):
            return None
        return EncoderSkew(delay=rounded(d, 6), ratio=self.ratio, sign=self.sign)


def velocity_reading(twist_term: float, current_slope: tuple[float, float] | None) -> str:
    """Which reading a velocity term in the twist supports, as a sentence.

    **Arguments:** `twist_term` (the twist's velocity term as a torque, N·m per rad/s of link
    speed: its coefficient over the compliance), `current_slope` (the current's own viscous
    slope and its standard error, N·m·s/rad, from [`current_viscous_slope`][]; `None` when the
    log has no current distinct from the reference torque).
    """
    size = f"{abs(twist_term):.3g} N·m·s/rad"
    if current_slope is None:
        return (
            f"the twist carries a velocity term of {size}: output-side viscous friction and an "
            "encoder time skew give the same column here, and without a motor current distinct "
            "from the reference torque nothing tells them apart; check the encoders' sampling "
            "instants (a skew of a few ms is common), or record the motor current to decide"
        )
    slope, se = current_slope
    # friction in the twist is at most the friction in the current; the margin covers the
    # compliance the twist is converted to torque by
    upper = SKEW_MARGIN * (abs(slope) + 2.0 * se)
    if abs(twist_term) > upper:
        return (
            f"skew, not friction: the twist's velocity term ({size}) is over {SKEW_MARGIN:g} "
            f"times the viscous friction the motor current shows ({abs(slope):.3g} ± "
            f"{2 * se:.2g} N·m·s/rad), "
            "which includes every friction the twist could see; correct the encoders' "
            "timestamps rather than the friction model"
        )
    return (
        f"friction, not skew: the twist's velocity term ({size}) is within {SKEW_MARGIN:g} "
        f"times the viscous friction the motor current shows ({abs(slope):.3g} ± {2 * se:.2g} "
        "N·m·s/rad)"
    )


def current_viscous_slope(
    current: Float[ArrayLike, " n"], torque: Float[ArrayLike, " n"], omega: Float[ArrayLike, " n"]
) -> tuple[float, float] | None:
    """The motor current's viscous friction slope [N·m·s/rad] and its standard error: the
    least-squares coefficient of the link speed when the reference torque is regressed on the
    current (in torque units by its fitted gain), a constant, a Coulomb step and the speed;
    `None` when the current is the reference itself (a log whose only torque is current-based)
    or does not vary."""
    i, tq, w = (np.asarray(x, np.float64) for x in (current, torque, omega))
    ok = np.isfinite(i) & np.isfinite(tq) & np.isfinite(w)
    i, tq, w = i[ok], tq[ok], w[ok]
    if i.size < 10 or np.ptp(i) == 0 or np.ptp(w) == 0:
        return None
    if np.corrcoef(i, tq)[0, 1] > 1.0 - 1e-9:
        return None
    scale = np.quantile(np.abs(w), 0.9) * 0.05 or 1.0
    x = np.column_stack([i, np.ones_like(i), np.tanh(w / scale), w])
    beta, *_ = np.linalg.lstsq(x, tq, rcond=None)
    gain = beta[0]
    if not gain != 0:
        return None
    r = tq - x @ beta
    cov = np.linalg.pinv(x.T @ x) * float(r @ r) / max(1, i.size - 4)
    # T = g I - F_v w (+ ...): the current's friction slope in N·m·s/rad is -beta_w
    return float(-beta[3]), float(np.sqrt(max(cov[3, 3], 0.0)))


CRUISE_BAND = 0.1
"""A moving sample cruises when its speed lies within this fraction of the median moving
speed."""

ONE_SPEED_SHARE = 0.7
"""A record moves at one speed when more than this share of its moving samples cruise."""


def cruise_share(omega: SamplesLike) -> tuple[float, float]:
    """`(share, speed)`: the share of the moving samples (speed over 2 % of the 99th
    percentile) whose speed lies within `CRUISE_BAND` of their median speed, and that median
    [rad/s]. Near 1, a twist proportional to speed (a skew, Song et al. eq. (5) read at two
    instants; viscous friction) is a constant times the direction while moving, the same
    column as Coulomb friction and, on a one-way sweep, as an offset the compliance absorbs:
    only the accelerations tell them apart."""
    w = np.abs(np.asarray(omega, np.float64))
    if w.size == 0:
        return 0.0, 0.0
    moving = w > 0.02 * np.quantile(w, 0.99)
    if not moving.any():
        return 0.0, 0.0
    speed = float(np.median(w[moving]))
    return float(np.mean(np.abs(w[moving] - speed) <= CRUISE_BAND * speed)), speed


class SkewFamily(AbstractFamily):
    """Encoder time skew: term `EncoderSkew`; one screening candidate at `SCREEN_DELAY`, signed
    as the velocity it follows (no plant effect: the sensor model of
    [`hdjax.plant.real_log`][] simulates a skew)."""

    name: ClassVar[str] = "skew"
    terms: ClassVar[tuple] = (EncoderSkew,)
    discover_families: ClassVar[tuple] = ("skew:encoders",)

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        if not ctx.wants("skew:encoders"):
            return []
        w = np.asarray(ctx.sig.omega_l)
        if ctx.sig.t is None or not np.any(w != 0):
            ctx.cannot_identify(
                "skew:encoders",
                "the link never moves, and a skew shows only as a twist proportional to speed",
                "record the joint moving",
            )
            return []
        share, speed = cruise_share(w)
        if share > ONE_SPEED_SHARE:
            ctx.barely_identify(
                "skew:encoders",
                f"TRAIN moves at one speed ({speed:.3g} rad/s in {100 * share:.0f} % of its "
                "moving samples), where a skew's twist, like viscous friction's, is a constant "
                "while moving that the compliance, Coulomb friction, hysteresis or a harmonic "
                "of the output angle absorbs, so only the accelerations tell them apart",
                "record the joint at two or more speeds before trusting a skew, viscous "
                "friction or their absence",
            )
        term = EncoderSkew(delay=SCREEN_DELAY, ratio=float(ctx.ratio), sign=float(ctx.twist_sign))
        return [Candidate.of(term)]
