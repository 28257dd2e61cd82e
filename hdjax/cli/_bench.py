"""`hdjax bench`: time estimation and the order sweep on this machine, print JSON."""

from __future__ import annotations

from .._errors import ConfigError
from .._joint import Joint
from ..compliance import ComplianceModel, calibrate_lstsq, estimate_torque
from ..compliance.internal import nested_fit
from ..config import check_memory
from ..pipelines import synthetic_recording
from ..pipelines.internal import PAPER_MS_PER_100, stacked_signals
from ._common import Progress, add_command, add_quiet

HELP = "time estimation and the polynomial-order sweep on this machine (prints JSON)"
EXAMPLE = """\
example:
  hdjax bench
  hdjax bench --samples 100000 --repeats 5

Prints one JSON object: the machine, the precision, compile time apart from steady state, the
time to estimate 100 samples (model; next to the paper's 9.232 ms) and the sweep of the
polynomial order 1-8 against one order-6 fit on the same data (target: ratio < 3).
"""


def add_parser(sub) -> None:
    p = add_command(sub, "bench", HELP, EXAMPLE)
    p.add_argument("--samples", type=int, default=100_000, help="training samples (default 1e5)")
    p.add_argument("--repeats", type=int, default=5, help="timing repeats; the minimum is kept")
    add_quiet(p)


def command(args, parser) -> int:
    import json

    if args.samples < 1000:
        raise ConfigError(f"--samples must be at least 1000, got {args.samples}")
    if args.repeats < 1:
        raise ConfigError(f"--repeats must be at least 1, got {args.repeats}")
    # the order-8 design of the paper's structure: 5 + 5 x 21 columns, held about three times
    check_memory(
        args.samples * (110 * 8 * 3 + 40 * 8),
        f"--samples {args.samples}",
        "use fewer samples",
    )
    result = bench_sweep(args.samples, args.repeats, Progress(args.quiet))
    print(json.dumps(result, indent=2))
    return 0


def bench_sweep(n_samples: int, repeats: int, progress=None) -> dict:
    """Sweep of the polynomial order 1-8 (nested fit) against one order-6 `calibrate_lstsq`.

    Both on the same synthetic recording of `n_samples` samples (paper model structure: five
    segments, per-segment coefficients, paper-form Fourier order 3), float64, steady state
    `min(timeit.repeat(number=1))` after a first (compiling) call, in the same process.
    """
    import platform
    import time
    import timeit

    import jax

    say = progress or (lambda m: None)
    joint = Joint(ratio=160.0, rated_torque=400.0)
    say(f"generating {n_samples} synthetic samples")
    rec = synthetic_recording(joint, n_samples, seed=0)
    scale = float(abs(rec.current).max())
    make = lambda p: ComplianceModel.paper(
        joint, poly_order=p, current_scale=scale, kinematic="harmonic", per_segment=True
    )
    single = make(6)
    big = make(8)
    members = [make(p) for p in range(1, 9)]
    sig, torque = stacked_signals(big, [rec])
    data = (sig, torque)

    def fit_single():
        return calibrate_lstsq(single, data).value.coef.block_until_ready()

    def fit_sweep():
        fits, _ = nested_fit(big, members, sig, torque)
        return [f.value.coef.block_until_ready() for f in fits]

    say("compiling and timing one order-6 fit")
    t0 = time.perf_counter()
    fit_single()
    single_first = time.perf_counter() - t0
    single_s = min(timeit.repeat(fit_single, number=1, repeat=repeats))
    say("compiling and timing the sweep of orders 1-8")
    t0 = time.perf_counter()
    fit_sweep()
    sweep_first = time.perf_counter() - t0
    sweep_s = min(timeit.repeat(fit_sweep, number=1, repeat=repeats))
    say("timing the estimate of 100 samples")
    model = calibrate_lstsq(single, data).value
    rec100 = rec.select(slice(0, 100))
    est = lambda: jax.block_until_ready(estimate_torque(model, rec100).torque)
    t0 = time.perf_counter()
    est()
    est_first = time.perf_counter() - t0
    est_s = min(timeit.repeat(est, number=1, repeat=max(repeats, 20)))
    ratio = sweep_s / single_s
    return {
        "benchmark": "sweep of polynomial order 1-8 vs one order-6 fit",
        "machine": {
            "processor": platform.processor() or platform.machine(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "backend": jax.default_backend(),
            "cpu_count": __import__("os").cpu_count(),
        },
        "precision": "float64",
        "n_samples": n_samples,
        "model": "5 segments, per-segment coefficients (Table I layout), harmonics 1, 2 of "
        "both angles",
        "single_order6_first_s": single_first,
        "single_order6_s": single_s,
        "sweep_orders_1_8_first_s": sweep_first,
        "sweep_orders_1_8_s": sweep_s,
        "ratio": ratio,
        "target_ratio": 3.0,
        "target_met": ratio < 3.0,
        "estimate_100_first_ms": 1e3 * est_first,
        "estimate_100_ms": 1e3 * est_s,
        "paper_estimate_100_ms": PAPER_MS_PER_100["model"],
        "speedup_vs_paper": PAPER_MS_PER_100["model"] / (1e3 * est_s),
    }
