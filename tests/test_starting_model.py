"""One starting model: `hdjax run` and `hdjax discover` calibrate it through the same function,
and `hdjax run` calibrates a saved structure (`[model] structure`, `--model`)."""

import json
import shutil

import pytest

from hdjax.cli import main
from hdjax.discover import fallback_tables

from .conftest import REPO

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
