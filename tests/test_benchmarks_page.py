"""The benchmarks page: its first lines say what is met and name what is not, every target of
the snapshot is described, the Song 2019 chart and the scale plots are drawn from the snapshot,
and the raw JSON sits in collapsed sections."""

import copy
import json
import sys

import pytest

from .conftest import REPO

sys.path.insert(0, str(REPO / "benchmarks"))
import _figures  # noqa: E402
import _page  # noqa: E402


@pytest.fixture(scope="module")
def snapshot():
    return json.loads((REPO / _page.SNAPSHOT).read_text())


def test_every_target_of_the_snapshot_is_described(snapshot):
    rows = _page.targets(snapshot)
    assert len(rows) >= 20
    for r in rows:
        assert not r["what"].startswith("`") or r["result"], r  # not the bare key fallback
        for text in (r["what"], r["result"], r["target"]):
            assert "?" not in text and "{" not in text, r


def _first_screen(page: str) -> str:
    """The page above its first table: what a reader sees first (a screen: at most 25 lines)."""
    lines = page.splitlines()
    head = lines[: next(i for i, line in enumerate(lines) if line.startswith("|"))]
    assert len(head) <= 25, len(head)
    return "\n".join(head)


def test_first_lines_name_each_missed_target(snapshot):
    page = _page.render(snapshot)
    first = _first_screen(page)
    rows = _page.targets(snapshot)
    missed = [r for r in rows if r["met"] is False]
    met = sum(bool(r["met"]) for r in rows)
    assert f"**{met} of {len(rows)} targets met.**" in first
    for r in missed:
        assert r["what"] in first and r["result"] in first and r["target"] in first
    # a target that a run misses is named there at once
    s = copy.deepcopy(snapshot)
    (entry,) = [e for e in s["benchmarks"] if e["script"].endswith("bench_sweep.py")]
    entry["result"]["target_met"] = False
    first = _first_screen(_page.render(s))
    assert "Not met:" in first and "sweep of 8 polynomial orders against one fit" in first
    # and with every target met, nothing is listed as missed
    for e in s["benchmarks"]:
        for path, _ in _page._flags(e.get("result", {})):
            *head, last = path.split("/")
            d = e["result"]
            for k in head:
                d = d[k]
            d[last] = True
    assert "Not met" not in _page.render(s)


def test_song_chart_and_outliers_come_from_the_snapshot(snapshot):
    entry = _page._entry(snapshot, "bench_song2019.py")
    result = entry["result"]
    fig = _figures.song2019(result)
    rms_axis, max_axis = fig.axes[:2]
    heights = sorted(round(p.get_height(), 9) for p in rms_axis.patches)
    rows = result["errors_Nm"]
    expected = sorted(round(r[k], 9) for r in rows for k in r if k.endswith("RMS"))
    assert heights == expected
    assert all(ax.get_title() for ax in fig.axes[:2])
    rated_line = [ln for ln in max_axis.get_lines() if "rated" in ln.get_label()]
    assert rated_line and rated_line[0].get_ydata()[0] == result["rated_torque_Nm"]
    # every maximum above the rated torque has its sentence, with the run's numbers
    sentences = " ".join(_page.song_outliers(result))
    rated = result["rated_torque_Nm"]
    for r in rows:
        for m in ("model", "network"):
            if r.get(f"{m} max", 0) > rated:
                assert f"{_page._fmt(r[f'{m} max'])} N·m" in sentences
                assert f"above the rated {_page._fmt(rated)} N·m" in sentences


def test_figures_linked_exist_and_json_is_collapsed(snapshot):
    page = _page.render(snapshot)
    assert f"benchmarks/{_page.SONG_FIGURE}" in page
    points = _page.scale_points(snapshot)
    assert "bench_discover_long.py" in points and "bench_stream_parquet.py" in points
    for script, pts in points.items():
        assert f"benchmarks/{_page.scale_figure(script)}" in page
        assert len(pts) >= 2
        fig = _figures.scale(script, pts)
        t_axis = fig.axes[0]
        xs = sorted(x for line in t_axis.get_lines() for x in line.get_xdata())
        assert xs[0] == min(p["samples"] for p in pts)
    for name in [_page.SONG_FIGURE] + [_page.scale_figure(s) for s in points]:
        assert (REPO / _page.FIGURES / name).is_file(), name
    ok = [e for e in snapshot["benchmarks"] if not e.get("error")]
    assert page.count('<details markdown="1">') == len(ok)
    assert "| `batch_estimation.ns_per_estimate` |" not in page  # no key/value dump
