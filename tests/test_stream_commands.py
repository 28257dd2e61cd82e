"""`hdjax run` and `hdjax sweep` with `[fit] chunk` stream the files (never whole recordings) and
give the in-memory run's metrics; the network's Kalman-filtered features carry across chunks."""

import json

import numpy as np
import pytest

import hdjax
from hdjax.cli import main
from hdjax.compliance import RecordingStream
from hdjax.network import build_features
from hdjax.pipelines import synthetic_recording
from hdjax.pipelines._streamed import stream_features

JOINT = hdjax.Joint(ratio=160.0, rated_torque=400.0)
CHUNK = 97  # small and not a divisor of any part's length: every part ends in a short chunk
# 1e-9 relative: the streamed calibration solves the same scaled normal equations (see
# tests/test_stream.py); estimates and network inputs are the same per-sample operations, and
# the errors are sums of the same terms in another order (~1e-15).
RTOL = 1e-9


def _config(name, data, chunk, network=True):
    figures = "true" if chunk else "false"  # the streamed run draws its decimated figures
    net = (
        "[network]\nhidden = [3]\nsteps = 30\nmax_train_samples = 200\nkalman = true\n"
        if network
        else "[network]\nenabled = false\n"
    )
    return (
        f'[experiment]\nname = "{name}"\nseed = 3\n[joint]\nratio = 160\nrated_torque = 400\n'
        f"[data]\n{data}"
        '[model]\npoly_order = 2\nkinematic = "paper"\nfourier_order = 1\nn_segments = 3\n'
        f"[fit]\nchunk = {chunk}\n{net}"
        f"[outputs]\nfigures = {figures}\ntiming = false\n[sweep]\nsetting = "
        '"model.n_segments"\nvalues = [1, 3]\n'
    )


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    pytest.importorskip("pyarrow")
    from hdjax.cli._convert import convert

    d = tmp_path_factory.mktemp("stream-cmds")
    hdjax.save_csv(synthetic_recording(JOINT, 1400, seed=5), d / "a.csv")
    convert(d / "a.csv", d / "a.parquet")  # the train file as Parquet
    hdjax.save_csv(synthetic_recording(JOINT, 900, seed=6), d / "b.csv")
    return d


def _no_whole_loads(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("a streamed run loaded a whole recording")

    for target in (
        "hdjax.pipelines._dataset._load",
        "hdjax._formats.load",
        "hdjax._formats.load_csv",
        "hdjax._io.load_csv",
    ):
        monkeypatch.setattr(target, refuse)


def _run(logs, tmp_path, command, data, chunk, network=True):
    cfg = tmp_path / f"{command}{chunk}.toml"
    cfg.write_text(_config(f"{command}{chunk}", data, chunk, network))
    out = tmp_path / f"out-{command}{chunk}"
    assert main([command, str(cfg), "--out", str(out), "--quiet"]) == 0
    return json.loads((out / "metrics.json").read_text()), out


def _close(a, b, path=""):
    """Every number of two metric trees equal to RTOL (timings and environment excluded)."""
    if isinstance(a, dict):
        for k in a:
            if k in ("environment", "wall_s", "fit_s", "data", "messages", "timing"):
                continue
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list) and a and isinstance(a[0], int | float | dict | list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert b == pytest.approx(a, rel=RTOL, abs=1e-300), path
    else:
        assert a == b, path


def test_run_streamed_equals_in_memory(logs, tmp_path, monkeypatch):
    data = (
        f'kind = "files"\ntrain = ["{logs / "a.parquet"}"]\nsplit = 0.3\nsettle = 0.05\ntest = []\n'
    )
    whole, _ = _run(logs, tmp_path, "run", data, 0)
    _no_whole_loads(monkeypatch)
    streamed, out = _run(logs, tmp_path, "run", data, CHUNK)
    _close(whole["model"], streamed["model"])
    _close(whole["network"], streamed["network"])
    assert streamed["data"]["n_train"] == whole["data"]["n_train"]
    ref = json.loads((tmp_path / "out-run0" / "model.json").read_text())
    got = json.loads((out / "model.json").read_text())
    c_ref = np.asarray(ref["compliance"]["coef"])
    c_got = np.asarray(got["compliance"]["coef"])
    np.testing.assert_allclose(c_got, c_ref, rtol=0, atol=RTOL * np.max(np.abs(c_ref)))
    assert (out / "figures" / "model_a.png").stat().st_size > 0


def test_sweep_streamed_equals_in_memory(logs, tmp_path, monkeypatch):
    data = f'kind = "files"\ntrain = ["{logs / "a.csv"}"]\ntest = ["{logs / "b.csv"}"]\n'
    whole, _ = _run(logs, tmp_path, "sweep", data, 0, network=False)
    _no_whole_loads(monkeypatch)
    streamed, _ = _run(logs, tmp_path, "sweep", data, CHUNK, network=False)
    assert [m["value"] for m in streamed["members"]] == [1, 3]
    for a, b in zip(whole["members"], streamed["members"]):
        assert b["rms"] == pytest.approx(a["rms"], rel=RTOL)
        assert b["max"] == pytest.approx(a["max"], rel=RTOL)
        assert b["per_recording"]["b"] == pytest.approx(a["per_recording"]["b"], rel=RTOL)


def test_kalman_features_carry_across_chunks():
    # two recordings: the filter restarts at the second one and carries between chunks within
    recs = [synthetic_recording(JOINT, n, seed=s) for n, s in ((700, 1), (350, 2))]
    kw = dict(periodic=True, orders=(1, 2), kalman=True)
    whole = np.concatenate([np.asarray(build_features(r, JOINT, **kw).x) for r in recs])
    chunks = list(stream_features(RecordingStream.from_recordings(recs, 61), JOINT, **kw))
    got = np.concatenate([np.asarray(f.x) for f, _, _ in chunks])
    assert chunks[0][0].layout == build_features(recs[0], JOINT, **kw).layout
    np.testing.assert_allclose(got, whole, rtol=RTOL, atol=1e-12 * np.max(np.abs(whole)))
    # the filter state matters: restarting it at each chunk gives other features
    restarted = np.concatenate(
        [
            np.asarray(build_features(c, JOINT, **kw).x)[:, 0]
            for r in recs
            for c in next(iter(RecordingStream.from_recordings([r], 61)))
        ]
    )
    assert np.max(np.abs(restarted - whole[:, 0])) > 1e-6 * np.max(np.abs(whole[:, 0]))


def test_streamed_figure_keeps_the_samples_of_the_whole_figure():
    # the figure of a streamed part plots what `_envelope` picks on the whole series
    from hdjax.pipelines._streamed import _Envelope
    from hdjax.report._figures import _envelope

    rng = np.random.default_rng(0)
    n = 20011
    t, meas = np.arange(n) * 1e-3, rng.standard_normal(n)
    est = meas + rng.standard_normal(n) * np.where(rng.random(n) < 0.01, 10.0, 1.0)
    env = _Envelope(n)
    for i in range(0, n, 97):
        env.add(t[i : i + 97], meas[i : i + 97], est[i : i + 97])
    tt, mm, ee = env.series()
    idx = _envelope(est - meas)
    np.testing.assert_array_equal(tt, t[idx])
    np.testing.assert_array_equal(ee, est[idx])
    np.testing.assert_array_equal(mm, meas[idx])


def test_twist_hysteresis_estimate_carries_across_chunks():
    """A model with the residual loop's hysteresis (a Dahl state of the measured twist) gives,
    streamed, the in-memory estimate: the state carries from chunk to chunk and restarts with
    each recording. Restarting it at every chunk instead gives another estimate."""
    from hdjax.compliance import ComplianceModel, calibrate_lstsq, estimate_torque
    from hdjax.effects import TwistHysteresis, twist_compliance
    from hdjax.pipelines._paper import stacked_signals
    from hdjax.pipelines._streamed import estimate_model_streamed

    train = [synthetic_recording(JOINT, 1400, seed=5)]
    tests = [synthetic_recording(JOINT, n, seed=s) for n, s in ((700, 6), (450, 7))]
    scale = float(np.max(np.abs(np.asarray(train[0].current))))
    base = ComplianceModel.paper(JOINT, n_segments=3, poly_order=2, fourier_order=1,
                                 current_scale=scale)  # fmt: skip
    k = twist_compliance(*stacked_signals(base, train), JOINT.rated_torque)
    model = base.with_effects(TwistHysteresis(torque_scale=40.0, compliance=k))
    cal = calibrate_lstsq(model, stacked_signals(model, train)).value
    whole = [np.asarray(estimate_torque(cal, r).torque) for r in tests]
    err = np.concatenate([w - np.asarray(r.torque) for w, r in zip(whole, tests)])
    n = sum(r.n_samples for r in tests)
    got = estimate_model_streamed(cal, RecordingStream.from_recordings(tests, CHUNK), n, CHUNK)
    assert got.errors.n == n
    assert got.errors.rms == pytest.approx(np.sqrt(np.mean(err**2)), rel=RTOL)
    assert got.errors.peak == pytest.approx(np.max(np.abs(err)), rel=RTOL)
    est = np.concatenate(whole)
    # the carried state matters: the same model with the state restarted at every chunk
    restarted = [
        np.asarray(estimate_torque(cal, c).torque)
        for r in tests
        for c in next(iter(RecordingStream.from_recordings([r], CHUNK)))
    ]
    assert np.max(np.abs(np.concatenate(restarted) - est)) > 1e-3 * np.max(np.abs(est))
