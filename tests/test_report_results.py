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
    from .helpers import assert_figure, png_image

    t = np.linspace(0, 1, 5000)
    meas = 100 * np.sin(6 * t)
    est = meas + np.where(np.arange(5000) == 1234, 50.0, 0.1)
    png = torque_figure(t, meas, est, title="x", rated=400.0)
    assert png.startswith(PNG)
    assert_figure(png, (825, 528))  # 7.5 x 4.8 in at 110 dpi
    m = {"slow": {"max_pct": 5.0, "rms_pct": 1.0}, "fast": {"max_pct": 9.0, "rms_pct": 2.0}}
    paper = {"model": {"slow": (84.8, 42.3), "fast": (400.0, 67.06)}}
    png = error_rate_figure({"model": m, "network": None}, paper=paper, rated=400.0)
    assert_figure(png, (825, 462))
    png = sweep_figure(
        [1, 2, 3], [3.0, 1.0, 0.9], [0.1, 0.2, 0.3], setting="s", knee=1, metric="RMS"
    )
    assert_figure(png, (770, 440))
    # and the check itself refuses a blank canvas of the right size
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(7.0, 4.0))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    assert png_image(buf.getvalue()).shape[:2] == (440, 770)
    with pytest.raises(AssertionError, match="pixels are drawn|colours"):
        assert_figure(buf.getvalue(), (770, 440))


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
    with ResultDir(out) as rd:
        rd.write_text("old.txt", "old")
    with pytest.raises(ConfigError, match="already exists here; .*--overwrite"):
        ResultDir(out)
    with ResultDir(out, overwrite=True) as rd:
        rd.write_text("new.txt", "new")
    assert sorted(p.name for p in out.iterdir()) == [".hdjax-result", "new.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]  # no .old or staging left


def test_result_dir_replaces_only_what_hdjax_wrote(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    for overwrite in (False, True):
        with pytest.raises(ConfigError, match=r"not an hdjax result folder \(it holds thesis"):
            ResultDir(mine, overwrite=overwrite)
    assert (mine / "thesis.tex").read_text() == "years of work"
    out = tmp_path / "res"
    with ResultDir(out) as rd:
        rd.write_text("a.txt", "a")
    (out / "notes.txt").write_text("added by the user")
    with pytest.raises(ConfigError, match=r"holds files hdjax did not write \(notes.txt\)"):
        ResultDir(out, overwrite=True)
    # an empty folder is used as if it were absent
    empty = tmp_path / "empty"
    empty.mkdir()
    with ResultDir(empty) as rd:
        rd.write_text("a.txt", "a")
    assert (empty / "a.txt").read_text() == "a"


def test_result_dir_never_replaces_an_input_or_the_current_directory(tmp_path, monkeypatch):
    data = tmp_path / "proj" / "data.csv"
    data.parent.mkdir()
    data.write_text("t\n0\n")
    with pytest.raises(ConfigError, match="holds the input"):
        ResultDir(tmp_path / "proj", overwrite=True, inputs=[data])
    with pytest.raises(ConfigError, match="is also an input"):
        ResultDir(data, overwrite=True, inputs=[data])
    with pytest.raises(ConfigError, match="lies inside the input"):
        ResultDir(tmp_path / "proj" / "sub", inputs=[tmp_path / "proj"])
    monkeypatch.chdir(tmp_path / "proj")
    for out in (".", str(tmp_path)):
        with pytest.raises(ConfigError, match="current directory"):
            ResultDir(out, overwrite=True)
    with pytest.raises(ConfigError, match="is a file, not a folder"):
        ResultDir(data / "out")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["data.csv", "proj"]


def test_result_files_follow_the_umask(tmp_path):
    import os

    old = os.umask(0o022)
    try:
        with ResultDir(tmp_path / "r") as rd:
            rd.write_text("figures/a.txt", "a")
    finally:
        os.umask(old)
    assert (tmp_path / "r").stat().st_mode & 0o777 == 0o755
    assert (tmp_path / "r" / "figures").stat().st_mode & 0o777 == 0o755
    assert (tmp_path / "r" / "figures" / "a.txt").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "r" / ".hdjax-result").stat().st_mode & 0o777 == 0o644


def test_markdown_table():
    text = markdown_table(["a", "b"], [[1.23456, None], ["x", float("nan")]])
    assert text.splitlines() == ["| a | b |", "|---|---|", "| 1.235 | n/a |", "| x | n/a |"]
