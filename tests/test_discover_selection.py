"""`hdjax discover --select-samples`: effects chosen on whole blocks of a long TRAIN log, the
model written calibrated on every row of it (streamed), memory bounded by the selection.

References: the blocks in closed form, the log's own rows, and in-memory least squares
(`calibrate_lstsq`) of the written structure on the whole TRAIN recording.
"""

import json
import tracemalloc
import warnings

import numpy as np
import pytest

import hdjax
from hdjax.cli import main
from hdjax.compliance import calibrate_lstsq
from hdjax.discover._pipeline import canonical
from hdjax.discover._subsample import load_selection, selection_blocks
from hdjax.modelfile import load_model

from .discover_data import ARCSEC, synthetic_recording

EFFECTS = [("harmonic_m", 2.0, 30 * ARCSEC)]
N_TRAIN, SELECT, CHUNK = 36_000, 12_000, 2048


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("select")
    hdjax.save_csv(synthetic_recording(1, EFFECTS, n=N_TRAIN), d / "train.csv")
    hdjax.save_csv(synthetic_recording(2, EFFECTS, n=6000), d / "test.csv")
    (d / "joint.toml").write_text("[joint]\nratio = 160\nrated_torque = 400\n")
    return d


def _argv(files, out, *extra):
    return [
        "discover", "--train", str(files / "train.csv"), "--test", str(files / "test.csv"),
        "--joint", str(files / "joint.toml"), "--out", str(out), "--quiet", "--no-figures",
        *extra,
    ]  # fmt: skip


def test_blocks_are_equal_and_centred_in_equal_strata():
    blocks = selection_blocks(100_000, 20_000)
    assert len(blocks) == 20
    # stratum 5000 rows, block 1000 rows: each starts 2000 rows into its stratum
    assert blocks == [(5000 * b + 2000, 5000 * b + 3000) for b in range(20)]
    # fewer blocks where the selection is short: none below 1000 rows
    assert selection_blocks(90_000, 3500) == [(b * 30_000 + 14_417, b * 30_000 + 15_583)
                                              for b in range(3)]  # fmt: skip
    assert selection_blocks(5000, 8000) == [(0, 5000)]


def test_the_selection_holds_the_logs_own_rows(files):
    whole = hdjax.load_csv(files / "train.csv")
    rec, sel = load_selection(files / "train.csv", SELECT, chunk=1000)
    rows = np.concatenate([np.arange(a, b) for a, b in selection_blocks(N_TRAIN, SELECT)])
    assert sel == dict(samples_total=N_TRAIN, samples_selected=SELECT, blocks=12,
                       block_samples=1000)  # fmt: skip
    for name in ("t", "theta_m", "theta_l", "current", "torque"):
        np.testing.assert_array_equal(
            np.asarray(rec.column(name)), np.asarray(whole.column(name))[rows]
        )
    # a log no longer than the selection is read whole
    rec, sel = load_selection(files / "train.csv", N_TRAIN, chunk=1000)
    assert sel == {} and rec.n_samples == N_TRAIN


def test_the_model_written_is_calibrated_on_every_row_of_train(files, tmp_path):
    out = tmp_path / "out"
    argv = _argv(files, out, "--chunk", CHUNK, "--select-samples", SELECT)
    inputs = {p: p.read_bytes() for p in files.iterdir()}
    assert main([str(a) for a in argv]) == 0
    # the inputs are read, never written: byte-identical, none removed, none added beside them
    assert {p: p.read_bytes() for p in files.iterdir()} == inputs
    rep = json.loads((out / "report.json").read_text())
    assert rep["selection"]["refit"] == "whole log"
    assert rep["selection"]["samples_total"] == N_TRAIN
    assert "harmonic:theta_m:2" in rep["effects"]
    model = load_model(out / "model.json").compliance
    train = hdjax.load_csv(files / "train.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = calibrate_lstsq(canonical(model), train).value
        rows = np.concatenate([np.arange(a, b) for a, b in selection_blocks(N_TRAIN, SELECT)])
        part = calibrate_lstsq(canonical(model), train, rows=rows).value
    coef = np.asarray(model.coef)
    scale = np.max(np.abs(np.asarray(whole.coef)))
    assert np.max(np.abs(coef - np.asarray(whole.coef))) <= 1e-9 * scale
    # the selection alone calibrates it visibly otherwise: the refit is what set the model
    assert np.max(np.abs(coef - np.asarray(part.coef))) > 1e-6 * scale
    # the TEST errors reported are the written model's
    test = hdjax.load_csv(files / "test.csv")
    est = hdjax.compliance.estimate_torque(model, test).torque
    m = hdjax.error_metrics(est, test.torque, 400.0)
    assert rep["final"]["rms"] == pytest.approx(m.rms, rel=1e-9)
    assert any("calibrated again on all" in n for n in rep["notes"])


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--select-samples", "20000"], ["--select-samples needs --chunk"]),
        (["--chunk", "2048", "--select-samples", "500"], ["--select-samples must be at least"]),
    ],
)
def test_bad_selection_arguments_are_refused_in_one_line(files, tmp_path, capsys, extra, words):
    assert main(_argv(files, tmp_path / "out", *extra)) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and all(w in err for w in words), err
    assert not (tmp_path / "out").exists()


def test_reading_the_selection_grows_with_the_selection_not_the_log(tmp_path):
    # the peak traced memory of reading a 4x longer log, the same selection: at most 1.3x
    peaks = []
    for n in (20_000, 80_000):
        path = tmp_path / f"log{n}.csv"
        hdjax.save_csv(synthetic_recording(3, n=n), path)
        tracemalloc.start()
        load_selection(path, 5000, chunk=1000)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] <= 1.3 * peaks[0], peaks
