"""Benchmark: `hdjax fleet` of 16 joint-logs on a 2-worker local Dask cluster against 1 worker.

Target: the 2-worker run is >= 1.7x faster than the 1-worker run (the reference, timed in the
same run). 4 joints x 4 dated logs of `--samples` samples each (three undeclared effects whose
amplitude drifts over the dates), task calibrate + discover, both runs cold (`--no-cache`, fresh
result folders). Each worker is one single-threaded process (as `hdjax fleet` starts them).

    python benchmarks/bench_fleet.py [--samples 10000] [--logs 16]
"""

import argparse
import json
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


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--logs", type=int, default=16)
    args = ap.parse_args()
    import hdjax
    from tests.discover_data import ARCSEC, JOINT, synthetic_recording

    tmp = Path(tempfile.mkdtemp(prefix="hdjax-fleet-"))
    out = {"benchmark": "hdjax fleet, 2 workers against 1", **machine()}
    try:
        n_joints = 4
        per = -(-args.logs // n_joints)
        lines = ['[fleet]\nname = "bench"\ntask = "calibrate+discover"\nmax_effects = 3\n']
        k = 0
        for j in range(n_joints):
            entries = []
            for d in range(per):
                if k == args.logs:
                    break
                effects = [
                    ("harmonic_m", 2.0, (20 + 5 * d) * ARCSEC),
                    ("coulomb_l", 8 * ARCSEC, 0.05),
                ]
                rec = synthetic_recording(100 * j + d, effects, n=args.samples)
                path = tmp / f"j{j}-{d}.csv"
                hdjax.save_csv(rec, path)
                entries.append(f'{{ path = "{path.name}", date = 2026-0{d + 1}-01 }}')
                k += 1
            lines.append(
                f'[[joints]]\nname = "joint{j}"\nratio = {JOINT.ratio}\n'
                f"rated_torque = {JOINT.rated_torque}\nlogs = [{', '.join(entries)}]\n"
            )
        (tmp / "fleet.toml").write_text("\n".join(lines))
        runs = {}
        for workers in (1, 2):
            cmd = [
                sys.executable, "-m", "hdjax", "fleet", str(tmp / "fleet.toml"),
                "--out", str(tmp / f"out{workers}"), "--workers", str(workers), "--no-cache", "-q",
            ]  # fmt: skip
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
            runs[workers] = {
                "wall_s": time.perf_counter() - t0,
                "exit_code": proc.returncode,
                "summary": proc.stdout.strip().splitlines()[-1:] or proc.stderr[-300:],
            }
        import pyarrow.parquet as pq

        rows = pq.read_table(tmp / "out2" / "results.parquet").to_pylist()
        out.update(
            logs=args.logs,
            samples_per_log=args.samples,
            reference_1_worker=runs[1],
            workers_2=runs[2],
            tasks_ok=sum(r["status"] == "ok" for r in rows),
            worker_pids_used=len({r["worker_pid"] for r in rows}),
            speedup=runs[1]["wall_s"] / runs[2]["wall_s"],
            target_speedup=1.7,
        )
        out["target_met"] = bool(out["speedup"] >= 1.7)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
