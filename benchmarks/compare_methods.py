"""Comparison table and figure over the plant's four scenarios.

Closed-form LS, recursive LS, Adam and Levenberg-Marquardt on the compliance model, the paper's
network, the hybrid (compliance + network on its residual) and the joint fit with plant
parameters: RMS and maximum error (N·m and % of rated torque), fit time and estimate time per
sample, on test recordings independent of the training recordings.

Run: `python benchmarks/compare_methods.py [--duration 60] [--steps 4000] [--out DIR]`; writes
`compare_methods.json` and `compare_methods.png` to `--out` and prints the JSON. `--paper-hybrid`
gives the hybrid and joint fits the linear rows' compliance structure (with the current
polynomial) and the paper's inputs only, as the first version of this comparison did.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import jax

import hdjax  # noqa: F401  (float64)
from hdjax import pipelines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="seconds per scenario")
    ap.add_argument("--steps", type=int, default=4000, help="Adam steps of hybrid/joint fits")
    ap.add_argument("--hidden", type=int, nargs="+", default=[32])
    ap.add_argument("--out", default="benchmarks/results")
    ap.add_argument(
        "--paper-hybrid",
        action="store_true",
        help="hybrid/joint without the dynamic inputs and with the current polynomial",
    )
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    result = pipelines.compare_methods(
        duration=args.duration,
        steps=args.steps,
        hidden=tuple(args.hidden),
        dynamic=not args.paper_hybrid,
        verbose=True,
    )
    result["total_time_s"] = time.perf_counter() - t0
    result["machine"] = {
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
    }
    result["precision"] = "float64"
    (out / "compare_methods.json").write_text(json.dumps(result, indent=2))
    pipelines.plot_comparison(result, out / "compare_methods.png")
    print(pipelines.format_table(result))
    print(json.dumps(result["best"], indent=2))


if __name__ == "__main__":
    main()
