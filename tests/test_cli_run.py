"""`hdjax run` and `hdjax estimate` through `main([...])`: results, repeatability, bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest

import hdjax
from hdjax import Joint, save_csv
from hdjax.cli import main
from hdjax.compliance import estimate_torque
from hdjax.modelfile import load_model
from hdjax.pipelines import synthetic_recording

CONFIG = """
[experiment]
name = "tiny"
seed = 4
[joint]
ratio = 160
rated_torque = 400
[data]
kind = "synthetic"
n_samples = 1500
[model]
poly_order = 3
kinematic = "none"
per_segment = false
[network]
hidden = [4]
steps = 40
max_train_samples = 300
[outputs]
timing_repeats = 2
"""


@pytest.fixture(scope="session")
def run_dir(tmp_path_factory):
    """One full run (both methods, figures, timing) shared by the tests below."""
    base = tmp_path_factory.mktemp("run")
    cfg = base / "tiny.toml"
    cfg.write_text(CONFIG)
    out = base / "out"
    assert main(["run", str(cfg), "--out", str(out), "--quiet"]) == 0
    return cfg, out


def test_run_writes_a_complete_result(run_dir):
    cfg, out = run_dir
    names = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert names == [
        ".hdjax-result",
        "config.resolved.toml",
        "figures/error_rate.png",
        "figures/model_synthetic.png",
        "figures/network_synthetic.png",
        "metrics.json",
        "model.json",
        "report.md",
    ]
    m = json.loads((out / "metrics.json").read_text())
    assert m["environment"]["seed"] == 4 and m["environment"]["precision"] == "float64"
    assert "hdjax_version" in m["environment"]
    assert m["network"]["available"] is True
    for method in ("model", "network"):
        s = m[method]["scenarios"]["synthetic"]
        assert s["rms"] <= s["max"] and s["n"] == 1500
        assert m[method]["timing"]["ms_per_100"] > 0
    # the synthetic data follows a known compliance: the model's held-out error stays small
    # (the fitted model lacks the data's first-order kinematic term, hence not exact)
    assert m["model"]["scenarios"]["synthetic"]["rms_pct"] <= 1.0  # measured 0.42 %
    report = (out / "report.md").read_text()
    for rel in ("figures/error_rate.png", "figures/model_synthetic.png"):
        assert f"]({rel})" in report
    from .helpers import assert_figure

    assert_figure(out / "figures" / "model_synthetic.png", (825, 528))
    assert_figure(out / "figures" / "network_synthetic.png", (825, 528))
    assert_figure(out / "figures" / "error_rate.png", (825, 462))
    # no staging directories left beside the result
    assert sorted(p.name for p in out.parent.iterdir()) == ["out", "tiny.toml"]


def test_run_on_the_known_plant_is_accurate(tmp_path, capsys):
    """End to end on the shipped Song et al. experiment: the built-in plant, all four load
    scenarios (3 s each, the first 0.5 s left out), the model-based method. Its held-out torque
    RMS must stay within 5 % of the rated torque in every scenario (measured 0.8-2.9 %; the
    paper reports 3.6-16.8 % on its bench), with no warning on the way."""
    from .conftest import REPO

    out = tmp_path / "song"
    argv = ["run", str(REPO / "experiments" / "song2019.toml"), "--out", str(out), "-q"]
    argv += ["--no-network", "--no-figures", "--set", "outputs.timing=false"]
    argv += ["--set", "data.duration=3.0", "--set", "data.settle=0.5"]
    assert main(argv) == 0
    assert capsys.readouterr().err == ""
    m = json.loads((out / "metrics.json").read_text())["model"]["scenarios"]
    assert sorted(m) == ["fast", "slow", "static", "sudden"]
    for name, s in m.items():
        assert s["n"] == 5000, name
        assert s["rms_pct"] <= 5.0, (name, s["rms_pct"])


def test_rerun_of_resolved_config_repeats_the_numbers(run_dir, tmp_path):
    _, out = run_dir
    again = tmp_path / "again"
    rc = main(
        [
            "run",
            str(out / "config.resolved.toml"),
            "--out",
            str(again),
            "--quiet",
            "--no-figures",
            "--no-network",
        ]
    )
    assert rc == 0
    a = json.loads((out / "metrics.json").read_text())["model"]["scenarios"]
    b = json.loads((again / "metrics.json").read_text())["model"]["scenarios"]
    assert a == b  # same machine, same seed: the same numbers


def test_existing_output_refused_unless_overwrite(run_dir, capsys):
    cfg, out = run_dir
    before = (out / "metrics.json").read_text()
    assert main(["run", str(cfg), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"hdjax: error: {out}: a result folder already exists here; choose another --out or pass "
        "--overwrite to replace it"
    )
    assert (out / "metrics.json").read_text() == before


def test_overwrite_and_crash_leave_no_half_result(run_dir, tmp_path, monkeypatch):
    cfg, _ = run_dir
    out = tmp_path / "o"
    args = ["run", str(cfg), "--out", str(out), "--quiet", "--no-network", "--no-figures"]
    assert main(args) == 0
    assert main(args + ["--overwrite"]) == 0
    from hdjax.cli import _run

    def boom(*a, **k):
        raise RuntimeError("simulated crash while writing the report")

    monkeypatch.setattr(_run, "render_report", boom)
    with pytest.raises(RuntimeError):
        main(["run", str(cfg), "--out", str(tmp_path / "crashed"), "--quiet", "--no-network"])
    assert not (tmp_path / "crashed").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]


def test_unknown_option_and_command_did_you_mean(run_dir, capsys):
    cfg, _ = run_dir
    assert main(["run", str(cfg), "--overwite"]) == 2
    assert "unknown option '--overwite' (did you mean '--overwrite'?)" in capsys.readouterr().err
    assert main(["rnu", str(cfg)]) == 2
    assert "unknown command 'rnu' (did you mean 'run'?)" in capsys.readouterr().err
    assert main(["sweep", str(cfg), "--setings", "x"]) == 2
    assert "did you mean '--setting'" in capsys.readouterr().err


def test_help_explains_options_with_an_example(capsys):
    for cmd in ("run", "sweep", "estimate", "bench"):
        assert main([cmd, "--help"]) == 0
        text = capsys.readouterr().out
        assert "example:" in text and "--" in text
    assert main(["--help"]) == 0
    assert "discover" in capsys.readouterr().out


def test_discover_shares_the_parser(capsys):
    assert main(["discover", "--help"]) == 0
    assert "--train" in capsys.readouterr().out
    assert main(["discover", "--trian", "a.csv", "--out", "d"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "hdjax discover: unknown option '--trian' (did you mean '--train'?); see "
        "'hdjax discover --help'"
    )


# -- estimate ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def new_csv(tmp_path_factory):
    rec = synthetic_recording(Joint(ratio=160.0, rated_torque=400.0), 800, seed=11)
    path = tmp_path_factory.mktemp("data") / "new.csv"
    save_csv(rec, path)
    return rec, path


def test_estimate_applies_the_saved_model(run_dir, new_csv, tmp_path):
    from hdjax.network import predict_torque as network_estimate

    _, out = run_dir
    rec, data = new_csv
    dest = tmp_path / "est.csv"
    args = ["estimate", "--model", str(out / "model.json"), "--data", str(data), "-q"]
    assert main(args + ["--out", str(dest)]) == 0
    got = np.genfromtxt(dest, delimiter=",", names=True)
    saved = load_model(out / "model.json")
    want = estimate_torque(saved.compliance, rec)
    np.testing.assert_allclose(got["torque_estimate"], np.asarray(want.torque), rtol=1e-15)
    np.testing.assert_array_equal(got["in_range"], np.asarray(want.in_range).astype(float))
    np.testing.assert_array_equal(got["torque_measured"], np.asarray(rec.torque))
    assert main(args + ["--out", str(dest)]) == 2  # exists, no --overwrite
    assert main(args + ["--out", str(dest), "--overwrite", "--method", "network"]) == 0
    got = np.genfromtxt(dest, delimiter=",", names=True)
    want = network_estimate(saved.network, rec, saved.joint)
    np.testing.assert_allclose(got["torque_estimate"], np.asarray(want), rtol=1e-15)


def test_estimate_refuses_corrupt_and_incompatible_models(run_dir, new_csv, tmp_path, capsys):
    _, out = run_dir
    _, data = new_csv
    text = (out / "model.json").read_text()
    bad = tmp_path / "bad.json"
    bad.write_text(text[: len(text) // 2])
    args = ["estimate", "--data", str(data), "--out", str(tmp_path / "e.csv")]
    assert main(args + ["--model", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "corrupt model file" in err
    d = json.loads(text)
    d["format_version"] = 0
    bad.write_text(json.dumps(d))
    assert main(args + ["--model", str(bad)]) == 2
    assert "format version 0 is incompatible" in capsys.readouterr().err
    joint = tmp_path / "j.toml"
    joint.write_text("[joint]\nratio = 100\nrated_torque = 400\n")
    assert main(args + ["--model", str(out / "model.json"), "--joint", str(joint)]) == 2
    assert "calibrated for ratio 160 but the data's joint has ratio 100" in capsys.readouterr().err
    assert not (tmp_path / "e.csv").exists()


def test_python_dash_m_hdjax():
    res = subprocess.run(
        [sys.executable, "-m", "hdjax", "--version"], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0 and res.stdout.startswith("hdjax ")


def test_save_logs_writes_the_recordings_and_a_discover_file_that_runs(tmp_path):
    # [outputs] save_logs: the run's recordings as CSV (read back equal) and discover.toml,
    # which hdjax discover runs as written (its paths relative to it)
    from .conftest import REPO

    out = tmp_path / "run"
    cfg = REPO / "experiments" / "synthetic.toml"
    argv = ["run", str(cfg), "--out", str(out), "--no-figures", "--no-network", "-q"]
    argv += ["--set", "data.n_samples=4000", "--set", "outputs.save_logs=true"]
    assert main(argv) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["logs"]["files"] == ["logs/train.csv", "logs/test_synthetic.csv"]
    back = hdjax.load_recording(out / "logs" / "train.csv")
    assert back.n_samples == 4000 and back.torque is not None
    assert "## The logs" in (out / "report.md").read_text()
    disc = tmp_path / "disc"
    argv = ["discover", "--config", str(out / "discover.toml"), "--out", str(disc)]
    assert main([*argv, "--max-effects", "1", "--no-figures", "--quiet"]) == 0
    rep = json.loads((disc / "report.json").read_text())
    assert rep["baseline"]["rms"] > 0 and rep["train"].endswith("train.csv")
