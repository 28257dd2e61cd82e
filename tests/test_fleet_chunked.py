"""Fleet tasks with `chunk > 0` read their log chunk by chunk and give the whole log's row.

The task runner is called in-process (what a Dask worker calls); the references are the same
tasks with `chunk = 0`. The estimated model carries the residual loop's hysteresis (a Dahl
state of the measured twist), whose state must cross the chunk boundaries.
"""

import dataclasses
import json

import numpy as np
import pytest

import hdjax
from hdjax.compliance import ComplianceModel, calibrate_lstsq
from hdjax.effects import TwistHysteresis, twist_compliance
from hdjax.fleet import load_manifest
from hdjax.fleet._task import run_task
from hdjax.modelfile import save_model
from hdjax.pipelines import synthetic_recording
from hdjax.pipelines._paper import stacked_signals

from . import discover_data

RTOL = 1e-9
CHUNK = 97  # divides no log's length: every log ends in a short chunk
JOINT = hdjax.Joint(ratio=160.0, rated_torque=400.0)


def _rows(
    tmp_path, task, logs, chunk, *, ratio=160.0, rated=400.0, extra="", model=None, structure=""
):
    """The rows of one joint's `logs` ([(file, date)]) run as `task` with `chunk`."""
    entries = ", ".join(f'{{ path = "{p}", date = {d} }}' for p, d in logs)
    text = (
        f'[fleet]\nname = "cell"\ntask = "{task}"\nchunk = {chunk}\n{extra}'
        f'[[joints]]\nname = "j"\nratio = {ratio}\nrated_torque = {rated}\n'
        + (f'model = "{model}"\n' if model else "")
        + f"logs = [{entries}]\n"
        + structure
    )
    path = tmp_path / f"cell-{task.replace('+', '-')}-{chunk}.toml"
    path.write_text(text)
    return [run_task(t.spec) for t in load_manifest(path).tasks]


@pytest.fixture(scope="module")
def hysteresis_model(tmp_path_factory):
    """A saved model with a twist-driven hysteresis term, and logs (one without torque)."""
    d = tmp_path_factory.mktemp("fleet-chunked")
    calib = synthetic_recording(JOINT, 1500, seed=70)
    scale = float(np.max(np.abs(np.asarray(calib.current))))
    base = ComplianceModel.paper(JOINT, poly_order=3, per_segment=False, fourier_order=1,
                                 current_scale=scale)  # fmt: skip
    k = twist_compliance(*stacked_signals(base, [calib]), JOINT.rated_torque)
    model = base.with_effects(TwistHysteresis(torque_scale=40.0, compliance=k))
    fitted = calibrate_lstsq(model, calib).value
    save_model(d / "model.json", JOINT, compliance=fitted)
    # the fitted model's active terms, kept in memory: what a task row must report
    coef = np.asarray(fitted.coef)
    expected = {n: float(c) for n, c, a in zip(fitted.term_names, coef, fitted.active) if a}
    (d / "expected_coefficients.json").write_text(json.dumps(expected))
    hdjax.save_csv(synthetic_recording(JOINT, 1200, seed=71), d / "a.csv")
    no_torque = synthetic_recording(JOINT, 900, seed=72)
    hdjax.save_csv(dataclasses.replace(no_torque, torque=None), d / "b.csv")
    # angles of a joint with another ratio, under the model's ratio
    hdjax.save_csv(synthetic_recording(hdjax.Joint(ratio=100.0, rated_torque=400.0), 900, seed=73),
                   d / "c.csv")  # fmt: skip
    return d


def test_streamed_estimate_task_equals_whole_log(hysteresis_model):
    d = hysteresis_model
    logs = [("a.csv", "2026-01-05"), ("b.csv", "2026-02-02")]
    whole = _rows(d, "estimate", logs, 0, model="model.json")
    streamed = _rows(d, "estimate", logs, CHUNK, model="model.json")
    expected = json.loads((d / "expected_coefficients.json").read_text())
    assert len(expected) > 3
    for a, b in zip(whole, streamed):
        assert a["status"] == b["status"] == "ok", (a["error"], b["error"])
        assert a["n_samples"] == b["n_samples"]
        assert b["in_range_pct"] == pytest.approx(a["in_range_pct"], rel=1e-12)
        # the model's own coefficients, from the fit before it was saved (not from the file)
        assert b["coefficients"] == a["coefficients"] == expected
    assert "test_rms_Nm" not in whole[1] and "test_rms_Nm" not in streamed[1]  # no torque
    for key in ("test_rms_Nm", "test_max_Nm"):
        assert streamed[0][key] == pytest.approx(whole[0][key], rel=RTOL)


def test_streamed_estimate_task_refuses_another_joints_data(hysteresis_model):
    d = hysteresis_model
    # the angles show ratio 100 where the model has 160: refused after the pass, in one line
    (wrong_angles,) = _rows(d, "estimate", [("c.csv", "2026-03-02")], CHUNK, model="model.json")
    assert wrong_angles["status"] == "failed"
    assert "ratio is 160" in wrong_angles["error"] and "\n" not in wrong_angles["error"]
    (whole,) = _rows(d, "estimate", [("c.csv", "2026-03-02")], 0, model="model.json")
    assert whole["status"] == "failed" and "ratio is 160" in whole["error"]
    # the joint's declared ratio differs from the model's: refused on the first chunk
    (wrong_joint,) = _rows(
        d, "estimate", [("a.csv", "2026-01-05")], CHUNK, ratio=100.0, model="model.json"
    )
    assert wrong_joint["status"] == "failed" and "calibrated for ratio 160" in wrong_joint["error"]


def test_streamed_discover_task_equals_whole_log(tmp_path):
    rec = discover_data.synthetic_recording(
        41, [("harmonic_m", 2.0, 25 * discover_data.ARCSEC)], n=3000
    )
    hdjax.save_csv(rec, tmp_path / "log.csv")
    logs = [("log.csv", "2026-01-05")]
    # a structure 3000 samples determine well (scaled condition ~1e3); the manifest's default
    # per-segment sextic has ~2e11 here, where two summation orders agree only to ~cond * u
    structure = "[model]\nper_segment = false\npoly_order = 3\nfourier_order = 1\n"
    kw = dict(ratio=discover_data.RATIO, rated=discover_data.RATED, extra="max_effects = 1\n")
    (whole,) = _rows(tmp_path, "calibrate+discover", logs, 0, structure=structure, **kw)
    (streamed,) = _rows(tmp_path, "calibrate+discover", logs, 256, structure=structure, **kw)
    assert whole["status"] == streamed["status"] == "ok", (whole["error"], streamed["error"])
    assert streamed["effects"] == whole["effects"] == ["harmonic:theta_m:2"]
    ref = np.array(list(whole["coefficients"].values()))
    got = np.array([streamed["coefficients"][k] for k in whole["coefficients"]])
    np.testing.assert_allclose(got, ref, rtol=0, atol=RTOL * np.max(np.abs(ref)))
    for key in ("baseline_test_rms_Nm", "test_rms_Nm", "test_max_Nm", "n_samples"):
        assert streamed[key] == pytest.approx(whole[key], rel=RTOL), key
