"""`hdjax sweep`: nested fits equal separate fits, the knee, resuming, bad settings."""

import json

import numpy as np
import pytest

from hdjax import RESULTS, Joint
from hdjax.cli import main
from hdjax.compliance import ComplianceModel, calibrate_lstsq, estimate_torque_arrays
from hdjax.compliance._nested import batched_estimates, estimable, member_message, nested_fit
from hdjax.pipelines import synthetic_recording
from hdjax.pipelines._paper import stacked_signals

JOINT = Joint(ratio=160.0, rated_torque=400.0)

CONFIG = """
[experiment]
name = "sw"
[joint]
ratio = 160
rated_torque = 400
[data]
kind = "synthetic"
n_samples = 4000
[model]
kinematic = "none"
per_segment = false
[sweep]
setting = "model.poly_order"
values = [1, 2, 3, 4, 5, 6]
[outputs]
figures = false
"""


def test_nested_members_equal_separate_fits():
    """Each member of the one-pass sweep equals calibrate_lstsq on its own structure
    (coefficients to 1e-8 relative: both solve the same scaled least-squares problem, by
    different factorizations), and the batched held-out estimate equals each model's own
    (to 1e-7 relative, the coefficient agreement carried through the inversion)."""
    train = synthetic_recording(JOINT, 4000, seed=1)
    test = synthetic_recording(JOINT, 1000, seed=2)
    make = lambda p: ComplianceModel.paper(
        JOINT, poly_order=p, current_scale=12.0, kinematic="none", per_segment=True
    )
    big = make(5)
    orders = [1, 3, 5]
    sig, torque = stacked_signals(big, [train])
    fits, _ = nested_fit(big, [make(p) for p in orders], sig, torque)
    test_sig, _ = stacked_signals(big, [test])
    torques = batched_estimates(big, fits, test_sig)
    for p, fit, tq in zip(orders, fits, torques):
        ref = calibrate_lstsq(make(p), (sig, torque)).value
        assert fit.value.active == ref.active and fit.ok
        c, r = np.asarray(fit.value.coef), np.asarray(ref.coef)
        assert np.max(np.abs(c - r)) <= 1e-8 * np.max(np.abs(r))
        own = np.asarray(estimate_torque_arrays(ref, test_sig))
        np.testing.assert_allclose(tq, own, rtol=1e-7, atol=1e-9)


def test_a_reversed_twist_is_a_result_code_not_free_text():
    """A joint whose encoders count against the torque (the model's twist_sign disagrees with
    the data's) calibrates a negative compliance in every segment: each member's result is
    RESULTS.twist_reversed, its message names the segments, and it gets no held-out estimate."""
    train = synthetic_recording(JOINT, 2000, seed=3)
    flipped = Joint(ratio=160.0, rated_torque=400.0, twist_sign=-1.0)
    make = lambda p: ComplianceModel.paper(
        flipped, poly_order=p, current_scale=12.0, kinematic="none", per_segment=False
    )
    big = make(3)
    sig, torque = stacked_signals(big, [train])
    fits, _ = nested_fit(big, [make(1), make(3)], sig, torque)
    assert [f.result for f in fits] == [RESULTS.twist_reversed] * 2
    assert not any(estimable(f) for f in fits)
    assert all("cannot be inverted" in member_message(f) for f in fits)
    assert all(f.stats["n_terms"] == f.stats["rank"] for f in fits)
    assert batched_estimates(big, fits, sig) == [None, None]


def test_knee_is_the_true_polynomial_order(tmp_path):
    """The synthetic twist has a cubic current term: the held-out error stops falling at 3."""
    cfg = tmp_path / "sw.toml"
    cfg.write_text(CONFIG)
    out = tmp_path / "out"
    assert main(["sweep", str(cfg), "--out", str(out), "--quiet"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["knee"] == {"index": 2, "value": 3}
    rms = [r["rms"] for r in m["members"]]
    assert rms[0] > 1.2 * rms[2] and abs(rms[5] - rms[2]) < 0.02 * rms[2]
    assert "| 3 |" in (out / "report.md").read_text()
    assert not (tmp_path / "out.partial").exists()
    # which torque the members were scored against, as 'hdjax run' says it
    desc = "reference: the torque the synthetic recordings were generated from (column)"
    assert m["reference"] == {"kind": "column", "description": desc}
    assert f"Torque {desc}." in (out / "report.md").read_text()


def test_sweep_over_data_names_the_reference_column(tmp_path):
    """Members built from files (a sweep over a [data] setting): the report and metrics name
    the log column the torque came from; the resolved config finds the log from anywhere."""
    import tomllib

    from hdjax import save_csv

    save_csv(synthetic_recording(JOINT, 800, seed=3), tmp_path / "log.csv")
    text = (tmp_path / "log.csv").read_text().replace(",torque", ",tq", 1)
    (tmp_path / "log.csv").write_text(text)
    cfg = tmp_path / "files.toml"
    cfg.write_text(
        '[joint]\nratio = 160\nrated_torque = 400\n[data]\nkind = "files"\n'
        'train = ["log.csv"]\nsplit = 0.3\n[data.columns]\ntorque = "tq"\n'
        '[model]\nkinematic = "none"\npoly_order = 2\nper_segment = false\n'
        "[outputs]\nfigures = false\n"
    )
    out = tmp_path / "split"
    argv = ["sweep", str(cfg), "--setting", "data.split", "--values", "0.25,0.5"]
    assert main(argv + ["--out", str(out), "-q"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    desc = "reference: the log column 'tq' ([data.columns] torque)"
    assert m["reference"]["description"] == desc
    assert [r["reference"]["description"] for r in m["members"]] == [desc, desc]
    assert f"Torque {desc}." in (out / "report.md").read_text()
    resolved = tomllib.loads((out / "config.resolved.toml").read_text())
    assert resolved["data"]["train"] == [str(tmp_path.resolve() / "log.csv")]


def _interrupt_at_the_second_member(monkeypatch):
    """The sweep's member loop, interrupted (Ctrl-C) when the second member starts; returns
    the real loop and the list of the members' segment counts it was called with."""
    from hdjax.cli import _sweep

    real, calls = _sweep._member_loop, []

    def interrupted(*a, **k):
        calls.append(a[0]["model"]["n_segments"])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(_sweep, "_member_loop", interrupted)
    return real, calls


def test_interrupted_sweep_resumes(tmp_path, monkeypatch, capsys):
    from hdjax.cli import _sweep

    cfg = tmp_path / "sw.toml"
    cfg.write_text(CONFIG)
    out = tmp_path / "seg"
    args = [
        "sweep",
        str(cfg),
        "--setting",
        "model.n_segments",
        "--values",
        "1,3,5",
        "--out",
        str(out),
    ]
    real, calls = _interrupt_at_the_second_member(monkeypatch)
    assert main(args) == 130
    assert not out.exists()
    assert len(list((tmp_path / "seg.partial" / "members").iterdir())) == 1
    calls.clear()
    monkeypatch.setattr(_sweep, "_member_loop", lambda *a, **k: calls.append(1) or real(*a, **k))
    assert main(args) == 0
    assert len(calls) == 2  # only the two members not done before
    assert "resuming: 1 of 3 members cached" in capsys.readouterr().err
    m = json.loads((out / "metrics.json").read_text())
    assert [r["value"] for r in m["members"]] == [1, 3, 5]
    assert not (tmp_path / "seg.partial").exists()


def test_fresh_ignores_cached_member_results(tmp_path, monkeypatch, capsys):
    """A member result left in OUT.partial by an interrupted sweep is taken as it is by the next
    run (here a doctored one: its error numbers changed), and computed again with --fresh."""
    import shutil

    from hdjax.cli import _sweep

    cfg = tmp_path / "sw.toml"
    cfg.write_text(CONFIG)
    argv = ["sweep", str(cfg), "--setting", "model.n_segments", "--values", "1,3"]
    real, calls = _interrupt_at_the_second_member(monkeypatch)
    assert main([*argv, "--out", str(tmp_path / "a"), "-q"]) == 130
    (member,) = (tmp_path / "a.partial" / "members").iterdir()
    cached = json.loads(member.read_text())
    true_rms = cached["result"]["rms"]
    cached["result"].update(rms=123.25, max=456.5)
    member.write_text(json.dumps(cached))
    shutil.copytree(tmp_path / "a.partial", tmp_path / "b.partial")  # the same, for --fresh
    monkeypatch.setattr(_sweep, "_member_loop", lambda *a, **k: calls.append(a) or real(*a, **k))
    capsys.readouterr()

    calls.clear()
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    assert "resuming: 1 of 2 members cached" in capsys.readouterr().err
    assert len(calls) == 1  # only the member not cached
    (first, second) = json.loads((tmp_path / "a" / "metrics.json").read_text())["members"]
    assert (first["rms"], first["max"]) == (123.25, 456.5)  # the cached numbers, as they were

    calls.clear()
    assert main([*argv, "--out", str(tmp_path / "b"), "--fresh"]) == 0
    (first_b, second_b) = json.loads((tmp_path / "b" / "metrics.json").read_text())["members"]
    assert first_b["rms"] == pytest.approx(true_rms, rel=1e-9) and first_b["max"] != 456.5
    assert "resuming" not in capsys.readouterr().err
    assert len(calls) == 2  # both members computed
    assert second_b["rms"] == pytest.approx(second["rms"], rel=1e-9)
    assert not (tmp_path / "b.partial").exists()


def test_sweep_over_unknown_setting(tmp_path, capsys):
    cfg = tmp_path / "sw.toml"
    cfg.write_text(CONFIG)
    assert (
        main(
            ["sweep", str(cfg), "--setting", "model.poly_oder", "--out", str(tmp_path / "o"), "-q"]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert "cannot sweep over unknown setting 'model.poly_oder'" in err
    assert "did you mean 'model.poly_order'" in err
    cfg.write_text(CONFIG.replace('"model.poly_order"', '"model.polyorder"'))
    assert main(["sweep", str(cfg)]) == 2
    assert "did you mean 'model.poly_order'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_sweep_values_are_validated_before_work(tmp_path, capsys):
    cfg = tmp_path / "sw.toml"
    cfg.write_text(CONFIG)
    assert main(["sweep", str(cfg), "--values", "1,2.5", "--out", str(tmp_path / "o")]) == 2
    assert "poly_order must be an integer, got 2.5" in capsys.readouterr().err
    assert main(["sweep", str(cfg), "--values", "3:1"]) == 2
    assert "empty range" in capsys.readouterr().err
