"""The tables of docs/export.md, rendered from the benchmark snapshot (never typed by hand).

`python benchmarks/run_all.py --only bench_export.py` measures them and writes the snapshot
(docs/benchmarks/results.json); each docs build replaces the markers below with these tables.
"""

from __future__ import annotations

import json
from pathlib import Path

SNAPSHOT = Path(__file__).resolve().parents[1] / "benchmarks" / "results.json"
STEP_MARKER = "<!-- generated: export step -->"
CAUSALITY_MARKER = "<!-- generated: export causality -->"


def _result() -> dict | None:
    try:
        snapshot = json.loads(SNAPSHOT.read_text())
    except (OSError, ValueError):
        return None
    for entry in snapshot.get("benchmarks", []):
        if entry["script"].endswith("bench_export.py") and "result" in entry:
            return {**entry["result"], "_when": entry.get("date", ""), "_args": entry["args"]}
    return None


def _missing() -> str:
    return "*Not measured yet: run `python benchmarks/run_all.py --only bench_export.py`.*\n"


def _g(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


def step_table() -> str:
    """C step time and agreement with the JAX estimate, per model and precision."""
    r = _result()
    if r is None:
        return _missing()
    rows = [
        "| model | precision | ns per step | largest difference from JAX [N·m] | "
        "% of rated torque |",
        "|---|---|---|---|---|",
    ]
    for key, label in (
        ("paper_model_step", "the paper's (5 segments, per-segment terms, kinematic order 3)"),
        ("every_effect_model_step", "a term of every effect family"),
        ("network_step", "network (6 inputs, 20 neurons, Kalman-filtered current)"),
    ):
        for c in r[key]["c"]:
            rows.append(
                f"| {label} | {c['precision']} | {c['ns_per_step']:.0f} | "
                f"{_g(c['max_abs_error_vs_jax_Nm'])} | {_g(c['max_error_pct_of_rated'])} |"
            )
    p = r["paper_model_step"]
    e = r["export_command"]
    lines = [
        "\n".join(rows),
        "",
        f"Measured {r['_when']} on {r['cpu_count']} CPUs (load average "
        f"{', '.join(str(x) for x in r['load_average_1_5_15'])}), compiled with "
        f"`{r['compiler']['flags']}` ({r['compiler']['version']}), one `hdjax_batch` call over "
        "10^6 samples, the best of 5. The JAX one-sample call of the same model from Python "
        f"(`estimate_torque_single`) takes {p['jax_single_sample_median_us']:.1f} µs, Song et "
        f"al. report {p['paper_us_per_estimate']:.1f} µs per estimate on their controller. "
        f"`hdjax export` of a saved model took {e['best_command_s']['model']:.2f} s (compliance "
        f"model) and {e['best_command_s']['network']:.2f} s (network) in a fresh process with "
        f"the compilation cache off, after an import of {e['import_floor_s']:.1f} s.",
        "",
    ]
    return "\n".join(lines)


def causality_table() -> str:
    """The held-out error of the whole-recording and the causal estimate."""
    r = _result()
    if r is None:
        return _missing()
    rows = [
        "| case | velocity | samples | RMS error, whole recording [N·m] | RMS error, causal "
        "[N·m] | change | samples that differ | largest difference [N·m] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in r["causality_plant"] + r["causality_lara8"]:
        if "not_invertible" in row:
            rows.append(f"| {row['case']} | {row['velocity']} | not invertible | | | | | |")
            continue
        rows.append(
            f"| {row['case']} | `{row['velocity']}` | {row['samples']} | "
            f"{_g(row['rms_whole_Nm'], 4)} | {_g(row['rms_causal_Nm'], 4)} | "
            f"{row['rms_cost_pct']:+.2g} % | {row['samples_differing']} | "
            f"{_g(row['max_abs_difference_Nm'])} |"
        )
    return "\n".join(rows) + "\n"
