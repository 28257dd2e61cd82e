"""The real LARA8 log (joint 3) through experiments/lara8_joint3.toml's column map."""

import csv
import tomllib
import warnings

import numpy as np
import pytest

import hdjax
from hdjax.compliance import ComplianceModel, calibrate_lstsq, estimate_torque
from tests.conftest import REPO

CONFIG = REPO / "experiments" / "lara8_joint3.toml"
ARCSEC = 180.0 * 3600.0 / np.pi


@pytest.fixture(scope="module")
def lara8(lara8_dir):
    doc = tomllib.loads(CONFIG.read_text())
    data = doc["data"]
    # the file is also an experiment for the `hdjax` command (issue 5), whose [data] names the
    # log under `train`; a plain `path` is accepted too. Paths are relative to the config.
    rel = data["path"] if "path" in data else data["train"][0]
    path = (CONFIG.parent / rel).resolve()
    assert path == (lara8_dir / "validate.csv").resolve()
    table = {"columns": data["columns"], "extras": data.get("extras", {})}
    rec = hdjax.load_csv(path, hdjax.ColumnMap.from_dict(table))
    joint = hdjax.Joint.from_dict(doc["joint"])
    return doc, joint, rec


def _raw_column(lara8_dir, name):
    """One column of the raw log, read with the csv module (not through hdjax)."""
    with open(lara8_dir / "validate.csv", newline="") as f:
        return np.array([float(row[name]) for row in csv.DictReader(f)])


def test_config_loads_and_describes_the_joint(lara8, lara8_dir):
    doc, joint, rec = lara8
    assert joint.ratio == 101 and joint.twist_sign == -1
    assert joint.encoder_bits_motor == joint.encoder_bits_load == 24
    assert rec.n_samples == 1832 and set(rec.extras) <= {"joint_velocity_3"}
    # current and torque are the same log column (see the config's comments)
    np.testing.assert_array_equal(np.asarray(rec.current), np.asarray(rec.torque))
    assert doc["model"]["poly_order"] == 0  # current == reference torque: no polynomial
    # 2^24 counts per revolution: the output turns ~0.83 rev, the motor ~84 rev (ratio 101)
    # (independent: the raw counts' span read with the csv module, times 2 pi / 2^24; the map's
    # offset = "first" shifts the angle, which leaves the span as it is)
    span_l, span_m = float(np.ptp(rec.theta_l)), float(np.ptp(rec.theta_m))
    counts = {n: _raw_column(lara8_dir, f"encoder_{n}inc_3") for n in ("load", "motor")}
    assert span_l == pytest.approx(np.ptp(counts["load"]) * 2 * np.pi / 2**24, rel=1e-12)
    assert span_m == pytest.approx(np.ptp(counts["motor"]) * 2 * np.pi / 2**24, rel=1e-12)
    assert 0.8 < span_l / (2 * np.pi) < 0.9  # ~0.83 rev
    assert span_m / span_l == pytest.approx(101, rel=0.01)


def test_twist_is_plausible(lara8):
    _, joint, rec = lara8
    raw = np.asarray(hdjax.twist(rec.theta_m, rec.theta_l, joint.ratio))  # before the sign flip
    torque = np.asarray(rec.torque)
    span = np.ptp(raw) * ARCSEC
    assert 900 < span < 1300  # ~1100 arcsec over the sweep
    r = np.corrcoef(raw, torque)[0, 1]
    slope = np.polyfit(torque, raw * ARCSEC, 1)[0]
    print(f"twist span {span:.0f} arcsec, r = {r:.3f}, slope {slope:.2f} arcsec/N·m")
    assert r < -0.9
    assert slope == pytest.approx(-5.7, abs=0.3)
    flipped = np.asarray(hdjax.twist(rec.theta_m, rec.theta_l, joint.ratio, joint.twist_sign))
    np.testing.assert_array_equal(flipped, -raw)


def test_shared_calibration_reports_the_unreached_segment(lara8, lara8_dir):
    _, joint, rec = lara8
    # the paper's five segments, no current polynomial (current == reference), kinematic error
    # as harmonics 1, 2 of the motor angle and 1 of the output angle, shared coefficients. (A
    # second output harmonic absorbs the torque: joint 3 carries the arm's gravity load, a
    # function of the output angle, and the compliances turn negative.)
    model = ComplianceModel.paper(
        joint,
        poly_order=0,
        kinematic="harmonic",
        harmonic_orders_m=(1.0, 2.0),
        harmonic_orders_l=(1.0,),
        per_segment=False,
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = calibrate_lstsq(model, rec)
    assert any("left out" in str(w.message) for w in caught)
    # tau0 = 150 N·m: knots at +-50, +-100; nothing below -100 N·m
    assert res.stats["dropped"] == ("k3 (no sample reaches torque segment 0)",)
    counts = res.stats["segment_counts"]
    assert counts[0] == 0 and all(c > 50 for c in counts[1:])
    k_arcsec = np.asarray(res.value.k)[1:] * ARCSEC
    print("segment compliances [arcsec/N·m]", k_arcsec, "residual",
          res.stats["residual_rms"] * ARCSEC)  # fmt: skip
    assert np.all(k_arcsec > 0)  # invertible with twist_sign = -1
    # every sample lies in the calibrated segments 1-4 (none below -100 N·m), so the torque
    # range is the whole log's: its extremes in the raw column, read with the csv module
    raw = _raw_column(lara8_dir, "joint_torque_current_3")
    assert raw.min() > -100.0
    lo, hi = res.value.torque_range
    assert lo == pytest.approx(raw.min(), rel=1e-12) and hi == pytest.approx(raw.max(), rel=1e-12)
    est = estimate_torque(res.value, rec)
    err = hdjax.error_metrics(est.torque, rec.torque, joint.rated_torque)
    print("in-sample", err.as_dict())
    assert err.rms_pct < 10.0  # a shared 4-segment model explains most of the twist
