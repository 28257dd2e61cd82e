"""Error metrics of a torque estimate: RMS, maximum and error rate (Song et al. Fig. 17)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ._custom_types import ArrayLike, Bool, Float
from ._errors import DataError


class ErrorMetrics(NamedTuple):
    """Torque-estimate error statistics over the samples used."""

    rms: float
    """Root-mean-square error [N·m]."""
    max: float
    """Maximum absolute error [N·m]."""
    bias: float
    """Mean error (estimate minus reference) [N·m]."""
    rms_pct: float
    """RMS error in % of rated torque."""
    max_pct: float
    """Maximum absolute error in % of rated torque (the paper's error rate, Fig. 17)."""
    n: int
    """Number of samples used."""

    def as_dict(self) -> dict:
        return {k: (int(v) if k == "n" else float(v)) for k, v in self._asdict().items()}


def error_metrics(
    estimate: Float[ArrayLike, " ..."],
    reference: Float[ArrayLike, " ..."],
    rated_torque: float,
    mask: Bool[ArrayLike, " ..."] | Sequence[bool] | None = None,
) -> ErrorMetrics:
    """RMS, maximum and percentage errors of `estimate` against `reference`.

    The error rate is given in % of the rated torque $\\tau_0$, as Song et al. Fig. 17.
    `mask` (boolean) selects the samples to count, e.g. those inside the calibrated range.
    """
    est = np.asarray(estimate, np.float64)
    ref = np.asarray(reference, np.float64)
    if est.shape != ref.shape:
        raise DataError(f"estimate shape {est.shape} differs from reference shape {ref.shape}")
    if rated_torque <= 0:
        raise DataError(f"rated_torque must be positive, got {rated_torque}")
    err = est - ref
    if mask is not None:
        err = err[np.asarray(mask, bool)]
    if err.size == 0:
        raise DataError("no samples to compute error metrics on")
    if not np.isfinite(err).all():
        raise DataError("the estimate contains NaN or inf; cannot compute error metrics")
    rms = float(np.sqrt(np.mean(err**2)))
    mx = float(np.max(np.abs(err)))
    return ErrorMetrics(
        rms=rms,
        max=mx,
        bias=float(np.mean(err)),
        rms_pct=100.0 * rms / rated_torque,
        max_pct=100.0 * mx / rated_torque,
        n=int(err.size),
    )
