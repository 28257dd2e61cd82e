"""Benchmark: `hdjax fleet` of 16 joint-logs on a 2-worker local Dask cluster against 1 worker.

Target: the 2-worker run is >= 1.7x faster than the 1-worker run (the reference, timed in the
same run). 4 joints x 4 dated logs of `--samples` samples each (three undeclared effects whose
amplitude drifts over the dates), task calibrate + discover. Each worker is one single-threaded
process bound to its own core (as `hdjax fleet` starts them; `--no-pin` leaves them unbound,
and then one worker alone spreads over more than one core: JAX's dispatch and XLA's compiler
run beside the task). Both runs do the same work from the same cache state:

- `--cache cold` (default): the command as a user first runs it, the persistent compilation
  cache on (the CLI's default) but empty: each run gets its own new cache folder. The workers
  of one run share it, so a program one worker compiled is loaded, not compiled again, by the
  other (a task compiles the programs of the model structures its residual loop reaches).
- `--cache off`: both runs with `--no-cache` (every worker compiles everything it needs).
- `--cache warm`: a private cache filled by an untimed run, then both runs against it.

Wall time is from starting the command to its exit (cluster start-up, worker imports, the
tasks, the table and the report). The timeline splits it: `startup_s` until the first task
started (from its finish time less its own seconds), `tasks_s` until the last task finished,
`tail_s` the rest (results table, report, cluster shut-down). CPU seconds are those of the
command and all its processes (the driver, the scheduler, the nannies and the workers).

    python benchmarks/bench_fleet.py [--samples 10000] [--logs 16] [--cache cold|warm]
"""

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

from _long_logs import machine  # noqa: E402

DONE = re.compile(r"\] (\d+)/(\d+) done")


def _write_fleet(tmp: Path, n_logs: int, n_samples: int) -> Path:
    import hdjax
    from tests.discover_data import ARCSEC, JOINT, synthetic_recording

    n_joints = 4
    per = -(-n_logs // n_joints)
    lines = ['[fleet]\nname = "bench"\ntask = "calibrate+discover"\nmax_effects = 3\n']
    k = 0
    for j in range(n_joints):
        entries = []
        for d in range(per):
            if k == n_logs:
                break
            effects = [
                ("harmonic_m", 2.0, (20 + 5 * d) * ARCSEC),
                ("coulomb_l", 8 * ARCSEC, 0.05),
            ]
            rec = synthetic_recording(100 * j + d, effects, n=n_samples)
            path = tmp / f"j{j}-{d}.csv"
            hdjax.save_csv(rec, path)
            entries.append(f'{{ path = "{path.name}", date = 2026-0{d + 1}-01 }}')
            k += 1
        lines.append(
            f'[[joints]]\nname = "joint{j}"\nratio = {JOINT.ratio}\n'
            f"rated_torque = {JOINT.rated_torque}\nlogs = [{', '.join(entries)}]\n"
        )
    (tmp / "fleet.toml").write_text("\n".join(lines))
    return tmp / "fleet.toml"


def _run(manifest: Path, out: Path, workers: int, cache: str, env: dict, pin=True) -> dict:
    """One `hdjax fleet` run in a fresh process: wall, CPU seconds and the task timeline."""
    import pyarrow.parquet as pq

    cmd = [sys.executable, "-m", "hdjax", "fleet", str(manifest), "--out", str(out),
           "--workers", str(workers)] + (["--no-cache"] if cache == "off" else [])  # fmt: skip
    cmd += [] if pin else ["--no-pin"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load = [round(x, 2) for x in os.getloadavg()]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip
    done_at = []
    for line in proc.stderr:  # the progress bar: a line per change (not a terminal)
        m = DONE.search(line)
        if m and int(m.group(1)) > len(done_at):
            done_at.append(time.perf_counter() - t0)
    stdout = proc.stdout.read()
    proc.wait()
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    rows = pq.read_table(out / "results.parquet").to_pylist()
    per_worker: dict = {}
    for r in rows:
        per_worker.setdefault(r["worker_pid"], []).append(r["seconds"])
    first = min(done_at) if done_at else float("nan")
    first_seconds = min(r["seconds"] for r in rows)
    return {
        "wall_s": round(wall, 2),
        "exit_code": proc.returncode,
        "summary": stdout.strip().splitlines()[-1:],
        "load_average_at_start": load,
        "cpu_user_s": round(after.ru_utime - before.ru_utime, 1),
        "cpu_system_s": round(after.ru_stime - before.ru_stime, 1),
        "startup_s": round(first - first_seconds, 2),
        "tasks_s": round((done_at[-1] if done_at else wall) - (first - first_seconds), 2),
        "tail_s": round(wall - (done_at[-1] if done_at else wall), 2),
        "task_seconds_per_worker": {
            str(pid): {
                "n": len(s),
                "sum": round(sum(s), 1),
                "max": round(max(s), 1),
                "median": round(float(sorted(s)[len(s) // 2]), 1),
            }
            for pid, s in per_worker.items()
        },
        "tasks_ok": sum(r["status"] == "ok" for r in rows),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--logs", type=int, default=16)
    ap.add_argument("--cache", choices=("cold", "off", "warm"), default="cold")
    ap.add_argument("--no-pin", action="store_true", help="workers not bound to cores")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="hdjax-fleet-"))
    out = {"benchmark": "hdjax fleet, 2 workers against 1", **machine()}
    try:
        manifest = _write_fleet(tmp, args.logs, args.samples)
        env = dict(os.environ, XDG_CACHE_HOME=str(tmp / "cache"))
        if args.cache == "warm":  # untimed: fills the private cache both timed runs load
            _run(manifest, tmp / "warmup", 2, "warm", env)
        runs = {}
        for w in (1, 2):
            if args.cache == "cold":  # an empty cache for each run
                env = dict(os.environ, XDG_CACHE_HOME=str(tmp / f"cache{w}"))
            runs[w] = _run(manifest, tmp / f"out{w}", w, args.cache, env, not args.no_pin)
            print(json.dumps({f"workers_{w}": runs[w]}), file=sys.stderr, flush=True)  # as it goes
        out.update(
            logs=args.logs,
            samples_per_log=args.samples,
            cache=args.cache,
            workers_pinned=not args.no_pin,
            reference_1_worker=runs[1],
            workers_2=runs[2],
            worker_pids_used=len(runs[2]["task_seconds_per_worker"]),
            speedup=round(runs[1]["wall_s"] / runs[2]["wall_s"], 3),
            target_speedup=1.7,
            load_average_at_end=[round(x, 2) for x in os.getloadavg()],
        )
        out["target_met"] = bool(out["speedup"] >= 1.7)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
