"""Benchmark: sweeping the polynomial order 1-8 against fitting the single order-6 model.

Target: on 10^5 samples the whole sweep (eight calibrated models) takes less than 3x
the time of one order-6 `calibrate_lstsq`. The sweep shares one Gram pass of the order-8 model
(and one QR of it for members too ill-conditioned for the semi-normal equations) across all
members; the reference implementations timed in the same process are the single order-6 fit and
a plain loop of eight `calibrate_lstsq` calls.

    python benchmarks/bench_sweep.py [--samples 100000] [--repeats 5]

Prints one JSON object (float64, CPU; compile-and-first-run apart from the steady state, which
is `min(timeit.repeat(number=1))` with `block_until_ready`).
"""

import argparse
import json
import time
import timeit

from hdjax.cli._bench import bench_sweep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-loop", action="store_true", help="skip the 8-fit loop reference")
    args = parser.parse_args()
    result = bench_sweep(args.samples, args.repeats)
    if not args.no_loop:
        from hdjax import Joint
        from hdjax.compliance import ComplianceModel, calibrate_lstsq
        from hdjax.pipelines import synthetic_recording
        from hdjax.pipelines._paper import stacked_signals

        joint = Joint(ratio=160.0, rated_torque=400.0)
        rec = synthetic_recording(joint, args.samples, seed=0)
        scale = float(abs(rec.current).max())
        models = [
            ComplianceModel.paper(
                joint, poly_order=p, current_scale=scale, kinematic="harmonic", per_segment=True
            )
            for p in range(1, 9)
        ]
        data = stacked_signals(models[-1], [rec])

        def loop():
            return [calibrate_lstsq(m, data).value.coef.block_until_ready() for m in models]

        t0 = time.perf_counter()
        loop()
        result["loop_of_8_fits_first_s"] = time.perf_counter() - t0
        result["loop_of_8_fits_s"] = min(timeit.repeat(loop, number=1, repeat=args.repeats))
        result["sweep_speedup_vs_loop"] = result["loop_of_8_fits_s"] / result["sweep_orders_1_8_s"]
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
