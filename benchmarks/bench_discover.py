"""Benchmark: the whole residual loop on 10^5 training samples with three undeclared effects.

Target: three effects found and added in under 60 s on a 2-core CPU, compilation
included (the loop runs once, from a fresh process). float64 throughout.

    python benchmarks/bench_discover.py [--samples 100000]

Prints JSON: the time, the effects found, and the errors before and after.
"""

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import hdjax  # noqa: E402
from hdjax.discover import DiscoverOptions, discover  # noqa: E402
from tests.discover_data import JOINT, synthetic_recording  # noqa: E402

ARCSEC = math.pi / (180 * 3600)
EFFECTS = [
    ("harmonic_m", 2.0, 30 * ARCSEC),
    ("coulomb_l", 8 * ARCSEC, 0.05),
    ("temperature", 0.02),
]
EXPECTED = {"harmonic:theta_m:2", "coulomb:omega_l", "column:temperature*torque"}


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=100_000)
    args = ap.parse_args()
    t0 = time.perf_counter()
    train = synthetic_recording(1, EFFECTS, n=args.samples)
    test = synthetic_recording(2, EFFECTS, n=max(args.samples // 4, 2000))
    t_data = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = discover(train, test, JOINT, DiscoverOptions(max_effects=5))
    seconds = time.perf_counter() - t0
    found = set(res.aux.effects)
    out = {
        "benchmark": "discover loop, 3 undeclared effects",
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "precision": "float64",
        "jax": hdjax.__version__ and __import__("jax").__version__,
        "train_samples": train.n_samples,
        "data_seconds": round(t_data, 2),
        "loop_seconds_including_compile": round(seconds, 2),
        "effects": res.aux.effects,
        "expected_found": sorted(EXPECTED & found),
        "baseline_rms": res.aux.baseline.rms,
        "final_rms": res.aux.final.rms,
        "target_seconds": 60.0,
        "target_met": bool(seconds < 60.0 and EXPECTED <= found),
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
