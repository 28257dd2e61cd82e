"""What the residual loop says after its last step: every added effect's amplitude with its
interval, the structure left unexplained, the checks of the reference, and loud notes where
cross-validation and TEST disagree."""

from __future__ import annotations

import numpy as np

from .._errors import CalibrationError, InversionError
from ..effects import EncoderSkew
from ..reference import reference_checks
from ._chunked import twist_residual
from ._folds import correlation_length
from ._pipeline import calibrate, canonical, chunks_of, design
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


def _skew_row(model, data, est_train, options, joint) -> dict:
    """The interval row of the skew column calibrated into `model` (raises as `calibrate`)."""
    # the screening delay (the family's default) on the side the fit finds, not refined to its
    # fixed point: the column hardly depends on the size of the delay it is built for, only on
    # which encoder it delays, and a refined delay is a new static field whose programs would
    # compile again for every record (a reading is not worth that)
    kw = dict(ratio=float(joint.ratio), sign=float(joint.twist_sign))
    screen = EncoderSkew(**kw).delay
    for delay in (screen, -screen):
        term = EncoderSkew(delay=delay, **kw)
        with_skew, est = calibrate(
            model.with_effects(term), data, [], est_train, options.chunk, refine=False
        )
        if float(np.asarray(with_skew.coef)[-1]) * delay > 0:
            break
    return effect_amplitudes(with_skew, data, est, options)[-1]


def skew_estimate(models, data, options, joint) -> str | None:
    """The encoders' time skew TRAIN reads, in ms with its 95 % interval, when the loop did
    not add `skew:encoders`: the skew family's exact column ([`hdjax.effects.EncoderSkew`][])
    calibrated into the starting and the final model, and bootstrapped as an added effect is.
    `models` is `[(label, model, TRAIN estimate), ...]`. A delay is a property of the logging,
    not of the joint, so it is worth a line even when it did not pass the stopping rule; where
    the readings disagree, the record does not identify it apart from the model's other
    terms, and the sentence says so. `None` when the skew is in the final model, not among
    the offered families, or the record never moves."""
    final = models[-1][1]
    view = data.view()
    if (
        any(t.key == "skew:encoders" for t in final.effect_terms)
        or "skew:encoders" not in options.library.families
        or view.sig.t is None
        or not np.any(np.asarray(view.sig.omega_l) != 0)
    ):
        return None
    readings, rows = [], []
    for label, model, est in models:
        try:
            row = _skew_row(model, data, est, options, joint)
        except (CalibrationError, InversionError) as err:
            readings.append(f"into the {label}: not calibrated ({err})")
            continue
        if "delay_ms" in row:
            lo, hi = row["delay_ms_ci95"]
            rows.append((lo, hi))
            readings.append(f"into the {label}: {row['delay_ms']:.3g} ms [{lo:.3g}, {hi:.3g}]")
    if not rows:
        return None
    covers = all(lo <= 0.0 <= hi for lo, hi in rows)
    agree = max(lo for lo, _ in rows) <= min(hi for _, hi in rows)
    if covers:
        advice = "every interval covers 0 ms: TRAIN shows no skew"
    elif not agree:
        advice = (
            "the intervals do not overlap, so TRAIN does not tell the skew apart from the "
            "model's other terms; record the joint at two or more speeds to measure it"
        )
        if options.fourier_order:
            advice += (
                ", and start without the paper's kinematic columns ([model] fourier_order = "
                "0): at two speeds those functions of angle times speed (Song et al. eq. (9)) "
                "take part of a twist proportional to speed"
            )
    else:
        advice = (
            "check the encoders' sampling instants; if the delay is real, correct the "
            "timestamps and run discover again"
        )
    return (
        "skew:encoders, not added by the loop: the delay between the load and motor encoders "
        "(positive: the load encoder read later) that TRAIN reads, with 95 % intervals, "
        + "; ".join(readings)
        + "; "
        + advice
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
