"""`hdjax fleet` on a 2-worker local Dask cluster: 8 small simulated joint-logs, one broken."""

import json

import numpy as np
import pytest

import hdjax
from hdjax.cli import main
from hdjax.compliance import ComplianceModel, calibrate_lstsq
from hdjax.config import synthetic_recording

pytest.importorskip("distributed")
pq = pytest.importorskip("pyarrow.parquet")

JOINTS = {"r1-j1": (160.0, 400.0), "r1-j2": (100.0, 150.0)}
DATES = ["2026-01-05", "2026-02-02", "2026-03-02", "2026-03-30"]


def test_fleet_two_workers_one_broken_and_resume(tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    lines = ['[fleet]\nname = "cell"\ntask = "calibrate"\n', "[model]\nfourier_order = 1\n"]
    recs = {}
    for j, (name, (ratio, rated)) in enumerate(JOINTS.items()):
        joint = hdjax.Joint(ratio=ratio, rated_torque=rated)
        entries = []
        for k, date in enumerate(DATES):
            rec = synthetic_recording(joint, 1500, seed=10 * j + k, source=name)
            path = logs / f"{name}-{date}.parquet"
            hdjax.save_csv(rec, path.with_suffix(".csv"))
            hdjax.cli.main(["convert", str(path.with_suffix(".csv")), str(path), "-q"])
            recs[(name, date)] = rec
            entries.append(f'{{ path = "logs/{path.name}", date = {date} }}')
        if j == 1:  # broken on purpose: a text cell in the middle of the log
            bad = logs / "broken.csv"
            text = (logs / f"{name}-{DATES[0]}.csv").read_text().splitlines()
            text[700] = text[700].replace(",", ",oops,", 1).rsplit(",", 1)[0]
            bad.write_text("\n".join(text) + "\n")
            entries[-1] = f'{{ path = "logs/{bad.name}", date = {DATES[-1]} }}'
        lines.append(
            f'[[joints]]\nname = "{name}"\nratio = {ratio}\nrated_torque = {rated}\n'
            f"logs = [{', '.join(entries)}]\n"
        )
    manifest = tmp_path / "cell.toml"
    manifest.write_text("\n".join(lines))
    out = tmp_path / "out"
    code = main(["fleet", str(manifest), "--out", str(out), "--workers", "2"])
    err = capsys.readouterr().err
    assert code == 1  # one task failed, the other seven ran
    assert "8/8 done, 0 running, 1 failed" in err
    table = pq.read_table(out / "results.parquet").to_pylist()
    assert len(table) == 8 and [r["status"] for r in table].count("ok") == 7
    broken = next(r for r in table if r["status"] == "failed")
    assert broken["log"].endswith("broken.csv") and "\n" not in broken["error"]
    assert "non-numeric cell 'oops'" in broken["error"] and broken["error"] in err
    # a row's coefficients are the in-process calibration of the same log
    row = next(r for r in table if r["joint"] == "r1-j1" and r["date"] == DATES[1])
    rec = recs[("r1-j1", DATES[1])]
    joint = hdjax.Joint(ratio=160.0, rated_torque=400.0)
    model = ComplianceModel.paper(
        joint, current_scale=float(np.max(np.abs(np.asarray(rec.current)))), fourier_order=1
    )
    ref = calibrate_lstsq(model, rec).value
    for name, value in zip(ref.term_names, np.asarray(ref.coef)):
        np.testing.assert_allclose(row[f"coef:{name}"], value, rtol=1e-12, atol=1e-300)
    assert row["n_samples"] == 1500 and row["twist_rms_arcsec"] > 0
    from .helpers import assert_figure

    for name in JOINTS:
        png = out / "figures" / f"drift_{name}.png"
        assert_figure(png, (825, 880))  # 7.5 x 8 in at 110 dpi
    report = (out / "report.md").read_text()
    assert "non-numeric cell" in report and "## r1-j2" in report
    # resumable: fix the broken log and run again; only that task runs
    (logs / "broken.csv").write_text((logs / f"r1-j2-{DATES[0]}.csv").read_text())
    code = main(["fleet", str(manifest), "--out", str(out), "--workers", "2", "--overwrite"])
    err = capsys.readouterr().err
    assert code == 0 and "7 of 8 tasks finished before; skipped" in err
    table2 = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["status"] for r in table2] == ["ok"] * 8
    assert [r["seconds"] for r in table2[:7]] == [r["seconds"] for r in table[:7]]  # reused
    marker = json.loads((out / ".hdjax-result").read_text())
    assert marker["command"] == "fleet" and "results.parquet" in marker["files"]
