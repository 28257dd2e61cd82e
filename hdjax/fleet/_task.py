"""One fleet task: a (joint, log) pair calibrated, calibrated and discovered, or estimated.

[`run_task`][] takes and returns plain data (dicts of numbers and strings), so a Dask worker in
another process, or on another machine, can run it; any error becomes the row's one-line
`error` with `status = "failed"`, never an exception that stops the other tasks.
"""

from __future__ import annotations

import os
import time
import warnings
from types import SimpleNamespace

import numpy as np

from .._cache import enable_compilation_cache
from .._errors import DataError, HdjaxError, ModelMismatchError
from .._formats import load_recording
from .._io import ColumnMap
from .._joint import Joint
from .._metrics import error_metrics
from ..compliance import (
    RecordingStream,
    calibrate_lstsq,
    calibrate_stream,
    estimate_torque,
)
from ..compliance.internal import peak_abs
from ..discover import DiscoverOptions, discover
from ..discover.internal import paper_model
from ..modelfile import check_compatible, load_model
from ..modelfile.internal import ratio_mismatch
from ..pipelines.internal import ErrorSums, model_estimates

ARCSEC = 648000.0 / np.pi
_CACHE_SET: list = []


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())
    return text if isinstance(err, HdjaxError) else f"{type(err).__name__}: {text}"


def run_task(spec: dict, cache_dir: str | None = None) -> dict:
    """Run one task of a fleet manifest (see [`hdjax.fleet.load_manifest`][]).

    **Arguments:**

    - `spec`: the task's plain-data description ([`hdjax.fleet.Task`][]`.spec`).
    - `cache_dir`: JAX's persistent compilation cache for this worker process, or `None`.

    **Returns:** the task's row: `joint`, `log`, `date`, `task`, `status` (`"ok"` or
    `"failed"`), `error`, `seconds`, `n_samples`, the calibrated `coefficients` (term name to
    value), `twist_rms_arcsec`, `condition`, and for discover the `effects` added, their
    `amplitudes` (each effect's amplitude in arcsec of twist and in N·m of equivalent torque,
    each with its 95 % interval, as the residual loop reports them) and the TEST torque errors
    before and after.
    """
    if cache_dir and not _CACHE_SET:
        enable_compilation_cache(cache_dir)
        _CACHE_SET.append(cache_dir)
    t0 = time.perf_counter()
    row = {
        "joint": spec["joint_name"],
        "log": spec["log"],
        "date": spec["date"],
        "task": spec["task"],
        "status": "ok",
        "error": "",
        "worker_pid": os.getpid(),
    }
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            row.update(_RUNNERS[spec["task"]](spec))
        row["warnings"] = [" ".join(str(w.message).split()) for w in caught][:20]
    except Exception as err:  # noqa: BLE001 - every failure becomes the task's row
        row.update(status="failed", error=_one_line(err))
    row["seconds"] = time.perf_counter() - t0
    return row


def _joint_and_map(spec):
    joint = Joint.from_dict(spec["joint"])
    cmap = ColumnMap.from_dict(spec["columns"]) if spec["columns"] else None
    return joint, cmap


def _coefficients(model) -> dict:
    coef = np.asarray(model.coef)
    return {n: float(c) for n, c, a in zip(model.term_names, coef, model.active) if a}


def _calibrate(spec) -> dict:
    joint, cmap = _joint_and_map(spec)
    chunk = spec["settings"]["chunk"]
    if chunk:
        stream = RecordingStream.from_files([spec["log"]], cmap, chunk=chunk)
        scale = peak_abs(stream) or 1.0
        res = calibrate_stream(
            paper_model(spec["model_structure"], joint, scale), stream, chunk=chunk
        )
    else:
        rec = load_recording(spec["log"], cmap)
        scale = float(np.max(np.abs(np.asarray(rec.current)))) or 1.0
        res = calibrate_lstsq(paper_model(spec["model_structure"], joint, scale), rec)
    return {
        "n_samples": res.stats["n_samples"],
        "coefficients": _coefficients(res.value),
        "twist_rms_arcsec": res.stats["residual_rms"] * ARCSEC,
        "condition": res.stats["condition"],
    }


def _pair(interval) -> tuple[float | None, float | None]:
    if interval is None:
        return None, None
    return float(interval[0]), float(interval[1])


def _effect_amplitudes(steps) -> list[dict]:
    """Each added effect's amplitude with its 95 % interval, as the residual loop reports it
    (the `amplitude` of each step of `hdjax discover`'s report: a moving-block bootstrap over
    TRAIN): in arcsec of twist (`amplitude_arcsec`, `low`, `high`) and in N·m of equivalent torque
    (`amplitude_Nm`, `low_Nm`, `high_Nm`); `None` where the loop gave none."""
    # matched by the effect's key (the loop gives each step the interval of its own effect)
    by_key = {s.amplitude["effect"]: s.amplitude for s in steps if s.amplitude}
    out = []
    for step in steps:
        amp = by_key.get(step.key, {})
        lo, hi = _pair(amp.get("arcsec_ci95"))
        lo_nm, hi_nm = _pair(amp.get("nm_ci95"))
        out.append(
            {
                "effect": step.key,
                "amplitude_arcsec": None if amp.get("arcsec") is None else float(amp["arcsec"]),
                "low": lo,
                "high": hi,
                "amplitude_Nm": None if amp.get("nm") is None else float(amp["nm"]),
                "low_Nm": lo_nm,
                "high_Nm": hi_nm,
                "cv_gain": float(step.cv_gain),
            }
        )
    return out


def _calibrate_discover(spec) -> dict:
    joint = Joint.from_dict(spec["joint"])
    _, cmap = _joint_and_map(spec)
    m, s = spec["model_structure"], spec["settings"]
    # with `chunk`, the log is parsed and the loop's fits accumulated chunk by chunk (the same
    # results to rounding, as `hdjax discover --chunk`)
    rec = load_recording(spec["log"], cmap, chunk=s["chunk"] or None)
    train, test = rec.split(1.0 - s["split"])
    options = DiscoverOptions(
        max_effects=s["max_effects"],
        min_gain=s["min_gain"],
        n_segments=m["n_segments"],
        poly_order=m["poly_order"],
        fourier_order=m["fourier_order"],
        per_segment=m["per_segment"],
        chunk=s["chunk"],
    )
    sol = discover(train, test, joint, options)
    result = sol.aux
    twist = result.steps[-1].twist_rms_arcsec if result.steps else result.baseline_twist_rms_arcsec
    return {
        "n_samples": rec.n_samples,
        "coefficients": _coefficients(sol.value),
        "twist_rms_arcsec": float(twist),
        "effects": list(result.effects),
        "amplitudes": _effect_amplitudes(result.steps),
        "baseline_test_rms_Nm": float(result.baseline.rms),
        "test_rms_Nm": float(result.final.rms),
        "test_max_Nm": float(result.final.max),
    }


def _estimate(spec) -> dict:
    joint, cmap = _joint_and_map(spec)
    saved = load_model(spec["model_file"])
    if saved.compliance is None:
        raise ValueError(f"{spec['model_file']}: holds no compliance model")
    if spec["settings"]["chunk"]:
        return _estimate_streamed(spec, saved, joint, cmap)
    rec = load_recording(spec["log"], cmap)
    check_compatible(saved, rec, joint)
    est = estimate_torque(saved.compliance, rec)
    out = {
        "n_samples": rec.n_samples,
        "coefficients": _coefficients(saved.compliance),
        "in_range_pct": 100.0 * float(np.mean(np.asarray(est.in_range))),
    }
    if rec.torque is not None:
        m = error_metrics(np.asarray(est.torque), np.asarray(rec.torque), joint.rated_torque)
        out.update(test_rms_Nm=float(m.rms), test_max_Nm=float(m.max))
    return out


KEPT_ROWS = 20000
"""Rows of the angles a streamed estimate keeps (evenly thinned) for the gear-ratio check."""


def _estimate_streamed(spec, saved, joint, cmap) -> dict:
    """`_estimate` with the log read and estimated `chunk` samples at a time (memory bounded by
    the chunk; the estimate of every sample is the whole log's). The saved model's checks run
    on the first chunk (its ratio and columns) and, after the pass, on every k-th sample of the
    angles (the gear ratio the data shows)."""
    chunk = spec["settings"]["chunk"]
    stream = RecordingStream.from_files([spec["log"]], cmap, chunk=chunk)
    n, in_range, sums, kept, stride = 0, 0, None, [], 1
    for rows, est in model_estimates(saved.compliance, stream, chunk, need_torque=False):
        if n == 0:
            check_compatible(saved, rows, joint, check_angles=False)
            sums = None if rows.torque is None else ErrorSums()
        torque = np.asarray(est.torque)
        if sums is not None:
            sums.add(torque - np.asarray(rows.torque))
        in_range += int(np.sum(np.asarray(est.in_range)))
        idx = np.arange(n, n + torque.shape[0])
        pick = idx % stride == 0
        kept.append(np.stack([np.asarray(rows.theta_l)[pick], np.asarray(rows.theta_m)[pick]]))
        n += torque.shape[0]
        if sum(k.shape[1] for k in kept) > 2 * KEPT_ROWS:  # thin what is kept: bounded
            stride *= 2
            kept = [np.concatenate(kept, axis=1)[:, ::2]]
    if n == 0:
        raise DataError(f"{spec['log']}: the log holds no samples")
    angles = np.concatenate(kept, axis=1)
    why = ratio_mismatch(
        saved.joint.ratio,
        SimpleNamespace(theta_l=angles[0], theta_m=angles[1], source=spec["log"]),
        whose="the model's",
    )
    if why:
        raise ModelMismatchError(why)
    out = {
        "n_samples": n,
        "coefficients": _coefficients(saved.compliance),
        "in_range_pct": 100.0 * in_range / n,
    }
    if sums is not None:
        m = sums.as_dict(joint.rated_torque)
        out.update(test_rms_Nm=float(m["rms"]), test_max_Nm=float(m["max"]))
    return out


_RUNNERS = {
    "calibrate": _calibrate,
    "calibrate+discover": _calibrate_discover,
    "estimate": _estimate,
}
