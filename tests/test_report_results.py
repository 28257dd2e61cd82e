"""Figures, the knee rule and atomically written result directories."""

import numpy as np
import pytest

from hdjax import ConfigError
from hdjax.report import (
    ResultDir,
    error_rate_figure,
    find_knee,
    markdown_table,
    sweep_figure,
    torque_figure,
)

PNG = b"\x89PNG\r\n\x1a\n"


def test_knee_of_an_l_shaped_curve():
    # normalised: x = i/7, y = (y-1)/8 -> chord minus curve is 0, .357, .714, .571, ... -> i = 2
    assert find_knee(range(1, 9), [9, 5, 1, 1, 1, 1, 1, 1]) == 2
    # order of the points does not matter; non-finite points are skipped
    assert find_knee([3, 1, 2, 4, 5], [1.0, 9.0, 5.0, np.nan, 1.0]) == 0


def test_no_knee_without_a_bend():
    assert find_knee([1, 2, 3, 4], [4.0, 3.0, 2.0, 1.0]) is None  # straight line
    assert find_knee([1, 2, 3], [1.0, 1.0, 1.0]) is None  # flat
    assert find_knee([1, 2], [2.0, 1.0]) is None  # too few points


def test_figures_are_png():
    t = np.linspace(0, 1, 5000)
    meas = 100 * np.sin(6 * t)
    est = meas + np.where(np.arange(5000) == 1234, 50.0, 0.1)
    assert torque_figure(t, meas, est, title="x", rated=400.0).startswith(PNG)
    m = {"slow": {"max_pct": 5.0, "rms_pct": 1.0}, "fast": {"max_pct": 9.0, "rms_pct": 2.0}}
    paper = {"model": {"slow": (84.8, 42.3), "fast": (400.0, 67.06)}}
    assert error_rate_figure({"model": m, "network": None}, paper=paper, rated=400.0).startswith(
        PNG
    )
    png = sweep_figure(
        [1, 2, 3], [3.0, 1.0, 0.9], [0.1, 0.2, 0.3], setting="s", knee=1, metric="RMS"
    )
    assert png.startswith(PNG)


def test_result_dir_commits_only_when_complete(tmp_path):
    out = tmp_path / "res"
    with pytest.raises(RuntimeError):
        with ResultDir(out) as rd:
            rd.write_json("metrics.json", {"a": 1.0})
            raise RuntimeError("crash in the middle")
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no staging directory left behind
    with ResultDir(out) as rd:
        rd.write_json("metrics.json", {"a": float("nan")})
    assert (out / "metrics.json").read_text().strip().endswith("}")
    assert '"a": null' in (out / "metrics.json").read_text()


def test_result_dir_refuses_existing_unless_overwrite(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    (out / "old.txt").write_text("old")
    with pytest.raises(ConfigError, match="already exists; .*--overwrite"):
        ResultDir(out)
    with ResultDir(out, overwrite=True) as rd:
        rd.write_text("new.txt", "new")
    assert sorted(p.name for p in out.iterdir()) == ["new.txt"]


def test_markdown_table():
    text = markdown_table(["a", "b"], [[1.23456, None], ["x", float("nan")]])
    assert text.splitlines() == ["| a | b |", "|---|---|", "| 1.235 | n/a |", "| x | n/a |"]
