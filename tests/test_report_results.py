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


def test_knee_of_curves_without_a_bend():
    assert find_knee([1, 2, 3, 4], [4.0, 3.0, 2.0, 1.0]) == 3  # still falling: the last
    assert find_knee([1, 2, 3], [1.0, 1.0, 1.0]) == 0  # flat: the cheapest
    assert find_knee([1, 2], [2.0, 1.0]) == 1
    assert find_knee([1, 2], [np.nan, np.inf]) is None  # nothing finite


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


def test_knee_never_marks_a_point_worse_than_a_cheaper_one():
    # a sweep whose error rises from its first value (a Fourier order of 0 is best): the knee
    # is that first value; the chord rule marked order 1, 6 % worse than order 0
    orders = [0, 1, 2, 3, 4]
    rms = [4.787, 5.065, 5.2, 5.9, 6.4]
    assert find_knee(orders, rms) == 0
    # on any curve, no point cheaper than the knee is better, and the knee is within the
    # stated 5 % of the best
    rng = np.random.default_rng(0)  # seed 0, fixed
    for _ in range(200):
        y = rng.uniform(1.0, 10.0, size=7)
        k = find_knee(range(7), y)
        assert all(y[j] > y[k] for j in range(k)) and y[k] <= 1.05 * y.min()


def _texts_inside(fig, ax):
    """Every text artist of `ax` lies inside the axes' box, and the title inside the figure."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = ax.get_window_extent(renderer)
    for t in ax.texts:
        tb = t.get_window_extent(renderer)
        assert box.x0 <= tb.x0 and tb.x1 <= box.x1 and box.y0 <= tb.y0 and tb.y1 <= box.y1, t
    title = ax.title.get_window_extent(renderer)
    assert 0 <= title.x0 and title.x1 <= fig.bbox.width, ax.get_title()


def test_error_rate_figure_with_one_method():
    import matplotlib.pyplot as plt

    from hdjax.report import error_rate_title
    from hdjax.report._figures import _error_rate

    m = {"synthetic": {"max_pct": 2.2, "rms_pct": 0.42}}
    fig = _error_rate({"model": m, "network": None}, paper=None, rated=400.0)
    (ax,) = fig.axes
    # the network was not run: no "n/a" mark, the title names the one method shown
    assert not ax.texts and "both" not in ax.get_title()
    assert ax.get_title() == error_rate_title({"model": m, "network": None})
    assert "model-based" in ax.get_title() and "network" not in ax.get_title()
    _texts_inside(fig, ax)
    # a bar, not half the frame: at most 0.3 of the axis span on a single scenario
    lo, hi = ax.get_xlim()
    assert max(p.get_width() for p in ax.patches) <= 0.3 * (hi - lo)
    # a log axis over the data's decades, without a 0 tick
    assert ax.get_yscale() == "log"
    ymin, ymax = ax.get_ylim()
    assert 0 < ymin <= 0.42 and 2.2 < ymax <= 100
    fig.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels() if ymin <= t.get_position()[1] <= ymax]
    assert labels and "0" not in labels
    plt.close(fig)
    both = {"model": m, "network": m}
    assert "model-based and BP network" in error_rate_title(both)


def test_sweep_figure_integer_ticks_and_fit_time_from_zero():
    import matplotlib.pyplot as plt

    from hdjax.report._figures import _sweep

    fig = _sweep([0, 1, 2, 3], [4.787, 5.065, 5.2, 5.9], [0.147, 0.1505, 0.149, 0.148],
                 setting="model.fourier_order", knee=0, metric="RMS")  # fmt: skip
    ax, ax2 = fig.axes
    fig.canvas.draw()
    ticks = [t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
    assert ticks and all(float(t).is_integer() for t in ticks)
    assert ax2.get_ylim()[0] == 0.0  # 0.147-0.1505 s is noise, drawn as such
    assert ax.get_title()
    plt.close(fig)
