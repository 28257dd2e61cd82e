"""Checks of the discover inputs, in plain Python, before anything is fitted."""

from __future__ import annotations

import math

import numpy as np

from .._errors import DataError
from .._joint import Joint
from .._recording import Recording

RATIO_TOLERANCE = 0.02
MIN_SAMPLES = 500


def apparent_ratio(rec: Recording) -> float | None:
    """The reduction ratio the angles imply, $\\mathrm{cov}(\\theta_m, \\theta_l) /
    \\mathrm{var}(\\theta_l)$, or `None` when the output hardly moves (span < 0.05 rad)."""
    tl = np.asarray(rec.theta_l)
    if np.ptp(tl) < 0.05:
        return None
    tm = np.asarray(rec.theta_m)
    tl = tl - tl.mean()
    return float(np.dot(tm - tm.mean(), tl) / np.dot(tl, tl))


def check_inputs(
    train: Recording,
    test: Recording,
    joint: Joint,
    *,
    min_order_m: float,
    ignore_columns: tuple[str, ...] = (),
) -> list[str]:
    """Validate TRAIN/TEST against each other and the joint; return notes for the report.

    Refuses: a missing reference torque; TRAIN and TEST whose angles imply different ratios, or
    a ratio other than the joint's; a TEST without an extra column TRAIN has; an extra column of
    TRAIN that is constant (unless ignored); a TRAIN too short for the lowest candidate order of
    the motor angle or with fewer than `MIN_SAMPLES` samples.
    """
    notes = []
    for rec, name in ((train, "TRAIN"), (test, "TEST")):
        if rec.torque is None:
            raise DataError(f"{name} ({rec.source}) has no 'torque' column; discover needs it")
    ratios = {name: apparent_ratio(rec) for rec, name in ((train, "TRAIN"), (test, "TEST"))}
    if ratios["TRAIN"] and ratios["TEST"]:
        a, b = ratios["TRAIN"], ratios["TEST"]
        if abs(a - b) > RATIO_TOLERANCE * max(abs(a), abs(b)):
            raise DataError(
                f"TRAIN and TEST come from joints with different ratios: their angles imply "
                f"{a:.4g} ({train.source}) and {b:.4g} ({test.source}); use recordings of one joint"
            )
    for name, r in ratios.items():
        if r is not None and abs(r - joint.ratio) > RATIO_TOLERANCE * joint.ratio:
            raise DataError(
                f"{name}'s angles imply a reduction ratio of {r:.4g}, but the joint file says "
                f"{joint.ratio:g}; check the joint's 'ratio' or the angle columns' units"
            )
    missing = sorted(set(train.extras) - set(test.extras) - set(ignore_columns))
    if missing:
        raise DataError(
            f"TEST ({test.source}) lacks column(s) {', '.join(missing)} that TRAIN has; the model "
            "may use them, so TEST needs the same columns (or pass --ignore-column NAME)"
        )
    for name, x in train.extras.items():
        if name in ignore_columns:
            continue
        if float(np.ptp(np.asarray(x))) == 0.0:
            raise DataError(
                f"TRAIN's extra column {name!r} is constant ({float(np.asarray(x)[0]):g}), so no "
                f"effect can depend on it; drop it or pass --ignore-column {name}"
            )
    n = train.n_samples
    if n < MIN_SAMPLES:
        raise DataError(
            f"TRAIN has {n} samples; the loop needs at least {MIN_SAMPLES} (cross-validation in "
            "5 folds of whole blocks)"
        )
    span = float(np.ptp(np.asarray(train.theta_m)))
    need = 2.0 * math.pi / min_order_m
    if span < need:
        dur = float(train.t[-1] - train.t[0])
        speed = span / dur if dur > 0 else 0.0
        more = (
            f"; at its mean speed of {speed:.3g} rad/s that is {need / speed:.3g} s"
            if speed
            else ""
        )
        raise DataError(
            f"TRAIN is too short to resolve the lowest candidate order {min_order_m:g} of the "
            f"motor angle: theta_m spans {span:.3g} rad but one period of that order needs "
            f"{need:.3g} rad{more} (the recording lasts {dur:.3g} s)"
        )
    for name in ignore_columns:
        notes.append(f"column {name!r} ignored on request")
    return notes
