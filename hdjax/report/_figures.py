"""Figures of a run: estimated against measured torque (Song et al. Figs. 9-16), the error-rate
comparison (Fig. 17), and a sweep's held-out error and compute time with the knee marked.

matplotlib is imported lazily (Agg backend), so `import hdjax` stays light.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._custom_types import ArrayLike, Real
from .._plotting import png_bytes, pyplot

_METHOD_LABEL = {"model": "model-based (eqs. 7-10, 26-27)", "network": "BP network (eqs. 36-46)"}


_plt = pyplot


_png = png_bytes


def _envelope(err, limit: int = 6000):
    """Indices to plot: per chunk of samples the first one and the one of largest |error|, so
    a decimated plot keeps every spike."""
    n = err.size
    step = max(1, -(-2 * n // limit))
    if step == 1:
        return np.arange(n)
    starts = np.arange(0, n, step)
    peaks = [s + int(np.argmax(np.abs(err[s : s + step]))) for s in starts]
    return np.unique(np.concatenate([starts, peaks]))


def torque_figure(
    t: Real[ArrayLike, " n"],
    measured: Real[ArrayLike, " n"],
    estimated: Real[ArrayLike, " n"],
    *,
    title: str,
    rated: float | None = None,
    errors: tuple[float, float] | None = None,
) -> bytes:
    """Estimated against measured torque with the error below (as Song et al. Figs. 9-16).

    **Arguments:** `t` [s], `measured` and `estimated` torque [N·m]; `title`; `rated` torque
    [N·m] for a secondary error axis in % of rated torque; `errors`, the `(rms, max)` error
    over every sample when the arrays are already decimated (a streamed run).

    **Returns:** PNG bytes.
    """
    plt = _plt()
    t = np.asarray(t)
    meas = np.asarray(measured)
    est = np.asarray(estimated)
    err = est - meas
    s = _envelope(err)
    fig, (ax1, ax2) = plt.subplots(
        2, 1, figsize=(7.5, 4.8), sharex=True, gridspec_kw={"height_ratios": [2.2, 1]}
    )
    ax1.plot(t[s], meas[s], color="black", lw=1.2, label="measured (torque sensor)")
    ax1.plot(t[s], est[s], color="tab:red", lw=0.9, alpha=0.85, label="estimated")
    ax1.set_ylabel("torque [N·m]")
    ax1.legend(loc="best", fontsize=8)
    ax1.set_title(title, fontsize=10)
    ax1.grid(alpha=0.3)
    ax2.plot(t[s], err[s], color="tab:blue", lw=0.8)
    ax2.axhline(0.0, color="gray", lw=0.6)
    rms, mx = float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err)))
    if errors is not None:
        rms, mx = (float(v) for v in errors)
    ax2.set_ylabel("error [N·m]")
    ax2.set_xlabel("time [s]")
    ax2.grid(alpha=0.3)
    ax2.text(
        0.01,
        0.95,
        f"RMS {rms:.3g} N·m, max {mx:.3g} N·m",
        transform=ax2.transAxes,
        va="top",
        fontsize=8,
    )
    if rated:
        sec = ax2.secondary_yaxis(
            "right", functions=(lambda e: 100 * e / rated, lambda p: p * rated / 100)
        )
        sec.set_ylabel("% of rated")
    fig.tight_layout()
    return _png(fig)


def error_rate_figure(metrics: dict, *, paper: dict | None = None, rated: float) -> bytes:
    """Error rate in % of rated torque, both methods side by side (as Song et al. Fig. 17).

    **Arguments:**

    - `metrics`: method -> scenario -> metrics dict (`max_pct`, `rms_pct`); a method whose
      value is `None` is drawn as "not available".
    - `paper`: method -> scenario -> (max, RMS) [N·m] of the paper, drawn as markers.
    - `rated`: rated torque [N·m] (for the paper's values in %).

    **Returns:** PNG bytes.
    """
    plt = _plt()
    methods = list(metrics)
    scenarios = []
    for m in methods:
        for s in metrics[m] or {}:
            if s not in scenarios:
                scenarios.append(s)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    width = 0.8 / max(1, len(methods))
    colors = {"model": "tab:blue", "network": "tab:orange"}
    x = np.arange(len(scenarios))
    for i, m in enumerate(methods):
        pos = x - 0.4 + width * (i + 0.5)
        vals = metrics[m]
        color = colors.get(m, f"C{i}")
        if vals is None:
            for p in pos:
                ax.text(p, 0.5, "n/a", ha="center", fontsize=8, rotation=90)
            continue
        mx = [vals[s]["max_pct"] if s in vals else np.nan for s in scenarios]
        rms = [vals[s]["rms_pct"] if s in vals else np.nan for s in scenarios]
        ax.bar(pos, mx, width * 0.9, color=color, alpha=0.45, label=f"{m}: max")
        ax.bar(pos, rms, width * 0.9, color=color, alpha=1.0, label=f"{m}: RMS")
        if paper and m in paper:
            pm = [100 * paper[m][s][0] / rated if s in paper[m] else np.nan for s in scenarios]
            pr = [100 * paper[m][s][1] / rated if s in paper[m] else np.nan for s in scenarios]
            ax.plot(pos, pm, "v", color="black", ms=6, label="paper: max" if i == 0 else None)
            ax.plot(
                pos, pr, "_", color="black", ms=12, mew=2, label="paper: RMS" if i == 0 else None
            )
    ax.set_xticks(x)
    ax.set_xticklabels(scenarios)
    ax.set_ylabel("error [% of rated torque]")
    ax.set_title("Error rate, both methods (cf. Song et al. Fig. 17)", fontsize=10)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return _png(fig)


def find_knee(
    x: Real[ArrayLike, " n"] | Sequence[float], y: Real[ArrayLike, " n"] | Sequence[float]
) -> int | None:
    """Index of the knee of a decreasing error curve (largest distance below the chord).

    Both axes are scaled to [0, 1]; the knee is the point farthest below the straight line from
    the first to the last point (the "Kneedle" rule of Satopää et al. 2011). `None` for fewer
    than three finite points or a curve that does not bend below its chord.
    """
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    ok = np.isfinite(x) & np.isfinite(y)
    idx = np.flatnonzero(ok)
    if idx.size < 3:
        return None
    xs, ys = x[idx], y[idx]
    order = np.argsort(xs)
    xs, ys, idx = xs[order], ys[order], idx[order]
    xr = (xs - xs[0]) / (xs[-1] - xs[0]) if xs[-1] > xs[0] else np.zeros_like(xs)
    span = ys.max() - ys.min()
    if span <= 0:
        return None
    yr = (ys - ys.min()) / span
    chord = yr[0] + (yr[-1] - yr[0]) * xr
    below = chord - yr
    k = int(np.argmax(below))
    return int(idx[k]) if below[k] > 1e-12 else None


def sweep_figure(
    values: Sequence[Any],
    error: Real[ArrayLike, " n"] | Sequence[float],
    seconds: Real[ArrayLike, " n"] | Sequence[float],
    *,
    setting: str,
    knee: int | None,
    metric: str,
) -> bytes:
    """Held-out error and compute time against a swept setting, with the knee marked.

    **Returns:** PNG bytes.
    """
    plt = _plt()
    labels = [str(v) for v in values]
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
    x = np.asarray(values, np.float64) if numeric else np.arange(len(values), dtype=np.float64)
    fig, ax = plt.subplots(figsize=(7.0, 4.0))
    err = np.asarray(error, np.float64)
    ax.plot(x, err, "o-", color="tab:blue", label=f"held-out {metric}")
    ax.set_xlabel(setting)
    ax.set_ylabel(f"held-out torque {metric} [N·m]")
    if np.all(err[np.isfinite(err)] > 0) and np.nanmax(err) / max(np.nanmin(err), 1e-300) > 30:
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    if not numeric:
        ax.set_xticks(x)
        ax.set_xticklabels(labels)
    ax2 = ax.twinx()
    ax2.plot(x, np.asarray(seconds, np.float64), "s--", color="tab:gray", label="fit time")
    ax2.set_ylabel("fit time [s]")
    if knee is not None:
        ax.axvline(x[knee], color="tab:red", ls=":", lw=1.5)
        ax.plot([x[knee]], [err[knee]], "o", ms=12, mfc="none", mec="tab:red", mew=2)
        ax.annotate(
            f"knee: {labels[knee]}",
            (x[knee], err[knee]),
            textcoords="offset points",
            xytext=(10, 12),
            color="tab:red",
        )
    ax.set_title(f"Sweep over {setting}", fontsize=10)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper right")
    fig.tight_layout()
    return _png(fig)
