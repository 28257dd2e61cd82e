"""The benchmarks page of the docs, rendered from the snapshot that `run_all.py` writes.

`render(snapshot)` is a pure function of the JSON, so the committed page can be checked against
the committed snapshot (tests/test_docs.py): no number on the page is typed by hand. The figures
it links are drawn from the same snapshot by `_figures.py` (`run_all.py` writes both).

The page opens with what is met and what is not: one line naming every missed target, then one
table of every target (what is measured, the result, the target, met). `TARGETS` says, for each
target flag a script prints, what it measures and which of the script's numbers are its result
and its target; the numbers themselves are read from the snapshot.
"""

from __future__ import annotations

import json
import math
import re

# a script's label may cite the tracker ("(issue 2)") or name its temporary folder; user docs
# never show either
_TRACKER = re.compile(r"\s*\(issues? #?\d+[^)]*\)")
_TEMP = re.compile(r"/tmp/[^\s,;|)\"]*")

PAGE = "docs/benchmarks.md"
SNAPSHOT = "docs/benchmarks/results.json"
FIGURES = "docs/benchmarks"  # the figures' folder; the page links them relative to docs/

# script -> [(flag, what is measured, result, target)]. `{a/b}` is the number at key path a/b
# of the script's JSON (keys may hold dots, so paths use "/"), formatted as on the rest of page.
TARGETS: dict[str, list[tuple[str, str, str, str]]] = {
    "bench_compliance.py": [
        (
            "batch_estimation/met",
            "batch torque estimation, {batch_estimation/n_samples} samples",
            "{batch_estimation/ns_per_estimate} ns a sample; {batch_estimation/speedup_vs_numpy}"
            "× NumPy; {batch_estimation/speedup_vs_paper}× the paper's",
            "≤ {batch_estimation/target_ns_per_estimate} ns; "
            "≥ {batch_estimation/target_speedup_vs_numpy}×; "
            "≥ {batch_estimation/target_speedup_vs_paper}×",
        ),
        (
            "single_sample/met",
            "one-sample estimate, median latency",
            "{single_sample/median_us} µs",
            "≤ {single_sample/target_median_us} µs",
        ),
        (
            "calibration_lstsq_1e6/met",
            "least-squares calibration, 10^6 samples",
            "{calibration_lstsq_1e6/per_segment_paper/seconds} s per-segment model, "
            "{calibration_lstsq_1e6/shared_paper/seconds} s shared",
            "≤ {calibration_lstsq_1e6/target_s} s",
        ),
        (
            "block_rls/met_shared",
            "block recursive LS, shared model ({block_rls/shared_paper/n_coef} coefficients)",
            "{block_rls/shared_paper/best_samples_per_s_recursion} samples/s",
            "≥ {block_rls/target_samples_per_s} samples/s",
        ),
        (
            "block_rls/met_per_segment",
            "block recursive LS, per-segment model "
            "({block_rls/per_segment_paper/n_coef} coefficients)",
            "{block_rls/per_segment_paper/best_samples_per_s_recursion} samples/s",
            "≥ {block_rls/target_samples_per_s} samples/s",
        ),
    ],
    "bench_export.py": [
        (
            "paper_model_step/met",
            "exported C step of the paper's model, -O2",
            "{paper_model_step/c/0/ns_per_step} ns double, {paper_model_step/c/1/ns_per_step} ns "
            "single; JAX one-sample call {paper_model_step/jax_single_sample_median_us} µs, the "
            "paper's {paper_model_step/paper_us_per_estimate} µs",
            "≤ {paper_model_step/target_ns_per_step} ns",
        ),
        (
            "paper_model_step/accuracy_met",
            "exported C step of the paper's model against the JAX estimate",
            "max {paper_model_step/c/0/max_abs_error_vs_jax_Nm} N·m double, "
            "{paper_model_step/c/1/max_error_pct_of_rated} % of rated single",
            "≤ 1e-9 N·m double, ≤ 0.1 % of rated single",
        ),
        (
            "network_step/met",
            "exported C step of the network",
            "{network_step/c/0/ns_per_step} ns double, {network_step/c/1/ns_per_step} ns single",
            "≤ {network_step/target_ns_per_step} ns",
        ),
        (
            "network_step/accuracy_met",
            "exported C step of the network against the JAX estimate",
            "max {network_step/c/0/max_abs_error_vs_jax_Nm} N·m double, "
            "{network_step/c/1/max_error_pct_of_rated} % of rated single",
            "≤ 1e-9 N·m double, ≤ 0.1 % of rated single",
        ),
        (
            "export_command/met",
            "`hdjax export` of a saved model, fresh process",
            "{export_command/best_command_s/model} s model, "
            "{export_command/best_command_s/network} s network (imports "
            "{export_command/import_floor_s} s beside)",
            "≤ {export_command/target_s} s",
        ),
    ],
    "bench_discover.py": [
        (
            "target_met",
            "discover loop, {train_samples} TRAIN samples, 3 undeclared effects",
            "{loop_seconds_including_compile} s; found {expected_found}",
            "< {target_seconds} s, all 3 found",
        ),
    ],
    "bench_discover_long.py": [
        (
            "target_met",
            "`hdjax discover`, {train_samples} TRAIN samples, cold process",
            "{wall_s} s, peak {peak_rss_gb} GB",
            "≤ {target_seconds} s",
        ),
    ],
    "bench_discover_select.py": [
        (
            "target_met",
            "`hdjax discover --chunk {chunk} --select-samples {select_samples}`, {train_samples} "
            "TRAIN samples from Parquet, cold process",
            "{wall_s} s, peak {peak_rss_gb} GB",
            "≤ {target_seconds} s and ≤ {target_peak_rss_gb} GB",
        ),
        (
            "cost/same_effects",
            "what the selection costs: {cost/select_samples} of {cost/train_samples} TRAIN "
            "samples against the full in-memory run",
            "same effects: {cost/same_effects}; final TEST RMS {cost/test_rms_over_full}× the "
            "full run's; 95 % interval widths {cost/interval_width_over_full} the full run's",
            "the same effects",
        ),
    ],
    "bench_fleet.py": [
        (
            "target_met",
            "`hdjax fleet`, {logs} logs: 2 workers against 1",
            "{speedup}× faster",
            "≥ {target_speedup}×",
        ),
    ],
    "bench_network.py": [
        (
            "training/met",
            "network training to scikit-learn's validation error",
            "{training/speedup}× faster than scikit-learn",
            "≥ {training/target_speedup}×, same error",
        ),
        (
            "estimation/met",
            "network estimate, batch of {estimation/batch_size}",
            "{estimation/speedup_batch}× the paper's {estimation/paper_us_per_estimate} µs",
            "≥ {estimation/target_speedup}×",
        ),
    ],
    "bench_plant.py": [
        (
            "scenarios/met",
            "simulate 4 scenarios × 60 s, compile included",
            "{scenarios/seconds_including_compile} s",
            "< {scenarios/target_s} s",
        ),
        (
            "single_song/met",
            "plant, Song preset, one trajectory",
            "{single_song/steps_per_s} steps/s",
            "≥ {single_song/target} steps/s",
        ),
        (
            "single_hashimoto/met",
            "plant, Hashimoto preset, one trajectory",
            "{single_hashimoto/steps_per_s} steps/s",
            "≥ {single_hashimoto/target} steps/s",
        ),
        (
            "batch64_song/met",
            "plant, Song preset, 64 trajectories",
            "{batch64_song/steps_per_s_summed} steps/s",
            "≥ {batch64_song/target} steps/s",
        ),
        (
            "batch64_hashimoto/met",
            "plant, Hashimoto preset, 64 trajectories",
            "{batch64_hashimoto/steps_per_s_summed} steps/s",
            "≥ {batch64_hashimoto/target} steps/s",
        ),
        (
            "scipy_song/met",
            "plant against SciPy's RK45, open loop",
            "{scipy_song/ratio}× faster",
            "≥ {scipy_song/target_ratio}×",
        ),
    ],
    "bench_song2019.py": [
        (
            "target_met",
            "the paper's job (`hdjax run experiments/song2019.toml`), fresh process",
            "{process_wall_s} s",
            "{target}",
        ),
    ],
    "bench_strain.py": [
        (
            "target_met",
            "strain-gauge torque loop against NumPy",
            "{speedup}× faster",
            "{target}",
        ),
    ],
    "bench_stream_parquet.py": [
        (
            "target_seconds_met",
            "calibration streamed from Parquet, {samples} samples: time",
            "{fit_s} s",
            "≤ {target_seconds} s",
        ),
        (
            "target_rss_met",
            "calibration streamed from Parquet, {samples} samples: peak memory",
            "{peak_rss_gb} GB",
            "≤ {target_rss_gb} GB",
        ),
    ],
    "bench_sweep.py": [
        (
            "target_met",
            "sweep of 8 polynomial orders against one fit",
            "{ratio}× one fit's time",
            "≤ {target_ratio}×",
        ),
    ],
    "bench_warm_start.py": [
        (
            "target_wall_met",
            "second `hdjax discover`, warm compilation cache",
            "{second_with_cache/wall_s} s, of which imports alone {import_floor/wall_s_median} s",
            "≤ {target_wall_s} s",
        ),
        (
            "target_no_compile_over_0.1s_met",
            "second `hdjax discover`: compilations over 0.1 s",
            "{second_with_cache/n_events_over_0.1s}",
            "none",
        ),
    ],
    "discover_noise.py": [
        (
            "false/met",
            "clean joints with white encoder noise (0.3-2 arcsec, 1-4 kHz) given an effect "
            "they do not have",
            "{false/joints_with_an_effect} of {false/of}",
            "at most 1 in 20",
        ),
        (
            "coverage/met",
            "95 % interval of a θ_m order-2 harmonic through `discover`, noisy joints",
            "covers the truth in {coverage/covered} of {coverage/of}; every interval holds its "
            "estimate: {coverage/every_interval_contains_its_estimate}",
            "90-99 %, and every interval holds its estimate",
        ),
    ],
    "real_log_cases.py": [
        (
            "summary/skew/delay_met",
            "encoder skew 0.3-3 ms either sign (alone, with hysteresis, with a harmonic) found "
            "as its delay within 10 %",
            "{summary/skew/delay_ok}",
            "every draw",
        ),
        (
            "summary/skew/test_met",
            "encoder skew: TEST error at most 1.5× the true structure refitted",
            "{summary/skew/test_ok}; worst {summary/skew/test_over_true_max}×",
            "every draw",
        ),
        (
            "summary/hysteresis/test_met",
            "hysteresis from rest, loaded the other way, one-way sweeps: TEST error at most "
            "1.5× the true structure refitted",
            "{summary/hysteresis/test_ok}; worst {summary/hysteresis/test_over_true_max}×",
            "every draw",
        ),
        (
            "summary/hysteresis/not_worse_met",
            "hysteresis from rest: TEST error not above the starting model's",
            "{summary/hysteresis/not_worse}",
            "every draw",
        ),
        (
            "two_speeds/summary/skew/delay_met",
            "TRAIN at two speeds (0.25 and 0.4 rad/s): encoder skew found as its delay within 10 %",
            "{two_speeds/summary/skew/delay_ok}",
            "every draw",
        ),
        (
            "two_speeds/summary/skew/test_met",
            "TRAIN at two speeds: encoder skew, TEST error at most 1.5× the true structure "
            "refitted",
            "{two_speeds/summary/skew/test_ok}; worst "
            "{two_speeds/summary/skew/test_over_true_max}×",
            "every draw",
        ),
        (
            "two_speeds/summary/hysteresis/test_met",
            "TRAIN at two speeds: hysteresis from rest, TEST error at most 1.5× the true "
            "structure refitted",
            "{two_speeds/summary/hysteresis/test_ok}; worst "
            "{two_speeds/summary/hysteresis/test_over_true_max}×",
            "every draw",
        ),
        (
            "two_speeds/summary/hysteresis/not_worse_met",
            "TRAIN at two speeds: hysteresis from rest, TEST error not above the starting model's",
            "{two_speeds/summary/hysteresis/not_worse}",
            "every draw",
        ),
    ],
    "compare_methods.py": [
        (
            f"{s}/target_met",
            f"best estimator on the {s} scenario",
            f"{{{s}/method}}: RMS {{{s}/rms_pct}} %, max {{{s}/max_pct}} % of rated",
            "some method with RMS ≤ 1 % and max ≤ 5 % of rated",
        )
        for s in ("slow", "fast", "sudden", "static")
    ],
}


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "yes" if value else "**no**"
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        if value == 0:
            return "0"
        if abs(value) >= 1e5 or abs(value) < 1e-3:
            return f"{value:.3e}"
        return f"{value:.4g}"
    if value is None:
        return ""
    if isinstance(value, list):
        return ", ".join(_fmt(v) for v in value)
    text = _TEMP.sub("(a temporary folder)", _TRACKER.sub("", str(value)))
    return text.replace("|", "\\|").replace("\n", " ")


def _get(result: dict, path: str):
    """The value at key path `a/b/c` of a script's JSON (a list's item by its index, `a/0/b`);
    KeyError when it is not there."""
    value = result
    for key in path.split("/"):
        value = value[int(key)] if isinstance(value, list) and key.isdigit() else value[key]
    return value


def _fill(template: str, result: dict) -> str:
    """`template` with each `{a/b}` replaced by that number of `result` ("?" when missing)."""

    def one(match):
        try:
            return _fmt(_get(result, match.group(1)))
        except (KeyError, TypeError):
            return "?"

    return re.sub(r"\{([^{}]+)\}", one, template)


def _flags(value, prefix=""):
    """(key path, bool) of every target flag of a script's JSON (a key `met`, `*_met`, `met_*`)."""
    if isinstance(value, dict):
        for k, v in value.items():
            path = f"{prefix}/{k}" if prefix else str(k)
            named = k == "met" or k.endswith("_met") or k.startswith("met_")
            if named and isinstance(v, bool):
                yield path, v
            else:
                yield from _flags(v, path)


def _name(entry: dict) -> str:
    return entry["script"].split("/")[-1]


def targets(snapshot: dict) -> list[dict]:
    """Every target of the snapshot: script, flag, what, result, target, met (None: the script
    failed). A flag that `TARGETS` does not describe is listed by its key path."""
    rows = []
    for entry in snapshot["benchmarks"]:
        name = _name(entry)
        if entry.get("error"):
            failed = {"what": "(the script failed)", "result": "", "target": ""}
            rows.append(dict(script=name, flag="", **failed, met=None))
            continue
        result = entry["result"]
        known = {flag: (what, res, tgt) for flag, what, res, tgt in TARGETS.get(name, [])}
        for flag, met in _flags(result):
            what, res, tgt = known.get(flag, (f"`{flag}`", "", ""))
            filled = {"what": _fill(what, result), "result": _fill(res, result)}
            filled["target"] = _fill(tgt, result)
            rows.append(dict(script=name, flag=flag, **filled, met=met))
    return rows


def _anchor(name: str) -> str:
    return name.replace(".", "")


def _summary(snapshot: dict) -> list[str]:
    rows = targets(snapshot)
    met = [r for r in rows if r["met"]]
    missed = [r for r in rows if r["met"] is False]
    failed = sorted({r["script"] for r in rows if r["met"] is None})
    counted = len(rows) - len([r for r in rows if r["met"] is None])
    lines = [f"**{len(met)} of {counted} targets met.**" + (" Not met:" if missed else "")]
    if missed:
        lines += [""] + [
            f"- **{r['what']}** (`{r['script']}`): {r['result']}; target {r['target']}"
            for r in missed
        ]  # fmt: skip
    if failed:
        lines += ["", "**Failed to run:** " + ", ".join(f"`{s}`" for s in failed) + "."]
    lines += [
        "",
        "| benchmark | what is measured | result | target | met |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        met_text = "**failed**" if r["met"] is None else _fmt(r["met"])
        lines.append(
            f"| [`{r['script']}`](#{_anchor(r['script'])}) | {r['what']} | {r['result']} |"
            f" {r['target']} | {met_text} |"
        )
    return lines


def _rows_table(rows: list[dict]) -> str:
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns and not isinstance(row[k], dict | list)]
    out = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in rows:
        out.append("| " + " | ".join(_fmt(row.get(c)) for c in columns) + " |")
    return "\n".join(out)


def _entry(snapshot: dict, name: str) -> dict | None:
    for entry in snapshot["benchmarks"]:
        if _name(entry) == name and not entry.get("error"):
            return entry
    return None


# ---------------------------------------------------------------------------------------------
# Song et al. (2019) next to the paper

SONG_FIGURE = "song2019.png"
_QUANTITIES = [(m, q) for m in ("model", "network") for q in ("RMS", "max")]
_METHOD = {"model": "model-based", "network": "network"}


def song_outliers(result: dict) -> list[str]:
    """One sentence for each experiment of the Song 2019 table with an outlier: a maximum above
    the rated torque, or a value more than 3 times the paper's (or less than a third of it)."""
    rated = result.get("rated_torque_Nm")
    sentences = []
    for row in result["errors_Nm"]:
        parts = []
        for method, q in _QUANTITIES:
            ours, paper = row.get(f"{method} {q}"), row.get(f"paper {method} {q}")
            if ours is None:
                continue
            label = f"the {_METHOD[method]} {q}"
            if q == "max" and rated and ours > rated:
                rms = row.get(f"{method} RMS")
                at = row.get(f"{method} max at s")
                where = f" at t = {_fmt(at)} s" if at is not None else ""
                parts.append(
                    f"{label}, {_fmt(ours)} N·m{where}, is above the rated {_fmt(rated)} N·m while"
                    f" its RMS is {_fmt(rms)} N·m: the maximum, {_fmt(ours / rms)} times the RMS,"
                    " is a short spike (in the run's figure of this experiment), not an error level"
                )
            elif paper and ours > 3 * paper:
                parts.append(
                    f"{label} is {_fmt(ours / paper)} times the paper's"
                    f" ({_fmt(ours)} against {_fmt(paper)} N·m)"
                )
            elif paper and ours < paper / 3:
                parts.append(
                    f"{label} is {_fmt(paper / ours)} times below the paper's"
                    f" ({_fmt(ours)} against {_fmt(paper)} N·m)"
                )
        if parts:
            sentence = "; ".join(parts)
            sentences.append(f"**{row['experiment']}**: {sentence[0].upper()}{sentence[1:]}.")
    return sentences


def _song(snapshot: dict) -> list[str]:
    entry = _entry(snapshot, "bench_song2019.py")
    if entry is None or not entry["result"].get("errors_Nm"):
        return []
    result = entry["result"]
    lines = [
        "## Song et al. (2019): errors next to the paper's",
        "",
        "The four load experiments of the paper's Section IV on the built-in simulated joint,"
        " both methods, on test runs neither method was fitted to"
        f" ([`bench_song2019.py`](#{_anchor(_name(entry))}); errors in N·m). The simulated joint"
        " is not the paper's bench: its noise, loads and unmodelled effects are its own, so a"
        " lower error than the paper's says the model fits its plant, not that it beats the"
        " paper.",
        "",
        f"![hdjax's errors next to the paper's, per experiment]({FIGURES[5:]}/{SONG_FIGURE})",
        "",
        _rows_table([{k: v for k, v in r.items() if " at " not in k} for r in result["errors_Nm"]]),
        "",
    ]
    outliers = song_outliers(result)
    if outliers:
        lines += ["Outliers (above the rated torque, or more than 3 times off the paper's):", ""]
        lines += [f"- {s}" for s in outliers] + [""]
    return lines


# ---------------------------------------------------------------------------------------------
# Time and memory against samples


def scale_points(snapshot: dict) -> dict[str, list[dict]]:
    """script -> the points (samples, series -> (seconds, peak GB)) that its scale plot shows.

    `bench_discover_long.py` measures the command on several TRAIN sizes (`scale`); the
    Parquet benchmark has its streamed fit and its in-memory reference on fewer samples."""
    out = {}
    entry = _entry(snapshot, "bench_discover_long.py")
    if entry and entry["result"].get("scale"):
        pts = []
        for p in entry["result"]["scale"]:
            series = {"in memory": (p.get("wall_s"), p.get("peak_rss_gb"))}
            if "chunked_wall_s" in p:
                series["--chunk"] = (p["chunked_wall_s"], p.get("chunked_peak_rss_gb"))
            pts.append({"samples": p["samples"], "series": series})
        out["bench_discover_long.py"] = pts
    entry = _entry(snapshot, "bench_stream_parquet.py")
    if entry and "reference" in entry["result"]:
        r = entry["result"]
        ref = r["reference"]
        n_ref = int(round(ref["seconds"] * ref["samples_per_s"]))
        out["bench_stream_parquet.py"] = [
            {"samples": n_ref, "series": {"in memory": (ref["seconds"], ref.get("peak_rss_gb")),
                                          "streamed": (ref.get("streamed_same_samples_s"),
                                                       None)}},
            {"samples": r["samples"], "series": {"streamed": (r["fit_s"], r["peak_rss_gb"])}},
        ]  # fmt: skip
    return out


def scale_figure(script: str) -> str:
    """The file name of a script's scale plot (in `FIGURES`)."""
    return f"scale_{script.removesuffix('.py')}.png"


def _scale(snapshot: dict) -> list[str]:
    points = scale_points(snapshot)
    if not points:
        return []
    lines = ["## Time and memory against samples", ""]
    for script, pts in points.items():
        lines += [
            f"[`{script}`](#{_anchor(script)}): wall time and peak resident memory against the"
            " number of samples (samples on a log axis; a point is missing where the run did not"
            " measure it; each script's section gives its run's load average).",
            "",
            f"![{script}: time and memory against samples]({FIGURES[5:]}/{scale_figure(script)})",
            "",
        ]
        names = list(dict.fromkeys(s for p in pts for s in p["series"]))
        head = ["samples"] + [f"{s} {u}" for s in names for u in ("s", "GB")]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for p in pts:
            cells = [_fmt(p["samples"])]
            for s in names:
                t, m = p["series"].get(s, (None, None))
                cells += [_fmt(t), _fmt(m)]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return lines


# ---------------------------------------------------------------------------------------------
# One section a script


def _row_lists(result: dict, prefix: str = ""):
    """(key path, list) of every list of rows (dicts) in a script's JSON, at its top level or
    one table down (`two_speeds/draws`)."""
    for key, value in result.items():
        path = f"{prefix}{key}"
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            yield path, value
        elif isinstance(value, dict) and not prefix:
            yield from _row_lists(value, f"{path}/")


def _section(entry: dict) -> str:
    command = " ".join(["python", entry["script"], *entry["args"]])
    when = ""
    if entry.get("date"):
        when = f", run {entry['date']} (load average {entry.get('load_average', '?')})"
    out = [f"### `{_name(entry)}`\n", f"`{command}`, {entry['seconds']:.1f} s{when}\n"]
    if entry.get("error"):
        out.append(
            f"**Failed** (exit code {entry['returncode']}):\n\n```text\n{entry['error']}\n```\n"
        )
        return "\n".join(out)
    result = entry["result"]
    for key, value in _row_lists(result):
        if len(value) <= 40:
            out.append(f"`{key}`:\n\n{_rows_table(value)}\n")
    raw = _TEMP.sub("(a temporary folder)", json.dumps(result, indent=1))
    out.append(
        f'<details markdown="1"><summary>The JSON it printed</summary>\n\n```json\n{raw}\n```\n\n'
        "</details>\n"
    )
    return "\n".join(out)


def _settings(snapshot: dict) -> str:
    quick = [_name(e) for e in snapshot["benchmarks"] if e.get("quick", snapshot["quick"])]
    if not quick:
        return "full settings"
    if len(quick) == len(snapshot["benchmarks"]):
        return "quick settings (`--quick`)"
    return "full settings, except quick settings (`--quick`) for " + ", ".join(
        f"`{q}`" for q in quick
    )


def render(snapshot: dict) -> str:
    """The page (Markdown) for a snapshot of `run_all.py`."""
    machine = snapshot["machine"]
    lines = [
        "<!-- Written by benchmarks/run_all.py from docs/benchmarks/results.json; do not edit. -->",
        "",
        "# Benchmarks",
        "",
        *_summary(snapshot),
        "",
        "Every number on this page, and every figure, was written by `python"
        " benchmarks/run_all.py` from the JSON the benchmark scripts print; rerun it to measure"
        " your machine (`--quick` uses smaller problems; `--only NAME` reruns one script)."
        " Timings depend on the machine and its load.",
        "",
        f"- latest run: {snapshot['date']}, commit `{snapshot['commit']}`, {_settings(snapshot)}",
        f"- machine: {machine['cpu']}, {machine['cpus']} CPUs, {machine['platform']}",
        f"- load average at the start of the latest run: {machine['load_average']} (the machine is"
        " shared; each script's section gives its own run's date and load)",
        f"- Python {machine['python']}, JAX {machine['jax']}, float64",
        "",
        *_song(snapshot),
        *_scale(snapshot),
        "## Every script",
        "",
        "Each script's command, time, tables and the JSON it printed (unfold it).",
        "",
    ]
    for entry in snapshot["benchmarks"]:
        lines.append(_section(entry))
    return "\n".join(lines).rstrip() + "\n"
