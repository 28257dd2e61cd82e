"""A model's errors on a recording: TEST's torque errors after inversion (Song et al. eqs.
(26)-(27)), and the twist residual of the compliance model (eq. (15)) and its RMS."""

from __future__ import annotations

import numpy as np

from .._metrics import error_metrics
from ._chunked import twist_residual
from ._pipeline import PipelineData, canonical, chunks_of, design, estimate, has_path
from ._scores import _as_data

ARCSEC = 180.0 * 3600.0 / np.pi


def test_errors(model, test, rated):
    """TEST torque errors of `model` (the pipeline's signals: gaps honoured; with a context,
    estimated through the whole log and scored on TEST's rows). **Returns:** the metrics and
    the estimate on TEST's rows."""
    data = _as_data(model, test)
    torque = data.part(estimate(model, data))
    return error_metrics(torque, data.part(data.torque), rated), torque


def twist_rms(model, data, driver=None, chunk=0) -> float:
    """RMS [arcsec] of the twist residual (eq. (15)) of `model` on `data`'s rows, the
    hysteresis driven by `driver` (default the model's own estimate)."""
    data = _as_data(model, data)
    if driver is None and has_path(model):
        driver = estimate(model, data)
    r = data.part(residual(model, data, driver, chunk))
    return float(np.sqrt(np.mean(r**2)) * ARCSEC)


def residual(model, data: PipelineData, driver, chunk: int) -> np.ndarray:
    """The twist residual of `model` on `data` (hysteresis driven by `driver`), the design
    formed whole or, with `chunk`, chunk by chunk."""
    sig, torque = data.pair(driver)
    if chunk:
        return twist_residual(canonical(model), chunks_of(sig, torque, chunk))
    return np.asarray(sig.twist) - design(model, sig, torque) @ np.asarray(model.coef)
