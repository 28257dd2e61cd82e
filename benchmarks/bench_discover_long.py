"""Benchmark: `hdjax discover` on 10^6 training samples, cold (fresh process, no cache).

Target: <= 60 s wall on this 2-core CPU, compilation included. The command runs as a user
runs it (`hdjax discover --train --test --joint --out`, figures included, `--no-cache`), on
recordings with three undeclared effects; its wall and CPU time (user + system of the child:
on a shared machine the CPU time is the figure that does not depend on the load, which is
recorded at the start and the end) and its peak resident memory (getrusage of the child) are
measured, with the loop's own wall/CPU seconds per phase (its last progress line).
Reference, timed in the same run: loading the training CSV and calibrating the paper's model
on it in this process (the loop's first step).

    python benchmarks/bench_discover_long.py [--samples 1000000]
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
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

from _long_logs import machine  # noqa: E402


def _phases(stderr: str) -> dict:
    """The loop's `phases [s wall / s cpu]: name w/c, ...` line as `{name: [wall, cpu]}`."""
    line = next((x for x in stderr.splitlines()[::-1] if "phases [s wall / s cpu]" in x), "")
    return {
        m[1]: [float(m[2]), float(m[3])]
        for m in re.finditer(r"([A-Za-z][\w ]*?) ([\d.]+)/([\d.]+)", line.split(":", 1)[-1])
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=1_000_000)
    args = ap.parse_args()
    import numpy as np
    from bench_discover import EFFECTS, EXPECTED

    import hdjax
    from hdjax.compliance import ComplianceModel, calibrate_lstsq
    from tests.discover_data import JOINT, synthetic_recording

    tmp = Path(tempfile.mkdtemp(prefix="hdjax-discover-"))
    out = {"benchmark": "hdjax discover on a long log, cold", **machine()}
    try:
        hdjax.save_csv(synthetic_recording(1, EFFECTS, n=args.samples), tmp / "train.csv")
        hdjax.save_csv(
            synthetic_recording(2, EFFECTS, n=max(args.samples // 4, 2000)), tmp / "test.csv"
        )
        (tmp / "joint.toml").write_text(
            f"[joint]\nratio = {JOINT.ratio}\nrated_torque = {JOINT.rated_torque}\n"
        )
        cmd = [
            sys.executable, "-m", "hdjax", "discover", "--train", str(tmp / "train.csv"),
            "--test", str(tmp / "test.csv"), "--joint", str(tmp / "joint.toml"),
            "--out", str(tmp / "out"), "--no-cache",
        ]  # fmt: skip
        t0 = time.perf_counter()
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6
        report = (
            json.loads((tmp / "out" / "report.json").read_text()) if not proc.returncode else {}
        )
        found = set(report.get("effects") or [])
        load_end = [round(x, 2) for x in os.getloadavg()]
        # reference: the first step of the loop, in this process
        t0 = time.perf_counter()
        train = hdjax.load_csv(tmp / "train.csv")
        load_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        scale = float(np.max(np.abs(np.asarray(train.current))))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            calibrate_lstsq(ComplianceModel.paper(JOINT, current_scale=scale,
                                                  per_segment=False), train)  # fmt: skip
        cal_s = time.perf_counter() - t0
        out.update(
            train_samples=args.samples,
            exit_code=proc.returncode,
            stderr_tail=proc.stderr[-500:] if proc.returncode else "",
            wall_s=wall,
            cpu_s=cpu,
            load_average_1_5_15_end=load_end,
            phases_wall_cpu_s=_phases(proc.stderr),
            peak_rss_gb=peak,
            effects=report.get("effects") or [],
            test_rms=(report.get("final") or {}).get("rms"),
            expected_found=sorted(EXPECTED & found),
            reference={"load_csv_s": load_s, "baseline_calibration_s": cal_s},
            target_seconds=60.0,
            target_met=bool(proc.returncode == 0 and wall <= 60.0),
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
