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


def _exp_i(x: np.ndarray) -> np.ndarray:
    """$e^{ix}$ from one cosine and one sine (NumPy's complex `exp` does more work)."""
    out = np.empty(x.shape, np.complex128)
    out.real = np.cos(x)
    out.imag = np.sin(x)
    return out


def _sums_on_grid(theta, weights, orders):
    # Sums S_w(k) = sum_n w_n e^{i k theta_n} on an evenly spaced grid k_j = k_0 + j dk.
    # Split j = J*B + b: e^{i k_j theta} = e^{i k_{JB} theta} e^{i b dk theta}, so the sums
    # of all m orders are one complex matrix product of (m/B x n) and (n x B) factors. With
    # B ~ sqrt(m) it costs 2 sqrt(m) n exponentials instead of m n, and every factor is a
    # directly evaluated exponential (no recurrence whose rounding grows along the grid).
    # Returns the sums for each weight vector and, for the double angle, S_1(2k).
    m = orders.size
    step = (orders[-1] - orders[0]) / (m - 1)
    b = math.isqrt(m - 1) + 1
    nj = -(-m // b)
    e = _exp_i(np.multiply.outer(orders[np.arange(nj) * b], theta))
    f = _exp_i(np.multiply.outer(np.arange(b) * step, theta))
    s = np.vstack([e * w for w in weights]) @ f.T
    s2 = (e * e) @ (f * f).T
    return [blk.ravel()[:m] for blk in np.split(s, len(weights))], s2.ravel()[:m]


def _sums_direct(theta, weights, orders):
    e = _exp_i(np.multiply.outer(orders, theta))
    return [e @ w for w in weights], (e * e).sum(axis=1)


def _ls_power(theta: np.ndarray, r: np.ndarray, orders: np.ndarray) -> np.ndarray:
    r"""Explained-variance fraction of the fit $r \approx a\cos k\theta + b\sin k\theta + c$.

    For each order the 3x3 normal equations (with a relative ridge of $10^{-12}$, which only
    matters for a degenerate order) are assembled from the sums $\sum r e^{ik\theta}$,
    $\sum e^{ik\theta}$ and $\sum e^{2ik\theta}$ ($\cos^2 = (1 + \cos 2x)/2$, ...), as in
    Zechmeister & Kürster (2009), eqs. (5)-(13). NumPy, not jit: one grid size per call would
    compile (or load from the cache) a program each time for a few milliseconds of work.
    """
    r = r - np.mean(r)
    total = float(r @ r)
    n = theta.size
    uniform = orders.size > 16 and np.allclose(
        np.diff(orders), (orders[-1] - orders[0]) / (orders.size - 1), rtol=1e-9, atol=0.0
    )
    ones = np.ones_like(r)
    (sr, s1), s2 = (_sums_on_grid if uniform else _sums_direct)(theta, [r, ones], orders)
    ridge = 1e-12 * n
    g = np.empty((orders.size, 3, 3))
    g[:, 0, 0] = 0.5 * (n + s2.real) + ridge  # sum cos^2
    g[:, 1, 1] = 0.5 * (n - s2.real) + ridge  # sum sin^2
    g[:, 0, 1] = g[:, 1, 0] = 0.5 * s2.imag  # sum cos sin
    g[:, 0, 2] = g[:, 2, 0] = s1.real
    g[:, 1, 2] = g[:, 2, 1] = s1.imag
    g[:, 2, 2] = n + ridge
    rhs = np.stack([sr.real, sr.imag, np.full(orders.size, r.sum())], axis=1)
    beta = np.linalg.solve(g, rhs[..., None])[..., 0]
    # 1 - |r - X beta|^2 / |r|^2 with X^T X beta = rhs - ridge * beta: no cancellation
    explained = np.einsum("ij,ij->i", beta, rhs) + ridge * np.einsum("ij,ij->i", beta, beta)
    return explained / total


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
    power = _ls_power(theta[idx], residual[idx], orders)
    return OrderSpectrum(signal, orders, power, resolution)


def order_power(
    theta: Real[ArrayLike, " n"],
    residual: Real[ArrayLike, " n"],
    orders: Real[ArrayLike, " n_orders"] | Sequence[float],
) -> Float[np.ndarray, " n_orders"]:
    """Periodogram values at given orders."""
    idx = subsample(np.asarray(theta).size)
    th = np.asarray(theta, np.float64)[idx]
    r = np.asarray(residual, np.float64)[idx]
    return _ls_power(th, r, np.asarray(orders, np.float64).reshape(-1))


def refine_peak(
    theta: Real[ArrayLike, " n"], residual: Real[ArrayLike, " n"], order: float, resolution: float
) -> float:
    """Refine a periodogram peak by golden-section search within ±resolution/2."""
    theta = np.asarray(theta, np.float64)
    idx = subsample(theta.size)
    th = theta[idx]
    r = np.asarray(residual, np.float64)[idx]

    def power(k):
        return float(_ls_power(th, r, np.array([k], np.float64))[0])

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
