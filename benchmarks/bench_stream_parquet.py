"""Benchmark: calibration of 10^8 samples streamed from Parquet, time and peak memory.

Targets: <= 120 s and a peak resident memory <= 2 GB on this 2-core CPU. The Parquet file
(about 4 GB) is generated chunk by chunk in a temporary folder and deleted afterwards. The
streamed fit runs in a fresh process whose peak resident set size (getrusage ru_maxrss) is
measured. Reference, timed in the same run: the in-memory `calibrate_lstsq` of the first
10^6 samples (time, memory, and the agreement of the streamed fit with it on those samples).

    python benchmarks/bench_stream_parquet.py [--samples 100000000] [--chunk 524288]
"""

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import numpy as np  # noqa: E402
from _long_logs import joint_log, machine  # noqa: E402

CHILD = """
import json, resource, sys, time
sys.path.insert(0, {repo!r}); sys.path.insert(0, {here!r})
t0 = time.perf_counter()
import numpy as np
from _long_logs import model
from hdjax.compliance import RecordingStream, calibrate_stream
import warnings
warnings.simplefilter("ignore")
path, chunk = sys.argv[1], int(sys.argv[2])
t1 = time.perf_counter()
res = calibrate_stream(model(), RecordingStream.from_files([path], chunk=chunk,
                       check_units=False), chunk=chunk)
t2 = time.perf_counter()
print(json.dumps({{"fit_s": t2 - t1, "import_s": t1 - t0, "n": res.stats["n_samples"],
    "coef": np.asarray(res.value.coef).tolist(), "condition": res.stats["condition"],
    "residual_rms_arcsec": res.stats["residual_rms"] * 206264.8,
    "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}}))
"""


def child(path, chunk):
    code = CHILD.format(repo=str(HERE.parent), here=str(HERE))
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", code, str(path), str(chunk)], capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    if out.returncode:
        raise SystemExit(out.stderr[-3000:])
    return {**json.loads(out.stdout.strip().splitlines()[-1]), "process_wall_s": wall}


def write_parquet(path, n, chunk):
    from hdjax._formats._parquet import ParquetWriter

    with ParquetWriter(path, ["t", "theta_m", "theta_l", "current", "torque"]) as w:
        for start in range(0, n, chunk):
            w.write(joint_log(start, min(chunk, n - start)))


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=100_000_000)
    ap.add_argument("--chunk", type=int, default=1 << 19)
    ap.add_argument("--reference-samples", type=int, default=1_000_000)
    ap.add_argument("--dir", help="where to put the temporary Parquet files (default: /tmp)")
    args = ap.parse_args()
    out = {"benchmark": "calibration streamed from Parquet", **machine()}
    tmp = Path(tempfile.mkdtemp(prefix="hdjax-bench-", dir=args.dir))
    try:
        # -- reference: the in-memory fit of the first samples, and the streamed one on them -----
        from _long_logs import model

        import hdjax
        from hdjax.compliance import calibrate_lstsq

        n_ref = min(args.reference_samples, args.samples)
        small = tmp / "small.parquet"
        write_parquet(small, n_ref, args.chunk)
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
        t0 = time.perf_counter()
        rec = hdjax.load_recording(small, check_units=False)
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = calibrate_lstsq(model(), rec)
        ref_s = time.perf_counter() - t0
        rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
        del rec
        streamed_small = child(small, min(args.chunk, n_ref))
        c_ref = np.asarray(ref.value.coef)
        rel = float(
            np.max(np.abs(np.asarray(streamed_small["coef"]) - c_ref)) / np.max(np.abs(c_ref))
        )
        out["reference"] = {
            "what": f"in-memory calibrate_lstsq on the first {n_ref} samples (load included)",
            "seconds": ref_s,
            "samples_per_s": n_ref / ref_s,
            "peak_rss_gb": max(rss0, rss1),
            "streamed_same_samples_s": streamed_small["fit_s"],
            "streamed_vs_in_memory_max_rel_coef_diff": rel,
            "condition": float(ref.stats["condition"]),
        }
        # -- the long log --------------------------------------------------------------------
        big = tmp / "long.parquet"
        t0 = time.perf_counter()
        write_parquet(big, args.samples, args.chunk)
        out["generate_s"] = time.perf_counter() - t0
        out["file_gb"] = big.stat().st_size / 1e9
        res = child(big, args.chunk)
        out.update(
            samples=res["n"],
            chunk=args.chunk,
            fit_s=res["fit_s"],
            process_wall_s=res["process_wall_s"],
            samples_per_s=res["n"] / res["fit_s"],
            peak_rss_gb=res["peak_rss_gb"],
            condition=res["condition"],
            residual_rms_arcsec=res["residual_rms_arcsec"],
            target_seconds=120.0,
            target_rss_gb=2.0,
        )
        out["target_seconds_met"] = bool(res["fit_s"] <= 120.0)
        out["target_rss_met"] = bool(res["peak_rss_gb"] <= 2.0)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
