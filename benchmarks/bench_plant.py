"""Plant benchmarks: prints one JSON document.

Targets: >= 50x faster than scipy.integrate.solve_ivp on the same equations and horizon,
>= 3e5 RK4 steps/s for one trajectory, >= 5e6 steps/s summed over a vmap batch of 64 (compile
time reported apart), the four 60-s scenarios in < 10 s including compilation.

The batch of 64 is split over one JAX CPU device per core (`jax_num_cpu_devices`, set before
JAX starts; `--devices 1` keeps one), as `hdjax.plant.spread_batch` does for any batch; a single
trajectory is one sequential loop and runs on one core either way.

Run: `python benchmarks/bench_plant.py [--devices N]` (float64; CPU).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import timeit

import jax

if __name__ == "__main__":
    _ap = argparse.ArgumentParser(description="Plant benchmarks, JSON on stdout.")
    _ap.add_argument("--devices", type=int, default=os.cpu_count() or 1, help="JAX CPU devices")
    ARGS = _ap.parse_args()
    jax.config.update("jax_num_cpu_devices", ARGS.devices)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.integrate  # noqa: E402

import hdjax  # noqa: F401, E402  (float64)
from hdjax import plant  # noqa: E402
from hdjax.plant._simulate import _integrate_batch, _integrate_jit  # noqa: E402

DT = 5e-4


def _best(fn, repeat=5):
    return min(timeit.repeat(fn, number=1, repeat=repeat))


def bench_scenarios():
    """The four 60-s experiments in one batched call, first call (compile included) and again."""
    t0 = time.perf_counter()
    recs = plant.simulate_scenarios(key=jax.random.key(0), duration=60.0)
    jax.block_until_ready(recs["slow"].torque)
    first = time.perf_counter() - t0
    again = _best(
        lambda: jax.block_until_ready(
            plant.simulate_scenarios(key=jax.random.key(1), duration=60.0)["slow"].torque
        ),
        2,
    )
    return {
        "what": "4 scenarios x 60 s, dt = output period = 0.5 ms, Song preset, sensors on",
        "seconds_including_compile": first,
        "seconds_after_compile": again,
        "target_s": 10.0,
        "met": first < 10.0,
    }


def bench_single(params, label, seconds=20.0):
    drive = plant.scenario_drive("slow", params, duration=seconds, dt=DT, key=jax.random.key(0))
    gains = plant.default_gains(params)
    s0 = plant.equilibrium_state(params, theta_l=drive.theta_ref[0])
    run = lambda: jax.block_until_ready(_integrate_jit(params, gains, s0, drive, DT))
    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    best = _best(run, 7)  # min of 7: the VM has bursts of steal time
    n = drive.n_steps
    return {
        "what": f"{label}: closed loop (PD+FF controller + plant), one trajectory, {n} RK4 steps",
        "compile_and_first_run_s": first,
        "steady_s": best,
        "steps_per_s": n / best,
        "target": 3e5,
        "met": n / best >= 3e5,
    }


def bench_batch(params, label, batch=64, seconds=2.0):
    drive = plant.scenario_drive("slow", params, duration=seconds, dt=DT, key=jax.random.key(0))
    drives = jax.tree.map(lambda x: jnp.broadcast_to(x, (batch,) + x.shape), drive)
    # different initial link angles per member (vmap over initial conditions)
    offsets = jnp.linspace(-0.2, 0.2, batch)
    drives = eqx.tree_at(lambda d: d.theta_ref, drives, drives.theta_ref + offsets[:, None])
    drives = plant.spread_batch(drives)  # one part per JAX device (per core, see the module)
    gains = plant.default_gains(params)
    run = lambda: jax.block_until_ready(_integrate_batch(params, gains, None, drives, DT, 1, 1))
    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    best = _best(run, 3)
    n = drive.n_steps * batch
    return {
        "what": f"{label}: vmap over {batch} initial conditions, {drive.n_steps} steps each, "
        f"split over {len(jax.local_devices())} CPU device(s)",
        "compile_and_first_run_s": first,
        "steady_s": best,
        "steps_per_s_summed": n / best,
        "target": 5e6,
        "met": n / best >= 5e6,
    }


def bench_scipy(params, label, horizon=0.5):
    """Open loop, the same right-hand side (`plant.derivatives`), same horizon."""
    tau, load = 1.0, -100.0
    s0 = plant.zero_state()
    leaves0, tree = jax.tree.flatten(s0)
    n = int(round(horizon / DT))

    @jax.jit
    def ours(s):
        step = lambda s, _: (plant.rk4_step(params, s, tau, load, DT), None)
        return jax.lax.scan(step, s, None, length=n)[0]

    rhs_jit = jax.jit(
        lambda x: jnp.stack(
            jax.tree.leaves(plant.derivatives(params, jax.tree.unflatten(tree, list(x)), tau, load))
        )
    )
    rhs = lambda t, x: np.asarray(rhs_jit(jnp.asarray(x)))
    x0 = np.array([float(v) for v in leaves0])
    rhs(0.0, x0)
    t0 = time.perf_counter()
    jax.block_until_ready(ours(s0))
    first = time.perf_counter() - t0
    t_ours = _best(lambda: jax.block_until_ready(ours(s0)))
    sol = {}

    def run_scipy():
        sol["r"] = scipy.integrate.solve_ivp(
            rhs, (0.0, horizon), x0, method="RK45", rtol=1e-8, atol=1e-10
        )

    t_scipy = _best(run_scipy, 2)
    end = np.array([float(v) for v in jax.tree.leaves(ours(s0))])
    ref = sol["r"].y[:, -1]
    nn = float(params.ratio)
    twist_err = abs((end[0] / nn - end[2]) - (ref[0] / nn - ref[2]))
    return {
        "what": f"{label}: open loop, {horizon} s; ours fixed-step RK4 dt=0.5 ms in lax.scan, "
        "scipy solve_ivp RK45 rtol=1e-8 atol=1e-10 calling the jitted plant.derivatives",
        "ours_compile_and_first_s": first,
        "ours_s": t_ours,
        "scipy_s": t_scipy,
        "scipy_rhs_evaluations": int(sol["r"].nfev),
        "ratio": t_scipy / t_ours,
        "final_twist_difference_rad": twist_err,
        "target_ratio": 50.0,
        "met": t_scipy / t_ours >= 50.0,
    }


def main():
    song, hashi = plant.song_params(), plant.hashimoto_params()
    result = {
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
            "jax": jax.__version__,
            "devices": [str(d) for d in jax.devices()],
        },
        "precision": "float64",
        "scenarios": bench_scenarios(),  # first, so its compilation is not shared with others
        "single_song": bench_single(song, "Song preset (default effects)"),
        "single_hashimoto": bench_single(hashi, "Hashimoto preset"),
        "batch64_song": bench_batch(song, "Song preset (default effects)"),
        "batch64_hashimoto": bench_batch(hashi, "Hashimoto preset"),
        "scipy_song": bench_scipy(song, "Song preset (default effects)"),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
