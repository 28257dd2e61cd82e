"""Datasets from files through a column map, paths relative to the config, bad input."""

import math

import numpy as np
import pytest

from hdjax import ConfigError, DataError, Joint, save_csv
from hdjax.cli import main
from hdjax.config import load_experiment
from hdjax.pipelines import build_dataset, synthetic_recording

JOINT = Joint(ratio=160.0, rated_torque=400.0)


@pytest.fixture(scope="module")
def rec():
    return synthetic_recording(JOINT, 600, seed=3)


def _counts_csv(path, rec):
    """The recording as a log in another layout: motor counts (2^20 per rev), load angle in
    degrees, current in mA, torque under another name."""
    cpr = 2**20
    cols = {
        "time_s": np.asarray(rec.t),
        "enc_m": np.round(np.asarray(rec.theta_m) / (2 * math.pi) * cpr),
        "load_deg": np.degrees(np.asarray(rec.theta_l)),
        "i_mA": 1000.0 * np.asarray(rec.current),
        "tq": np.asarray(rec.torque),
        "temperature": np.full(rec.n_samples, 25.0),
    }
    body = np.column_stack(list(cols.values()))
    np.savetxt(path, body, delimiter=",", header=",".join(cols), comments="", fmt="%.17g")


CONFIG = """
[joint]
ratio = 160
rated_torque = 400
[data]
kind = "files"
train = ["logs/cal.csv"]
test = {held = "logs/cal.csv"}
[data.columns]
t = "time_s"
theta_m = {source = "enc_m", counts_per_rev = 1048576}
theta_l = {source = "load_deg", scale = 0.017453292519943295}
current = {source = "i_mA", scale = 0.001}
torque = "tq"
"""


def test_files_through_column_map_relative_to_config(tmp_path, rec):
    (tmp_path / "logs").mkdir()
    _counts_csv(tmp_path / "logs" / "cal.csv", rec)
    cfg = tmp_path / "exp.toml"
    cfg.write_text(CONFIG)
    ds = build_dataset(load_experiment(cfg))
    got = ds.train[0]
    # counts quantise theta_m to 2*pi/2^20 rad; the other columns are exact up to rounding
    assert np.max(np.abs(np.asarray(got.theta_m) - np.asarray(rec.theta_m))) <= math.pi / 2**20
    np.testing.assert_allclose(np.asarray(got.theta_l), np.asarray(rec.theta_l), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(got.current), np.asarray(rec.current), rtol=1e-12)
    assert set(got.extras) == {"temperature"}
    assert list(ds.test) == ["held"]


def test_split_makes_test_part(tmp_path, rec):
    save_csv(rec, tmp_path / "a.csv")
    cfg = tmp_path / "exp.toml"
    cfg.write_text(
        '[joint]\nratio = 160\nrated_torque = 400\n[data]\nkind = "files"\n'
        'train = ["a.csv"]\nsplit = 0.25\n'
    )
    ds = build_dataset(load_experiment(cfg))
    assert ds.train[0].n_samples == 450 and ds.test["a"].n_samples == 150


def test_missing_data_file_through_cli(tmp_path, capsys):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(CONFIG)
    assert main(["run", str(cfg), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert str(tmp_path / "logs" / "cal.csv") in err and "no such file" in err
    assert not (tmp_path / "out").exists()


def test_column_map_naming_absent_column_through_cli(tmp_path, rec, capsys):
    (tmp_path / "logs").mkdir()
    _counts_csv(tmp_path / "logs" / "cal.csv", rec)
    cfg = tmp_path / "exp.toml"
    cfg.write_text(CONFIG.replace('source = "enc_m"', 'source = "enc_mot"'))
    assert main(["run", str(cfg), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no column 'enc_mot' (for 'theta_m')" in err and "did you mean 'enc_m'" in err


def test_unknown_schema_column_in_map(tmp_path, rec):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(CONFIG.replace('torque = "tq"', 'torqe = "tq"'))
    with pytest.raises(Exception, match=r"'torqe' is not a schema column.*did you mean 'torque'"):
        build_dataset(load_experiment(cfg))


def test_missing_file_is_data_error(tmp_path):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(CONFIG)
    with pytest.raises(DataError, match="no such file"):
        build_dataset(load_experiment(cfg))


def test_plant_scenarios_calibration_and_test_seeds_differ(tmp_path):
    cfg = tmp_path / "exp.toml"
    cfg.write_text(
        '[experiment]\nseed = 3\n[joint]\nratio = 160\nrated_torque = 400\n[data]\nkind = "plant"\n'
        'scenarios = ["static"]\nduration = 0.4\nsettle = 0.1\n'
    )
    ds = build_dataset(load_experiment(cfg))
    (train,), test = ds.train, ds.test["static"]
    assert train.n_samples == test.n_samples == 600  # 0.3 s kept at the 0.5 ms period
    assert float(test.t[0]) >= 0.1
    assert not np.array_equal(np.asarray(train.torque), np.asarray(test.torque))  # other noise
    assert "seed 3" in ds.provenance[0] and "seed 1003" in ds.provenance[1]


def test_split_in_blocks_spans_the_run(tmp_path, rec):
    save_csv(rec, tmp_path / "a.csv")
    cfg = tmp_path / "exp.toml"
    cfg.write_text(
        '[joint]\nratio = 160\nrated_torque = 400\n[data]\nkind = "files"\n'
        'train = ["a.csv"]\nsplit = 0.25\nsplit_blocks = 100\n'
    )
    ds = build_dataset(load_experiment(cfg))
    t = np.asarray(rec.t)
    # blocks 0..5 of 100 samples; every 4th (block 3) is held out
    np.testing.assert_array_equal(np.asarray(ds.test["a"].t), t[300:400])
    np.testing.assert_array_equal(np.asarray(ds.train[0].t), np.r_[t[:300], t[400:]])


def test_real_log_kind_simulates_two_motions_read_as_a_robot_log():
    # [data] kind = "real_log" (experiments/real_log.toml, shortened): calibration and test are
    # two motions of one joint (its encoders' offsets shared), read with jittered time stamps,
    # dropped samples and the experiment's skew
    from tests.conftest import REPO

    short = {
        "data.sweeps": [[-0.3, 0.3]],
        "data.test_sweeps": [[-0.2, 0.25]],
        "data.drop": 0.05,
    }
    ds = build_dataset(load_experiment(REPO / "experiments" / "real_log.toml", short))
    (train,), test = ds.train, ds.test["sweep"]
    assert train.torque is not None and test.torque is not None
    for rec in (train, test):
        dt = np.diff(np.asarray(rec.t))
        assert np.ptp(dt[dt < 1.5e-3]) > 0.2e-3  # jitter of 0.2 periods either way
        assert np.any(dt > 1.5e-3)  # dropped samples
    # another motion: the load angle spans the two sweeps' ranges (plus the run-in)
    span = lambda r: float(np.ptp(np.asarray(r.theta_l)))  # noqa: E731
    assert abs(span(train) - span(test)) > 0.05, (span(train), span(test))
    assert any("skew 1.5 ms" in p for p in ds.provenance), ds.provenance
    cfg = REPO / "experiments" / "real_log.toml"
    for bad in ([[1.0, 1.0]], [[1.0]], [], "x", [[0.0, math.inf]], [[math.nan, 1.0]]):
        with pytest.raises(ConfigError, match="sweeps must be a non-empty list"):
            load_experiment(cfg, {"data.sweeps": bad})
    for key, bad, words in (
        ("data.encoder_bits", 36, "encoder_bits must be <= 32"),
        ("data.sample_period", 1e-5, "sample_period must be >= 0.00025"),
    ):
        with pytest.raises(ConfigError, match=words):
            load_experiment(cfg, {key: bad})
    with pytest.raises(ConfigError, match="take about .* s to simulate"):
        build_dataset(load_experiment(cfg, {"data.speed": 1e-4}))
    # a sweep that starts where the last one ended needs no move between them (it divided by 0)
    again = build_dataset(load_experiment(cfg, short | {"data.sweeps": [[-0.3, 0.3], [0.3, 0.0]]}))
    assert np.all(np.isfinite(np.asarray(again.train[0].torque)))
