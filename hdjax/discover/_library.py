"""The library of candidate effects: named groups of twist-model terms.

Each candidate is a term group of [`hdjax.compliance`][] with a key from a fixed vocabulary:

- `harmonic:theta_m:K`: $\\cos K\\theta_m, \\sin K\\theta_m$, kinematic error of the wave
  generator side (order $K$, decimal);
- `harmonic:theta_l:K`: $\\cos K\\theta_l, \\sin K\\theta_l$, kinematic error of the output;
- `coulomb:omega_m`, `coulomb:omega_l`: $\\tanh(\\omega/\\omega_s)$, Coulomb / Stribeck
  friction between current and wave generator, or at the output bearing;
- `viscous:omega_m`, `viscous:omega_l`: $\\omega$, viscous friction;
- `hysteresis:torque`: a Dahl state of the torque path, hysteresis of flexspline and wave
  generator;
- `backlash:torque`: $\\tanh(T/T_b)$, lost motion around zero torque;
- `stiffness:torque`: $(T/\\tau_0)^3$, stiffness beyond the piecewise segments;
- `damping:twist_rate`: $s(\\omega_l - \\omega_m/N)$, structural damping of the flexspline;
- `column:NAME`: $(x - \\bar x)/s_x$, a drift with an extra column (e.g. temperature);
- `column:NAME*torque`: $(x - \\bar x)/s_x \\cdot T/\\tau_0$, a compliance that drifts with it.

Harmonic orders come from the order spectrum of the residual (peaks, refined), merged with the
integers and the combination orders $2 \\pm 2/N$; an order is offered only when the recording
covers at least one full period of it. Nonlinear parameters (the smoothing speed
$\\omega_s$, the Dahl scale, the backlash width) are scanned on a short grid; each grid member
is a separate candidate of the same key, and the best one wins.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..compliance import (
    Backlash,
    Column,
    ColumnTimesTorque,
    Coulomb,
    Harmonics,
    Hysteresis,
    Stiffening,
    TwistRate,
    Viscous,
)
from ..compliance._terms import _fmt
from ._hysteresis import TwistHysteresis
from ._spectrum import OrderSpectrum, order_power, order_spectrum, refine_peak, spectrum_peaks

FAMILIES = (
    "harmonic:theta_m",
    "harmonic:theta_l",
    "coulomb:omega_m",
    "coulomb:omega_l",
    "viscous:omega_m",
    "viscous:omega_l",
    "hysteresis:torque",
    "backlash:torque",
    "stiffness:torque",
    "damping:twist_rate",
    "column",
)


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One candidate effect: its vocabulary `key`, `family` and the term group it adds."""

    key: str
    family: str
    term: object
    origin: str = "grid"


@dataclasses.dataclass(frozen=True)
class LibraryOptions:
    """Which candidate effects to offer, and their grids.

    - `orders_m`, `orders_l`: (min, max) trial orders of the motor and output angles.
    - `integer_orders_m`, `integer_orders_l`: grid orders always offered (if resolvable).
    - `n_peaks`: spectrum peaks taken per angle.
    - `smoothing_fractions`: $\\omega_s$ grid as fractions of the velocity's RMS.
    - `dahl_fractions`, `backlash_fractions`: Dahl scale and backlash width as fractions of
      $\\tau_0$.
    - `families`: the families to offer (default all).
    """

    orders_m: tuple[float, float] = (0.5, 8.0)
    orders_l: tuple[float, float] = (0.5, 12.0)
    integer_orders_m: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0)
    integer_orders_l: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0)
    n_peaks: int = 3
    smoothing_fractions: tuple[float, ...] = (0.003, 0.01, 0.03, 0.1, 0.3)
    dahl_fractions: tuple[float, ...] = (0.01, 0.025, 0.05, 0.1, 0.2)
    backlash_fractions: tuple[float, ...] = (0.005, 0.01, 0.02, 0.05)
    families: tuple[str, ...] = FAMILIES


def candidate_columns(term, sig, torque) -> np.ndarray:
    """A candidate's columns as a NumPy array, computed in NumPy where the term is simple.

    Scoring evaluates dozens of candidates once each; NumPy avoids compiling a JAX program per
    candidate (their orders and scales are static fields). The result equals `term.columns`.
    """
    name = type(term).__name__
    if name == "Harmonics":
        th = np.asarray(sig.get(term.signal))
        return np.column_stack([f(k * th) for k in term.orders for f in (np.cos, np.sin)])
    if name == "Coulomb":
        return np.tanh(np.asarray(sig.get(term.signal)) / term.omega_s)[:, None]
    if name == "Viscous":
        return (np.asarray(sig.get(term.signal)) / term.scale)[:, None]
    if name == "Column":
        return ((np.asarray(sig.get(term.name)) - term.center) / term.scale)[:, None]
    if name == "Backlash":
        return np.tanh(np.asarray(torque) / term.width)[:, None]
    if name == "Stiffening":
        return ((np.asarray(torque) / term.torque_scale) ** 3)[:, None]
    return np.asarray(term.columns(sig, torque))


def harmonic_key(signal: str, order: float) -> str:
    return f"harmonic:{signal}:{_fmt(round(order, 6))}"


def min_resolvable_order(theta) -> float:
    """The lowest order with at least one full period inside the angle's span."""
    span = float(np.ptp(np.asarray(theta)))
    return math.inf if span <= 0 else 2.0 * math.pi / span


def _named_orders(grid: tuple[float, ...], ratio: float, signal: str) -> list[float]:
    named = list(grid)
    if signal == "theta_m":
        named += [2.0 - 2.0 / ratio, 2.0 + 2.0 / ratio, 1.0 - 1.0 / ratio, 1.0 + 1.0 / ratio]
    return named


def harmonic_candidates(
    signal: str,
    theta,
    residual,
    *,
    ratio: float,
    order_range: tuple[float, float],
    grid: tuple[float, ...],
    n_peaks: int,
    existing: list[float],
) -> tuple[list[Candidate], OrderSpectrum | None]:
    """Harmonic candidates of one angle: spectrum peaks (refined) plus named orders."""
    lowest = max(order_range[0], min_resolvable_order(theta))
    if lowest >= order_range[1]:
        return [], None
    spec = order_spectrum(
        theta, residual, signal=signal, min_order=lowest, max_order=order_range[1]
    )
    res = spec.resolution
    named = [k for k in _named_orders(grid, ratio, signal) if lowest <= k <= order_range[1]]
    orders: list[tuple[float, str]] = []
    for k, _ in spectrum_peaks(spec, n_peaks=n_peaks):
        k = refine_peak(theta, residual, k, res)
        # A peak within half a resolution of a named order (an integer, 2 - 2/N, ...) cannot be
        # told apart from it by this record: report the named order unless it fits clearly worse.
        near = [m for m in named if abs(m - k) < res / 2]
        if near:
            m = min(near, key=lambda m: abs(m - k))
            p_peak, p_named = order_power(theta, residual, [k, m])
            if p_named >= 0.95 * p_peak:
                k = m
        orders.append((k, "spectrum"))
    orders += [(k, "grid") for k in named]
    out, seen = [], []
    for k, origin in orders:
        if any(abs(k - e) < res / 2 for e in existing):
            continue  # already in the model
        if any(abs(k - s) < 1e-6 for s in seen):
            continue
        seen.append(k)
        term = Harmonics(signal=signal, orders=(float(round(k, 6)),))
        out.append(Candidate(harmonic_key(signal, k), f"harmonic:{signal}", term, origin))
    return out, spec


def build_library(
    sig,
    torque,
    residual,
    *,
    ratio: float,
    rated_torque: float,
    existing_keys: tuple[str, ...],
    existing_terms: tuple = (),
    options: LibraryOptions = LibraryOptions(),
    extra_columns: tuple[str, ...] = (),
    twist_sign: float = 1.0,
    compliance: float | None = None,
) -> tuple[list[Candidate], dict[str, OrderSpectrum]]:
    """All candidate effects for the present residual, and the order spectra used.

    **Arguments:** `sig` (training [`hdjax.compliance.Signals`][]), `torque` (reference),
    `residual` (twist residual of the present model), `existing_keys` (effects already in the
    model, not offered again), `extra_columns` (names of usable extra columns).
    """
    fams = set(options.families)
    cands: list[Candidate] = []
    spectra: dict[str, OrderSpectrum] = {}
    existing_orders = {"theta_m": [], "theta_l": []}
    for term in existing_terms:
        if isinstance(term, Harmonics):
            existing_orders[term.signal] += list(term.orders)
    for signal, rng, grid in (
        ("theta_m", options.orders_m, options.integer_orders_m),
        ("theta_l", options.orders_l, options.integer_orders_l),
    ):
        if f"harmonic:{signal}" not in fams:
            continue
        c, spec = harmonic_candidates(
            signal,
            sig.get(signal),
            residual,
            ratio=ratio,
            order_range=rng,
            grid=grid,
            n_peaks=options.n_peaks,
            existing=existing_orders[signal],
        )
        cands += c
        if spec is not None:
            spectra[signal] = spec
    for signal in ("omega_m", "omega_l"):
        w = np.asarray(sig.get(signal))
        rms = float(np.sqrt(np.mean(w**2)))
        if rms == 0.0:
            continue
        if f"coulomb:{signal}" in fams and f"coulomb:{signal}" not in existing_keys:
            for frac in options.smoothing_fractions:
                term = Coulomb(signal=signal, omega_s=float(f"{frac * rms:.4g}"))
                cands.append(Candidate(term.key, term.key, term))
        if f"viscous:{signal}" in fams and f"viscous:{signal}" not in existing_keys:
            term = Viscous(signal=signal, scale=float(f"{rms:.4g}"))
            cands.append(Candidate(term.key, term.key, term))
    if "hysteresis:torque" in fams and "hysteresis:torque" not in existing_keys:
        for frac in options.dahl_fractions:
            # with the model's compliance, the state follows the measured deformation
            # (hdjax/discover/_hysteresis.py); without it, the torque path
            term = (
                Hysteresis(torque_scale=frac * rated_torque)
                if compliance is None
                else TwistHysteresis(torque_scale=frac * rated_torque, compliance=compliance)
            )
            cands.append(Candidate(term.key, term.key, term))
    if "backlash:torque" in fams and "backlash:torque" not in existing_keys:
        for frac in options.backlash_fractions:
            term = Backlash(width=frac * rated_torque)
            cands.append(Candidate(term.key, term.key, term))
    if "stiffness:torque" in fams and "stiffness:torque" not in existing_keys:
        term = Stiffening(torque_scale=float(rated_torque))
        cands.append(Candidate(term.key, term.key, term))
    if "damping:twist_rate" in fams and "damping:twist_rate" not in existing_keys:
        rate = np.asarray(sig.omega_l) - np.asarray(sig.omega_m) / ratio
        rms = float(np.sqrt(np.mean(rate**2)))
        if rms > 0.0:
            term = TwistRate(ratio=float(ratio), sign=float(twist_sign), scale=float(f"{rms:.4g}"))
            cands.append(Candidate(term.key, term.key, term))
    if "column" in fams:
        for name in extra_columns:
            x = np.asarray(sig.get(name))
            center, scale = float(f"{x.mean():.6g}"), float(f"{x.std():.4g}")
            if scale == 0.0:
                continue
            t1 = Column(name=name, center=center, scale=scale)
            t2 = ColumnTimesTorque(
                name=name, center=center, scale=scale, torque_scale=float(rated_torque)
            )
            for term in (t1, t2):
                if term.key not in existing_keys:
                    cands.append(Candidate(term.key, "column", term))
    return cands, spectra
