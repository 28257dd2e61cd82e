"""`hdjax fleet` on a 2-worker local Dask cluster: 8 small simulated joint-logs, one broken."""

import json
import os
import socket

import numpy as np
import pytest

import hdjax
from hdjax._lazy import dask_distributed
from hdjax._metrics import error_metrics
from hdjax.cli import main
from hdjax.cli._fleet import WORKER_ENV, worker_env
from hdjax.compliance import ComplianceModel, calibrate_lstsq, estimate_torque
from hdjax.modelfile import save_model
from hdjax.pipelines import synthetic_recording

from . import discover_data
from .helpers import assert_figure

distributed = pytest.importorskip("distributed")
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


# -- calibrate+discover and estimate on a Dask cluster given by --scheduler ----------------------
# One 2-worker cluster for the tests below, started by the test as a user would start theirs.


@pytest.fixture(scope="module")
def scheduler():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, env=worker_env()
    )
    with distributed.Client(cluster) as client:
        pids = set(client.run(os.getpid).values())
    yield cluster.scheduler_address, pids
    cluster.close()


def _manifest(tmp_path, task, joints, extra=""):
    """A manifest of `joints`: name -> (ratio, rated torque, [(log path, date)], model file)."""
    lines = [f'[fleet]\nname = "cell"\ntask = "{task}"\n{extra}']
    for name, (ratio, rated, logs, model) in joints.items():
        entries = ", ".join(f'{{ path = "{p}", date = {d} }}' for p, d in logs)
        lines.append(
            f'[[joints]]\nname = "{name}"\nratio = {ratio}\nrated_torque = {rated}\n'
            + (f'model = "{model}"\n' if model else "")
            + f"logs = [{entries}]\n"
        )
    path = tmp_path / "cell.toml"
    path.write_text("\n".join(lines))
    return path


def test_fleet_discover_on_a_scheduler_reports_each_amplitude_with_its_interval(
    tmp_path, scheduler, capsys
):
    address, pids = scheduler
    # one undeclared effect, a twice-per-motor-turn harmonic, drifting from 20 to 30 arcsec
    truth = {"2026-01-05": 20.0, "2026-02-02": 30.0}
    logs = []
    for k, (date, amp) in enumerate(truth.items()):
        rec = discover_data.synthetic_recording(
            40 + k, [("harmonic_m", 2.0, amp * discover_data.ARCSEC)], n=4000
        )
        hdjax.save_csv(rec, tmp_path / f"j-{date}.csv")
        logs.append((f"j-{date}.csv", date))
    joints = {"j": (discover_data.RATIO, discover_data.RATED, logs, None)}
    manifest = _manifest(tmp_path, "calibrate+discover", joints, "max_effects = 1\n")
    out = tmp_path / "out"
    code = main(["fleet", str(manifest), "--out", str(out), "--scheduler", address, "-q"])
    assert code == 0, capsys.readouterr().err
    table = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["date"] for r in table] == list(truth)
    for row in table:
        assert row["status"] == "ok" and row["worker_pid"] in pids  # ran on that cluster
        assert row["effects"] == ["harmonic:theta_m:2"]
        assert row["test_rms_Nm"] < 0.5 * row["baseline_test_rms_Nm"]
        (a,) = row["amplitudes"]
        assert a["effect"] == "harmonic:theta_m:2"
        values = [a[c] for c in ("amplitude_arcsec", "low", "high", "amplitude_Nm", "low_Nm",
                                 "high_Nm")]  # fmt: skip
        assert all(v is not None and np.isfinite(v) for v in values), a
        assert a["low"] <= a["amplitude_arcsec"] <= a["high"]
        assert a["low_Nm"] <= a["amplitude_Nm"] <= a["high_Nm"]
        assert a["low"] < a["high"] and a["low_Nm"] < a["high_Nm"]
        # the amplitude is the harmonic's simulated one (closed form), to 5 %
        np.testing.assert_allclose(a["amplitude_arcsec"], truth[row["date"]], rtol=0.05)
        # N·m of equivalent torque: the twist over a compliance between the segments' extremes
        # (the active ones: a compliance the fit leaves out has a null column)
        k = [row[f"coef:k{j}"] for j in range(1, 6) if row[f"coef:k{j}"] is not None]
        assert len(k) >= 3
        rad = a["amplitude_arcsec"] * discover_data.ARCSEC
        assert rad / max(k) <= a["amplitude_Nm"] <= rad / min(k)
        assert a["cv_gain"] > 0
    assert_figure(out / "figures" / "drift_j.png", (825, 880))
    assert "harmonic:theta_m:2" in (out / "report.md").read_text()


def test_fleet_estimate_applies_the_saved_model_to_each_log(tmp_path, scheduler, capsys):
    address, pids = scheduler
    joint = hdjax.Joint(ratio=160.0, rated_torque=400.0)
    recs = {d: synthetic_recording(joint, 1500, seed=60 + k) for k, d in enumerate(DATES[:3])}
    for d, rec in recs.items():
        hdjax.save_csv(rec, tmp_path / f"{d}.csv")
    calib = recs[DATES[0]]
    scale = float(np.max(np.abs(np.asarray(calib.current))))
    # a structure 1500 samples determine well (the per-segment sextic would extrapolate)
    model = ComplianceModel.paper(
        joint, poly_order=3, per_segment=False, fourier_order=1, current_scale=scale
    )
    model = calibrate_lstsq(model, calib).value
    save_model(tmp_path / "model.json", joint, compliance=model)
    logs = [(f"{d}.csv", d) for d in DATES[1:3]]
    joints = {
        "r1-j1": (160.0, 400.0, logs, "model.json"),
        # the same model for a joint of another ratio: refused, in that task's row only
        "r1-j2": (100.0, 150.0, logs[:1], "model.json"),
    }
    manifest = _manifest(tmp_path, "estimate", joints)
    out = tmp_path / "out"
    code = main(["fleet", str(manifest), "--out", str(out), "--scheduler", address, "-q"])
    err = capsys.readouterr().err
    assert code == 1
    table = pq.read_table(out / "results.parquet").to_pylist()
    assert [(r["joint"], r["status"]) for r in table] == [
        ("r1-j1", "ok"), ("r1-j1", "ok"), ("r1-j2", "failed")
    ]  # fmt: skip
    bad = table[2]
    assert "calibrated for ratio 160" in bad["error"] and "\n" not in bad["error"]
    assert bad["error"] in err
    for row in table[:2]:
        assert row["worker_pid"] in pids and row["n_samples"] == 1500
        rec = recs[row["date"]]
        est = estimate_torque(model, rec)
        ref = error_metrics(np.asarray(est.torque), np.asarray(rec.torque), joint.rated_torque)
        np.testing.assert_allclose(row["test_rms_Nm"], float(ref.rms), rtol=1e-9)
        np.testing.assert_allclose(row["test_max_Nm"], float(ref.max), rtol=1e-9)
        np.testing.assert_allclose(
            row["in_range_pct"], 100 * np.mean(np.asarray(est.in_range)), rtol=1e-12
        )
        assert row["test_rms_Nm"] < 0.01 * joint.rated_torque  # the model fits these logs
        for name, value in zip(model.term_names, np.asarray(model.coef)):
            np.testing.assert_allclose(row[f"coef:{name}"], value, rtol=1e-12, atol=1e-300)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _one_line(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert err.startswith("hdjax: error:"), err
    for w in words:
        assert w in err, err
    return err


def test_fleet_bad_scheduler_is_one_line_and_quick(tmp_path, capsys, monkeypatch):
    rec = synthetic_recording(hdjax.Joint(ratio=160.0, rated_torque=400.0), 200, seed=1)
    hdjax.save_csv(rec, tmp_path / "a.csv")
    joints = {"j": (160.0, 400.0, [("a.csv", DATES[0])], None)}
    manifest = str(_manifest(tmp_path, "calibrate", joints))
    out = tmp_path / "out"
    run = lambda *a: main(["fleet", manifest, "--out", str(out), *a])  # noqa: E731
    nobody = f"tcp://127.0.0.1:{_free_port()}"
    distributed = dask_distributed()  # the module the command takes its Client from
    asked, real = [], distributed.Client
    monkeypatch.setattr(distributed, "Client", lambda *a, **k: asked.append(k) or real(*a, **k))
    assert run("--scheduler", nobody, "--connect-timeout", "1") == 2
    # the client is given the 1 s of --connect-timeout, not the 20 s default
    assert [k.get("timeout") for k in asked] == ["1.0s"], asked
    _one_line(capsys, nobody, "cannot connect", "--connect-timeout")
    assert not out.exists()
    for address in ("nonsense", "127.0.0.1", "foo://127.0.0.1:8786"):
        assert run("--scheduler", address) == 2
        _one_line(capsys, repr(address), "not a scheduler address", "tcp://HOST:PORT")
    assert run("--scheduler", " ") == 2
    _one_line(capsys, "--scheduler is empty")
    assert run("--scheduler", nobody, "--workers", "2") == 2
    _one_line(capsys, "--workers", "drop")
    assert run("--workers", "0") == 2
    _one_line(capsys, "--workers must be >= 1, got 0")
    assert run("--scheduler", nobody, "--connect-timeout", "0") == 2
    _one_line(capsys, "--connect-timeout must be a positive number")
    assert run("--connect-timeout", "5") == 2
    _one_line(capsys, "--connect-timeout applies to --scheduler only")
    assert not out.exists()


# -- --fresh and --no-pin ------------------------------------------------------------------------


def _two_logs(tmp_path):
    """A calibrate manifest of one joint with two small logs."""
    joint = hdjax.Joint(ratio=160.0, rated_torque=400.0)
    logs = []
    for k, date in enumerate(DATES[:2]):
        hdjax.save_csv(synthetic_recording(joint, 1500, seed=70 + k), tmp_path / f"{date}.csv")
        logs.append((f"{date}.csv", date))
    return _manifest(tmp_path, "calibrate", {"j": (160.0, 400.0, logs, None)})


def test_fleet_fresh_reruns_tasks_that_finished_before(tmp_path, scheduler, capsys):
    # a finished task's row (OUT/tasks/ID.json, here doctored) is taken as it is by the next
    # run, and computed again with --fresh
    address, pids = scheduler
    manifest, out = str(_two_logs(tmp_path)), tmp_path / "out"

    def run(*flags):
        return main(["fleet", manifest, "--out", str(out), "--scheduler", address, *flags])

    assert run("-q") == 0, capsys.readouterr().err
    first = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["n_samples"] for r in first] == [1500, 1500]
    task = out / "tasks" / f"{first[0]['task_id']}.json"
    row = json.loads(task.read_text())
    row.update(n_samples=1234, twist_rms_arcsec=98.75)
    task.write_text(json.dumps(row))
    capsys.readouterr()

    assert run("--overwrite") == 0
    assert "2 of 2 tasks finished before; skipped" in capsys.readouterr().err
    reused = pq.read_table(out / "results.parquet").to_pylist()
    assert [(r["n_samples"], r["twist_rms_arcsec"]) for r in reused] == [
        (1234, 98.75), (1500, first[1]["twist_rms_arcsec"])
    ]  # fmt: skip

    assert run("--overwrite", "--fresh") == 0
    rerun = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["n_samples"] for r in rerun] == [1500, 1500]
    for r, f in zip(rerun, first):
        assert r["status"] == "ok" and r["worker_pid"] in pids
        np.testing.assert_allclose(r["twist_rms_arcsec"], f["twist_rms_arcsec"], rtol=1e-12)
    assert json.loads(task.read_text())["n_samples"] == 1500  # the task's own file too
    err = capsys.readouterr().err
    assert "finished before" not in err and "2/2 done, 0 running, 0 failed" in err


def test_fleet_pins_the_local_workers_unless_no_pin(tmp_path, scheduler, monkeypatch, capsys):
    # the local cluster is built as asked, then each of its workers bound to a core; not with
    # --no-pin. The cluster and the binding are stood in for (the tasks run on the test's
    # cluster); what the command asks of them is recorded
    from types import SimpleNamespace

    from hdjax.cli import _fleet

    address, pids = scheduler
    clusters, pinned = [], []

    class LocalCluster:
        def __init__(self, **kwargs):
            clusters.append(kwargs)

        def close(self):
            pass

    def client(cluster):
        assert isinstance(cluster, LocalCluster)
        return distributed.Client(address)

    fake = SimpleNamespace(
        LocalCluster=LocalCluster, Client=client, as_completed=distributed.as_completed
    )
    monkeypatch.setattr(_fleet, "dask_distributed", lambda: fake)
    monkeypatch.setattr(_fleet, "_pin", lambda c: pinned.append(c.scheduler.address))
    manifest = str(_two_logs(tmp_path))
    for k, flags in enumerate([[], ["--no-pin"]]):
        out = tmp_path / f"out{k}"
        assert main(["fleet", manifest, "--out", str(out), "--workers", "3", "-q", *flags]) == 0
        rows = pq.read_table(out / "results.parquet").to_pylist()
        assert [r["status"] for r in rows] == ["ok", "ok"]
        assert all(r["worker_pid"] in pids for r in rows)
    # one worker per task (2 tasks, --workers 3), single-threaded processes with WORKER_ENV
    assert [(c["n_workers"], c["threads_per_worker"], c["processes"]) for c in clusters] == [
        (2, 1, True), (2, 1, True)
    ]  # fmt: skip
    assert all(c["env"] == worker_env() for c in clusters)
    # the caller's own XLA flags reach the workers, with the single-thread flag once
    monkeypatch.setenv("XLA_FLAGS", "--xla_backend_optimization_level=0")
    env = worker_env()
    assert env["XLA_FLAGS"].split() == [
        "--xla_backend_optimization_level=0",
        *WORKER_ENV["XLA_FLAGS"].split(),
    ]
    assert {k: v for k, v in env.items() if k != "XLA_FLAGS"} == {
        k: v for k, v in WORKER_ENV.items() if k != "XLA_FLAGS"
    }
    monkeypatch.setenv("XLA_FLAGS", env["XLA_FLAGS"])
    assert worker_env() == env
    assert pinned == [address]  # by default only, not with --no-pin
