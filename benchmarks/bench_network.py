"""Network benchmarks: training against scikit-learn, estimation against the paper.

Targets:

- training at least 5x faster than `sklearn.neural_network.MLPRegressor` with the same
  architecture (6 inputs, sigmoid hidden layer(s), linear output), the same standardised data and
  the same target validation loss (the one scikit-learn reaches), timed in this process;
- estimation at least 500x faster per estimate than the paper's 25.442 ms per 100 estimates
  (Song et al. 2019, Section IV.B, i7-7700H), i.e. at most 0.509 us per estimate.

Run: `python benchmarks/bench_network.py [--hidden 20] [--n-train 6000]`; prints JSON.

`--periodic` measures instead what the periodic angle features (sin/cos of the angles, beyond the
paper) do on plant data, with the plant's kinematic error on and off
([`hdjax.pipelines.periodic_features_effect`][]); writes `periodic_features.json` to `--out`, prints
the JSON and a Markdown table. `--duration` sets the seconds per scenario recording.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import timeit
import warnings
from pathlib import Path

import jax
import numpy as np

import hdjax
from hdjax import network as hn

PAPER_MS_PER_100 = 25.442
JOINT = hdjax.Joint(ratio=160.0, rated_torque=400.0)


def _data(n: int, seed: int = 0):
    """Training data: a plant scenario when hdjax.plant has them, else a synthetic joint."""
    try:
        from hdjax.plant import simulate_scenario  # noqa: F401

        rec = simulate_scenario("slow", duration=n * 1e-3 / 2, key=jax.random.key(seed))
        source = "hdjax.plant scenario 'slow'"
    except Exception:  # plant scenarios not available: the synthetic joint of the tests
        rng = np.random.default_rng(seed)
        t = np.arange(n) * 1e-3
        tau = 200 * np.sin(2 * np.pi * 0.7 * t) + 80 * np.sin(2 * np.pi * 1.9 * t + 1.0)
        theta_l = 0.3 * np.sin(2 * np.pi * 0.25 * t)
        tw = tau / 2.0e4 + 1e-4 * np.sin(2 * 160 * theta_l)
        current = tau / 16.0 + rng.normal(scale=0.05, size=n)
        rec = hdjax.make_recording(t, 160 * (theta_l - tw), theta_l, current, tau)
        source = "synthetic joint (twist = tau/2e4 + 1e-4 sin(320 theta_l), noisy current)"
    feats = hn.build_features(rec, JOINT)
    return np.asarray(feats.x), np.asarray(rec.torque), feats, source


def bench_training(hidden, n_train, lr, epochs, batch):
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    x, y, feats, source = _data(n_train + n_train // 3)
    val = np.arange(x.shape[0]) % 4 == 3  # interleaved validation samples
    xt, yt, xv, yv = x[~val], y[~val], x[val], y[val]
    # Same standardisation for both (the network stores it; scikit-learn gets standardised data).
    xm, xs, ym, ys = xt.mean(0), xt.std(0), yt.mean(), yt.std()
    xs = np.where(xs > 0, xs, 1.0)

    # ---- scikit-learn reference: Adam, minibatches, fixed epochs ------------------------
    sk = MLPRegressor(
        hidden_layer_sizes=hidden,
        activation="logistic",
        solver="adam",
        learning_rate_init=lr,
        batch_size=batch,
        max_iter=epochs,
        tol=0.0,
        n_iter_no_change=10**9,
        random_state=0,
        shuffle=True,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        t0 = time.perf_counter()
        sk.fit((xt - xm) / xs, (yt - ym) / ys)
        sk_time = time.perf_counter() - t0
    sk_pred = sk.predict((xv - xm) / xs) * ys + ym
    target = float(np.sqrt(np.mean((sk_pred - yv) ** 2)))

    # ---- hdjax: jitted Adam on the same minibatch size, stopping at scikit-learn's val RMS ---
    net = hn.Network(feats.layout, hidden, key=jax.random.key(0))
    steps = 20_000

    def run():
        res = hn.train_optax(
            net,
            xt,
            yt,
            learning_rate=lr,
            steps=steps,
            key=jax.random.key(1),
            x_val=xv,
            y_val=yv,
            target_rmse=target,
            eval_every=100,
            batch_size=batch,
        )
        jax.block_until_ready(res.value)
        return res

    t0 = time.perf_counter()
    res = run()
    first = time.perf_counter() - t0
    ours = min(timeit.repeat(run, number=1, repeat=3))
    reached = res.stats["target_reached"]
    return (
        {
            "data": source,
            "n_train": int(xt.shape[0]),
            "n_val": int(xv.shape[0]),
            "architecture": f"6 -> {list(hidden)} sigmoid -> 1 linear",
            "sklearn": {
                "solver": f"adam lr={lr} batch={batch} epochs={epochs}",
                "fit_s": sk_time,
                "val_rmse_Nm": target,
            },
            "hdjax": {
                "trainer": f"train_optax adam lr={lr} batch={batch}, stop at val RMS <= sklearn's",
                "compile_and_first_run_s": first,
                "steady_fit_s": ours,
                "steps": res.stats["steps"],
                "val_rmse_Nm": float(res.stats["val_rmse"][-1]),
                "reached_target": reached,
            },
            "speedup": sk_time / ours,
            "target_speedup": 5.0,
            "met": bool(reached and sk_time / ours >= 5.0),
        },
        res.value,
        feats,
    )


def bench_estimation(network, n=100_000):
    x = np.random.default_rng(0).normal(size=(n, network.layout.n_features))
    feats = hn.Features(x=jax.numpy.asarray(x), layout=network.layout)
    t0 = time.perf_counter()
    hn.predict(network, feats).block_until_ready()
    compile_s = time.perf_counter() - t0
    batch = (
        min(
            timeit.repeat(
                lambda: hn.predict(network, feats).block_until_ready(), number=1, repeat=20
            )
        )
        / n
    )
    small = hn.Features(x=feats.x[:100], layout=network.layout)
    hn.predict(network, small).block_until_ready()
    per100 = (
        min(
            timeit.repeat(
                lambda: hn.predict(network, small).block_until_ready(), number=100, repeat=5
            )
        )
        / 100
    )
    paper = PAPER_MS_PER_100 * 1e-3 / 100
    return {
        "paper_us_per_estimate": paper * 1e6,
        "batch_size": n,
        "compile_s": compile_s,
        "us_per_estimate_batch": batch * 1e6,
        "speedup_batch": paper / batch,
        "ms_per_call_of_100_from_python": per100 * 1e3,
        "speedup_call_of_100": (PAPER_MS_PER_100 * 1e-3) / per100,
        "target_speedup": 500.0,
        "met": bool(paper / batch >= 500.0),
    }


def _machine():
    return {
        "platform": platform.platform(),
        "processor": platform.processor(),
        "cpus": os.cpu_count(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
    }


def bench_periodic(args):
    from hdjax import pipelines

    t0 = time.perf_counter()
    hidden = (32,) if args.hidden is None else tuple(args.hidden)
    result = pipelines.periodic_features_effect(
        duration=args.duration, hidden=hidden, steps=args.steps, verbose=True
    )
    result["total_time_s"] = time.perf_counter() - t0
    result["machine"] = _machine()
    result["precision"] = "float64"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "periodic_features.json").write_text(json.dumps(result, indent=2))
    print(json.dumps(result["summary"], indent=2))
    print(pipelines.format_periodic_table(result))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--hidden", type=int, nargs="+", default=None, help="default 20 (32 with --periodic)"
    )
    ap.add_argument("--n-train", type=int, default=6000)
    ap.add_argument("--lr", type=float, default=1e-2)
    ap.add_argument("--epochs", type=int, default=200)
    ap.add_argument("--batch", type=int, default=200)
    ap.add_argument("--periodic", action="store_true", help="measure the periodic features")
    ap.add_argument("--duration", type=float, default=60.0, help="with --periodic: s/scenario")
    ap.add_argument("--steps", type=int, default=4000, help="with --periodic: Adam steps")
    ap.add_argument("--out", default="benchmarks/results", help="with --periodic: JSON folder")
    args = ap.parse_args()
    if args.periodic:
        bench_periodic(args)
        return
    args.hidden = [20] if args.hidden is None else args.hidden
    train, net, _ = bench_training(
        tuple(args.hidden), args.n_train, args.lr, args.epochs, args.batch
    )
    est = bench_estimation(net)
    print(
        json.dumps(
            {
                "machine": _machine(),
                "precision": "float64",
                "training": train,
                "estimation": est,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
