"""One fleet task: a (joint, log) pair calibrated, calibrated and discovered, or estimated.

[`run_task`][] takes and returns plain data (dicts of numbers and strings), so a Dask worker in
another process, or on another machine, can run it; any error becomes the row's one-line
`error` with `status = "failed"`, never an exception that stops the other tasks.
"""

from __future__ import annotations

import os
import time
import warnings

import numpy as np

from .._cache import enable_compilation_cache
from .._errors import HdjaxError
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
from ..compliance._stream_fit import peak_abs
from ..config import check_compatible, load_model
from ..config._schema import paper_model
from ..discover import DiscoverOptions, discover

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
    rec = load_recording(spec["log"], cmap)
    train, test = rec.split(1.0 - spec["settings"]["split"])
    m, s = spec["model_structure"], spec["settings"]
    options = DiscoverOptions(
        max_effects=s["max_effects"],
        min_gain=s["min_gain"],
        n_segments=m["n_segments"],
        poly_order=m["poly_order"],
        fourier_order=m["fourier_order"],
        per_segment=m["per_segment"],
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


_RUNNERS = {
    "calibrate": _calibrate,
    "calibrate+discover": _calibrate_discover,
    "estimate": _estimate,
}
