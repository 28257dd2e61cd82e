"""Run every benchmark script, keep their JSON, and write the docs' benchmarks page.

    python benchmarks/run_all.py            # full settings (tens of minutes on 2 cores)
    python benchmarks/run_all.py --quick    # smaller problems (a few minutes)
    python benchmarks/run_all.py --only bench_plant.py

Each script (`benchmarks/bench_*.py`, `benchmarks/compare_methods.py` and the residual loop's
statistics `discover_noise.py` and `real_log_cases.py`) runs in its own
process, one after the other, and prints JSON. This writes:

- `benchmarks/results/<script>.json`: each script's JSON (the folder is not committed);
- `docs/benchmarks/results.json`: the snapshot the page is made from (machine, date, commit,
  command, seconds and JSON of every script), committed with the page;
- `docs/benchmarks.md`: the page, rendered by `benchmarks/_page.py`;
- `docs/benchmarks/*.png`: its figures (the Song 2019 errors next to the paper's, time and
  memory against samples), drawn by `benchmarks/_figures.py` from the same snapshot.

With `--only`, the other scripts' entries of the existing snapshot are kept.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))

import _figures  # noqa: E402
import _page  # noqa: E402

# Smaller problems for --quick (scripts not listed run with their defaults).
QUICK = {
    "bench_discover.py": ["--samples", "20000"],
    "bench_sweep.py": ["--samples", "20000", "--repeats", "2"],
    "bench_network.py": ["--n-train", "2000", "--epochs", "50"],
    "compare_methods.py": ["--duration", "10", "--steps", "300"],
    "bench_discover_long.py": ["--samples", "100000", "--scale", "25000,50000"],
    "bench_discover_select.py": [
        "--samples",
        "1000000",
        "--select",
        "100000",
        "--reference-samples",
        "200000",
    ],  # fmt: skip
    "bench_fleet.py": ["--samples", "5000", "--logs", "4"],
    "bench_stream_parquet.py": ["--samples", "4000000", "--reference-samples", "500000"],
    "bench_warm_start.py": ["--samples", "20000"],
    "bench_export.py": ["--duration", "5", "--samples", "200000", "--check", "20000"],
    "discover_noise.py": ["--joints", "4", "--coverage-joints", "6"],
    "real_log_cases.py": ["--draws", "2"],
}


def scripts() -> list[str]:
    """The benchmark scripts, by name, in the order they run."""
    found = sorted(p.name for p in HERE.glob("bench_*.py")) + ["compare_methods.py"]
    # the residual loop's statistics over many simulated joints (real-log effects, noise)
    found += ["discover_noise.py", "real_log_cases.py"]
    return [s for s in found if (HERE / s).exists()]


def _last_json(text: str):
    """The last JSON object in a script's stdout (progress lines may precede it)."""
    decoder = json.JSONDecoder()
    found = None
    for i, ch in enumerate(text):
        if ch == "{" and (i == 0 or text[i - 1] == "\n"):
            try:
                found, _ = decoder.raw_decode(text[i:])
            except json.JSONDecodeError:
                continue
    return found


def run_one(script: str, quick: bool, timeout: float) -> dict:
    """Run one script in its own process; its snapshot entry (command, seconds, date, load,
    and its JSON or the tail of its error)."""
    args = QUICK.get(script, []) if quick else []
    command = [sys.executable, str(HERE / script), *args]
    print(f"[run_all] {' '.join(['python', 'benchmarks/' + script, *args])}", file=sys.stderr)
    date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else ""
    start = time.perf_counter()
    try:
        done = subprocess.run(
            command, cwd=REPO, capture_output=True, text=True, timeout=timeout, check=False
        )
        code, out, err = done.returncode, done.stdout, done.stderr
    except subprocess.TimeoutExpired as exc:
        code, out, err = -1, exc.stdout or "", f"timed out after {timeout:.0f} s"
        out = out.decode() if isinstance(out, bytes) else out
    seconds = time.perf_counter() - start
    entry = {
        "script": f"benchmarks/{script}",
        "args": args,
        "quick": bool(args),
        "seconds": seconds,
        "returncode": code,
        "date": date,
        "load_average": load,
    }
    result = _last_json(out) if code == 0 else None
    if result is None:
        tail = (err or out).strip().splitlines()[-8:]
        entry["error"] = "\n".join(tail) or f"exit code {code}, no JSON on stdout"
    else:
        entry["result"] = result
        (REPO / "benchmarks" / "results").mkdir(parents=True, exist_ok=True)
        name = Path(script).stem
        (REPO / "benchmarks" / "results" / f"{name}.json").write_text(json.dumps(result, indent=2))
    print(f"[run_all]   {seconds:.1f} s, exit code {code}", file=sys.stderr)
    return entry


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _commit() -> str:
    try:
        return (
            subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True
            ).stdout.strip()
            or "unknown"
        )
    except OSError:
        return "unknown"


def machine() -> dict:
    """This machine: CPU, core count, platform, Python and JAX versions, load average."""
    import jax

    load = os.getloadavg() if hasattr(os, "getloadavg") else ()
    return {
        "cpu": _cpu(),
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "load_average": ", ".join(f"{x:.2f}" for x in load),
    }


def main(argv=None) -> int:
    """Run the chosen scripts, write the snapshot, the page and its figures; 1 if one failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller problems (minutes)")
    parser.add_argument("--only", action="append", metavar="SCRIPT", help="run only this script")
    parser.add_argument("--timeout", type=float, default=1800, help="seconds per script")
    args = parser.parse_args(argv)
    chosen = scripts()
    if args.only:
        unknown = [s for s in args.only if s not in chosen]
        if unknown:
            parser.error(f"unknown script(s) {unknown}; scripts: {', '.join(chosen)}")
        chosen = [s for s in chosen if s in args.only]
    snapshot_path = REPO / _page.SNAPSHOT
    snapshot = {
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": _commit(),
        "quick": args.quick,
        "machine": machine(),
        "benchmarks": [],
    }
    entries = {e["script"]: e for e in [run_one(s, args.quick, args.timeout) for s in chosen]}
    if args.only and snapshot_path.exists():
        old = json.loads(snapshot_path.read_text())
        for e in old["benchmarks"]:  # an entry of an older snapshot: its run's settings
            e.setdefault(
                "quick", bool(old.get("quick")) and bool(QUICK.get(Path(e["script"]).name))
            )
        merged = [entries.pop(e["script"], e) for e in old["benchmarks"]]
        entries = {e["script"]: e for e in merged + list(entries.values())}
    snapshot["benchmarks"] = sorted(entries.values(), key=lambda e: e["script"])
    snapshot_path.parent.mkdir(parents=True, exist_ok=True)
    snapshot_path.write_text(json.dumps(snapshot, indent=1) + "\n")
    (REPO / _page.PAGE).write_text(_page.render(snapshot))
    _figures.write(snapshot, REPO / _page.FIGURES)
    failed = [e["script"] for e in snapshot["benchmarks"] if e.get("error")]
    print(f"[run_all] wrote {_page.PAGE}; failed: {failed or 'none'}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
