"""What the final model leaves: residual structure above the noise, for the report.

Two kinds are listed:

- **order peaks**: peaks of the order spectrum of the final TRAIN twist residual
  ([`hdjax.discover.order_spectrum`][]) standing `PEAK_FACTOR` times above the spectrum's
  median (its noise floor) and explaining at least `MIN_POWER` of the residual's variance;
  amplitude $\\sqrt{2 p \\sigma_r^2}$; each peak is judged with the stronger listed ones'
  sinusoids removed, so their side lobes are not listed;
- **shape against a signal** (torque, both velocities): the residual's mean in `N_BINS`
  quantile bins of the signal; listed when the bin means explain at least `MIN_POWER` of the
  residual's variance, well above what chance gives for the record's effective sample count
  (samples divided by the correlation length of what the shape leaves). Amplitude: half the
  range of the bin means.

The user then knows what is left, even when the loop's vocabulary has no name for it.
"""

from __future__ import annotations

import numpy as np

from ._folds import correlation_length as residual_correlation_length
from ._library import min_resolvable_order
from ._spectrum import OrderSpectrum, order_power, order_spectrum, spectrum_peaks

ARCSEC = 180.0 * 3600.0 / np.pi
PEAK_FACTOR = 10.0
MIN_POWER = 0.02
N_BINS = 20


def all_spectra(
    residual: np.ndarray,
    angles: dict[str, np.ndarray],
    order_ranges: dict[str, tuple[float, float]],
    spectra: dict[str, OrderSpectrum],
) -> dict[str, OrderSpectrum]:
    """`spectra` plus the order spectrum of `residual` against each angle the library did not
    search (its family left out of the options): what is left is looked for on every angle,
    also where the vocabulary offers no name for it."""
    out = dict(spectra)
    for signal, theta in angles.items():
        if signal in out:
            continue
        theta = np.asarray(theta, np.float64)
        lo, hi = order_ranges[signal]
        lo = max(lo, min_resolvable_order(theta))
        if lo < hi:
            out[signal] = order_spectrum(theta, residual, signal=signal, min_order=lo, max_order=hi)
    return out


def _remove_sinusoid(theta, r, order):
    """`r` less its least-squares fit $a \\cos k\\theta + b \\sin k\\theta + c$."""
    theta = np.asarray(theta, np.float64)
    x = np.column_stack([np.cos(order * theta), np.sin(order * theta), np.ones_like(theta)])
    return r - x @ np.linalg.lstsq(x, r, rcond=None)[0]


def unexplained_structure(
    residual: np.ndarray,
    spectra: dict[str, OrderSpectrum],
    signals: dict[str, np.ndarray],
    *,
    correlation_length: int,
    starts: np.ndarray | None = None,
    angles: dict[str, np.ndarray] | None = None,
) -> list[dict]:
    """Residual structure left by the final model (see the module docstring).

    `correlation_length` is the residual's; `starts` marks its segments (gaps); `angles` (the
    spectra's angles, optional) lets each peak be judged with the stronger ones removed."""
    r = np.asarray(residual, np.float64)
    r = r - r.mean()
    var = float(np.mean(r**2))
    out: list[dict] = []
    if var == 0.0:
        return out
    for signal, spec in spectra.items():
        floor = float(np.median(spec.power))
        theta = None if angles is None else angles.get(signal)
        clean = r
        for order, p in spectrum_peaks(spec, n_peaks=3, min_power=MIN_POWER):
            if theta is not None:
                # with the stronger peaks' sinusoids removed first: a side lobe of a listed
                # peak (a swinging angle's periodogram has strong ones) is not listed again
                p = float(order_power(theta, clean, [order])[0]) * np.mean(clean**2) / var
            if p >= PEAK_FACTOR * floor and p >= MIN_POWER:
                out.append(
                    dict(
                        signal=signal,
                        kind="order",
                        order=round(order, 4),
                        amplitude_arcsec=float(np.sqrt(2 * p * var) * ARCSEC),
                        explained=float(p),
                    )
                )
                if theta is not None:
                    clean = _remove_sinusoid(theta, clean, order)
    for name, x in signals.items():
        x = np.asarray(x, np.float64)
        if np.ptp(x) == 0.0:
            continue
        edges = np.quantile(x, np.linspace(0, 1, N_BINS + 1))
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, N_BINS - 1)
        counts = np.bincount(idx, minlength=N_BINS)
        sums = np.bincount(idx, weights=r, minlength=N_BINS)
        means = np.where(counts > 0, sums / np.maximum(counts, 1), 0.0)
        explained = float(np.sum(counts * means**2) / np.sum(r**2))
        # chance from the memory of what the shape leaves (a strong shape of a slow signal
        # makes the residual itself correlated over the signal's time scale)
        rest = residual_correlation_length(r - means[idx], starts)
        n_eff = max(1.0, r.size / max(1, min(correlation_length, rest)))
        chance = 5.0 * N_BINS / n_eff  # a few times the explained fraction of pure noise
        if explained >= max(MIN_POWER, chance):
            centres = 0.5 * (edges[:-1] + edges[1:])
            out.append(
                dict(
                    signal=name,
                    kind="shape",
                    amplitude_arcsec=float(0.5 * np.ptp(means[counts > 0]) * ARCSEC),
                    explained=explained,
                    bins=[float(c) for c in centres],
                    bin_means_arcsec=[float(m * ARCSEC) for m in means],
                )
            )
    return out
