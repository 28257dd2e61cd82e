"""Derived signals: twist (Song et al. eq. (5)) and velocities (eqs. (13)-(14))."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._custom_types import Array, Float
from ._errors import DataError


@eqx.filter_jit
def _twist(theta_m, theta_l, ratio, sign):
    return sign * (theta_l - theta_m / ratio)


def twist(theta_m, theta_l, ratio: float, sign: float = 1.0) -> Float[Array, " n"]:
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
def _backward_difference(t, theta):
    v = jnp.diff(theta) / jnp.diff(t)
    return jnp.concatenate([v[:1], v])


def finite_difference_velocity(t, theta) -> Float[Array, " n"]:
    r"""Angular velocity by the paper's backward difference, Song et al. eqs. (13)-(14).

    $\omega_k = (\theta_k - \theta_{k-1}) / (t_k - t_{k-1})$ with the actual time stamps (so
    jitter and gaps are honoured); the first sample takes the second's value.
    """
    t = jnp.asarray(t, jnp.float64)
    theta = jnp.asarray(theta, jnp.float64)
    if t.shape != theta.shape or t.ndim != 1 or t.shape[0] < 2:
        raise DataError(
            f"t and theta must be 1-D of one length >= 2, got {t.shape} and {theta.shape}"
        )
    return _backward_difference(t, theta)


@eqx.filter_jit
def _local_slope(t, theta, half_window: int):
    n = t.shape[0]
    offsets = jnp.arange(-half_window, half_window + 1)
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
    return num / den


def smoothed_velocity(t, theta, half_window: int = 5) -> Float[Array, " n"]:
    """Angular velocity by a local least-squares line over `2*half_window+1` samples.

    A smoothing alternative to eqs. (13)-(14) that uses the actual (jittered) time stamps; its
    noise falls as $h^{-3/2}$ with the window half-width $h$, at the price of a delay-free but
    wider low-pass. Windows are clipped at the ends.
    """
    if not isinstance(half_window, int) or half_window < 1:
        raise DataError(f"half_window must be a positive integer, got {half_window!r}")
    t = jnp.asarray(t, jnp.float64)
    theta = jnp.asarray(theta, jnp.float64)
    if t.shape != theta.shape or t.ndim != 1 or t.shape[0] < 2:
        raise DataError(
            f"t and theta must be 1-D of one length >= 2, got {t.shape} and {theta.shape}"
        )
    return _local_slope(t, theta, half_window)


def find_gaps(t, factor: float = 3.0) -> np.ndarray:
    """Indices `k` where `t[k+1] - t[k]` exceeds `factor` times the median step (sample gaps)."""
    dt = np.diff(np.asarray(t, np.float64))
    if dt.size == 0:
        return np.zeros(0, dtype=int)
    return np.flatnonzero(dt > factor * np.median(dt))
