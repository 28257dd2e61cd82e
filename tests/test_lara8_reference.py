"""The LARA8 force/torque-sensor reference: its DH table, and (with ../shared) the real log."""

import json

import numpy as np
import pytest

import hdjax
from hdjax.reference import (
    detect_holds,
    dh_arm_from_table,
    jacobian_columns,
    joint_torque,
    load_dh_table,
)
from tests.conftest import REPO

DH = REPO / "experiments" / "lara8_dh.toml"
FTS = REPO / "experiments" / "lara8_fts.toml"
LEVER = 0.7 + 0.1735  # d4 + d6: joint 3's axis to the flange with the other joints at zero


def test_joint3_column_with_the_other_joints_at_zero():
    # The column [0.8735 cos t3, 0, -0.8735 sin t3, 0, 1, 0] holds in base axes at the
    # sensor point (pinocchio's LOCAL_WORLD_ALIGNED). In the last DH frame the column is the
    # constant [0.8735, 0, 0, 0, 1, 0] (the flange turns with joint 3), and in the sensor frame
    # (turned 180 degrees about z from it, see the table's comments) [-0.8735, 0, 0, 0, -1, 0].
    import tomllib

    arm = load_dh_table(DH)
    table = tomllib.loads(DH.read_text())["arm"]
    flange = dh_arm_from_table({k: v for k, v in table.items() if k != "tool"})
    t3 = np.linspace(-2.6, 2.6, 27)
    q = np.zeros((t3.size, 6))
    q[:, 2] = t3
    zero, one = np.zeros_like(t3), np.ones_like(t3)
    base = np.stack([LEVER * np.cos(t3), zero, -LEVER * np.sin(t3), zero, one, zero], 1)
    got = np.asarray(jacobian_columns(arm, q, 2, frame="base"))
    np.testing.assert_allclose(got, base, atol=1e-12)
    six = np.stack([LEVER * one, zero, zero, zero, one, zero], 1)
    np.testing.assert_allclose(
        np.asarray(jacobian_columns(flange, q, 2, frame="tool")), six, atol=1e-12
    )
    sensor = np.asarray(jacobian_columns(arm, q, 2, frame="tool"))
    np.testing.assert_allclose(sensor, six * np.array([-1, 1, 1, 1, -1, 1]), atol=1e-12)
    # not the expression in the tool frame: it differs away from t3 = 0
    assert np.max(np.abs(sensor - base)) > 1.0


@pytest.fixture(scope="module")
def raw(lara8_dir):
    names = [f"joint_angles_{i}" for i in range(1, 7)] + [f"fts_reading_{i}" for i in range(1, 7)]
    names += ["target_joint_torque_3", "joint_torque_current_3"]
    cmap = hdjax.ColumnMap.from_dict(
        {
            "columns": {
                "t": "Timestamp",
                "theta_m": "encoder_motorinc_3",
                "theta_l": "encoder_loadinc_3",
                "current": "joint_torque_current_3",
            },
            "extras": {n: n for n in names},
        }
    )
    rec = hdjax.load_csv(lara8_dir / "validate.csv", cmap, check_units=False)
    return {"t": np.asarray(rec.t), **{n: np.asarray(rec.extras[n]) for n in names}}


def test_the_thesis_and_the_direct_log_numbers_are_reproduced(raw):
    # References: the thesis' current-based RMS against the F/T torque (6.48 N·m) and the
    # task's direct computation (19.9 N·m RMS, 4.7 N·m bias), both quoted to 2-3 digits.
    arm = load_dh_table(DH)
    q = np.stack([raw[f"joint_angles_{i}"] for i in range(1, 7)], 1)
    w = np.stack([raw[f"fts_reading_{i}"] for i in range(1, 7)], 1)
    cur, model = raw["joint_torque_current_3"], raw["target_joint_torque_3"]
    err = cur - joint_torque(np.asarray(jacobian_columns(arm, q, 2, frame="tool")), w, model)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(6.48, abs=0.005)
    mixed = joint_torque(np.asarray(jacobian_columns(arm, q, 2, frame="base")), w, model)
    assert np.sqrt(np.mean((cur - mixed) ** 2)) == pytest.approx(19.9, abs=0.05)
    assert np.mean(cur - mixed) == pytest.approx(4.7, abs=0.1)
    holds = detect_holds(w, raw["t"])
    assert holds.n_fresh == 736 and holds.median_period_s == pytest.approx(0.010, abs=2e-4)


def test_hdjax_run_reports_the_wrench_reference(lara8_dir, tmp_path):
    out = tmp_path / "run"
    argv = ["run", str(FTS), "--out", str(out), "--no-figures", "--no-network", "--quiet"]
    argv += ["--set", "outputs.save_model=false"]
    from hdjax.cli import main

    assert main(argv) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    ref = metrics["data"]["reference"]
    assert ref["kind"] == "wrench" and "J_3(q)^T" in ref["description"]
    (info,) = ref["files"].values()
    assert info["holds"]["fresh_rows"] == 736 and info["offset"]["method"] == "none"
    assert "reference from the force/torque sensor" in (out / "report.md").read_text()
    assert metrics["data"]["n_train"] + metrics["model"]["scenarios"]["validate"]["n"] == 736


def test_discover_config_takes_the_reference_table(lara8_dir, tmp_path):
    from hdjax.discover._config import load_discover_config

    cfg = tmp_path / "d.toml"
    text = FTS.read_text()
    ref = text[text.index("[data.reference]") : text.index("[model]")]
    ref = ref.replace('dh = "lara8_dh.toml"', f'dh = "{DH}"')
    cfg.write_text(
        "[joint]\nratio = 101\nrated_torque = 150\ntwist_sign = -1\n[data]\n"
        f'path = "{lara8_dir / "validate.csv"}"\n'
        '[data.columns]\nt = "Timestamp"\ntheta_m = { source = "encoder_motorinc_3", '
        'counts_per_rev = 16777216 }\ntheta_l = { source = "encoder_loadinc_3", '
        'counts_per_rev = 16777216 }\ncurrent = "joint_torque_current_3"\n' + ref
    )
    train, test, _, _, notes = load_discover_config(cfg)
    assert train.n_samples + test.n_samples == 736
    assert any(n.startswith("reference from the force/torque sensor") for n in notes)


def test_the_reference_page_is_not_stale(lara8_dir):
    # docs/lara8-reference.md is generated by benchmarks/lara8_reference.py; its deterministic
    # rows (the compliance model as configured, the residual loop's start and end with the
    # effects it added, the current) and the loop's skew reading are recomputed here, so a
    # change to the code that moves them fails until the page is regenerated (the network's
    # row, five trainings, is not)
    import importlib.util
    import re

    spec = importlib.util.spec_from_file_location(
        "lara8_reference", REPO / "benchmarks" / "lara8_reference.py"
    )
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    rows, kept = gen.deformation_rows(gen.load_experiment(gen.CONFIG))
    page = (REPO / "docs" / "lara8-reference.md").read_text()
    fix = "; run python benchmarks/lara8_reference.py to regenerate it"
    table = {
        "song_config": "Song model as configured",
        "song_discover_start": "starting model of the residual loop",
        "song_discover_final": "after `discover`",
        "current": "current-based torque `joint_torque_current_3`",
    }
    for key, label in table.items():
        (line,) = [x for x in page.splitlines() if x.startswith("|") and label in x]
        shown = [float(v) for v in re.findall(r"\| (-?\d+\.\d+)", line)]
        expected = [round(rows[key][k], 2) for k in ("rms", "max", "bias")]
        assert shown == expected, f"{label}: the page says {shown}, the code gives {expected}{fix}"
    final = rows["song_discover_final"]
    effects = ", ".join(f"`{e}`" for e in final["effects"]) or "none"
    start = f"; from the {final['start']}" if final.get("start") else ""
    assert f"(added: {effects}{start})" in page, (
        f"the page names other effects or another start than {effects}{start}{fix}"
    )
    # the loop's reading of the encoders' skew (delays in ms, with intervals, and its advice)
    # is prose, not a table row: a change that moves it must fail here too
    skew = gen.skew_reading(kept["notes"])
    assert skew in page, f"the page's encoder-skew reading is not the code's: {skew!r}{fix}"
