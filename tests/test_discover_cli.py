"""`hdjax discover` through the command line: the contract and every bad input of issue 6."""

import json
import math

import numpy as np
import pytest

import hdjax
from hdjax.cli import main

from .discover_data import synthetic_recording


def _discover_cli(argv):
    """`hdjax discover ARGV` through the `hdjax` command's one entry point."""
    return main(["discover", *map(str, argv)])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("discover")
    train = synthetic_recording(1, [("harmonic_m", 2.0, 30 * 4.85e-6)], n=8000)
    test = synthetic_recording(2, [("harmonic_m", 2.0, 30 * 4.85e-6)], n=4000)
    hdjax.save_csv(train, d / "train.csv")
    hdjax.save_csv(test, d / "test.csv")
    (d / "joint.toml").write_text("[joint]\nratio = 160\nrated_torque = 400\n")
    return d


def _run(files, out, *extra, train="train.csv", test="test.csv"):
    argv = [
        "--train",
        str(files / train),
        "--test",
        str(files / test),
        "--joint",
        str(files / "joint.toml"),
        "--out",
        str(out),
        "--quiet",
        *extra,
    ]
    return _discover_cli(argv)


def _one_line_error(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    assert err.startswith(("hdjax: error:", "hdjax discover: error:")), err
    for w in words:
        assert w in err, err
    return err


@pytest.fixture(scope="module")
def csv_report(files, tmp_path_factory):
    out = tmp_path_factory.mktemp("discover-csv") / "out"
    assert _run(files, out, "--no-figures") == 0
    return json.loads((out / "report.json").read_text())


def test_contract_report(files, csv_report):
    rep = csv_report
    assert set(rep["baseline"]) >= {"rms", "max"}
    assert rep["effects"] == [s["effect"] for s in rep["steps"]]
    assert rep["effects"][0] == "harmonic:theta_m:2"
    assert rep["final"]["rms"] == rep["steps"][-1]["rms"]
    assert rep["final"]["rms"] < 0.5 * rep["baseline"]["rms"]
    # the numbers are the TEST errors of the final model, recomputed independently here
    model = hdjax.compliance.ComplianceModel.from_dict(rep["final_model"])
    test = hdjax.load_csv(files / "test.csv")
    est = np.asarray(hdjax.compliance.estimate_torque(model, test).torque)
    err = est - np.asarray(test.torque)
    assert rep["final"]["rms"] == pytest.approx(np.sqrt(np.mean(err**2)), rel=1e-9)
    assert rep["final"]["max"] == pytest.approx(np.max(np.abs(err)), rel=1e-9)


def test_min_gain_above_the_effects_gain_adds_nothing(files, csv_report, tmp_path):
    # --min-gain sets the least cross-validated twist gain: above the gain of the effect the
    # default run adds, the same logs add no effect, and the stopping rule states the value
    gain = csv_report["steps"][0]["cv_gain"]  # about 0.996: the harmonic is the whole error
    assert csv_report["effects"] == ["harmonic:theta_m:2"] and 0.05 < gain < 0.999, gain
    min_gain = math.ceil(1000 * (gain + 1) / 2) / 1000  # above the gain, below 1
    assert gain < min_gain < 1
    out = tmp_path / "out"
    assert _run(files, out, "--no-figures", "--min-gain", min_gain) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["effects"] == [] and rep["steps"] == [], rep["effects"]
    assert rep["final"]["rms"] == rep["baseline"]["rms"]
    rule = f"removes at least {100 * min_gain:.4g}% (min_gain)"  # as given: 99.8%, not 100%
    assert rule in rep["stopping_rule"], rep["stopping_rule"]
    assert rule in (out / "report.md").read_text()
    assert "removes at least 5% (min_gain)" in csv_report["stopping_rule"]  # the default


def test_parquet_inputs_equal_csv(files, csv_report, tmp_path):
    # --train/--test read every log format through the same loader as the other commands: the
    # same logs as Parquet give the CSV run's report (the values round-trip exactly)
    pytest.importorskip("pyarrow")
    from hdjax.cli._convert import convert

    for name in ("train", "test"):
        convert(files / f"{name}.csv", tmp_path / f"{name}.parquet")
    out = tmp_path / "out"
    pq = {k: str(tmp_path / f"{k}.parquet") for k in ("train", "test")}  # absolute: files / pq
    assert _run(files, out, "--no-figures", **pq) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["effects"] == csv_report["effects"]
    for key in ("baseline", "final"):
        for m in ("rms", "max"):
            assert rep[key][m] == pytest.approx(csv_report[key][m], rel=1e-12, abs=0)
    np.testing.assert_allclose(
        rep["final_model"]["coef"], csv_report["final_model"]["coef"], rtol=1e-12, atol=0
    )


def test_chunk_parses_the_logs_in_chunks(files, csv_report, tmp_path, monkeypatch):
    # --chunk also reads --train and --test chunk by chunk (no whole-file CSV parse) and gives
    # the in-memory report, to the chunked loop's precision
    def refuse(*a, **k):
        raise AssertionError("--chunk parsed a whole CSV file")

    monkeypatch.setattr("hdjax._formats.load_csv", refuse)
    out = tmp_path / "out"
    assert _run(files, out, "--no-figures", "--chunk", "1000") == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["effects"] == csv_report["effects"]
    for key in ("baseline", "final"):
        for m in ("rms", "max"):
            assert rep[key][m] == pytest.approx(csv_report[key][m], rel=1e-9, abs=0)
    # the chunked loop's fit agrees norm-wise (its smallest coefficients to ~1e-13 absolute)
    coef, ref = (np.asarray(r["final_model"]["coef"]) for r in (rep, csv_report))
    assert np.max(np.abs(coef - ref)) <= 1e-9 * np.max(np.abs(ref))


def test_figures_and_markdown(files, tmp_path):
    out = tmp_path / "out"
    assert _run(files, out, "--max-effects", "1") == 0
    names = {p.name for p in (out / "figures").iterdir()}
    assert {"spectrum_0.png", "residual_0.png", "residual_1.png", "torque.png"} <= names
    md = (out / "report.md").read_text()
    assert "harmonic:theta_m:2" in md and "figures/torque.png" in md
    from .helpers import assert_figure

    assert_figure(out / "figures" / "torque.png", (1100, 550))  # 10 x 5 in at 110 dpi
    assert_figure(out / "figures" / "residual_0.png", (1100, 352))


def test_the_discovered_model_is_used_by_the_commands_the_report_prints(files, tmp_path):
    # discover ends in a model: the report's "Use it" commands run as printed; the estimate
    # of TEST through model.json, and hdjax run of experiment.toml, have the TEST error the
    # report states
    out = tmp_path / "out"
    assert _run(files, out, "--max-effects", "1", "--no-figures") == 0
    rep = json.loads((out / "report.json").read_text())
    md = (out / "report.md").read_text()
    use = md.split("## Use it", 1)[1]
    commands = [c for c in use.split("```")[1].strip().splitlines()]
    estimate_cmd = commands[0].replace("LOG.csv", str(files / "test.csv"))
    estimate_cmd = estimate_cmd.replace("torque.csv", str(tmp_path / "torque.csv"))
    assert main(estimate_cmd.split()[1:] + ["--quiet"]) == 0
    est = np.genfromtxt(tmp_path / "torque.csv", delimiter=",", names=True)
    ref = hdjax.load_csv(files / "test.csv").torque
    rms = float(np.sqrt(np.mean((est["torque_estimate"] - np.asarray(ref)) ** 2)))
    assert rep["effects"] == ["harmonic:theta_m:2"]
    assert rms == pytest.approx(rep["final"]["rms"], rel=1e-9)
    # experiment.toml: hdjax run calibrates the final structure again, to the same TEST error
    assert commands[1] == f"hdjax run {out}/experiment.toml --out {out}_run"
    assert main(commands[1].split()[1:] + ["--quiet"]) == 0
    run = json.loads((tmp_path / "out_run" / "metrics.json").read_text())["model"]["scenarios"]
    (scored,) = run.values()
    assert scored["rms"] == pytest.approx(rep["final"]["rms"], rel=1e-9)
    assert scored["max"] == pytest.approx(rep["final"]["max"], rel=1e-9)
    assert main(commands[2].split()[1:]) == 0
    assert (tmp_path / "out_c" / "hdjax_estimator.c").is_file()


def test_refuses_non_empty_out_without_overwrite(files, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("x")
    assert _run(files, out) == 2
    _one_line_error(capsys, "--overwrite")
    assert sorted(p.name for p in out.iterdir()) == ["old.txt"]


def test_different_ratios(files, tmp_path, capsys):
    rec = hdjax.load_csv(files / "test.csv")
    other = rec.select(slice(None))
    other = hdjax.make_recording(
        other.t,
        np.asarray(other.theta_m) * 100 / 160,
        other.theta_l,
        other.current,
        other.torque,
    )
    hdjax.save_csv(other, tmp_path / "test100.csv")
    (tmp_path / "test100.csv").rename(files / "test100.csv")
    out = tmp_path / "out"
    assert _run(files, out, test="test100.csv") == 2
    _one_line_error(capsys, "different ratios")
    assert not out.exists()


def test_test_lacks_a_train_column(files, tmp_path, capsys):
    rec = hdjax.load_csv(files / "train.csv")
    hdjax.save_csv(
        rec.with_extras(temperature=np.linspace(20, 30, rec.n_samples)), files / "train_temp.csv"
    )
    assert _run(files, tmp_path / "o", train="train_temp.csv") == 2
    _one_line_error(capsys, "lacks column", "temperature")


def test_test_lacks_a_core_column(files, tmp_path, capsys):
    text = (files / "test.csv").read_text().splitlines()
    header = text[0].split(",")
    keep = [i for i, h in enumerate(header) if h != "current"]
    rows = [",".join(line.split(",")[i] for i in keep) for line in text]
    (files / "test_nocurrent.csv").write_text("\n".join(rows) + "\n")
    assert _run(files, tmp_path / "o", test="test_nocurrent.csv") == 2
    _one_line_error(capsys, "current")


def test_too_short_says_the_length_needed(files, tmp_path, capsys):
    rec = hdjax.load_csv(files / "train.csv")
    # 600 samples while the motor turns less than the 4*pi rad that order 0.5 needs
    short = rec.select(slice(0, 600))
    theta_l = 0.01 * np.sin(np.linspace(0, 3.0, 600))
    slow = hdjax.make_recording(
        short.t,
        160 * theta_l,
        theta_l,
        short.current,
        short.torque,
    )
    assert float(np.ptp(np.asarray(slow.theta_m))) < 4 * np.pi
    hdjax.save_csv(slow, files / "short.csv")
    assert _run(files, tmp_path / "o", train="short.csv") == 2
    err = _one_line_error(capsys, "too short", "needs")
    assert "rad" in err and " s" in err


def test_constant_extra_column(files, tmp_path, capsys):
    for name in ("train.csv", "test.csv"):
        rec = hdjax.load_csv(files / name)
        hdjax.save_csv(
            rec.with_extras(temperature=np.full(rec.n_samples, 25.0)), files / f"const_{name}"
        )
    assert _run(files, tmp_path / "o", train="const_train.csv", test="const_test.csv") == 2
    _one_line_error(capsys, "constant", "temperature", "--ignore-column")
    # and it runs when told to ignore the column
    assert (
        _run(
            files,
            tmp_path / "o2",
            "--ignore-column",
            "temperature",
            "--no-figures",
            "--max-effects",
            "1",
            train="const_train.csv",
            test="const_test.csv",
        )
        == 0
    )


def test_every_figure_panel_has_a_title(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from hdjax.discover._report import _plot_spectra

    class Spec:
        orders = np.arange(1, 50) / 2
        power = np.full(49, 0.01)

    titles = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: titles.append(
        [ax.get_title() for ax in fig.axes]))  # fmt: skip
    _plot_spectra({"theta_m": Spec(), "theta_l": Spec()}, ["harmonic:theta_m:2"], "spectrum",
                  tmp_path / "s.png")  # fmt: skip
    ((motor, load),) = titles
    assert "theta_m" in motor and "theta_l" in load


def test_report_markdown_notes_once_under_a_heading_and_narrow_tables():
    from hdjax.discover._report import report_markdown

    amplitude = dict(arcsec=20.0, arcsec_ci95=[19.0, 21.0], nm=3.0, nm_ci95=[2.9, 3.1])
    step = dict(effect="harmonic:theta_m:2", rms=1.1, max=7.9, cv_torque_rms=1.2,
                cv_twist_rms_arcsec=3.4, cv_gain=0.5, stability=1.0, aliases=[],
                amplitude=amplitude)  # fmt: skip
    d = dict(
        baseline=dict(rms=4.4, max=12.6, cv_torque_rms=4.5, cv_twist_rms_arcsec=9.0),
        steps=[step],
        stopping_rule="rule",
        unexplained=[
            dict(signal="theta_l", kind="order", order=3.0, amplitude_arcsec=1.0, explained=0.02)
        ],
        notes=["warning: k5 is poorly covered", "candidate x could not be added"] * 3,
    )
    md = report_markdown(d, [])
    assert md.count("warning: k5 is poorly covered") == 1
    assert md.count("candidate x could not be added") == 1
    head, notes = md.split("## Notes\n", 1)
    assert "- warning: k5" in notes and "Left unexplained" in head
    rows = [line for line in md.splitlines() if line.startswith("|")]
    assert max(line.count("|") - 1 for line in rows) <= 6  # no table wider than 6 columns
    assert "20 arcsec [19, 21]" in md  # the details are still there, in the second table
    # an effect whose coefficient is its physical parameter (a skew's delay) shows it, in ms
    skew = dict(amplitude | {"delay_ms": 2.13, "delay_ms_ci95": [2.05, 2.2]}, effect="skew")
    md = report_markdown(d | {"steps": [dict(step, effect="skew:encoders", amplitude=skew)]}, [])
    assert "| delay 2.13 ms [2.05, 2.2]; 20 arcsec [19, 21]" in md


def test_one_log_cut_by_test_blocks_runs_whole_and_draws_its_figures(files, tmp_path):
    # TRAIN and TEST from one log: the loop sees the log whole (context) and the report's
    # figures are drawn from TEST's own rows
    cfg = tmp_path / "disc.toml"
    cfg.write_text(
        "[joint]\nratio = 160\nrated_torque = 400\n"
        f'[data]\npath = "{files / "train.csv"}"\ntest_blocks = {{ block = 500, every = 4 }}\n'
        "[discover]\nmax_effects = 1\n"
    )
    out = tmp_path / "out"
    assert _discover_cli(["--config", str(cfg), "--out", str(out), "--quiet"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert any("blocks of one log" in n for n in rep["notes"]), rep["notes"]
    assert rep["effects"] == ["harmonic:theta_m:2"]
    assert (out / "figures" / "spectrum_0.png").exists()


def test_config_families_restrict_the_library(files, tmp_path, capsys):
    # [discover] families: the loop offers only those families (here not the harmonic the logs
    # carry, so it cannot be added and no harmonic is ranked); an unknown name is one line
    def config(families):
        cfg = tmp_path / "disc.toml"
        cfg.write_text(
            "[joint]\nratio = 160\nrated_torque = 400\n"
            f'[data]\ntrain = "{files / "train.csv"}"\ntest = "{files / "test.csv"}"\n'
            f"[discover]\nmax_effects = 1\nfamilies = {families}\n"
        )
        return cfg

    out = tmp_path / "out"
    argv = ["--config", config('["coulomb:omega_m", "viscous:omega_m"]'), "--out", out]
    assert _discover_cli([*argv, "--quiet", "--no-figures"]) == 0
    rep = json.loads((out / "report.json").read_text())
    ranked = {r["key"].split(":")[0] for r in rep["last_ranking"]}
    assert ranked and ranked <= {"coulomb", "viscous"}, ranked
    assert not any(e.startswith("harmonic") for e in rep["effects"]), rep["effects"]
    for bad, words in (
        ('["harmonic:theta_x"]', ["unknown family 'harmonic:theta_x'", "harmonic:theta_m"]),
        ('"hysteresis:torque"', ["expected a non-empty list"]),
        ("[]", ["expected a non-empty list"]),
    ):
        assert _discover_cli(["--config", config(bad), "--out", tmp_path / "o2"]) == 2
        _one_line_error(capsys, "[discover] families", *words)
        assert not (tmp_path / "o2").exists()


def test_a_discover_files_settings_are_checked_and_the_command_line_wins(
    files, tmp_path, capsys, monkeypatch
):
    # every [discover] value is checked before anything runs (one line naming the key); a
    # setting given on the command line (--chunk, --max-effects) overrides the file's
    from hdjax.discover import internal as _loop

    def config(lines):
        cfg = tmp_path / "disc.toml"
        cfg.write_text(
            "[joint]\nratio = 160\nrated_torque = 400\n"
            f'[data]\ntrain = "{files / "train.csv"}"\ntest = "{files / "test.csv"}"\n'
            f"[discover]\n{lines}\n"
        )
        return cfg

    for lines, words in (
        ('max_effects = "five"', "max_effects must be a whole number >= 0"),
        ("max_effects = 2.9", "max_effects must be a whole number >= 0"),
        ("min_gain = 1.5", "min_gain must be a number in (0, 1)"),
        ("min_gain = true", "min_gain must be a number in (0, 1)"),
        ("n_segments = 0", "n_segments must be a whole number from 1 to 20"),
        ("poly_order = -2", "poly_order must be a whole number from 0 to 12"),
        ('ignore_columns = "temp"', "ignore_columns must be a list of column names"),
        ("chunk = 3", "chunk must be 0 (the whole record at once) or at least 16"),
    ):
        out = tmp_path / "o"
        assert _discover_cli(["--config", config(lines), "--out", out]) == 2, lines
        _one_line_error(capsys, "[discover]", words)
        assert not out.exists()
    seen = []

    def stop(train, test, joint, options, **kw):
        seen.append(options)
        raise KeyboardInterrupt

    monkeypatch.setattr(_loop, "discover", stop)
    cfg = config("chunk = 0\nmax_effects = 4")
    for extra, chunk, most in (([], 0, 4), (["--chunk", "64", "--max-effects", "1"], 64, 1)):
        _discover_cli(["--config", cfg, "--out", tmp_path / "p", "--quiet", *extra])
        assert (seen[-1].chunk, seen[-1].max_effects) == (chunk, most), seen[-1]
