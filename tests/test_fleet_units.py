"""The fleet's pieces without a cluster: a task's one-line error, the drift figure's stiffness
panel and the progress bar's running count."""

import datetime as dt

import numpy as np
import pytest

from hdjax.cli._fleet import _running
from hdjax.fleet import _table, load_manifest, run_task

from .test_cli_broken_inputs import _mcap_bytes


@pytest.mark.parametrize("damage", ["cut", "junk"])
def test_a_damaged_mcap_log_fails_its_task_in_one_line_without_a_class_name(tmp_path, damage):
    data = _mcap_bytes()
    data = data[: len(data) // 2] if damage == "cut" else b"not an MCAP file at all\n" * 4
    (tmp_path / "log.mcap").write_bytes(data)
    (tmp_path / "cell.toml").write_text(
        '[fleet]\nname = "cell"\ntask = "calibrate"\n'
        '[[joints]]\nname = "j"\nratio = 160\nrated_torque = 400\n'
        'logs = [{ path = "log.mcap", date = 2026-01-05 }]\n'
    )
    (task,) = load_manifest(tmp_path / "cell.toml").tasks
    row = run_task(task.spec)
    assert row["status"] == "failed"
    error = row["error"]
    assert error.startswith(str(tmp_path / "log.mcap")) and "not a readable MCAP file" in error
    # the mcap package's exception classes (RecordLengthLimitExceeded, InvalidMagic, ...)
    # never lead the line
    assert "Exceeded:" not in error and "InvalidMagic:" not in error and "\n" not in error


def _row(date: str, coefficients: dict) -> dict:
    return {"status": "ok", "date": date, "coefficients": coefficients, "amplitudes": []}


@pytest.mark.parametrize(
    "segments", [("k3", "k2", "k1", "k4", "k5"), ("k[0]", "k[1]", "k[2]")], ids=["5", "3"]
)
def test_drift_figure_plots_the_segment_stiffnesses_only(monkeypatch, segments):
    # k0 is the twist model's constant (an offset in rad), not a compliance: 1/k0 is no
    # stiffness; every segment's compliance k_j is, whatever the segment count
    figures = []
    monkeypatch.setattr(_table, "png_bytes", lambda fig: figures.append(fig) or b"")
    rng = np.random.default_rng(0)
    dates = ["2026-01-05", "2026-02-02", "2026-03-02"]
    rows = []
    for d in dates:
        coef = {k: float(rng.uniform(5e-6, 1e-5)) for k in segments}
        coef |= {"k0": -3e-4, "w3[seg 0]": 1e-6, "harmonic:theta_m:2:cos": 2e-5}
        rows.append(_row(d, coef))
    _table.drift_figure("j", rows)
    (fig,) = figures
    lines = fig.axes[0].get_lines()
    assert sorted(line.get_label() for line in lines) == sorted(segments)
    for line in lines:
        expected = [1.0 / r["coefficients"][line.get_label()] / 1e3 for r in rows]
        np.testing.assert_allclose(line.get_ydata(), expected, rtol=1e-15)
        assert list(line.get_xdata()) == [dt.date.fromisoformat(d) for d in dates]


class _Future:
    def __init__(self, key, done=False):
        self.key, self._done = key, done

    def done(self):
        return self._done


class _Client:
    """What `_running` asks of a Dask client: the tasks each worker holds (Dask lists queued
    ones beside the one executing) and the workers' threads."""

    def __init__(self, processing, nthreads):
        self._processing, self._nthreads = processing, nthreads

    def processing(self):
        return self._processing

    def nthreads(self):
        return self._nthreads


def test_progress_never_counts_more_running_than_worker_threads():
    futures = [_Future(f"t{i}") for i in range(6)] + [_Future("t6", done=True)]
    # two single-threaded workers, each holding three tasks (one executing, two queued)
    client = _Client({"w1": ("t0", "t1", "t2"), "w2": ("t3", "t4", "t6")}, {"w1": 1, "w2": 1})
    assert _running(client, futures) == 2
    # one task left: one running, whatever the threads
    assert _running(_Client({"w1": ("t0",)}, {"w1": 1, "w2": 1}), futures) == 1
    # a worker with 2 threads runs 2 of its tasks at once
    client = _Client({"w1": ("t0", "t1", "t2"), "w2": ("t3",)}, {"w1": 2, "w2": 1})
    assert _running(client, futures) == 3
