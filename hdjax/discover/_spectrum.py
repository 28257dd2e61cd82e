"""Order spectrum of a residual against an angle: a least-squares (Lomb-Scargle) periodogram.

A kinematic error repeats with the angle, not with time, and a joint rarely turns at constant
speed, so the residual is an unevenly "sampled" function of the angle. For each trial order $k$
the periodogram fits $r \\approx a \\cos k\\theta + b \\sin k\\theta + c$ by least squares and
reports the fraction of the residual's variance it explains (the generalised Lomb-Scargle
periodogram of Zechmeister & Kürster 2009). Peaks give the orders, integer or not (a
combination order such as $2 - 2/N$ of the motor angle shows as a peak just below 2).

References: M. Zechmeister, M. Kürster, "The generalised Lomb-Scargle periodogram", A&A 496,
577 (2009).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import ArrayLike, Float, Int, Real

MAX_SPECTRUM_SAMPLES = 10000


class OrderSpectrum(NamedTuple):
    """Explained-variance fraction of a residual against trial orders of one angle."""

    signal: str
    orders: Float[np.ndarray, " n_orders"]
    power: Float[np.ndarray, " n_orders"]
    resolution: float
    """Order resolution $2\\pi / \\mathrm{span}(\\theta)$: peaks closer than this merge."""


@jax.jit
def _ls_power(theta, r, orders):
    r = r - jnp.mean(r)
    total = jnp.sum(r * r)

    def one(k):
        c, s = jnp.cos(k * theta), jnp.sin(k * theta)
        x = jnp.stack([c, s, jnp.ones_like(c)], axis=1)
        g = x.T @ x + 1e-12 * jnp.eye(3, dtype=x.dtype) * theta.shape[0]
        beta = jnp.linalg.solve(g, x.T @ r)
        fit = x @ beta
        return 1.0 - jnp.sum((r - fit) ** 2) / total

    return jax.lax.map(one, orders, batch_size=64)


def subsample(n: int, limit: int = MAX_SPECTRUM_SAMPLES) -> Int[np.ndarray, " m"]:
    """Evenly spaced indices, at most `limit` of them (the periodogram needs no more)."""
    if n <= limit:
        return np.arange(n)
    return np.linspace(0, n - 1, limit).round().astype(int)


def order_spectrum(
    theta: Real[ArrayLike, " n"],
    residual: Real[ArrayLike, " n"],
    *,
    signal: str = "theta_m",
    min_order: float = 0.5,
    max_order: float = 8.0,
    oversample: float = 3.0,
) -> OrderSpectrum:
    """Least-squares periodogram of `residual` against the angle `theta` (radians).

    The order grid runs from `min_order` to `max_order` in steps of the resolution
    $2\\pi/\\mathrm{span}(\\theta)$ divided by `oversample`.
    """
    theta = np.asarray(theta, np.float64)
    residual = np.asarray(residual, np.float64)
    span = float(np.ptp(theta))
    resolution = 2.0 * math.pi / max(span, 1e-12)
    step = resolution / oversample
    n_orders = int(min(20000, max(2, math.floor((max_order - min_order) / step) + 1)))
    orders = np.linspace(min_order, max_order, n_orders)
    idx = subsample(theta.size)
    power = _ls_power(jnp.asarray(theta[idx]), jnp.asarray(residual[idx]), jnp.asarray(orders))
    return OrderSpectrum(signal, orders, np.asarray(power), resolution)


def order_power(
    theta: Real[ArrayLike, " n"],
    residual: Real[ArrayLike, " n"],
    orders: Real[ArrayLike, " n_orders"] | Sequence[float],
) -> Float[np.ndarray, " n_orders"]:
    """Periodogram values at given orders."""
    idx = subsample(np.asarray(theta).size)
    th = jnp.asarray(np.asarray(theta, np.float64)[idx])
    r = jnp.asarray(np.asarray(residual, np.float64)[idx])
    return np.asarray(_ls_power(th, r, jnp.asarray(orders, jnp.float64)))


def refine_peak(
    theta: Real[ArrayLike, " n"], residual: Real[ArrayLike, " n"], order: float, resolution: float
) -> float:
    """Refine a periodogram peak by golden-section search within ±resolution/2."""
    theta = np.asarray(theta, np.float64)
    idx = subsample(theta.size)
    th = jnp.asarray(theta[idx])
    r = jnp.asarray(np.asarray(residual, np.float64)[idx])

    def power(k):
        return float(_ls_power(th, r, jnp.asarray([k], jnp.float64))[0])

    lo, hi = order - resolution / 2, order + resolution / 2
    g = (math.sqrt(5) - 1) / 2
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    fa, fb = power(a), power(b)
    for _ in range(30):
        if fa > fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = power(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = power(b)
    return 0.5 * (lo + hi)


def spectrum_peaks(
    spec: OrderSpectrum, *, n_peaks: int = 3, min_power: float = 0.01
) -> list[tuple[float, float]]:
    """The strongest local maxima of a spectrum, at least one resolution apart."""
    if n_peaks <= 0:
        return []
    p = spec.power
    is_peak = np.r_[False, (p[1:-1] > p[:-2]) & (p[1:-1] >= p[2:]), False]
    cand = np.flatnonzero(is_peak & (p >= min_power))
    cand = cand[np.argsort(-p[cand])]
    chosen: list[int] = []
    for i in cand:
        if all(abs(spec.orders[i] - spec.orders[j]) >= spec.resolution for j in chosen):
            chosen.append(int(i))
        if len(chosen) == n_peaks:
            break
    return [(float(spec.orders[i]), float(p[i])) for i in chosen]
