"""The benchmarks page's figures, drawn from the snapshot that `run_all.py` writes.

`song2019(result)` draws hdjax's errors next to the paper's as grouped bars, `scale(points)` a
scale benchmark's wall time and peak memory against the samples; `write(snapshot, folder)` saves
every figure the page links (`_page.py` names them) and returns their paths.
"""

from __future__ import annotations

from pathlib import Path

import _page


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def song2019(result: dict):
    """Grouped bars: per experiment, hdjax's and the paper's RMS and maximum error of both
    methods (N·m; the rated torque marked on the maximum's panel)."""
    plt = _plt()
    rows = result["errors_Nm"]
    methods = [m for m in ("model", "network") if any(f"{m} RMS" in r for r in rows)]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
    width = 0.8 / (2 * len(methods))
    colors = {"model": ("tab:blue", "lightsteelblue"), "network": ("tab:orange", "navajowhite")}
    for ax, q in zip(axes, ("RMS", "max")):
        for i, m in enumerate(methods):
            for j, (who, key) in enumerate((("hdjax", f"{m} {q}"), ("paper", f"paper {m} {q}"))):
                x = [k + (2 * i + j - len(methods) + 0.5) * width for k in range(len(rows))]
                y = [r.get(key, float("nan")) for r in rows]
                label = f"{_page._METHOD[m]}, {who}"
                ax.bar(x, y, width, color=colors[m][j], edgecolor=colors[m][0], label=label)
        ax.set_xticks(range(len(rows)), [r["experiment"] for r in rows])
        ax.set_ylabel(f"{q} error [N·m]")
        ax.set_title(f"{q} error of the torque estimate")
        ax.grid(axis="y", alpha=0.3)
    rated = result.get("rated_torque_Nm")
    if rated:
        axes[1].axhline(rated, color="k", lw=0.8, ls="--", label=f"rated torque {rated:g} N·m")
    axes[1].legend(fontsize=7, loc="upper left")
    fig.suptitle("Song et al. (2019), Section IV: hdjax on the simulated joint and the paper")
    return fig


def scale(script: str, points: list[dict]):
    """Wall time and peak resident memory of each series against the number of samples
    (samples on a log axis), from `_page.scale_points`."""
    plt = _plt()
    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(9, 3.4), layout="constrained")
    names = list(dict.fromkeys(s for p in points for s in p["series"]))
    for name in names:
        for ax, k in ((ax_t, 0), (ax_m, 1)):
            xy = [(p["samples"], p["series"][name][k]) for p in points if name in p["series"]]
            xy = [(x, y) for x, y in xy if y is not None]
            if xy:
                ax.plot(*zip(*xy), "o-", label=name)
    for ax, what, unit in ((ax_t, "wall time", "s"), (ax_m, "peak resident memory", "GB")):
        ax.set_xscale("log")
        ax.set_ylim(bottom=0)  # from 0: the load of a shared machine moves times by tens of %
        ax.set_xlabel("samples")
        ax.set_ylabel(f"{what} [{unit}]")
        ax.set_title(what)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(f"{script}: time and memory against samples")
    return fig


def write(snapshot: dict, folder: Path) -> list[Path]:
    """Draw every figure the page of `snapshot` links into `folder`; the paths written."""
    plt = _plt()
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    entry = _page._entry(snapshot, "bench_song2019.py")
    if entry is not None and entry["result"].get("errors_Nm"):
        figs = [(_page.SONG_FIGURE, song2019(entry["result"]))]
    else:
        figs = []
    for script, points in _page.scale_points(snapshot).items():
        figs.append((_page.scale_figure(script), scale(script, points)))
    for name, fig in figs:
        fig.savefig(folder / name, dpi=110)
        plt.close(fig)
        written.append(folder / name)
    return written
