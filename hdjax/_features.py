"""Derived signals: twist (Song et al. eq. (5)), velocities (eqs. (13)-(14)) and time gaps.

[`hdjax.signals`][] is the one place a recording and a [`hdjax.Joint`][] become the per-sample
signals every model reads ([`hdjax.Signals`][]): the twist with the joint's sign, the motor and
load velocities, the extras and the time stamps (for the gaps). The compliance model, the
network's features, the hybrid and joint fits and the residual loop all start from it.
"""

from __future__ import annotations

import typing
from collections.abc import Callable, Iterable

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._custom_types import Array, ArrayLike, Float, Int
from ._errors import DataError
from ._joint import Joint
from ._recording import Recording

VELOCITY_METHODS = ("difference", "smoothed")
_CORE = ("twist", "current", "theta_m", "theta_l", "omega_m", "omega_l")


@eqx.filter_jit
def _twist(theta_m, theta_l, ratio, sign):
    return sign * (theta_l - theta_m / ratio)


def twist(
    theta_m: Float[ArrayLike, " n"],
    theta_l: Float[ArrayLike, " n"],
    ratio: float,
    sign: float = 1.0,
) -> Float[Array, " n"]:
    r"""Total torsional angle of the reducer, Song et al. eq. (5).

    $\Delta\theta = \theta_{fso} - \theta_{wgi} / N$, computed in float64 (a twist of one
    arcsecond sits under hundreds of radians of motor angle). `sign` flips the convention for
    encoders that count against the torque (see [`hdjax.Joint`][]).
    """
    if ratio <= 0:
        raise DataError(f"reduction ratio must be positive, got {ratio}")
    theta_m = jnp.asarray(theta_m, jnp.float64)
    theta_l = jnp.asarray(theta_l, jnp.float64)
    return _twist(theta_m, theta_l, float(ratio), float(sign))


@eqx.filter_jit
def _backward_difference(t, theta, causal: bool):
    v = jnp.diff(theta) / jnp.diff(t)
    # the first sample has no earlier one: the second's value, or (causal) at rest
    first = jnp.zeros_like(v[:1]) if causal else v[:1]
    return jnp.concatenate([first, v])


def finite_difference_velocity(
    t: Float[ArrayLike, " ..."], theta: Float[ArrayLike, " ..."], *, causal: bool = False
) -> Float[Array, " n"]:
    r"""Angular velocity by the paper's backward difference, Song et al. eqs. (13)-(14).

    $\omega_k = (\theta_k - \theta_{k-1}) / (t_k - t_{k-1})$ with the actual time stamps (so
    jitter and gaps are honoured). The first sample has no earlier one: it takes the second's
    value, or, with `causal`, 0 (what a controller computing one sample at a time knows then).
    """
    t = jnp.asarray(t, jnp.float64)
    theta = jnp.asarray(theta, jnp.float64)
    if t.shape != theta.shape or t.ndim != 1 or t.shape[0] < 2:
        raise DataError(
            f"t and theta must be 1-D of one length >= 2, got {t.shape} and {theta.shape}"
        )
    return _backward_difference(t, theta, bool(causal))


@eqx.filter_jit
def _local_slope(t, theta, half_window: int, causal: bool):
    n = t.shape[0]
    # the window: centred, or (causal) the 2h + 1 samples up to and including this one
    offsets = (
        jnp.arange(-2 * half_window, 1) if causal else jnp.arange(-half_window, half_window + 1)
    )
    idx = jnp.clip(jnp.arange(n)[:, None] + offsets[None, :], 0, n - 1)
    tw = t[idx] - t[:, None]
    xw = theta[idx] - theta[:, None]  # local reference keeps float64 precision on big angles
    # Clipped windows repeat edge samples; weight each distinct sample once.
    first = jnp.concatenate([jnp.ones((n, 1), bool), idx[:, 1:] != idx[:, :-1]], axis=1).astype(
        t.dtype
    )
    wsum = first.sum(axis=1, keepdims=True)
    tm = (first * tw).sum(axis=1, keepdims=True) / wsum
    xm = (first * xw).sum(axis=1, keepdims=True) / wsum
    num = (first * (tw - tm) * (xw - xm)).sum(axis=1)
    den = (first * (tw - tm) ** 2).sum(axis=1)
    # a window of one distinct sample (the first of a causal window) has no slope: at rest
    return jnp.where(den > 0, num / jnp.where(den > 0, den, 1.0), 0.0)


def smoothed_velocity(
    t: Float[ArrayLike, " ..."],
    theta: Float[ArrayLike, " ..."],
    half_window: int = 5,
    *,
    causal: bool = False,
) -> Float[Array, " n"]:
    """Angular velocity by a local least-squares line over `2*half_window+1` samples.

    A smoothing alternative to eqs. (13)-(14) that uses the actual (jittered) time stamps; its
    noise falls as $h^{-3/2}$ with the window half-width $h$, at the price of a delay-free but
    wider low-pass. Windows are clipped at the ends.

    The centred window reads `half_window` samples ahead of each estimate. With `causal` the
    window is the `2*half_window+1` samples up to and including the present one (what a
    controller has): the same noise, but the slope it gives is that of `half_window` samples
    ago (a delay of `half_window` sample periods). The first sample's velocity is then 0.
    """
    if not isinstance(half_window, int) or half_window < 1:
        raise DataError(f"half_window must be a positive integer, got {half_window!r}")
    t = jnp.asarray(t, jnp.float64)
    theta = jnp.asarray(theta, jnp.float64)
    if t.shape != theta.shape or t.ndim != 1 or t.shape[0] < 2:
        raise DataError(
            f"t and theta must be 1-D of one length >= 2, got {t.shape} and {theta.shape}"
        )
    return _local_slope(t, theta, half_window, bool(causal))


def find_gaps(t: Float[ArrayLike, " n"], factor: float = 3.0) -> Int[np.ndarray, " n_gaps"]:
    """Indices `k` where `t[k+1] - t[k]` exceeds `factor` times the median step (sample gaps),
    or does not advance (where stacked recordings meet)."""
    dt = np.diff(np.asarray(t, np.float64))
    if dt.size == 0:
        return np.zeros(0, dtype=int)
    return np.flatnonzero((dt > factor * np.median(dt)) | (dt <= 0))


class Signals(eqx.Module):
    """Model inputs derived from a recording (Song et al. eqs. (5), (11)-(14)).

    `theta_m` is the wave-generator input angle $\\theta_{wgi}$, `theta_l` the flexspline output
    angle $\\theta_{fso}$, `omega_*` their velocities and `twist` the total torsional angle
    $\\Delta\\theta$ of eq. (5) (with the joint's `twist_sign`); `extras` the recording's extra
    columns; `t` the time stamps (`None` for signals built by hand), from which [`gaps`][]
    finds the gaps in time. Build them with [`hdjax.signals`][].
    """

    twist: Float[Array, " n"]
    current: Float[Array, " n"]
    extras: dict[str, Float[Array, " n"]]
    theta_m: Float[Array, " n"]
    theta_l: Float[Array, " n"]
    omega_m: Float[Array, " n"]
    omega_l: Float[Array, " n"]
    t: Float[Array, " n"] | None = None

    @property
    def n_samples(self) -> int:
        return int(self.twist.shape[0])

    def get(self, name: str) -> Float[Array, " n"]:
        """A signal by name (`current`, `theta_m`, `omega_l`, ... or an extra column)."""
        if name in _CORE:
            return getattr(self, name)
        if name in self.extras:
            return self.extras[name]
        raise DataError(
            f"no signal {name!r}; available: {', '.join(_CORE)}"
            + "".join(f", {k}" for k in sorted(self.extras))
        )

    def gaps(self, factor: float = 3.0) -> Int[np.ndarray, " n_gaps"]:
        """Indices `k` after which the time stamps jump (see [`hdjax.find_gaps`][])."""
        if self.t is None:
            raise DataError("these signals carry no time stamps; build them with hdjax.signals")
        return find_gaps(self.t, factor)

    @classmethod
    def concatenate(cls, parts: Iterable[Signals]) -> Signals:
        """Several signals one after the other (velocities stay per part; the time stamps
        restart, which [`gaps`][] reports)."""
        parts = list(parts)
        if len(parts) == 1:
            return parts[0]
        cat = lambda name: jnp.concatenate([getattr(s, name) for s in parts])
        keys = set(parts[0].extras)
        if any(set(s.extras) != keys for s in parts):
            raise DataError("signals to concatenate must have the same extra columns")
        times = [s.t for s in parts]
        return cls(
            **{name: cat(name) for name in _CORE},
            extras={k: jnp.concatenate([s.extras[k] for s in parts]) for k in parts[0].extras},
            t=None if any(t is None for t in times) else jnp.concatenate(times),
        )


Velocity = Callable[[ArrayLike, ArrayLike], Array]


def velocity_estimator(velocity: str, half_window: int, causal: bool) -> Velocity:
    """The velocity of a sampled angle, `(t, x) -> ω`: the paper's backward difference
    (`"difference"`, Song et al. eqs. (13)-(14)) or a local least-squares line over
    `2*half_window+1` samples (`"smoothed"`); `causal` uses each sample and earlier ones only."""
    if velocity not in VELOCITY_METHODS:
        raise DataError(f"velocity must be one of {VELOCITY_METHODS}, got {velocity!r}")
    if velocity == "difference":
        return lambda t, x: finite_difference_velocity(t, x, causal=causal)
    return lambda t, x: smoothed_velocity(t, x, half_window, causal=causal)


def derive_signals(
    recording: Recording, ratio: float, twist_sign: float, diff: Velocity
) -> Signals:
    """[`hdjax.signals`][] with the joint given by its ratio and twist sign, and the velocity
    by `diff` (from `velocity_estimator`)."""
    return Signals(
        twist=twist(recording.theta_m, recording.theta_l, ratio, twist_sign),
        current=jnp.asarray(recording.current, jnp.float64),
        extras={k: jnp.asarray(v, jnp.float64) for k, v in recording.extras.items()},
        theta_m=jnp.asarray(recording.theta_m, jnp.float64),
        theta_l=jnp.asarray(recording.theta_l, jnp.float64),
        omega_m=diff(recording.t, recording.theta_m),
        omega_l=diff(recording.t, recording.theta_l),
        t=jnp.asarray(recording.t, jnp.float64),
    )


@typing.no_type_check  # checks `joint` itself: the older call signals(rec, ratio) gets a reason
def signals(
    recording: Recording,
    joint: Joint,
    *,
    velocity: str = "difference",
    half_window: int = 5,
    causal: bool = False,
) -> Signals:
    """The signals every model reads, from a recording and its joint (Song et al. eqs. (5),
    (11)-(14)).

    **Arguments:**

    - `recording`: the [`hdjax.Recording`][].
    - `joint`: the [`hdjax.Joint`][]: its ratio and twist sign give the twist of eq. (5).
    - `velocity`: `"difference"`, the paper's backward difference (eqs. (13)-(14)), or
      `"smoothed"`, a local least-squares line over `2*half_window+1` samples.
    - `causal`: derive every sample's velocities from that sample and earlier ones only, as a
      controller computing one sample at a time does (what `hdjax export` generates): the
      first sample is at rest, and the smoothed line uses the window ending at the sample
      (see [`hdjax.smoothed_velocity`][]).

    **Returns:** [`hdjax.Signals`][] (twist with the joint's sign, velocities, extras, time).
    """
    if not isinstance(joint, Joint):
        raise DataError(f"signals() needs an hdjax.Joint, got {type(joint).__name__}")
    diff = velocity_estimator(velocity, half_window, causal)
    return derive_signals(recording, joint.ratio, joint.twist_sign, diff)
