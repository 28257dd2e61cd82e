"""The fleet's results: one Parquet table (a row per joint-log) and a drift plot per joint."""

from __future__ import annotations

import datetime as dt

import numpy as np

from .._formats import require
from .._io import atomic_write_bytes
from .._plotting import png_bytes, pyplot
from ..compliance.internal import is_segment_name

FIXED = (
    ("task_id", "string"),
    ("joint", "string"),
    ("log", "string"),
    ("date", "string"),
    ("task", "string"),
    ("status", "string"),
    ("error", "string"),
    ("seconds", "float64"),
    ("worker_pid", "int64"),
    ("n_samples", "int64"),
    ("twist_rms_arcsec", "float64"),
    ("condition", "float64"),
    ("baseline_test_rms_Nm", "float64"),
    ("test_rms_Nm", "float64"),
    ("test_max_Nm", "float64"),
    ("in_range_pct", "float64"),
)


def _schema(coef_names):
    pa = require("pyarrow", "fleet")
    fields = [(name, getattr(pa, kind)()) for name, kind in FIXED]
    amp = pa.struct(
        [
            ("effect", pa.string()),
            ("amplitude_arcsec", pa.float64()),
            ("low", pa.float64()),
            ("high", pa.float64()),
            ("amplitude_Nm", pa.float64()),
            ("low_Nm", pa.float64()),
            ("high_Nm", pa.float64()),
            ("cv_gain", pa.float64()),
        ]
    )
    fields += [
        ("effects", pa.list_(pa.string())),
        ("amplitudes", pa.list_(amp)),
        ("warnings", pa.list_(pa.string())),
    ]
    fields += [(f"coef:{n}", pa.float64()) for n in coef_names]
    return pa.schema(fields)


def table_bytes(rows: list[dict]) -> bytes:
    """The rows as a Parquet file's bytes: fixed columns, then one `coef:NAME` column per
    coefficient any row has (null where a joint's model lacks it)."""
    pa = require("pyarrow", "fleet")
    import pyarrow.parquet as pq

    names = sorted({n for r in rows for n in (r.get("coefficients") or {})})
    schema = _schema(names)
    flat = []
    for r in rows:
        d = {name: r.get(name) for name, _ in FIXED}
        d["effects"] = list(r.get("effects") or [])
        d["amplitudes"] = list(r.get("amplitudes") or [])
        d["warnings"] = list(r.get("warnings") or [])
        coef = r.get("coefficients") or {}
        d.update({f"coef:{n}": coef.get(n) for n in names})
        flat.append(d)
    table = pa.Table.from_pylist(flat, schema=schema)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    return sink.getvalue().to_pybytes()


def write_table(rows: list[dict], path) -> None:
    """Write the rows as one Parquet table, atomically: the fixed columns, then one
    `coef:NAME` column per coefficient any row has (null where a joint's model lacks it)."""
    atomic_write_bytes(path, table_bytes(rows))


def _date(s: str):
    try:
        return dt.date.fromisoformat(s[:10])
    except ValueError:
        return None


def drift_figure(joint: str, rows: list[dict]) -> bytes:
    """How one joint's calibration moves over its logs' dates: the stiffness of each torque
    segment ($1/k_j$, Song et al. eq. (7)), the amplitude of each effect the residual loop
    added (with its 95 % interval), and the errors. Failed tasks are left out."""
    ok = sorted(
        (r for r in rows if r.get("status") == "ok" and _date(r["date"])),
        key=lambda r: r["date"],
    )
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 8.0), sharex=True)
    dates = [_date(r["date"]) for r in ok]
    k_names = sorted({n for r in ok for n in r.get("coefficients", {}) if is_segment_name(n)})
    for n in k_names:
        y = [1.0 / r["coefficients"][n] if r["coefficients"].get(n) else np.nan for r in ok]
        axes[0].plot(dates, np.asarray(y) / 1e3, "o-", label=n)
    axes[0].set_ylabel("segment stiffness [kN·m/rad]")
    if k_names:
        axes[0].legend(fontsize=7, ncol=min(5, len(k_names)))
    effects = sorted({a["effect"] for r in ok for a in r.get("amplitudes") or []})
    for e in effects:
        xs, ys, lo, hi = [], [], [], []
        for d, r in zip(dates, ok):
            for a in r.get("amplitudes") or []:
                amp = a.get("amplitude_arcsec")
                if a["effect"] == e and amp is not None:
                    xs.append(d)
                    ys.append(amp)
                    low, high = a.get("low"), a.get("high")
                    lo.append(0.0 if low is None else max(0.0, amp - low))
                    hi.append(0.0 if high is None else max(0.0, high - amp))
        axes[1].errorbar(xs, ys, yerr=[lo, hi], fmt="s-", capsize=3, label=e)
    axes[1].set_ylabel("effect amplitude [arcsec]")
    if effects:
        axes[1].legend(fontsize=7)
    else:
        axes[1].text(0.5, 0.5, "no effects added", ha="center", transform=axes[1].transAxes)
    for key, label in (
        ("twist_rms_arcsec", "twist residual [arcsec RMS]"),
        ("test_rms_Nm", "TEST torque error [N·m RMS]"),
    ):
        y = [r.get(key) if r.get(key) is not None else np.nan for r in ok]
        if np.isfinite(np.asarray(y, float)).any():
            axes[2].plot(dates, y, "o-", label=label)
    axes[2].set_ylabel("error")
    if axes[2].get_lines():
        axes[2].legend(fontsize=7)
    axes[2].set_xlabel("log date")
    n_failed = sum(r.get("status") != "ok" for r in rows)
    note = f" ({n_failed} failed task(s) left out)" if n_failed else ""
    fig.suptitle(f"drift of joint {joint}{note}")
    fig.autofmt_xdate()
    return png_bytes(fig)
