"""Speed of the compliance model: estimation, one-sample latency, calibration, RLS.

Run on one core, float64:

    taskset -c 0 python benchmarks/bench_compliance.py

The script pins XLA and BLAS to one thread itself (`XLA_FLAGS=--xla_cpu_multi_thread_eigen=false
intra_op_parallelism_threads=1`, `OPENBLAS_NUM_THREADS=1`, ...) unless they are already set, and
prints one JSON document: the machine, the precision, compile-and-first-call times apart from
steady state (min over `timeit.repeat(number=1)`, `block_until_ready`), the reference
implementations timed in the same process, the ratios and whether each target is met.
"""

from __future__ import annotations

import os

os.environ.setdefault(
    "XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import timeit  # noqa: E402
import warnings  # noqa: E402

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import hdjax  # noqa: E402
from hdjax.compliance import (  # noqa: E402
    ComplianceModel,
    Signals,
    calibrate_lstsq,
    calibrate_rls,
    estimate_torque,
    estimate_torque_single,
    rls_solve,
)

JOINT = hdjax.Joint(ratio=101.0, rated_torque=90.0, name="bench")
PAPER_NS_PER_ESTIMATE = 9.232e-3 / 100 * 1e9  # Song et al. 2019: 9.232 ms per 100 estimates


def cpu_name() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def signals(n: int, seed: int):
    rng = np.random.default_rng(seed)
    f = lambda lo, hi: jnp.asarray(rng.uniform(lo, hi, n), jnp.float64)
    torque = rng.uniform(-JOINT.rated_torque, JOINT.rated_torque, n)
    sig = Signals(
        twist=jnp.zeros(n, jnp.float64),
        current=f(-1.5, 1.5),
        theta_m=f(0.0, 60.0),
        theta_l=f(-3.0, 3.0),
        omega_m=f(-3.0, 3.0),
        omega_l=f(-3.0, 3.0),
        extras={},
    )
    return sig, torque


def truth(model: ComplianceModel, seed: int, spread: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    nb = model.n_base
    k = rng.uniform(2e-5, 4e-5, model.n_segments)
    shared = rng.uniform(-3e-5, 3e-5, nb)
    rows = model.n_segments if model.per_segment else 1
    base = np.concatenate([shared + spread * rng.uniform(-3e-5, 3e-5, nb) for _ in range(rows)])
    return np.concatenate([k, base])


_predict = eqx.filter_jit(lambda m, s, t: m.predict_twist(s, t))


def problem(model: ComplianceModel, n: int, seed: int, noise: float, spread: float = 0.02):
    sig, torque = signals(n, seed)
    m = eqx.tree_at(lambda mm: mm.coef, model, jnp.asarray(truth(model, seed + 1, spread)))
    twist = np.asarray(_predict(m, sig, jnp.asarray(torque)))
    twist = twist + noise * np.random.default_rng(seed + 2).standard_normal(n)
    return eqx.tree_at(lambda s: s.twist, sig, jnp.asarray(twist)), torque, m


def steady(fn, repeat: int) -> float:
    return min(timeit.repeat(fn, number=1, repeat=repeat))


# ---------------------------------------------------------------------------------------------
# The straightforward vectorised NumPy implementation of eqs. (8)-(10), (26)-(27)


def numpy_estimate(model_np: dict, sig: dict) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (26) per segment, eq. (27) per segment, and the segment rules, in plain NumPy."""
    cur, ul, um = sig["current"], sig["theta_l"] * sig["omega_l"], sig["theta_m"] * sig["omega_m"]
    cols = [np.ones_like(cur)] + [cur**i for i in range(1, 7)]
    for n in range(1, 4):
        cols += [np.cos(n * ul), np.sin(n * ul), np.cos(n * um), np.sin(n * um)]
    base = np.stack(cols, axis=1)  # n x 19
    h = base @ model_np["base_coef"].T  # n x n_seg: eq. (26)'s removed terms per segment
    k, lo, hi, a, f_a = (model_np[x] for x in ("k", "lo", "hi", "a", "f_a"))
    cand = (sig["twist"][:, None] - h - f_a + k * a) / k  # eq. (27) in each segment
    dist = np.maximum(lo - cand, cand - hi)
    valid = dist <= 0.0
    depth = np.where(valid, -dist / model_np["width"], -np.inf)
    seg = np.where(valid.any(axis=1), depth.argmax(axis=1), dist.argmin(axis=1))
    t = np.take_along_axis(cand, seg[:, None], axis=1)[:, 0]
    t = np.where(valid.any(axis=1), t, np.clip(t, lo[seg], hi[seg]))
    return t, seg


def numpy_model(model: ComplianceModel) -> dict:
    bounds = model.segment_bounds
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    a = np.clip(0.0, lo, hi)
    k = np.asarray(model.k)
    phi = np.clip(a[:, None], lo[None, :], hi[None, :]) - np.clip(0.0, lo, hi)[None, :]
    width = np.where(np.isfinite(hi - lo), hi - lo, 2 * model.rated_torque / model.n_segments)
    return dict(
        k=k, lo=lo, hi=hi, a=a, f_a=phi @ k, width=width, base_coef=np.asarray(model.base_coef)
    )


# ---------------------------------------------------------------------------------------------


def main() -> dict:
    warnings.simplefilter("ignore")
    out: dict = {
        "benchmark": "bench_compliance",
        "machine": {
            "cpu": cpu_name(),
            "affinity_cores": sorted(os.sched_getaffinity(0)),
            "XLA_FLAGS": os.environ.get("XLA_FLAGS"),
            "python": sys.version.split()[0],
            "jax": jax.__version__,
            "numpy": np.__version__,
            "backend": jax.default_backend(),
        },
        "precision": "float64" if jax.config.jax_enable_x64 else "float32",
    }
    paper = ComplianceModel.paper(JOINT)  # per-segment, 5 segments, poly 6, Fourier 3 (eq. 9)
    shared = ComplianceModel.paper(JOINT, per_segment=False)

    # -- calibrate a paper-form model once (small, exact data) --------------------------------
    sig_c, tq_c, _ = problem(paper, 20_000, seed=1, noise=5e-7)
    model = calibrate_lstsq(paper, (sig_c, tq_c)).value

    # -- 1. batch torque estimation -------------------------------------------------------------
    n = 1_000_000
    sig, torque, _ = problem(paper, n, seed=5, noise=0.0)
    twist = np.asarray(_predict(model, sig, jnp.asarray(torque)))
    sig = eqx.tree_at(lambda s: s.twist, sig, jnp.asarray(twist))
    run = lambda: jax.block_until_ready(estimate_torque(model, sig))
    t0 = time.perf_counter()
    est = run()
    first = time.perf_counter() - t0
    t_jax = steady(run, 7)
    sig_np = {k: np.asarray(getattr(sig, k)) for k in Signals.__dataclass_fields__ if k != "extras"}
    mnp = numpy_model(model)
    t_ref, seg_ref = numpy_estimate(mnp, sig_np)
    t_np = steady(lambda: numpy_estimate(mnp, sig_np), 3)
    agree = float(np.max(np.abs(np.asarray(est.torque) - t_ref)))
    ns = t_jax / n * 1e9
    ns_np = t_np / n * 1e9
    out["batch_estimation"] = {
        "model": "per-segment paper form: 5 segments, current polynomial order 6, Fourier "
        "order 3 in theta*omega (eqs. 7-10); input: Signals (twist, current, angles, velocities)",
        "n_samples": n,
        "compile_and_first_call_s": first,
        "ns_per_estimate": ns,
        "target_ns_per_estimate": 92.0,
        "numpy_reference_ns_per_estimate": ns_np,
        "speedup_vs_numpy": ns_np / ns,
        "target_speedup_vs_numpy": 3.0,
        "paper_ns_per_estimate": PAPER_NS_PER_ESTIMATE,
        "speedup_vs_paper": PAPER_NS_PER_ESTIMATE / ns,
        "target_speedup_vs_paper": 1000.0,
        "max_abs_difference_vs_numpy_Nm": agree,
        "same_segment_fraction": float(np.mean(np.asarray(est.segment) == seg_ref)),
        "max_abs_error_vs_true_torque_Nm_unambiguous": float(
            np.max(np.abs(np.asarray(est.torque) - torque)[~np.asarray(est.ambiguous)])
        ),
    }
    out["batch_estimation"]["met"] = bool(
        ns <= 92.0 and ns_np / ns >= 3.0 and ns * 1000 <= PAPER_NS_PER_ESTIMATE
    )

    # -- 2. one sample through the jitted estimator from Python ---------------------------------
    x = [
        float(v[0])
        for v in (sig.twist, sig.current, sig.theta_m, sig.theta_l, sig.omega_m, sig.omega_l)
    ]
    t0 = time.perf_counter()
    estimate_torque_single(model, *x)
    first = time.perf_counter() - t0
    lat = np.array(timeit.repeat(lambda: estimate_torque_single(model, *x), number=1, repeat=3000))
    sig1 = jax.tree_util.tree_map(lambda v: v[:1], sig)
    jax.block_until_ready(estimate_torque(model, sig1))
    lat_generic = np.array(
        timeit.repeat(
            lambda: jax.block_until_ready(estimate_torque(model, sig1)), number=1, repeat=300
        )
    )
    out["single_sample"] = {
        "function": "hdjax.compliance.estimate_torque_single (compiled per model, cached)",
        "compile_and_first_call_s": first,
        "median_us": float(np.median(lat) * 1e6),
        "p90_us": float(np.percentile(lat, 90) * 1e6),
        "target_median_us": 25.0,
        "generic_estimate_torque_on_1_sample_median_us": float(np.median(lat_generic) * 1e6),
        "met": bool(np.median(lat) * 1e6 <= 25.0),
    }

    # -- 3. closed-form calibration on 10^6 samples ---------------------------------------------
    cal = {}
    for name, m in (("per_segment_paper", paper), ("shared_paper", shared)):
        s, t, _ = problem(m, 1_000_000, seed=7, noise=5e-7)
        t0 = time.perf_counter()
        res = calibrate_lstsq(m, (s, t))
        first = time.perf_counter() - t0
        cal[name] = {
            "n_coef": m.n_coef,
            "compile_and_first_call_s": first,
            "seconds": steady(lambda m=m, s=s, t=t: calibrate_lstsq(m, (s, t)), 3),
            "condition": res.stats["condition"],
        }
        del s, t
    out["calibration_lstsq_1e6"] = {
        **cal,
        "target_s": 2.0,
        "met": bool(all(v["seconds"] <= 2.0 for v in cal.values())),
    }

    # -- 4. block recursive least squares -------------------------------------------------------
    from hdjax.compliance._lstsq import _SegmentedDesign

    rls = {}
    for name, m, n_rls, sizes in (
        ("shared_paper", shared, 1_000_000, (16, 32)),
        ("per_segment_paper", paper, 200_000, (16, 32)),
    ):
        s, t, _ = problem(m, n_rls, seed=9, noise=5e-7)
        ref = np.asarray(calibrate_lstsq(m, (s, t)).value.coef)
        # the recursion alone, on the prepared (column-scaled) design
        A = _SegmentedDesign(m, s, jnp.asarray(t)).dense()
        A = A / np.sqrt(np.mean(A * A, axis=0))
        b = np.asarray(s.twist)
        entry = {"n_coef": m.n_coef, "n_samples": n_rls}
        for bs in sizes:
            t0 = time.perf_counter()
            res = calibrate_rls(m, (s, t), block_size=bs)
            first = time.perf_counter() - t0
            run_all = lambda m=m, s=s, t=t, bs=bs: calibrate_rls(m, (s, t), block_size=bs)
            run_core = lambda A=A, b=b, bs=bs: jax.block_until_ready(rls_solve(A, b, block_size=bs))
            entry[f"block_{bs}"] = {
                "compile_and_first_call_s": first,
                "samples_per_s_recursion": n_rls / steady(run_core, 3),
                "samples_per_s_end_to_end": n_rls / steady(run_all, 2),
                "max_rel_diff_vs_batch": float(
                    np.max(np.abs(np.asarray(res.value.coef) - ref)) / np.max(np.abs(ref))
                ),
            }
        entry["best_samples_per_s_recursion"] = max(
            v["samples_per_s_recursion"] for k, v in entry.items() if k.startswith("block_")
        )
        rls[name] = entry
        del s, t, A
    out["block_rls"] = {
        **rls,
        "recursion": "rls_solve on the column-scaled dense design (eqs. 20-23 per block)",
        "end_to_end": "calibrate_rls: design, column selection, scaling, recursion, residual",
        "target_samples_per_s": 1e6,
        "met_shared": bool(rls["shared_paper"]["best_samples_per_s_recursion"] >= 1e6),
        "met_per_segment": bool(rls["per_segment_paper"]["best_samples_per_s_recursion"] >= 1e6),
    }
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
