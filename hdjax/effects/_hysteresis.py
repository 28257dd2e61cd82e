r"""Hysteresis: the twist depends on the torque's history, not only its present value.

Loading and unloading a harmonic drive trace different twist-torque curves (Song et al. Fig. 2,
the loop B to B'): friction inside the flexspline teeth and the wave-generator bearing stores and
releases a torque. The plant carries a hysteresis torque $z$ in parallel with the elastic torque,
driven by the deflection rate, with a Bouc-Wen, Dahl or LuGre law. The regression term is a
causal, rate-independent Dahl state, $z_k = z_{k-1} + \frac{\Delta u_k}{T_h}
(1 - z_{k-1}\,\mathrm{sgn}\,\Delta u_k)$, of the torque path (`Hysteresis`: at estimation driven
by the torque being estimated, by an implicit causal step, never by the reference sensor) or of
the measured twist over the compliance (`TwistHysteresis`, what the residual loop offers: the
plant's laws follow the deflection). The loop scans $T_h$ on a grid of fractions of the rated
torque.

References: Song et al. 2019, Section II and Fig. 2; P. R. Dahl, "Solid friction damping of
mechanical vibrations", AIAA Journal 14(12), 1976.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import (
    Array,
    ArrayLike,
    Float,
    Pointwise,
    PointwiseOut,
    Samples,
    SamplesLike,
    Scalar,
    Shaped,
)
from .._errors import ConfigError, did_you_mean
from .._features import Signals
from ._base import (
    SEGMENT_START,
    TORQUE_PATH,
    AbstractFamily,
    AbstractHysteresis,
    AbstractPathTerm,
    AbstractTerm,
    AbstractTorqueFreeTerm,
    Candidate,
    CandidateContext,
    PlantEffect,
    late,
)
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, concrete, fmt, hyper, is_zero, labels
from ._skew import BACK_SAMPLES, EncoderSkew, skew_column
from ._traced import opaque_hypers


def dahl_state(
    torque: SamplesLike, torque_scale: Scalar, reset: Shaped[ArrayLike, " n"] | None = None
) -> Samples:
    """Causal Dahl-type hysteresis state driven by a torque path.

    $z_k = z_{k-1} + \\frac{\\Delta T_k}{T_h} (1 - z_{k-1}\\,\\mathrm{sgn}\\,\\Delta T_k)$,
    clipped to $[-1, 1]$: the rate-independent Dahl model ($\\sigma = 1$) with the torque as its
    input, so
    $z$ saturates at $\\pm 1$ after a torque reversal of a few $T_h$ (the loop of Song et al.
    Fig. 2, B to B'). Starts at $z_0 = 0$, and restarts at 0 wherever `reset` (optional, nonzero
    at the first sample of a segment after a gap) is set.
    """

    dT = jnp.diff(torque, prepend=torque[:1]) / torque_scale
    if reset is None:
        reset = jnp.zeros(dT.shape, bool)
    return _dahl_scan(dT, jnp.asarray(reset).astype(bool))


@jax.jit
def _dahl_scan(du, reset):
    # du = dT / T_h, so one compiled scan serves every torque scale.
    def _step(z, x):
        d, rs = x
        # a segment after a gap starts afresh: no state, no step across the gap
        z, d = jnp.where(rs, 0.0, z), jnp.where(rs, 0.0, d)
        # Dahl: dz = dT/Th * (1 - z sign(dT)); explicit step, clipped for large steps.
        z = jnp.clip(z + d * (1.0 - z * jnp.sign(d)), -1.0, 1.0)
        return z, z

    return jax.lax.scan(_step, jnp.zeros((), du.dtype), (du, reset))[1]


def dahl_state_numpy(
    torque: SamplesLike, torque_scale: Scalar, reset: Shaped[ArrayLike, " n"] | None = None
) -> Float[np.ndarray, " n"]:
    """[`dahl_state`][] in NumPy, vectorised (no loop over samples).

    With $d_k = \\Delta T_k / T_h$ and $|z_{k-1}| \\le 1$, one step of the clipped recursion is
    the affine map $z_k = a_k z_{k-1} + b_k$: $a_k = 1 - |d_k|$, $b_k = d_k$ while $|d_k| < 1$
    (the clip never binds: $1 - z_k = (1 - z_{k-1})(1 - d_k) \\ge 0$ for $d_k \\ge 0$, and
    symmetrically), $a_k = 0$, $b_k = \\mathrm{sgn}\\,d_k$ once $|d_k| \\ge 1$ (the step
    saturates), and $a_k = b_k = 0$ at a reset. The linear recurrence is solved in blocks
    (`_affine_recurrence`); since $0 \\le a_k \\le 1$ rounding errors do not grow, and the
    result equals the sequential loop to a few units in the last place.
    """
    torque = np.asarray(torque, np.float64)
    du = np.diff(torque, prepend=torque[:1]) / torque_scale
    ad = np.abs(du)
    small = ad < 1.0
    a = np.where(small, 1.0 - ad, 0.0)
    b = np.where(small, du, np.sign(du))
    if reset is not None:
        # a segment after a gap starts afresh: no state, no step across the gap
        r = np.asarray(reset).astype(bool)
        a[r], b[r] = 0.0, 0.0
    return np.clip(_affine_recurrence(a, b), -1.0, 1.0)


def _affine_recurrence(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """$z_k = a_k z_{k-1} + b_k$ from $z_{-1} = 0$, in blocks of about $\\sqrt n$ samples.

    Each block runs the recursion from a zero state, all blocks at once (a loop over the
    position in the block, vectorised over the blocks); the state entering each block is then
    carried block to block, and added through the block's running product of $a$.
    """
    n = a.size
    if n == 0:
        return np.zeros(0)
    m = max(1, int(np.sqrt(n)))
    n_blocks = -(-n // m)
    pad = n_blocks * m - n
    # row j holds position j of every block, so each step below reads contiguous memory
    aa = np.concatenate([a, np.ones(pad)]).reshape(n_blocks, m).T.copy()
    bb = np.concatenate([b, np.zeros(pad)]).reshape(n_blocks, m).T.copy()
    for j in range(1, m):
        bb[j] += aa[j] * bb[j - 1]
    prod = np.cumprod(aa, axis=0)
    carry = np.zeros(n_blocks)
    z = 0.0
    for i in range(1, n_blocks):
        z = bb[-1, i - 1] + prod[-1, i - 1] * z
        carry[i] = z
    bb += prod * carry[None, :]
    return bb.T.reshape(-1)[:n]


def dahl_initial(
    driver: SamplesLike, torque_scale: Scalar, reset: Shaped[ArrayLike, " n"] | None = None
) -> Float[ArrayLike, " n"]:
    r"""The column that carries a Dahl state's initial value: $s\,P_k$ with
    $P_k = \prod_{j \le k} a_j$, $a_j = \max(0, 1 - |\Delta u_j| / T_h)$, from 1 at the record's
    start (and at each `reset`), and $s$ the direction of the driver's first substantial motion
    there (the sign of its displacement when $P$ first falls below 1/2).

    While no step saturates, the clipped recursion of [`dahl_state`][] is affine in its state
    ($z_k = a_k z_{k-1} + b_k$, see [`dahl_state_numpy`][]), so the state started from
    $z_0 = \zeta s$ is exactly `dahl_state` $+\ \zeta\,s P_k$: the initial state is one more
    linear coefficient. It is taken relative to the first motion's direction because a sweep
    from rest usually starts with the state its previous motion left, the other way
    ($\zeta pprox -1$). $s$ looks ahead to that first motion (at most until $P < 1/2$); before
    any motion the column is $\pm 1$ and constant, so it only shifts the twist at rest.
    """
    if isinstance(driver, jax.Array):
        r = jnp.zeros(driver.shape, bool) if reset is None else jnp.asarray(reset) != 0
        return _initial_jax(jnp.asarray(driver, jnp.float64), torque_scale, r)
    u = np.asarray(driver, np.float64)
    n = u.size
    du = np.abs(np.diff(u, prepend=u[:1])) / torque_scale
    r = np.zeros(n, bool) if reset is None else np.asarray(reset) != 0
    if n:
        r[0] = True
    a = np.where(r, 1.0, np.maximum(0.0, 1.0 - du))
    starts = np.flatnonzero(r)
    ends = np.r_[starts[1:], n]
    out = np.empty(n)
    for lo, hi in zip(starts, ends):
        p = np.cumprod(a[lo:hi])
        below = np.flatnonzero(p < 0.5)
        k = lo + (below[0] if below.size else hi - lo - 1)
        out[lo:hi] = (np.sign(u[k] - u[lo]) or 1.0) * p
    return out


@jax.jit
def _initial_jax(u, torque_scale, reset):
    # dahl_initial in JAX: the running product by a scan, the direction by segment reductions
    n = u.shape[0]
    reset = reset.at[0].set(True)
    du = jnp.abs(jnp.diff(u, prepend=u[:1])) / torque_scale

    def _step(p, x):
        d, rs = x
        p = jnp.where(rs, 1.0, p * jnp.maximum(0.0, 1.0 - d))
        return p, p

    p = jax.lax.scan(_step, jnp.ones((), u.dtype), (du, reset))[1]
    seg = jnp.cumsum(reset) - 1
    idx = jnp.arange(n)
    start = jax.ops.segment_min(idx, seg, num_segments=n)
    end = jax.ops.segment_max(idx, seg, num_segments=n)
    below = jax.ops.segment_min(jnp.where(p < 0.5, idx, n), seg, num_segments=n)
    k = jnp.where(below < n, below, end)
    s = jnp.sign(u[jnp.clip(k, 0, n - 1)] - u[jnp.clip(start, 0, n - 1)])
    s = jnp.where(s == 0, 1.0, s)
    return s[seg] * p


def play(
    driver: SamplesLike,
    half_width: float,
    reset: Shaped[ArrayLike, " n"] | None = None,
    start: Scalar | None = None,
) -> Float[ArrayLike, " n"]:
    r"""The play operator (a dead band) on a Dahl driver: $y_k = \min(\max(y_{k-1},
    u_k - h), u_k + h)$, the output held until the input leaves the band of half-width $h$
    around it, and $y = u$ at the record's first sample (or, with `start`, the first step taken
    from $y_{-1}$ = `start`, the value a previous chunk ended with) and at each `reset`.

    A rate-independent memory state moves with every change of its driver, so white noise on
    the driver random-walks it even while the joint rests (see [`TwistHysteresis`][]); behind
    a play a few noise deviations wide the state holds at rest, as the joint's does, and in
    motion it lags the driver by $h$ only. JAX in, JAX out; NumPy in, NumPy out.
    """
    u = jnp.asarray(driver, jnp.float64)
    r = jnp.zeros(u.shape, bool) if reset is None else jnp.asarray(reset).astype(bool)
    if start is None:
        r, start = r.at[0].set(True), 0.0
    y = _play_scan(u, jnp.asarray(half_width, jnp.float64), r, jnp.asarray(start, jnp.float64))
    return y if isinstance(driver, jax.Array) else np.asarray(y)


@jax.jit
def _play_scan(u, h, reset, y0):
    def _step(y, x):
        v, rs = x
        y = jnp.where(rs, v, jnp.clip(y, v - h, v + h))
        return y, y

    return jax.lax.scan(_step, y0, (u, reset))[1]


def driver_noise(driver: SamplesLike, reset: Shaped[ArrayLike, " n"] | None = None) -> float:
    r"""The white noise of a Dahl driver per sample, $\sigma$, where the noise is what moves
    the driver's differences from sample to sample; 0 where the motion does.

    The $k$-th difference of white noise has deviation $\sigma\sqrt{\binom{2k}{k}}$, so
    $\sigma_k = 1.4826\,\mathrm{MAD}(\Delta^k u)/\sqrt{\binom{2k}{k}}$ is the same for every
    $k$ (robust to the few large differences of reversals, held samples and gaps; differences
    across a `reset` are left out). A steady speed leaves no trace from $k = 2$ on, but a motion
    whose speed changes by more than the noise between samples adds most to the low differences
    and less to each higher one, so $\sigma_k$ falls with $k$. The noise is $\sigma_2$ when
    $\sigma_2, \sigma_3, \sigma_4$ agree within `WHITE_SPREAD`; otherwise the changes from
    sample to sample are the motion's own (a low sampling rate, a fast motion, an encoder whose
    quantum exceeds its noise), the noise cannot be told from them, and it is reported as 0.
    """
    sig = noise_deviations(driver, reset)
    if min(sig) <= 0.0 or max(sig) > WHITE_SPREAD * min(sig):
        return 0.0
    return sig[0]


def noise_deviations(
    driver: SamplesLike, reset: Shaped[ArrayLike, " n"] | None = None
) -> tuple[float, float, float]:
    r"""$(\sigma_2, \sigma_3, \sigma_4)$ of [`driver_noise`][]: the deviation of white noise
    that the driver's $k$-th differences would have, $1.4826\,\mathrm{MAD}(\Delta^k u)
    /\sqrt{\binom{2k}{k}}$, for $k = 2, 3, 4$ (0 for each when too few differences)."""
    u = np.asarray(driver, np.float64)
    keep = np.ones(u.size, bool) if reset is None else np.asarray(reset) == 0
    sig = []
    for k in (2, 3, 4):
        d = np.diff(u, k)
        ok = np.ones(d.size, bool)
        for j in range(1, k + 1):  # a difference spans samples i..i+k: no restart after i
            ok &= keep[j : j + d.size]
        d = d[ok]
        if d.size < 20:
            return (0.0, 0.0, 0.0)
        mad = float(np.median(np.abs(d - np.median(d))))
        sig.append(1.4826 * mad / math.sqrt(math.comb(2 * k, k)))
    return tuple(sig)


WHITE_SPREAD = 1.15
"""The most the noise deviations from the second, third and fourth differences may differ (a
ratio) for [`driver_noise`][] to read them as white noise: white noise gives 1 to within a few
per cent, and `benchmarks/dahl_noise.py` reports the ratio on simulated slow sweeps with white
encoder noise."""


def twist_play(sig: Signals, compliance: float, deviations: float = 3.0) -> float:
    """The play [N·m of torque path] of a [`TwistHysteresis`][] on these signals: `deviations`
    times the [`driver_noise`][] of the measured twist over `compliance` (restarting at
    `SEGMENT_START`), to 3 significant digits; 0 where no white noise is read."""
    reset = sig.extras.get(SEGMENT_START)
    h = deviations * driver_noise(np.asarray(sig.twist) / compliance, reset)
    return float(f"{h:.3g}") if h > 0 else 0.0


def after_play(term, driver: SamplesLike, reset=None, start: Scalar | None = None):
    """`term`'s Dahl `driver` after the term's [`play`][] (`TwistHysteresis.play`; a term
    without one, or with 0, leaves it as it is): the one place every Dahl state of a term,
    whole or chunk by chunk, passes the play."""
    h = getattr(term, "play", 0.0)
    return play(driver, h, reset, start) if h else driver


def _dahl_path(term, sig: Signals, torque, reset) -> Samples:
    return after_play(term, term.dahl_driver(sig, torque), reset)


def _dahl_column(
    term: Hysteresis | TwistHysteresis, sig: Signals, torque: SamplesLike | None = None
) -> Float[Array, "n k"]:
    """The Dahl state ([`dahl_state`][hdjax.effects.dahl_state]; the loop of Song et al. Fig. 2)
    of `term.dahl_driver` as one column, restarted at `SEGMENT_START` from the state
    `term.initial` $\\zeta$ times the first motion's direction ([`dahl_initial`][])."""
    term = opaque_hypers(term)  # constants round as traced values do
    reset = sig.extras.get(SEGMENT_START)
    driver = _dahl_path(term, sig, torque, reset)
    z = dahl_state(driver, term.torque_scale, reset)
    zeta = float(getattr(term, "initial", 0.0))
    if zeta:
        z = z + zeta * dahl_initial(jnp.asarray(driver), term.torque_scale, reset)
    lag = getattr(term, "lag", False)
    return (late(z, reset, None) if lag else z)[:, None]


def _dahl_column_numpy(
    term: Hysteresis | TwistHysteresis, sig: Signals, torque: SamplesLike | None = None
) -> Float[np.ndarray, "n k"]:
    """NumPy reference of `_dahl_column`."""
    reset = sig.extras.get(SEGMENT_START)
    reset = None if reset is None else np.asarray(reset)
    driver = np.asarray(_dahl_path(term, sig, torque, reset))
    z = dahl_state_numpy(driver, term.torque_scale, reset)
    zeta = float(getattr(term, "initial", 0.0))
    if zeta:
        z = z + zeta * dahl_initial(driver, term.torque_scale, reset)
    lag = getattr(term, "lag", False)
    return (np.asarray(late(z, reset, None)) if lag else z)[:, None]


class Hysteresis(AbstractPathTerm):
    """Hysteresis in twist as a Dahl state driven by the torque path ([`dahl_state`][]).

    At estimation the state is driven by the torque being estimated (the estimate without the
    path terms, causally, one pass), never by the reference sensor. At calibration it is
    driven by the signal `TORQUE_PATH` when present (the residual loop supplies the previous
    model's estimate), else by the reference torque.
    """

    torque_scale: float = hyper(1.0, positive=True)

    key, names = labels("hysteresis:torque", "dahl(T/{torque_scale})")

    def dahl_driver(self, sig: Signals, torque: SamplesLike | None = None) -> Samples:
        """The path the Dahl state follows: a torque path supplied with the signals (the
        estimate of a previous model, so that calibration sees the state the estimator will
        see) takes precedence over `torque`."""
        return sig.extras.get(TORQUE_PATH, torque)

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The Dahl state for the exported estimator: driven by the torque being estimated,
        by the exporter's implicit step per sample (as the JAX estimate's), from 0."""
        return CSnippet(path_scale=self.torque_scale, state=(("z", 0.0),))

    # the Dahl state of `dahl_driver` (shared by both hysteresis terms)
    columns = _dahl_column
    numpy_columns = _dahl_column_numpy


class TwistHysteresis(AbstractTorqueFreeTerm):
    """Hysteresis whose memory state follows the measured deformation.

    The flexspline's hysteresis is a torque $z$ in parallel with the elastic torque whose state
    follows the *deflection* path (the plant's Bouc-Wen, Dahl and LuGre laws): $T = T_s(d) +
    z(d)$, so in the twist domain $\\Delta\\theta \\approx f(T) - k\\,z(\\Delta\\theta)$, a state
    of the measured twist that needs no torque at all. It is computed causally from the
    measurement, the same way at calibration, in every cross-validation fold and at
    estimation, and the inversion only removes a known column (a torque-free term), which is
    stable whatever the loop's sharpness. The twist is divided by `compliance` (the joint's
    small-torque compliance, [`twist_compliance`][]) so that `torque_scale` reads in N·m of
    torque path, as for [`Hysteresis`][].

    **The encoders' noise.** The state at sample $k$ is driven by the twist up to sample $k-1$
    (one sample late): a state that read the present sample would carry that sample's encoder
    noise, and regressing the twist on it would fit the noise (the cross-validated twist error
    then falls below the noise floor and the effect's interval loses its coverage). One sample
    of delay is far below any hysteresis width.

    **The state at the start.** It runs through each stretch of the record and restarts at
    `SEGMENT_START`: the record's start, where recordings were joined, and, in the residual
    loop's signals ([`hdjax.discover.pipeline_signals`][]), after each gap in the log longer
    than 0.1 s (across a shorter one, dropped samples, the state carries on with the torque
    step over the gap), from the state
    `initial` $\\zeta$ times the direction of the first motion ([`dahl_initial`][]): 0 for a
    joint that starts unloaded, $-1$ for a one-way sweep from rest that starts with the state its
    last motion, the other way, left. The residual loop chooses $\\zeta$ from $\\{-1, 0, 1\\}$
    by cross-validation, with the width.

    **The encoders' noise at rest.** The Dahl law is rate-independent: every change of its
    driver moves the state, the encoder's white noise as much as the motion. On a slow sweep
    the noise's steps (tenths of a N·m of torque path per sample) dwarf the motion's, so the
    state would random-walk while the joint rests and forget its initial state before the
    joint moves. The driver therefore passes a [`play`][hdjax.effects.play] of half-width
    `play` [N·m of torque path] first: the residual loop sets it to three deviations of the
    driver's noise measured on TRAIN ([`twist_play`][]) on a one-way sweep from rest, and to
    0 (no play) on a record with reversals or where no white noise can be told from the motion
    ([`driver_noise`][]).

    **Beside an encoder time skew.** The state follows the flexspline's deflection, the twist of
    the two encoders read at one instant. In a model that also holds
    [`hdjax.effects.EncoderSkew`][] with delay $\\delta$, the recorded twist carries
    $\\delta\\,c_\\delta$ besides (about $\\delta\\,\\omega_l$: a step of tens of N·m of torque
    path each time the joint starts or stops, where the deflection has none), so the driver is
    the twist less that column (the skew term's own, computed the same way). The model
    sets `skew`, `ratio` and `sign` from its skew term ([`beside`][]); 0 (no skew) reads the
    recorded twist.
    """

    torque_scale: float = hyper(1.0, positive=True)
    compliance: float = hyper(1.0, positive=True)
    initial: float = hyper(0.0)
    play: float = hyper(0.0)
    skew: float = hyper(0.0)
    ratio: float = hyper(1.0, positive=True)
    sign: float = hyper(1.0)

    static_hypers: ClassVar[tuple[str, ...]] = ("initial", "play")
    """The initial state and the play are constants of the column programs: they branch on
    each being 0."""

    static_while_zero: ClassVar[tuple[str, ...]] = ("skew",)
    """Without a skew the driver is the recorded twist itself (no interpolation to run)."""

    @property
    def key(self) -> str:
        """The vocabulary key: hysteresis:torque."""
        return "hysteresis:torque"

    def names(self) -> tuple[str, ...]:
        """The state's column (with its initial state when not 0)."""
        skew = concrete(self.skew)  # None inside a compiled program (a traced value)
        twist = "twist@skew" if skew is None else "twist"
        if skew is not None and skew:
            twist = f"twist@{fmt(round(float(skew) * 1e3, 6))}ms"
        arg = f"{twist}/{fmt(self.compliance)}/{fmt(self.torque_scale)}"
        if self.play:
            arg += f" ± {fmt(self.play)}"
        return (f"dahl({arg}; from {fmt(self.initial)})" if self.initial else f"dahl({arg})",)

    def __check_init__(self):
        if isinstance(self.initial, (int, float)) and not -1.0 <= self.initial <= 1.0:
            raise ConfigError(
                f"TwistHysteresis: initial (the state at the start, a fraction of the loop "
                f"height) must lie in [-1, 1], got {self.initial!r}"
            )
        if isinstance(self.play, (int, float)) and not (
            math.isfinite(self.play) and self.play >= 0
        ):
            raise ConfigError(
                f"TwistHysteresis: play (the half-width of the dead band on the state's "
                f"driver, N·m of torque path) must be finite and >= 0, got {self.play!r}"
            )
        for name in ("skew", "sign"):
            v = getattr(self, name)
            if isinstance(v, (int, float)) and not math.isfinite(v):
                raise ConfigError(
                    f"TwistHysteresis: {name} (set from the model's encoder skew term) must be "
                    f"finite, got {v!r}; leave it out, and add an EncoderSkew to the model "
                    "to align the state at a delay"
                )

    lag: ClassVar[bool] = True
    """The column at sample $k$ is the state after sample $k-1$ (see the class docstring)."""

    def dahl_driver(self, sig: Signals, torque: SamplesLike | None = None) -> Samples:
        """The path the Dahl state follows: the measured twist over the compliance, the twist
        aligned at the model's encoder skew when it has one (class docstring)."""
        if is_zero(self.skew):
            return sig.twist / self.compliance
        xp = np if isinstance(sig.twist, np.ndarray) else jnp
        aligned = sig.twist - self.skew * skew_column(sig, self.skew, self.ratio, self.sign, xp)
        return aligned / self.compliance

    @property
    def lookback(self) -> int:
        """Samples before a chunk that its driver reads: those of the skew's interpolation."""
        return 0 if is_zero(self.skew) else BACK_SAMPLES + 1

    def beside(self, terms: tuple[AbstractTerm, ...]) -> TwistHysteresis:
        """The term aligned at the delay of the encoder skew among `terms` (none: 0)."""
        s = next((t for t in terms if isinstance(t, EncoderSkew)), None)
        want = (s.delay, s.ratio, s.sign) if s is not None else (0.0, 1.0, 1.0)
        if (self.skew, self.ratio, self.sign) == want:
            return self
        return dataclasses.replace(self, skew=want[0], ratio=want[1], sign=want[2])

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The Dahl state of the measured twist for the exported estimator: one step of
        [`dahl_state`][] per sample, from 0 and without a step at the first sample, of the
        driver after its [`play`][hdjax.effects.play] when `play` > 0; the column is the
        state before this sample's step (one sample late, as the JAX column); beside an
        encoder skew, the twist less the skew's column, computed as that term's own C code
        does ([`hdjax.effects.EncoderSkew.c_code`][]). A state that
        starts at `initial` $\ne 0$ takes its sign from the first motion, which a
        per-sample step has not seen yet: refused."""
        if self.initial:
            return CSnippet(
                noncausal=(
                    f"its state starts at {fmt(self.initial)} of the direction of the first "
                    "motion, which lies after the start; calibrate with the state from 0 "
                    "(initial = 0) to export"
                )
            )
        z, prev, out = c.state("z"), c.state("prev"), c.state("out")
        d, du = c.local("d"), c.local("du")
        one = c.num(1.0)
        twist, aligned = c.signal("twist"), CSnippet()
        if self.skew:  # the twist less the skew's column (its interpolation, its state)
            aligned = EncoderSkew(delay=self.skew, ratio=self.ratio, sign=self.sign).c_code(c)
            twist = f"({twist} - {c.num(self.skew)} * {aligned.columns[0]})"
        driver = (f"const {c.real} {d} = {twist} / {c.num(self.compliance)};",)
        if self.play:  # the play: the driver held within its band (as `play`)
            raw, h = c.local("raw"), c.num(self.play)
            driver = (
                f"const {c.real} {raw} = {twist} / {c.num(self.compliance)};",
                f"const {c.real} {d} = {c.first} ? {raw} : "
                f"hdjax_clip({prev}, {raw} - {h}, {raw} + {h});",
            )
        update = (
            *aligned.update,
            *driver,
            f"if ({c.first}) {prev} = {d};",
            f"{out} = {z};",
            f"const {c.real} {du} = ({d} - {prev}) / {c.num(self.torque_scale)};",
            f"{z} = hdjax_clip({z} + {du} * ({one} - {z} * hdjax_sign({du})), -{one}, {one});",
            f"{prev} = {d};",
        )
        state = (("z", 0.0), ("prev", 0.0), ("out", 0.0))
        return CSnippet(
            columns=(out,),
            state=state,
            update=update,
            double_state=aligned.double_state,
            helpers=aligned.helpers,
        )

    # the Dahl state of `dahl_driver` (shared by both hysteresis terms)
    columns = _dahl_column
    numpy_columns = _dahl_column_numpy


def one_way_from_rest(driver: SamplesLike, omega: SamplesLike) -> bool:
    """Whether a record is a one-way sweep from rest: it starts with its Dahl driver at rest
    ([`starts_at_rest`][]) and its link moves one way only (pauses allowed: of the samples
    in motion, over 5 % of the 99th-percentile speed, fewer than 2 % move the other way)."""
    w = np.asarray(omega, np.float64)
    moving = np.abs(w) > 0.05 * np.quantile(np.abs(w), 0.99) if w.size else w
    if not np.any(moving):
        return False
    minority = min(np.mean(w[moving] > 0), np.mean(w[moving] < 0))
    return bool(minority < 0.02) and starts_at_rest(driver)


def starts_at_rest(driver: SamplesLike) -> bool:
    """Whether a record starts with its Dahl driver at rest: its displacement over the first
    1 % of the samples (at least 10) is under a tenth of what the driver typically moves over
    that many samples. Only then is the state at the start a state the joint was left in (and
    worth choosing); a record that starts in motion starts from whatever state that motion
    built."""
    u = np.asarray(driver, np.float64)
    m = max(10, u.size // 100)
    if u.size < 4 * m:
        return False
    typical = np.quantile(np.abs(u[m:] - u[:-m]), 0.9)
    return bool(abs(u[m] - u[0]) <= 0.1 * typical)


def twist_compliance(sig: Signals, torque: SamplesLike, rated_torque: float) -> float:
    """The small-torque compliance [rad/(N·m)]: the least-squares slope of the twist against
    the reference torque over $|T| < \\tau_0/3$ (all samples if too few), 4 significant digits
    (a static field of [`TwistHysteresis`][])."""
    tw = np.asarray(sig.twist, np.float64)
    t = np.asarray(torque, np.float64)
    inner = np.abs(t) < rated_torque / 3.0
    if inner.sum() < 50:
        inner = np.ones(t.shape, bool)
    x = t[inner] - t[inner].mean()
    slope = float(np.dot(x, tw[inner] - tw[inner].mean()) / max(np.dot(x, x), 1e-300))
    return float(f"{abs(slope):.4g}") if slope != 0 else 1.0


# ---------------------------------------------------------------------------------------------
# Plant: a torque state z in parallel with the elastic torque, driven by the deflection rate
# ---------------------------------------------------------------------------------------------


def _abs(x, eps):
    return jnp.sqrt(x * x + eps)


class BoucWen(AbstractHysteresis):
    r"""Bouc-Wen hysteresis torque $z$ [N·m] driven by the deflection rate $\dot d$:

    $\dot z = a \dot d - \beta |\dot d| |z|^{n-1} z - \gamma \dot d |z|^n$,

    which saturates at $z_{max} = (a/(\beta+\gamma))^{1/n}$. `a` [N·m/rad] is the stiffness
    added right after a reversal; `beta`, `gamma` shape the loop (`beta >= gamma`,
    `beta + gamma > 0` keep it bounded and dissipative); `n` is a static integer exponent.
    Absolute values are smoothed ($\sqrt{x^2+\epsilon}$) so gradients exist.
    """

    a: Float[Array, ""] = bound("positive")
    beta: Float[Array, ""]
    gamma: Float[Array, ""]
    n: int = eqx.field(static=True, default=1)

    def rate(self, z: Pointwise, d_dot: Pointwise, inv: dict | None = None) -> PointwiseOut:
        az = _abs(z, 1e-12)
        ad = _abs(d_dot, 1e-16)
        zn = az ** (self.n - 1) if self.n > 1 else 1.0
        return self.a * d_dot - self.beta * ad * zn * z - self.gamma * d_dot * zn * az

    def saturation(self) -> Float[Array, ""]:
        return (self.a / (self.beta + self.gamma)) ** (1.0 / self.n)

    def initial_stiffness(self) -> Float[Array, ""]:
        return self.a


class Dahl(AbstractHysteresis):
    r"""Dahl hysteresis torque $z$ [N·m]: $\dot z = \sigma (\dot d - |\dot d| z / F_h)$.

    `sigma` [N·m/rad] is the stiffness right after a reversal, `level` [N·m] the saturation
    (the half-height of the loop).
    """

    sigma: Float[Array, ""] = bound("positive")
    level: Float[Array, ""] = bound("positive", inverse=True)

    def rate(self, z: Pointwise, d_dot: Pointwise, inv: dict | None = None) -> PointwiseOut:
        inv = self.reciprocals() if inv is None else inv
        return self.sigma * (d_dot - _abs(d_dot, 1e-16) * z * inv["level"])

    def saturation(self) -> Float[Array, ""]:
        return self.level

    def initial_stiffness(self) -> Float[Array, ""]:
        return self.sigma


class LuGre(AbstractHysteresis):
    r"""LuGre-type hysteresis: a bristle state with a Stribeck-shaped limit.

    $\dot z = \sigma_0 (\dot d - |\dot d| z / g(\dot d))$ with
    $g(v) = F_c + (F_s - F_c) e^{-(v/v_s)^2}$, so the loop height depends on the deflection rate.
    """

    sigma0: Float[Array, ""] = bound("positive")
    level: Float[Array, ""] = bound("positive")
    peak: Float[Array, ""] = bound("positive")
    speed: Float[Array, ""] = bound("positive", inverse=True)

    def rate(self, z: Pointwise, d_dot: Pointwise, inv: dict | None = None) -> PointwiseOut:
        inv = self.reciprocals() if inv is None else inv
        x = d_dot * inv["speed"]
        g = self.level + (self.peak - self.level) * jnp.exp(-(x * x))
        return self.sigma0 * (d_dot - _abs(d_dot, 1e-16) * z / g)

    def saturation(self) -> Float[Array, ""]:
        """Loop half-height at deflection rates well above `speed`."""
        return self.level

    def initial_stiffness(self) -> Float[Array, ""]:
        return self.sigma0


HYSTERESIS_MODELS = ("bouc_wen", "dahl", "lugre")


def _check_model(model) -> None:
    if model not in HYSTERESIS_MODELS:
        raise ConfigError(
            f"effect 'hysteresis': unknown model {model!r}"
            f"{did_you_mean(model, HYSTERESIS_MODELS)}"
            f"; known models: {', '.join(HYSTERESIS_MODELS)}"
        )


def _defaults(rated: float, k1: float, given) -> dict:
    """Bouc-Wen by default (hysteresis loss ~1 arcmin for size 40-50 units, ratio >= 80); the
    Dahl and LuGre defaults when the user names those models."""
    model = given.get("model", "bouc_wen")
    _check_model(model)
    stiff = 1.0 / k1
    level = 0.025 * rated
    if model == "dahl":
        return dict(model="dahl", sigma=0.5 * stiff, level=level)
    if model == "lugre":
        return dict(model="lugre", sigma0=0.5 * stiff, level=level, peak=1.5 * level, speed=1e-3)
    return dict(model="bouc_wen", a=0.5 * stiff, beta=0.5 * stiff / level, gamma=0.0, n=1)


_LAWS = {"bouc_wen": BoucWen, "dahl": Dahl, "lugre": LuGre}


def _build(name: str, p: dict):
    model = p["model"]
    _check_model(model)
    params = {k: v for k, v in p.items() if k != "model"}
    if model == "bouc_wen":
        n = p["n"]
        if not isinstance(n, int) or isinstance(n, bool) or n < 1:
            raise ConfigError(
                f"effect 'hysteresis': Bouc-Wen exponent n must be an int >= 1, got {n!r}"
            )
    law = _LAWS[model].from_params(name, params)
    if model == "bouc_wen":
        b, g = concrete(law.beta), concrete(law.gamma)
        if b is not None and g is not None and not (b + g > 0 and b - g >= 0):
            raise ConfigError(
                f"effect 'hysteresis': Bouc-Wen needs beta + gamma > 0 and beta >= gamma "
                f"(a bounded, dissipative loop), got beta={float(b)}, gamma={float(g)}"
            )
    return law


class HysteresisFamily(AbstractFamily):
    """Hysteresis: plant `hysteresis` (Bouc-Wen, Dahl, LuGre); term `Hysteresis` (a Dahl state
    of the torque path); a grid of Dahl scales."""

    name: ClassVar[str] = "hysteresis"
    terms: ClassVar[tuple] = (Hysteresis, TwistHysteresis)
    plant_effects: ClassVar[tuple] = (PlantEffect("hysteresis", "hysteresis", _defaults, _build),)
    discover_families: ClassVar[tuple] = ("hysteresis:torque",)
    options: ClassVar[dict] = {
        "dahl_fractions": (0.01, 0.025, 0.05, 0.1, 0.2),
        "dahl_wide_fractions": (0.5, 1.0, 2.0),
        "dahl_initial": True,
        "dahl_play": 3.0,
    }

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        """A Dahl state of the measured twist at each width of the grid `dahl_fractions` (of
        the rated torque).

        A one-way sweep from rest ([`one_way_from_rest`][]; a robot's joint moving from one
        pose to the next) is also offered the states 0, -1 and +1 at its start (of the first
        motion's direction, when `dahl_initial`) and the wide loops of `dahl_wide_fractions`,
        up to twice the rated torque: its only hysteresis is the transition from the state its
        last motion left, and that may span most of its torque range. A record with reversals
        identifies its loops at the reversals; there the state at the start is forgotten
        within a loop width, and a loop much wider than the torque varies within stands in for
        any slow drift (a temperature, say), so neither is offered.

        On a one-way sweep from rest the states' driver also passes a play of `dahl_play`
        deviations of its noise ([`twist_play`][]; 0 turns the play off), so that the state
        holds while the joint rests and its initial state reaches the motion (see
        [`TwistHysteresis`][]). A record with reversals re-identifies its state at each
        reversal and gets no play: there the state behind a play is clean enough to fit a
        sub-arcsecond twist that follows the direction of motion, which the held-out blocks
        take for hysteresis on joints that have none (the clean-joint false-discovery test
        fails with the play on every record, and TEST gets worse on those joints)."""
        if not ctx.wants("hysteresis:torque"):
            return []
        # the state follows the measured deformation (stable, needs no estimate)
        k = twist_compliance(ctx.sig, ctx.torque, ctx.rated_torque)
        fractions = tuple(ctx.option(self, "dahl_fractions"))
        swing = float(np.ptp(np.asarray(ctx.sig.twist))) / k
        if not swing >= min(fractions) * ctx.rated_torque:
            ctx.cannot_identify(
                "hysteresis:torque",
                f"the twist swings through {swing:.3g} N·m of torque path, less than the "
                f"narrowest loop searched ({min(fractions) * ctx.rated_torque:.3g} N·m)",
                "record the joint loaded and unloaded over a wider torque range",
            )
            return []
        starts, h = (0.0,), 0.0
        if one_way_from_rest(np.asarray(ctx.sig.twist), np.asarray(ctx.sig.omega_l)):
            h = twist_play(ctx.sig, k, float(ctx.option(self, "dahl_play")))
            fractions += tuple(ctx.option(self, "dahl_wide_fractions"))
            if ctx.option(self, "dahl_initial"):
                starts = (0.0, -1.0, 1.0)
        return [
            Candidate.of(
                TwistHysteresis(torque_scale=f * ctx.rated_torque, compliance=k, initial=z0, play=h)
            )
            for f in fractions
            for z0 in starts
        ]

    def neighbours(self, term: AbstractTerm, step: float) -> list[AbstractTerm]:
        """A Dahl state of the measured twist ([`TwistHysteresis`][]) with its width
        `torque_scale` a factor `step` up and down, the initial state and play kept: the grid
        of `dahl_fractions` is a factor 2-2.5 apart, and on a one-way sweep from rest the
        transition from the initial state, which the width shapes, is most of the loop."""
        if not isinstance(term, TwistHysteresis):
            return []
        return [
            dataclasses.replace(term, torque_scale=term.torque_scale * f) for f in (step, 1 / step)
        ]

    def setting_text(self, term: AbstractTerm) -> str:
        """The width of a [`TwistHysteresis`][], in N·m of torque path."""
        return f"width {term.torque_scale:.4g} N·m" if isinstance(term, TwistHysteresis) else ""
