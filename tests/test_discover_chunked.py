"""The residual loop with `chunk`: every fit accumulated chunk by chunk equals the in-memory one.

The references are the loop's own in-memory computations (whole design, per-fold QR-accurate
solves), run on the same small records; chunk sizes do not divide the record, a chunk boundary
falls inside a fold's block and at a gap, and the records have a gap where states restart.
"""

import numpy as np
import pytest

import hdjax
import hdjax.cli
from hdjax import ConfigError
from hdjax.discover import _pipeline as pipe
from hdjax.discover._chunked import check_chunk, dahl_chunked
from hdjax.discover._folds import contiguous_blocks, fold_assignment
from hdjax.discover._loop import DiscoverOptions, calibrate_baseline, discover, score_candidates
from hdjax.discover._uncertainty import effect_intervals
from hdjax.effects import Harmonics, Hysteresis, TwistHysteresis

from .discover_data import ARCSEC, JOINT, RATED, synthetic_recording

RTOL = 1e-9
GAIN_ATOL = 1e-6
EFFECTS = [("harmonic_m", 2.0, 8 * ARCSEC), ("hysteresis", 6 * ARCSEC, 20.0)]


def _with_gap(rec, at: int, width: int):
    """`rec` without samples `at:at + width`: a gap in time where memory states restart."""
    keep = np.ones(rec.n_samples, bool)
    keep[at : at + width] = False
    return rec.select(keep)


@pytest.fixture(scope="module")
def train():
    return _with_gap(synthetic_recording(1, EFFECTS, n=6400), 3100, 300)


@pytest.fixture(scope="module")
def test_rec():
    return synthetic_recording(2, EFFECTS, n=3000)


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _gain_close(a, b, tol) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return bool(np.all(np.abs(a - b) <= tol * np.maximum(1.0, np.abs(b))))


def _gram_tolerance(model, data, est) -> float:
    """The forward error bound of the Gram statistics the twist scores come from: ten times
    the scaled condition number of the base design's Gram matrix times the unit roundoff."""
    a = pipe.design(model, *data.pair(est))[:, np.asarray(model.active)]
    g = a.T @ a
    d = np.sqrt(np.diag(g))
    return 10.0 * np.linalg.cond(g / np.outer(d, d)) * np.finfo(float).eps / 2


@pytest.fixture(scope="module")
def base(train):
    notes = []
    model = calibrate_baseline(train, JOINT, DiscoverOptions(), notes)
    return model, pipe.pipeline_signals(train, model.ratio, model.twist_sign, model.velocity)


@pytest.mark.parametrize("chunk", [16, 997, 3100, 3101])
@pytest.mark.parametrize("numpy", [False, True])
def test_dahl_state_chunkwise_equals_whole_record(base, chunk, numpy):
    # 3100 puts a chunk boundary exactly at the gap (sample 3100 starts a segment), 3101 one
    # sample after it; 16 and 997 do not divide the 6100 samples
    model, data = base
    est = pipe.estimate(model, data)
    sig = data.with_driver(est)
    for term in (
        Hysteresis(torque_scale=0.05 * RATED),
        TwistHysteresis(torque_scale=0.02 * RATED, compliance=1.5e-5),
        TwistHysteresis(torque_scale=0.02 * RATED, compliance=1.5e-5, play=0.01 * RATED),
    ):
        whole = np.asarray(term.numpy_columns(sig) if numpy else term.columns(sig))[:, 0]
        chunked = dahl_chunked(term, sig, None, chunk, numpy=numpy)
        assert np.max(np.abs(chunked - whole)) < 1e-12
        # the state restarts at the gap, and is carried (not restarted) at other boundaries
        assert chunked[3100] == 0.0
        inner = [b for b in range(chunk, data.n, chunk) if b not in (3100, 3101)]
        if inner:
            assert np.any(np.abs(whole[np.asarray(inner) - 1]) > 1e-3)


@pytest.mark.parametrize("chunk", [16, 997, 6099])
def test_chunked_estimate_equals_whole_record(base, chunk, monkeypatch):
    # the inversion without a path term runs chunk by chunk (the last chunk padded); a model
    # with a path term (torque-driven hysteresis) still runs on the whole record
    import dataclasses

    calls = []
    chunked = pipe._invert_in_chunks
    monkeypatch.setattr(pipe, "_invert_in_chunks", lambda *a: calls.append(a[-1]) or chunked(*a))
    model, data = base
    est = pipe.estimate(model, data)
    fitted, _ = pipe.calibrate(
        model.with_effects(
            Harmonics(signal="theta_m", orders=(2.0,)),
            TwistHysteresis(torque_scale=0.02 * RATED, compliance=1.5e-5),
        ),
        data,
        [],
        est,
    )
    part = dataclasses.replace(data, chunk=chunk)
    np.testing.assert_array_equal(pipe.estimate(model, part), est)
    whole = pipe.estimate(fitted, data)
    assert np.isfinite(whole).all()
    assert _rel(pipe.estimate(fitted, part), whole) < 1e-13
    assert calls == [chunk, chunk]  # both estimates went chunk by chunk
    path = model.with_effects(Hysteresis(torque_scale=0.05 * RATED))
    path_fit, _ = pipe.calibrate(path, data, [], est)
    pipe.estimate(path_fit, part)
    assert calls == [chunk, chunk]  # not the path model


def test_chunked_calibration_equals_in_memory(base):
    model, data = base
    est = pipe.estimate(model, data)
    structure = pipe.canonical(
        model.with_effects(
            Hysteresis(torque_scale=0.05 * RATED),
            Harmonics(signal="theta_m", orders=(2.0,)),
        )
    )
    whole = pipe.quiet_calibrate(structure, data.pair(est), [])
    for chunk in (211, 4000):
        part = pipe.quiet_calibrate(structure, data.pair(est), [], chunk=chunk)
        assert _rel(part.value.coef, whole.value.coef) < RTOL
        assert part.value.active == whole.value.active
        assert part.value.torque_range == whole.value.torque_range


@pytest.mark.parametrize("path", [False, True])
def test_chunked_cross_validation_equals_in_memory(base, path):
    model, data = base
    blocks = contiguous_blocks(data.starts, 230)
    folds = fold_assignment(blocks, 5)
    term = (
        Hysteresis(torque_scale=0.05 * RATED)
        if path
        else TwistHysteresis(torque_scale=0.02 * RATED, compliance=1.5e-5)
    )
    fitted, est = pipe.calibrate(model.with_effects(term), data, [], pipe.estimate(model, data))
    whole = pipe.cross_validate(fitted, data, folds)
    # 997: boundaries inside the folds' 230-sample blocks
    part = pipe.cross_validate(fitted, data, folds, chunk=997)
    assert abs(part.twist_rms_arcsec / whole.twist_rms_arcsec - 1) < RTOL
    # An error RMS moves by at most the RMS of the estimates' difference on the rows it scores
    # (Minkowski), so it is held to that, not to a fixed 1e-9: an error of a few N·m on a
    # 400 N·m range magnifies the estimates' agreement (1e-10 of their range, the fits'
    # accuracy on designs of scaled condition number 1e10) fifty-fold
    sq_diff, n_scored = 0.0, 0
    for f, rows in enumerate(pipe.scored_rows(data, folds)):
        a, b = part.fold_estimate(f, data), whole.fold_estimate(f, data)
        assert _rel(a, b) < RTOL
        d2 = np.sum((a[rows] - b[rows]) ** 2)
        moved = abs(part.fold_torque_rms[f] - whole.fold_torque_rms[f])
        assert moved <= np.sqrt(d2 / rows.size) * (1 + 1e-9) + 1e-15 * b.std(), (f, moved)
        sq_diff, n_scored = sq_diff + d2, n_scored + rows.size
    moved = abs(part.torque_rms - whole.torque_rms)
    assert moved <= np.sqrt(sq_diff / n_scored) * (1 + 1e-9) + 1e-15, moved


@pytest.mark.parametrize("chunk", [0, 997])
def test_cross_validation_keeps_no_record_per_fold(base, chunk):
    """A structure's cross-validation holds one full-length vector (the squared errors), not
    one estimate per fold; the fold estimates it gives back on demand are those that scored
    it (each fold's held-out RMS recomputed from them, bit for bit)."""
    model, data = base
    blocks = contiguous_blocks(data.starts, 230)
    folds = fold_assignment(blocks, 5)
    fitted, _ = pipe.calibrate(
        model.with_effects(Hysteresis(torque_scale=0.05 * RATED)), data, [],
        pipe.estimate(model, data),
    )  # fmt: skip
    cv = pipe.cross_validate(fitted, data, folds, chunk=chunk)
    full_length = [
        name
        for name, value in vars(cv).items()
        for leaf in (value if isinstance(value, list) else [value])
        if isinstance(leaf, np.ndarray) and leaf.size >= data.n
    ]
    assert full_length == ["squared_errors"]
    for f in range(len(folds)):
        sq = cv.squared_errors[folds[f]]
        scored = ~np.isnan(sq)
        est = cv.fold_estimate(f, data)
        e = est[folds[f]][scored] - data.torque[folds[f]][scored]
        assert float(np.sqrt(np.sum(e**2) / scored.sum())) == cv.fold_torque_rms[f]


def test_chunked_candidate_scores_equal_in_memory(base):
    model, data = base
    blocks = contiguous_blocks(data.starts, 230)
    folds = fold_assignment(blocks, 5)
    rng = np.random.default_rng(0)
    n_blocks = int(blocks.max()) + 1
    resamples = [rng.permutation(np.arange(n_blocks) % 5) for _ in range(3)]
    est = pipe.estimate(model, data)
    out = []
    for chunk in (0, 1237):
        opts = DiscoverOptions(chunk=chunk)
        out.append(
            score_candidates(
                model, data, opts, (), folds=folds, blocks=blocks, resamples=resamples, est=est
            )
        )
    (s0, _, r0), (s1, _, r1) = out
    tol = _gram_tolerance(pipe.canonical(model), data, est)
    assert tol < 1e-4
    assert len(s0) == len(s1) > 10
    assert _rel(r1, r0) < RTOL
    for a, b in zip(s0, s1):
        assert a.candidate.key == b.candidate.key and a.candidate.term == b.candidate.term
        # gains are shares of the twist error (unit scale) from Gram statistics, which carry
        # their own rounding error, up to the scaled condition number of A^T A (here ~1e10)
        # times the roundoff (the in-memory pass differs from per-fold QR by ~1e-6 on these
        # data): two summation orders agree to that bound, not to 1e-9; it is far below any
        # decision (min_gain 0.05). A fold's gain is relative to its own base error, so a
        # large one scales the bound.
        assert _gain_close(a.gain, b.gain, tol)
        assert _gain_close(a.fold_gains, b.fold_gains, tol)
        assert a.selected == b.selected  # sparse regression's choice
        assert _gain_close(a.resampled, b.resampled, tol)


def test_chunked_intervals_equal_in_memory(base):
    model, data = base
    fitted, est = pipe.calibrate(
        model.with_effects(
            Harmonics(signal="theta_m", orders=(2.0,)),
            TwistHysteresis(torque_scale=0.02 * RATED, compliance=1.5e-5),
        ),
        data,
        [],
        pipe.estimate(model, data),
    )
    sig, torque = data.pair(est)
    whole = effect_intervals(fitted, pipe.design(fitted, sig, torque), data, est, length=400)
    part = effect_intervals(
        fitted, None, data, est, length=400, chunks=pipe.chunks_of(sig, torque, 1237)
    )
    assert [w["effect"] for w in whole] == [p["effect"] for p in part]
    for w, p in zip(whole, part):
        for key in ("arcsec", "nm"):
            assert abs(p[key] / w[key] - 1) < RTOL
        assert _rel(p["arcsec_ci95"], w["arcsec_ci95"]) < RTOL


def test_chunked_discover_equals_in_memory(train, test_rec):
    opts = dict(max_effects=2, n_resamples=5, n_shortlist=2, n_grid_tries=1)
    whole = discover(train, test_rec, JOINT, DiscoverOptions(**opts))
    part = discover(train, test_rec, JOINT, DiscoverOptions(chunk=1237, **opts))
    assert whole.aux.effects == part.aux.effects
    assert len(whole.aux.effects) == 2
    assert _rel(part.value.coef, whole.value.coef) < RTOL
    for key in (
        "baseline_test_rms",
        "final_test_rms",
        "baseline_cv_torque_rms",
        "final_cv_torque_rms",
    ):
        assert abs(part.stats[key] / whole.stats[key] - 1) < RTOL, key
    for a, b in zip(whole.aux.steps, part.aux.steps):
        assert _gain_close(a.cv_gain, b.cv_gain, GAIN_ATOL)
        assert abs(b.cv_torque_rms / a.cv_torque_rms - 1) < RTOL
        assert abs(b.cv_twist_rms_arcsec / a.cv_twist_rms_arcsec - 1) < RTOL
        assert abs(b.amplitude["arcsec"] / a.amplitude["arcsec"] - 1) < RTOL
    assert [r["key"] for r in whole.aux.final_ranking] == [r["key"] for r in part.aux.final_ranking]
    assert _rel(part.aux.train_residual_final, whole.aux.train_residual_final) < RTOL


@pytest.mark.parametrize("bad", [5, -1, 15])
def test_chunk_is_validated(bad):
    with pytest.raises(ConfigError, match="chunk must be 0 .* or at least 16 samples"):
        DiscoverOptions(chunk=bad)


@pytest.mark.parametrize("bad", [2.5, "1000", True, None])
def test_chunk_must_be_an_integer(bad):
    with pytest.raises(ConfigError, match=r"\[discover\] chunk must be an integer"):
        check_chunk(bad, "[discover] chunk")


def test_cli_rejects_a_short_chunk(tmp_path, capsys):
    rec = synthetic_recording(3, n=200)
    train, test = tmp_path / "train.csv", tmp_path / "test.csv"
    hdjax.save_csv(rec, train)
    hdjax.save_csv(rec, test)
    joint = tmp_path / "joint.toml"
    joint.write_text("[joint]\nratio = 160\nrated_torque = 400\n")
    argv = ["--train", train, "--test", test, "--joint", joint, "--out", tmp_path / "o"]
    code = hdjax.cli.main(["discover", *map(str, argv), "--chunk", "8"])
    assert code == 2
    err = capsys.readouterr().err
    assert "chunk" in err and "at least 16" in err
    assert not (tmp_path / "o").exists()


def test_chunked_scores_hold_chunks_not_the_record(base, monkeypatch):
    """Memory of the chunked candidate scores is bounded by the chunk: the rows kept for the
    sparse regression (every `step`-th) are copies, so no chunk's columns outlive it. Measured
    with tracemalloc (NumPy's allocations) when the first pass over the chunks has ended: what
    it still holds is far below every candidate's columns over the whole record, which a view
    of each chunk's rows would keep alive."""
    import tracemalloc

    import hdjax.discover._scores as loop

    monkeypatch.setattr(loop, "MAX_SINDY_ROWS", 300)  # thinned rows on this short record
    held = []
    real = loop.block_statistics_streamed

    def spy(passes, y, blocks_, select):
        start = tracemalloc.get_traced_memory()[0]

        def measured():
            held.append(tracemalloc.get_traced_memory()[0] - start)
            return select()

        return real(passes, y, blocks_, measured)

    monkeypatch.setattr(loop, "block_statistics_streamed", spy)
    model, data = base
    blocks = contiguous_blocks(data.starts, 230)
    folds = fold_assignment(blocks, 5)
    est = pipe.estimate(model, data)
    opts = DiscoverOptions(chunk=1237)  # the chunk of the test above: its programs reused
    tracemalloc.start()
    try:
        scored, _, _ = score_candidates(model, data, opts, (), folds=folds, blocks=blocks, est=est)
    finally:
        tracemalloc.stop()
    width = sum(len(s.candidate.term.names()) for s in scored) + model.n_coef
    whole = data.sig.n_samples * width * 8
    # what stays is the thinned rows (every 20th) and the chunk being read (a fifth of the
    # record), about a third of `whole` here; views of every chunk keep more than all of it
    assert held and held[0] < 0.5 * whole, (held, whole)
