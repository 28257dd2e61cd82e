"""The benchmarks page of the docs, rendered from the snapshot that `run_all.py` writes.

`render(snapshot)` is a pure function of the JSON, so the committed page can be checked against
the committed snapshot (tests/test_docs.py): no number on the page is typed by hand.
"""

from __future__ import annotations

import math
import re

# a script's label may cite the tracker ("(issue 2)") or name its temporary folder; user docs
# never show either
_TRACKER = re.compile(r"\s*\(issues? #?\d+[^)]*\)")
_TEMP = re.compile(r"/tmp/[^\s,;|)]*")

PAGE = "docs/benchmarks.md"
SNAPSHOT = "docs/benchmarks/results.json"


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
    text = _TEMP.sub("(a temporary folder)", _TRACKER.sub("", str(value)))
    return text.replace("|", "\\|").replace("\n", " ")


def _flatten(value, prefix=""):
    """(dotted key, leaf) pairs; lists of scalars stay one leaf, lists of tables are indexed."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _flatten(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        for i, v in enumerate(value):
            yield from _flatten(v, f"{prefix}[{i}]")
    elif isinstance(value, list):
        yield prefix, ", ".join(_fmt(v) for v in value)
    else:
        yield prefix, _fmt(value)


def _rows_table(rows: list[dict]) -> str:
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns and not isinstance(row[k], dict | list)]
    out = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in rows:
        out.append("| " + " | ".join(_fmt(row.get(c)) for c in columns) + " |")
    return "\n".join(out)


def _section(entry: dict) -> str:
    command = " ".join(["python", entry["script"], *entry["args"]])
    when = ""
    if entry.get("date"):
        when = f", run {entry['date']} (load average {entry.get('load_average', '?')})"
    out = [
        f"## `{entry['script'].split('/')[-1]}`\n",
        f"`{command}`, {entry['seconds']:.1f} s{when}\n",
    ]
    if entry.get("error"):
        out.append(
            f"**Failed** (exit code {entry['returncode']}):\n\n```text\n{entry['error']}\n```\n"
        )
        return "\n".join(out)
    result = entry["result"]
    scalars = {}
    for key, value in result.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            out.append(f"`{key}`:\n\n{_rows_table(value)}\n")
        else:
            scalars[key] = value
    leaves = list(_flatten(scalars))
    if leaves:
        table = ["| measure | value |", "|---|---|"]
        table += [f"| `{k}` | {v} |" for k, v in leaves]
        out.insert(2, "\n".join(table) + "\n")
    return "\n".join(out)


def _is_target_flag(key: str, shown: str) -> bool:
    last = key.split(".")[-1]
    named = last == "met" or last.endswith("_met") or last.startswith("met_")
    return named and shown in ("yes", "**no**")


def render(snapshot: dict) -> str:
    machine = snapshot["machine"]
    mode = "quick settings (`--quick`)" if snapshot["quick"] else "full settings"
    lines = [
        "<!-- Written by benchmarks/run_all.py from docs/benchmarks/results.json; do not edit. -->",
        "",
        "# Benchmarks",
        "",
        "Every number on this page was written by `python benchmarks/run_all.py` from the JSON the",
        "benchmark scripts print; rerun it to measure your machine (`--quick` uses smaller",
        "problems; `--only NAME` reruns one script). Timings depend on the machine and its load.",
        "",
        f"- latest run: {snapshot['date']}, commit `{snapshot['commit']}`, {mode}",
        f"- machine: {machine['cpu']}, {machine['cpus']} CPUs, {machine['platform']}",
        f"- load average at the start of the latest run: {machine['load_average']} (the machine is"
        " shared; each section gives its own run's date and load where recorded)",
        f"- Python {machine['python']}, JAX {machine['jax']}, float64",
        "",
        "| script | seconds | targets met |",
        "|---|---|---|",
    ]
    for entry in snapshot["benchmarks"]:
        name = entry["script"].split("/")[-1]
        if entry.get("error"):
            met = "**failed**"
        else:
            flags = [v for k, v in _flatten(entry["result"]) if _is_target_flag(k, v)]
            met = f"{sum(f == 'yes' for f in flags)} of {len(flags)}" if flags else ""
        lines.append(f"| [`{name}`](#{name.replace('.', '')}) | {entry['seconds']:.1f} | {met} |")
    lines.append("")
    for entry in snapshot["benchmarks"]:
        lines.append(_section(entry))
    return "\n".join(lines).rstrip() + "\n"
