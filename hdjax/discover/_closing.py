"""What the residual loop says after its last step: every added effect's amplitude with its
interval, the structure left unexplained, the checks of the reference, and loud notes where
cross-validation and TEST disagree."""

from __future__ import annotations

import numpy as np

from ..reference import reference_checks
from ._chunked_fits import twist_residual
from ._folds import correlation_length
from ._pipeline import canonical, chunks_of, design
from ._uncertainty import (
    bootstrap_length,
    effect_intervals,
    instrument_torque,
    instrumented_signals,
)
from ._unexplained import all_spectra, unexplained_structure


def effect_amplitudes(model, data, est_train, options) -> list:
    """Every added effect's amplitude with its 95 % moving-block bootstrap interval over
    TRAIN ([`hdjax.discover._uncertainty.effect_intervals`][])."""
    sig_d, torque = data.pair(est_train)
    if options.chunk:
        chunks = chunks_of(sig_d, torque, options.chunk)
        res_final = twist_residual(canonical(model), chunks)
        length = bootstrap_length(res_final, data.starts)
        sig_z = instrumented_signals(sig_d, data.starts)
        inst = chunks_of(sig_z, instrument_torque(torque, data.starts), options.chunk)
        return effect_intervals(
            model, None, data, est_train, length=length, chunks=chunks, instruments=inst
        )
    # designs on the whole record (memory states), statistics on TRAIN's rows
    view = data.view()
    a_final = data.part(design(model, sig_d, torque))
    res_final = view.twist - a_final @ np.asarray(model.coef)
    length = bootstrap_length(res_final, view.starts)
    inst = np.full(data.n, np.nan)
    inst[data.rows if data.rows is not None else slice(None)] = instrument_torque(
        view.torque, view.starts
    )
    z = data.part(design(model, instrumented_signals(sig_d, data.starts), inst))
    return effect_intervals(
        model, a_final, view, data.part(est_train), length=length, instruments=z
    )


def left_unexplained(resid, spectra, data, options) -> list:
    """Structure the final model leaves above the noise in the TRAIN residual
    ([`hdjax.discover._unexplained.unexplained_structure`][])."""
    view = data.view()
    corr = correlation_length(resid, view.starts) if resid is not None else 1
    angles = {s: np.asarray(view.sig.get(s)) for s in ("theta_m", "theta_l")}
    return unexplained_structure(
        resid if resid is not None else view.twist * 0.0,
        spectra
        if resid is None
        else all_spectra(
            resid,
            angles,
            {"theta_m": options.library.orders_m, "theta_l": options.library.orders_l},
            spectra,
        ),
        {
            "torque": view.torque,
            "omega_m": np.asarray(view.sig.omega_m),
            "omega_l": np.asarray(view.sig.omega_l),
        },
        correlation_length=corr,
        starts=view.starts,
        angles=angles,
    )


def closing_notes(ratio, cv, base_cv, final, base_metrics) -> list[str]:
    """Loud notes on the final result: cross-validation far from TEST, or TEST worse than
    the start (TEST never chooses, so it can disagree with cross-validation)."""
    notes = []
    if np.isfinite(ratio) and not 0.5 <= ratio <= 2.0:
        notes.append(
            f"cross-validation does not represent TEST: the final cross-validated torque RMS "
            f"({cv.torque_rms:.4g} N·m) is {ratio:.2g} times the TEST RMS ({final.rms:.4g} N·m), "
            "so the held-out blocks of TRAIN ask for "
            + ("more extrapolation than TEST does" if ratio > 1 else "less than TEST does")
            + "; the loop's choices rest on TRAIN's folds, and the TEST figure is what to trust"
        )
    if final.rms > base_metrics.rms:
        notes.append(
            f"warning: on TEST the final model's torque RMS ({final.rms:.4g} N·m) is "
            f"{final.rms / base_metrics.rms - 1:.1%} above the starting model's "
            f"({base_metrics.rms:.4g} N·m), although cross-validation on TRAIN lowered it from "
            f"{base_cv.torque_rms:.4g} to {cv.torque_rms:.4g} N·m: TRAIN and TEST differ"
        )
    return notes


def reference_findings(model, data, est_train, test_data, est_test) -> dict:
    """[`hdjax.reference.reference_checks`][] of TRAIN (the final model's estimate on its rows)
    and TEST (its estimate there, and the calibrated range)."""
    out = {}
    lo, hi = model.torque_range
    for part, d, est in (("TRAIN", data, data.part(est_train)), ("TEST", test_data, est_test)):
        v = d.view()
        est = np.asarray(est, np.float64)
        out[part] = reference_checks(
            np.asarray(v.sig.t),
            v.torque,
            est,
            current=np.asarray(v.sig.current),
            omega=np.asarray(v.sig.omega_l),
            in_range=(est >= lo) & (est <= hi),
        )
    return out
