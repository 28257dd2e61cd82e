"""Streaming least squares: chunked calibration equals the in-memory fit, states carry across
chunks, and the accumulators match numpy.linalg.lstsq."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax.compliance import (
    ComplianceModel,
    Hysteresis,
    NormalEquations,
    RecordingStream,
    StreamingQR,
    calibrate_lstsq,
    calibrate_stream,
)
from hdjax.effects import SEGMENT_START, TwistHysteresis, twist_compliance
from hdjax.pipelines import synthetic_recording
from hdjax.pipelines._paper import stacked_signals

JOINT = hdjax.Joint(ratio=100.0, rated_torque=100.0)
CHUNK = 777  # not a divisor of the recording lengths: every recording ends in a short chunk


@pytest.fixture(scope="module")
def recs():
    return [synthetic_recording(JOINT, n, seed=s) for n, s in ((4000, 1), (3100, 2))]


def model_of(velocity="difference", hysteresis=False, recs=None):
    """The paper's model; `hysteresis` True: a Dahl state of the torque path; "twist": of the
    measured twist (the residual loop's `hysteresis:torque`), its compliance from `recs`."""
    m = ComplianceModel.paper(JOINT, current_scale=1.0, velocity=velocity)
    if hysteresis in ("twist", "twist-play"):
        sig, torque = stacked_signals(m, recs)
        k = twist_compliance(sig, torque, JOINT.rated_torque)
        h = 2.0 if hysteresis == "twist-play" else 0.0  # a play of 2 N·m on the driver
        return m.with_effects(TwistHysteresis(torque_scale=10.0, compliance=k, play=h))
    return m.with_effects(Hysteresis(torque_scale=10.0)) if hysteresis else m


def assert_same_fit(a, b, rtol=1e-9):
    # 1e-9 relative: both solve the same scaled problem to ~cond * eps ~ 1e-10 (cond ~ 5e5)
    ca, cb = np.asarray(a.value.coef), np.asarray(b.value.coef)
    np.testing.assert_allclose(cb, ca, rtol=0, atol=rtol * np.max(np.abs(ca)))
    for key in ("rank", "n_terms", "n_samples", "segment_counts", "dropped"):
        assert a.stats[key] == b.stats[key], key
    assert a.value.active == b.value.active and a.value.torque_range == b.value.torque_range
    np.testing.assert_allclose(b.stats["residual_rms"], a.stats["residual_rms"], rtol=1e-9)
    np.testing.assert_allclose(b.stats["condition"], a.stats["condition"], rtol=1e-4)


@pytest.mark.parametrize(
    "velocity,hysteresis",
    [
        ("difference", False),
        ("difference", True),
        ("smoothed", True),
        ("difference", "twist"),
        ("smoothed", "twist"),
        ("difference", "twist-play"),
        ("smoothed", "twist-play"),
    ],
)
def test_stream_equals_in_memory(recs, velocity, hysteresis):
    """Velocities (a halo of neighbouring samples) and the Dahl state (carried, of the torque
    path or of the measured twist) cross chunk boundaries exactly as in one pass."""
    m = model_of(velocity, hysteresis, recs)
    mem = calibrate_lstsq(m, stacked_signals(m, recs))
    streamed = calibrate_stream(m, RecordingStream.from_recordings(recs, CHUNK), chunk=CHUNK)
    assert_same_fit(mem, streamed)


def test_twist_hysteresis_state_matters_across_chunks(recs):
    """The carried twist-driven state is what makes the streamed fit equal: the same fit with
    the state restarted at every chunk (`SEGMENT_START` set there) gives other coefficients."""
    m = model_of("difference", "twist", recs)
    sig, torque = stacked_signals(m, recs)
    mem = np.asarray(calibrate_lstsq(m, (sig, torque)).value.coef)
    starts = np.concatenate([np.arange(r.n_samples) % CHUNK == 0 for r in recs])
    extras = {**sig.extras, SEGMENT_START: jnp.asarray(starts.astype(np.float64))}
    restarted = calibrate_lstsq(m, (dataclasses.replace(sig, extras=extras), torque))
    coef = np.asarray(restarted.value.coef)
    assert np.max(np.abs(coef - mem)) > 1e-3 * np.max(np.abs(mem))


def test_well_conditioned_stream_reads_once(recs, monkeypatch):
    """Below REFINE_ABOVE_COND the log is read once (no refinement pass) and still agrees."""
    import hdjax.compliance._stream_fit as S

    m = ComplianceModel.paper(JOINT, current_scale=1.0, poly_order=1, kinematic="none",
                              per_segment=False)  # fmt: skip
    mem = calibrate_lstsq(m, stacked_signals(m, recs))
    assert mem.stats["condition"] < S.REFINE_ABOVE_COND
    passes = []
    real = S._passes
    monkeypatch.setattr(S, "_passes", lambda *a: passes.append(1) or real(*a))
    streamed = calibrate_stream(m, RecordingStream.from_recordings(recs, CHUNK), chunk=CHUNK)
    assert len(passes) == 1
    assert_same_fit(mem, streamed)


def test_stream_qr_path_equals_in_memory(recs, monkeypatch):
    """With the semi-normal equations refused, both fall back to QR (TSQR when streamed)."""
    import hdjax.compliance._lstsq as L
    import hdjax.compliance._stream_fit as S

    monkeypatch.setattr(L, "CSNE_MAX_COND", 0.0)
    monkeypatch.setattr(S, "CSNE_MAX_COND", 0.0)
    m = model_of()
    mem = calibrate_lstsq(m, stacked_signals(m, recs[:1]))
    streamed = calibrate_stream(m, RecordingStream.from_recordings(recs[:1], CHUNK), chunk=CHUNK)
    assert_same_fit(mem, streamed)


def test_stream_from_parquet_and_config_chunk(recs, tmp_path):
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    paths = []
    for i, r in enumerate(recs):
        paths.append(tmp_path / f"r{i}.parquet")
        pq.write_table(pa.table(r.to_numpy()), paths[-1], row_group_size=1000)
    m = model_of()
    ref = calibrate_stream(m, RecordingStream.from_recordings(recs, 512), chunk=512)
    files = calibrate_stream(m, RecordingStream.from_files(paths, chunk=512), chunk=512)
    np.testing.assert_array_equal(np.asarray(files.value.coef), np.asarray(ref.value.coef))
    # 4000 = 3 * 1333 + 1: the file's one-row tail is folded into a longer last chunk
    tail = calibrate_stream(m, RecordingStream.from_files(paths, chunk=1333), chunk=1333)
    assert_same_fit(calibrate_lstsq(m, stacked_signals(m, recs)), tail)
    # the [fit] chunk setting routes the pipeline's calibration through the stream
    from hdjax.config import experiment_from_dict
    from hdjax.pipelines._paper import calibrate

    exp = experiment_from_dict(
        {"joint": JOINT.to_dict(), "data": {"kind": "synthetic"}, "fit": {"chunk": 512}}
    )
    via_cfg = calibrate(exp, m, recs)
    np.testing.assert_array_equal(np.asarray(via_cfg.value.coef), np.asarray(ref.value.coef))
    with pytest.raises(hdjax.ConfigError, match="chunk = 512 streams"):
        experiment_from_dict({"joint": JOINT.to_dict(), "fit": {"chunk": 512, "method": "rls"}})


@pytest.mark.parametrize("seed", range(5))
def test_accumulators_match_lstsq(seed):
    """Normal equations with folds and TSQR against numpy.linalg.lstsq on random problems."""
    rng = np.random.default_rng(seed)
    n, p, folds = 600, 7, 3
    a = rng.standard_normal((n, p)) * np.logspace(0, 3, p)  # badly scaled columns
    x_true = rng.standard_normal(p)
    b = a @ x_true + 1e-3 * rng.standard_normal(n)
    fold = np.arange(n) * folds // n
    ne = NormalEquations(p, n_folds=folds)
    for lo in range(0, n, 128):
        sl = slice(lo, lo + 128)
        for k in range(folds):
            rows = np.flatnonzero(fold[sl] == k) + lo
            ne.add(a[rows].T, b[rows], fold=k)
            ne.add_rhs(b[rows], fold=k)
    for k in (None, 1):
        keep = np.ones(n, bool) if k is None else fold != k
        g, atb, btb, m = ne.total(leave_out=k)
        ref = np.linalg.lstsq(a[keep], b[keep], rcond=None)[0]
        np.testing.assert_allclose(np.linalg.solve(g, atb), ref, rtol=1e-8)
        assert m == keep.sum() and np.isclose(btb, b[keep] @ b[keep], rtol=1e-14)
    np.testing.assert_allclose(ref, x_true, atol=1e-3)  # the known truth, within the noise
    qr = StreamingQR(np.sqrt(np.sum(a * a, axis=0)))
    for lo in range(0, n, 100):
        qr.add(a[lo : lo + 100], b[lo : lo + 100])
    r, qtb, rss = qr.factor()
    x = np.linalg.solve(r, qtb) / qr.scale
    ref, res = np.linalg.lstsq(a, b, rcond=None)[:2]
    np.testing.assert_allclose(x, ref, rtol=1e-10)
    np.testing.assert_allclose(rss, res[0], rtol=1e-8)
