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
    """Error rate in % of rated torque, the methods side by side (as Song et al. Fig. 17).

    **Arguments:**

    - `metrics`: method -> scenario -> metrics dict (`max_pct`, `rms_pct`); a method whose
      value is `None` (not run) is left out of the figure.
    - `paper`: method -> scenario -> (max, RMS) [N·m] of the paper, drawn as markers.
    - `rated`: rated torque [N·m] (for the paper's values in %).

    **Returns:** PNG bytes.
    """
    return _png(_error_rate(metrics, paper=paper, rated=rated))


def error_rate_title(metrics: dict) -> str:
    """The title of [`hdjax.report.error_rate_figure`][] for `metrics`: the methods it shows."""
    shown = [_METHOD_NAME.get(m, m) for m, v in metrics.items() if v is not None]
    what = " and ".join(shown) if len(shown) <= 2 else ", ".join(shown)
    return f"Error rate, {what or 'no method'} (cf. Song et al. Fig. 17)"


_METHOD_NAME = {"model": "model-based", "network": "BP network"}


def _error_rate(metrics: dict, *, paper: dict | None, rated: float):
    from matplotlib.ticker import FuncFormatter

    plt = _plt()
    methods = [m for m in metrics if metrics[m] is not None]
    scenarios = []
    for m in methods:
        for s in metrics[m]:
            if s not in scenarios:
                scenarios.append(s)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    # a bar is at most 0.35 of a scenario's slot, so one method on one scenario stays a bar
    width = min(0.35, 0.8 / max(1, len(methods)))
    colors = {"model": "tab:blue", "network": "tab:orange"}
    x = np.arange(len(scenarios))
    shown = []
    for i, m in enumerate(methods):
        pos = x + width * (i - (len(methods) - 1) / 2)
        vals = metrics[m]
        color = colors.get(m, f"C{i}")
        mx = [vals[s]["max_pct"] if s in vals else np.nan for s in scenarios]
        rms = [vals[s]["rms_pct"] if s in vals else np.nan for s in scenarios]
        name = _METHOD_NAME.get(m, m)
        ax.bar(pos, mx, width * 0.9, color=color, alpha=0.45, label=f"{name}: max")
        ax.bar(pos, rms, width * 0.9, color=color, alpha=1.0, label=f"{name}: RMS")
        shown += mx + rms
        if paper and m in paper:
            pm = [100 * paper[m][s][0] / rated if s in paper[m] else np.nan for s in scenarios]
            pr = [100 * paper[m][s][1] / rated if s in paper[m] else np.nan for s in scenarios]
            ax.plot(pos, pm, "v", color="black", ms=6, label="paper: max" if i == 0 else None)
            ax.plot(
                pos, pr, "_", color="black", ms=12, mew=2, label="paper: RMS" if i == 0 else None
            )
            shown += pm + pr
    ax.set_xticks(x)
    ax.set_xticklabels(scenarios)
    ax.set_xlim(-0.6, len(scenarios) - 0.4)
    ax.set_ylabel("error [% of rated torque]")
    ax.set_title(error_rate_title(metrics), fontsize=10)
    # a log axis over the drawn values' decades (an error rate of 0 is not drawn)
    positive = [v for v in shown if np.isfinite(v) and v > 0]
    ax.set_yscale("log")
    if positive:
        lo = 10 ** np.floor(np.log10(min(positive)))
        hi = 10 ** np.ceil(np.log10(max(positive) * 1.5))
        ax.set_ylim(lo, hi)
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.grid(alpha=0.3, axis="y")
    if methods:
        ax.legend(fontsize=7, ncol=2, loc="upper left")
    fig.tight_layout()
    return fig


KNEE_TOLERANCE = 0.05
KNEE_RULE = (
    "the cheapest value (the smallest, or the first listed) whose held-out error is within "
    f"{KNEE_TOLERANCE:.0%} of the smallest held-out error"
)


def find_knee(
    x: Real[ArrayLike, " n"] | Sequence[float],
    y: Real[ArrayLike, " n"] | Sequence[float],
    *,
    tolerance: float = KNEE_TOLERANCE,
) -> int | None:
    """Index of the knee of a sweep: the cheapest setting whose error is close to the best.

    The knee is the point of smallest `x` (the cheapest setting) whose `y` is at most
    `(1 + tolerance)` times the smallest `y`. Every point cheaper than the knee is therefore
    worse than it by more than `tolerance`, and no point more than `tolerance` worse than the
    best is marked: a curve whose error rises from its first point has its knee there.

    **Arguments:** `x`, the swept setting (its order is the cost); `y`, the error at each;
    `tolerance`, the relative error above the best that still counts as good enough
    (default 5 %). Non-finite points are skipped.

    **Returns:** the index into `x`, or `None` when no point is finite.
    """
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    idx = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    if idx.size == 0:
        return None
    best = float(np.min(y[idx]))
    good = idx[y[idx] <= best + tolerance * abs(best)]
    return int(good[np.argmin(x[good])])


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

    **Arguments:** `values`, the swept setting's values (integer settings get integer ticks);
    `error` and `seconds` at each; `setting`, its name; `knee`, the index to mark (see
    [`hdjax.report.find_knee`][]) or `None`; `metric`, the error's name ("RMS").

    **Returns:** PNG bytes.
    """
    return _png(_sweep(values, error, seconds, setting=setting, knee=knee, metric=metric))


def _sweep(values, error, seconds, *, setting, knee, metric):
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
    integer = numeric and all(float(v).is_integer() for v in values)
    if not numeric or (integer and len(values) <= 15):
        ax.set_xticks(x)
        ax.set_xticklabels(labels)
    elif integer:
        from matplotlib.ticker import MaxNLocator

        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax2 = ax.twinx()
    secs = np.asarray(seconds, np.float64)
    ax2.plot(x, secs, "s--", color="tab:gray", label="fit time")
    ax2.set_ylabel("fit time [s]")
    # from 0, so timing noise of a few per cent does not look like a trend
    finite = secs[np.isfinite(secs)]
    ax2.set_ylim(0.0, 1.15 * float(finite.max()) if finite.size and finite.max() > 0 else 1.0)
    if knee is not None:
        ax.axvline(x[knee], color="tab:red", ls=":", lw=1.5)
        ax.plot([x[knee]], [err[knee]], "o", ms=12, mfc="none", mec="tab:red", mew=2)
        ax.annotate(
            f"knee: {labels[knee]} (within {KNEE_TOLERANCE:.0%} of the best)",
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
    return fig
