"""A given structure refitted by the loop's own pipeline (the true structure of a simulated
joint, say), and the order spectra of a model's residual."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._joint import Joint
from .._metrics import ErrorMetrics
from .._recording import Recording
from ..compliance import ComplianceModel
from ..compliance.internal import CalibrationData, prepare
from ..effects import AbstractTerm
from ._evaluate import test_errors
from ._options import DiscoverOptions
from ._pipeline import calibrate, estimate
from ._scores import _as_data
from ._spectrum import OrderSpectrum, order_spectrum
from ._start import calibrate_baseline


def refit_structure(
    train: Recording,
    test: Recording,
    joint: Joint,
    terms: Sequence[AbstractTerm],
    options: DiscoverOptions = DiscoverOptions(),
) -> ErrorMetrics:
    """TEST errors of the starting model plus `terms` (e.g. the true structure), calibrated by
    the same pipeline as the loop's (hysteresis driven by the model's own estimate).

    **Returns:** an [`hdjax.ErrorMetrics`][].
    """
    notes: list[str] = []
    base = calibrate_baseline(train, joint, options, notes)
    data = _as_data(base, train)
    model, _ = calibrate(base.with_effects(*terms), data, notes, estimate(base, data))
    return test_errors(model, test, joint.rated_torque)[0]


def residual_spectra(
    model: ComplianceModel, data: CalibrationData, *, orders: tuple[float, float] = (0.5, 8.0)
) -> dict[str, OrderSpectrum]:
    """Order spectra of a model's twist residual against both angles (for reports)."""
    sig, torque = prepare(model, data)
    r = np.asarray(sig.twist) - np.asarray(model.predict_twist(sig, torque))
    out = {}
    for signal in ("theta_m", "theta_l"):
        theta = np.asarray(sig.get(signal))
        lo = max(orders[0], 2 * np.pi / max(np.ptp(theta), 1e-12))
        if lo < orders[1]:
            out[signal] = order_spectrum(theta, r, signal=signal, min_order=lo, max_order=orders[1])
    return out
