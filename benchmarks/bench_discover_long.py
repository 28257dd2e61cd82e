"""Benchmark: `hdjax discover` on 10^6 training samples, cold (fresh process, no cache).

Target: <= 60 s wall on this 2-core CPU, compilation included. The command runs as a user
runs it (`hdjax discover --train --test --joint --out`, figures included, `--no-cache`), on
recordings with three undeclared effects; its wall and CPU time (user + system of the child:
on a shared machine the CPU time is the figure that does not depend on the load, which is
recorded at the start and the end) and its peak resident memory (getrusage of the child) are
measured, with the loop's own wall/CPU seconds per phase (its last progress line).
Reference, timed in the same run: loading the training CSV and calibrating the paper's model
on it in this process (the loop's first step).

With `--chunk N` (default 16384; 0: the in-memory run only) the command runs a second time
with `--chunk N` (the loop's fits accumulated over chunks of N samples), and the JSON adds
that run's wall, CPU and peak resident memory and its precision: the largest relative
difference of the final model's coefficients and of the reported errors (TEST and
cross-validated) from the in-memory run, and whether the effects found are the same.

With `--scale N1,N2,...` (default 100000,300000) both runs are repeated on N1, N2, ...
TRAIN samples, and `scale` lists the wall time and peak resident memory of each size (the
main run's size last): the benchmarks page plots them against the samples.

    python benchmarks/bench_discover_long.py [--samples 1000000] [--chunk 16384] [--scale ...]
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


def _run(cmd, out_dir: Path):
    """Run the command; `(process, wall s, CPU s, peak RSS GB, report or {})`."""
    t0 = time.perf_counter()
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
    peak = c1.ru_maxrss / 1e6
    report = json.loads((out_dir / "report.json").read_text()) if not proc.returncode else {}
    return proc, wall, cpu, peak, report


def _summary(proc, wall, cpu, peak, report) -> dict:
    """One run's exit code, times, peak memory, phases and effects, as the JSON records them."""
    return dict(
        exit_code=proc.returncode,
        stderr_tail=proc.stderr[-500:] if proc.returncode else "",
        wall_s=wall,
        cpu_s=cpu,
        phases_wall_cpu_s=_phases(proc.stderr),
        peak_rss_gb=peak,
        effects=report.get("effects") or [],
    )


def _run_isolated(cmd, out_dir: Path):
    """[`_run`][] in a fresh Python process, so its peak RSS is the command's own."""
    code = (
        "import json, resource, subprocess, sys, time\n"
        "t0 = time.perf_counter()\n"
        f"p = subprocess.run({cmd!r}, cwd={str(REPO)!r}, capture_output=True, text=True)\n"
        "r = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
        "print(json.dumps(dict(rc=p.returncode, err=p.stderr, wall=time.perf_counter() - t0,"
        " cpu=r.ru_utime + r.ru_stime, peak=r.ru_maxrss / 1e6)))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    d = json.loads(res.stdout)
    proc = subprocess.CompletedProcess(cmd, d["rc"], "", d["err"])
    report = json.loads((out_dir / "report.json").read_text()) if not d["rc"] else {}
    return proc, d["wall"], d["cpu"], d["peak"], report


def _precision(ref: dict, other: dict) -> dict:
    """Largest relative differences of `other`'s coefficients and errors from `ref`'s."""
    import numpy as np

    if not ref or not other:
        return {}

    def rel(a, b):
        a, b = np.asarray(a, float), np.asarray(b, float)
        if a.shape != b.shape:
            return float("inf")
        return float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-300))

    errors = lambda r: [
        r["baseline"]["rms"],
        r["baseline"]["cv_torque_rms"],
        r["final"]["rms"],
        *[s["cv_torque_rms"] for s in r["steps"]],
        *[s["cv_twist_rms_arcsec"] for s in r["steps"]],
    ]
    return dict(
        effects_equal=ref.get("effects") == other.get("effects"),
        coef_max_rel=rel(other["final_model"]["coef"], ref["final_model"]["coef"]),
        errors_max_rel=max(rel(x, y) for x, y in zip(errors(other), errors(ref))),
        cv_gain_max_abs=max(
            [abs(a["cv_gain"] - b["cv_gain"]) for a, b in zip(other["steps"], ref["steps"])]
            or [0.0]
        ),
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--chunk", type=int, default=16384, help="also run with --chunk N (0: not)")
    ap.add_argument(
        "--scale", default="100000,300000", help="smaller TRAIN sizes also run ('': none)"
    )
    args = ap.parse_args()
    sizes = [int(x) for x in args.scale.split(",") if x.strip()]
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
        proc, wall, cpu, peak, report = _run(cmd, tmp / "out")
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
            **_summary(proc, wall, cpu, peak, report),
            load_average_1_5_15_end=load_end,
            test_rms=(report.get("final") or {}).get("rms"),
            expected_found=sorted(EXPECTED & found),
            reference={"load_csv_s": load_s, "baseline_calibration_s": cal_s},
            target_seconds=60.0,
            target_met=bool(proc.returncode == 0 and wall <= 60.0),
        )
        if args.chunk:
            cmd_c = [*cmd[:-3], "--out", str(tmp / "out_chunk"), "--no-cache"]
            cmd_c += ["--chunk", str(args.chunk)]
            # peak resident memory of a child: ru_maxrss of RUSAGE_CHILDREN is the largest over
            # all children waited for, so the chunked run is measured in a fresh helper process
            proc_c, wall_c, cpu_c, peak_c, report_c = _run_isolated(cmd_c, tmp / "out_chunk")
            out["chunked"] = dict(
                chunk=args.chunk,
                **_summary(proc_c, wall_c, cpu_c, peak_c, report_c),
                precision=_precision(report, report_c),
            )
        out["scale"] = [_size(n, args.chunk, tmp) for n in sizes if n < args.samples]
        main_point = {"samples": args.samples, "wall_s": wall, "peak_rss_gb": peak}
        if args.chunk:
            main_point |= {
                "chunked_wall_s": out["chunked"]["wall_s"],
                "chunked_peak_rss_gb": out["chunked"]["peak_rss_gb"],
            }
        out["scale"].append(main_point)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(out, indent=2))


def _size(n: int, chunk: int, tmp: Path) -> dict:
    """Wall time and peak resident memory of the command on `n` TRAIN samples (in memory and,
    with `chunk`, chunked), each in a fresh helper process."""
    from bench_discover import EFFECTS

    import hdjax
    from tests.discover_data import synthetic_recording

    d = tmp / f"n{n}"
    d.mkdir()
    hdjax.save_csv(synthetic_recording(1, EFFECTS, n=n), d / "train.csv")
    hdjax.save_csv(synthetic_recording(2, EFFECTS, n=max(n // 4, 2000)), d / "test.csv")
    cmd = [
        sys.executable, "-m", "hdjax", "discover", "--train", str(d / "train.csv"),
        "--test", str(d / "test.csv"), "--joint", str(tmp / "joint.toml"), "--no-cache",
    ]  # fmt: skip
    proc, wall, _, peak, _ = _run_isolated([*cmd, "--out", str(d / "out")], d / "out")
    point = {"samples": n, "exit_code": proc.returncode, "wall_s": wall, "peak_rss_gb": peak}
    if chunk:
        cmd_c = [*cmd, "--out", str(d / "out_chunk"), "--chunk", str(chunk)]
        proc, wall, _, peak, _ = _run_isolated(cmd_c, d / "out_chunk")
        point |= {"chunked_exit_code": proc.returncode, "chunked_wall_s": wall,
                  "chunked_peak_rss_gb": peak}  # fmt: skip
    return point


if __name__ == "__main__":
    main()
