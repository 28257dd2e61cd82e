"""One starting model: `hdjax run` and `hdjax discover` calibrate it through the same function,
and `hdjax run` calibrates a saved structure (`[model] structure`, `--model`)."""

import json
import math
import shutil

import numpy as np
import pytest

import hdjax
from hdjax.cli import main
from hdjax.discover import DiscoverOptions, calibrate_baseline, fallback_tables
from hdjax.discover._start import collinear_families

from .conftest import REPO
from .discover_data import JOINT, RATIO, _hinge

EXAMPLES = REPO / "docs" / "examples"


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The worked example's logs and configs in a folder of their own."""
    here = tmp_path_factory.mktemp("example")
    for name in ("bench.toml", "bench_discover.toml", "bench_train.csv", "bench_test.csv"):
        shutil.copy(EXAMPLES / name, here / name)
    return here


def _scored(out):
    (scored,) = json.loads((out / "metrics.json").read_text())["model"]["scenarios"].values()
    return scored


def test_run_and_discover_start_from_the_same_model(example, capsys):
    # the worked example's TEST reaches the torque segment below -266.7 N·m that TRAIN hardly
    # covers: discover merged it and run did not, so their starting errors differed
    # (4.476 and 4.241 N·m RMS); both now calibrate through calibrate_start
    run_out, disc_out = example / "run", example / "disc"
    assert main(["run", str(example / "bench.toml"), "--out", str(run_out), "--no-figures"]) == 0
    cfg = str(example / "bench_discover.toml")
    args = ["discover", "--config", cfg, "--out", str(disc_out), "--max-effects", "0"]
    assert main(args + ["--no-figures", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "merged into its neighbour (knot -266.7 removed)" in err  # run says the merge
    assert err.count("no sample reaches torque segment 3") == 1  # and each left-out term once
    rep = json.loads((disc_out / "report.json").read_text())
    run = _scored(run_out)
    assert run["rms"] == pytest.approx(rep["baseline"]["rms"], rel=1e-12)
    assert run["max"] == pytest.approx(rep["baseline"]["max"], rel=1e-12)
    # the report says which settings the start used and where run differs on purpose
    (start,) = [n for n in rep["notes"] if n.startswith("starting model: [model]")]
    assert "per_segment = false" in start and "per_segment = true" in start
    assert "No `experiment.toml`" not in (disc_out / "report.md").read_text()


def test_fallback_tables_simplify_in_the_documented_order():
    table = {"n_segments": 5, "poly_order": 6, "kinematic": "harmonic", "per_segment": True}
    chain = fallback_tables({**table, "current_scale": "auto", "structure": ""})
    assert chain == [
        table,
        {**table, "per_segment": False},
        {**table, "per_segment": False, "poly_order": 0},
        {**table, "per_segment": False, "poly_order": 0, "kinematic": "none", "fourier_order": 0},
    ]
    # a step that changes nothing is not tried twice
    plain = {"poly_order": 0, "kinematic": "none", "fourier_order": 0, "per_segment": False}
    assert fallback_tables(plain) == [plain]
    # a failure that names the kinematic term alone drops it before the current polynomial
    shared = {**table, "per_segment": False}
    assert fallback_tables(table, frozenset({"kinematic"})) == [
        table,
        shared,
        {**shared, "kinematic": "none", "fourier_order": 0},
        {**shared, "poly_order": 0},
        {**shared, "poly_order": 0, "kinematic": "none", "fourier_order": 0},
    ]
    assert fallback_tables(table, frozenset({"kinematic", "poly"})) == chain


def test_a_motion_too_short_for_the_kinematic_term_keeps_the_current_polynomial():
    # the motor turns through 2 rad: the kinematic term's Fourier columns of theta_m are
    # collinear, the current polynomial is not. The start drops the kinematic term only;
    # before, it dropped the polynomial first and then both, and the loop found the twist's
    # cubic in the current again as stiffening (a clean joint's false discovery)
    rng = np.random.default_rng(4)
    n = 3000
    t = np.arange(n) * 1e-3
    torque = 300 * np.sin(2 * math.pi * 0.7 * t) + 60 * np.sin(2 * math.pi * 2.3 * t + 1)
    # the motor's own torque (inertia, friction) makes the current differ from the reference
    current = (torque + 40 * np.sin(2 * math.pi * 3.1 * t)) / (RATIO * 0.1)
    twist = _hinge(torque) + 2e-4 * (current / 25) + 3e-5 * (current / 25) ** 3
    theta_l = 0.006 * np.sin(2 * math.pi * 0.9 * t)
    theta_m = RATIO * (theta_l - twist) + 1e-7 * rng.standard_normal(n)
    rec = hdjax.make_recording(t, theta_m, theta_l, current, torque, source="short motion")
    options = DiscoverOptions(current_scale=25.0)
    table = {"poly_order": options.poly_order, "kinematic": "paper", "per_segment": False}
    notes = []
    model = calibrate_baseline(rec, JOINT, options, notes)
    assert any("collinear terms" in n and "a1" in n for n in notes), notes
    assert notes[-1] == 'starting model fell back to kinematic = "none", fourier_order = 0'
    assert sum(name.startswith("w") for name in model.term_names) == options.poly_order
    # the families are found from the terms each adds, not from their names' letters
    kw = {**table, "n_segments": 5, "fourier_order": 3}
    assert collinear_families(kw, [["k0", "a1", "b2"]], JOINT, 25.0) == {"kinematic"}
    assert collinear_families(kw, [["k1", "w2"], ["d3"]], JOINT, 25.0) == {"kinematic", "poly"}
    assert collinear_families(kw, [["k0", "k1"]], JOINT, 25.0) == frozenset()


def test_run_model_calibrates_a_saved_structure(example, tmp_path, capsys):
    # discover's model.json given to run --model: its structure calibrated on TRAIN again
    # gives the loop's final TEST error (an independent path: run's loader and estimate)
    disc = tmp_path / "disc"
    cfg = str(example / "bench_discover.toml")
    args = ["discover", "--config", cfg, "--out", str(disc), "--max-effects", "1"]
    assert main(args + ["--no-figures", "--quiet"]) == 0
    rep = json.loads((disc / "report.json").read_text())
    assert rep["effects"] == ["harmonic:theta_m:2"]
    out = tmp_path / "run"
    args = ["run", str(example / "bench.toml"), "--model", str(disc), "--out", str(out)]
    assert main(args + ["--no-figures", "--quiet"]) == 0
    assert _scored(out)["rms"] == pytest.approx(rep["final"]["rms"], rel=1e-9)
    resolved = (out / "config.resolved.toml").read_text()
    assert f'structure = "{disc / "model.json"}"' in resolved  # absolute: reruns from anywhere


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--model", "nowhere.json"], "no such file"),
        (["--set", 'model.structure="nowhere.json"'], "no such file"),
        (["--model", "DISC", "--set", "model.n_segments=3"], "not read when structure is given"),
        (["--model", "DISC", "--set", 'fit.method="rls"'], 'method = "lstsq"'),
    ],
)
def test_run_refuses_a_structure_it_cannot_use(example, tmp_path, capsys, extra, words):
    disc = example / "disc_model"
    if not disc.exists():
        assert (
            main(
                [
                    "discover",
                    "--config",
                    str(example / "bench_discover.toml"),
                    "--out",
                    str(disc),
                    "--max-effects",
                    "0",
                    "--no-figures",
                    "--quiet",
                ]
            )
            == 0
        )
    extra = [str(disc) if a == "DISC" else a for a in extra]
    out = tmp_path / "run"
    capsys.readouterr()
    code = main(["run", str(example / "bench.toml"), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and words in err, err
    assert not out.exists()
