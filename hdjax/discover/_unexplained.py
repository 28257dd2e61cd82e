"""What the final model leaves: residual structure above the noise, for the report.

Two kinds are listed:

- **order peaks**: peaks of the order spectrum of the final TRAIN twist residual
  ([`hdjax.discover.order_spectrum`][]) standing `PEAK_FACTOR` times above the spectrum's
  median (its noise floor) and explaining at least `MIN_POWER` of the residual's variance;
  amplitude $\\sqrt{2 p \\sigma_r^2}$;
- **shape against a signal** (torque, both velocities): the residual's mean in `N_BINS`
  quantile bins of the signal; listed when the bin means explain at least `MIN_POWER` of the
  residual's variance, well above what chance gives for the record's effective sample count
  (samples divided by the correlation length). Amplitude: half the range of the bin means.

The user then knows what is left, even when the loop's vocabulary has no name for it.
"""

from __future__ import annotations

import numpy as np

from ._spectrum import OrderSpectrum, spectrum_peaks

ARCSEC = 180.0 * 3600.0 / np.pi
PEAK_FACTOR = 10.0
MIN_POWER = 0.02
N_BINS = 20


def unexplained_structure(
    residual: np.ndarray,
    spectra: dict[str, OrderSpectrum],
    signals: dict[str, np.ndarray],
    *,
    correlation_length: int,
) -> list[dict]:
    """Residual structure left by the final model (see the module docstring)."""
    r = np.asarray(residual, np.float64)
    r = r - r.mean()
    var = float(np.mean(r**2))
    out: list[dict] = []
    if var == 0.0:
        return out
    for signal, spec in spectra.items():
        floor = float(np.median(spec.power))
        for order, p in spectrum_peaks(spec, n_peaks=3, min_power=MIN_POWER):
            if p >= PEAK_FACTOR * floor:
                out.append(
                    dict(
                        signal=signal,
                        kind="order",
                        order=round(order, 4),
                        amplitude_arcsec=float(np.sqrt(2 * p * var) * ARCSEC),
                        explained=float(p),
                    )
                )
    n_eff = max(1.0, r.size / max(1, correlation_length))
    chance = 5.0 * N_BINS / n_eff  # a few times the explained fraction of pure noise
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
