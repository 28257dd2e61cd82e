"""The residual loop on simulated joints with what real logs bring: encoder skew and hysteresis
from rest on one-way sweeps.

Each draw simulates one joint (`hdjax.plant.simulate_real_log`: slow one-way sweeps from rest
under gravity with pauses, jittered timestamps with dropped samples, white encoder noise,
2^24-count encoders with the joint's offsets), a TRAIN log and a TEST log of another sweep at
another speed, and runs `discover` on them as a user would. The true structure (the starting
model plus the true effects' terms; a hysteresis behind the play that the loop reads from
TRAIN's encoder noise, `hdjax.effects.twist_play`) is refitted by the same pipeline for
reference.

Two kinds of draw, `--draws` of each (seeds and parameters drawn from `--seed`):

- `skew`: a load-encoder delay of 0.3-3 ms (log-uniform) of either sign, alone, with
  hysteresis or with a θ_m order-2 harmonic (in turn). Checked: the delay is found
  (`skew:encoders`) within 10 % and the TEST error is at most 1.5 times the true structure's.
- `hysteresis`: a Dahl hysteresis of drawn height and width whose state starts loaded the
  other way (the sweep's run-in), no skew. Checked: the TEST error is at most 1.5 times the
  true structure's and not above the start's.

Each kind runs twice, with TRAIN in the two settings a user may have:

- one sweep at 0.4 rad/s (the JSON's top level): a speed-proportional twist (the skew) is a
  constant while moving there, which the compliance, Coulomb friction, hysteresis or an
  output-angle harmonic can absorb, so only the accelerations identify it;
- two sweeps at 0.25 and 0.4 rad/s joined 1 s apart (`two_speeds`), where the speed varies
  while moving.

Precision: float64 (x64 on). Prints JSON (every draw, and the share of draws that pass each
check); writes it to `benchmarks/out/real_log_cases.json`.

    python benchmarks/real_log_cases.py [--draws 10] [--seed 0] [--train-speeds 0.4]
        [--fourier-order N]

With `--train-speeds` only that setting runs: `--train-speeds 0.25,0.4` writes
`benchmarks/out/real_log_cases_speeds.json`. With `--fourier-order 0` the starting model (and
the true structure refitted) has no paper kinematic columns: at two speeds those columns,
functions of the product of angle and speed (Song et al. eq. (9)), take part of a twist that
is proportional to speed; the file name then ends in `_fourier0`.
"""

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import hdjax  # noqa: E402
from hdjax import plant  # noqa: E402
from hdjax.discover import (  # noqa: E402
    DiscoverOptions,
    discover,
    pipeline_signals,
    refit_structure,
)
from hdjax.effects import EncoderSkew, Harmonics, TwistHysteresis, twist_play  # noqa: E402

ARCMIN = math.pi / (180 * 60)
JOINT = hdjax.Joint(ratio=160, rated_torque=400)
RATED, K1 = 400.0, 1.0 / 6.7e4
DELAY_RTOL = 0.10
TWO_SPEEDS = (0.25, 0.4)
TEST_RATIO = 1.5


def draw(kind: str, i: int, seed: int) -> dict:
    """The parameters of draw `i` of `kind` (a dict the report keeps)."""
    rng = np.random.default_rng([seed, i, 0 if kind == "skew" else 1])
    d = {"kind": kind, "index": i, "seed": int(rng.integers(2**31))}
    if kind == "skew":
        d["skew_ms"] = float(np.exp(rng.uniform(np.log(0.3), np.log(3.0))) * rng.choice([-1, 1]))
        d["with"] = ("alone", "hysteresis", "harmonic")[i % 3]
    else:
        d["with"] = "hysteresis"
        d["skew_ms"] = 0.0
    if d["with"] == "hysteresis":
        d["hyst_arcmin"] = float(rng.uniform(0.3, 0.8))
        d["hyst_fraction"] = float(rng.uniform(0.02, 0.15))
    if d["with"] == "harmonic":
        d["harm_arcmin"] = float(rng.uniform(0.2, 0.5))
        d["harm_phase"] = float(rng.uniform(0, 2 * np.pi))
    return d


def _plant(d: dict) -> plant.PlantParams:
    eff = {"wg_compliance": True}
    if d["with"] == "hysteresis":
        # the Dahl law of the plant: level [N·m], sigma = level / (width * k1) per rad of twist
        width, level = d["hyst_fraction"] * RATED, d["hyst_arcmin"] * ARCMIN / K1
        eff["hysteresis"] = dict(model="dahl", sigma=level / (width * K1), level=level)
    if d["with"] == "harmonic":
        eff["harmonic_m"] = dict(
            orders=[2.0], amplitudes=[d["harm_arcmin"] * ARCMIN], phases=[d["harm_phase"]]
        )
    return plant.song_params(defaults=False, effects=eff)


def _joined(logs: list) -> "hdjax.Recording":
    """Recordings of one joint one after the other, 1 s apart (a gap: memory restarts)."""
    cols = {k: [] for k in ("t", "theta_m", "theta_l", "current", "torque")}
    t0 = 0.0
    for rec in logs:
        t = np.asarray(rec.t)
        cols["t"].append(t - t[0] + t0)
        t0 = cols["t"][-1][-1] + 1.0
        for k in ("theta_m", "theta_l", "current", "torque"):
            cols[k].append(np.asarray(getattr(rec, k)))
    joined = {k: np.concatenate(v) for k, v in cols.items()}
    return hdjax.make_recording(**joined, source="real-log plant, joined sweeps")


def _logs(d: dict, train_speeds: tuple[float, ...] = (0.4,)):
    params = _plant(d)
    sensors = plant.RealLogSensors(skew=d["skew_ms"] * 1e-3, offset_seed=d["seed"])
    key = jax.random.key(d["seed"])
    k1, k2 = jax.random.split(key)
    keys = jax.random.split(k1, len(train_speeds)) if len(train_speeds) > 1 else [k1]
    train = [
        plant.simulate_real_log(params, sensors, key=k, sweeps=((-1.2, 1.2),), speed=v)
        for k, v in zip(keys, train_speeds)
    ]
    train = train[0] if len(train) == 1 else _joined(train)
    test = plant.simulate_real_log(params, sensors, key=k2, sweeps=((-1.0, 1.1),), speed=0.3)
    return train, test


def _true_terms(d: dict, train) -> list:
    terms = []
    if d["skew_ms"]:
        terms.append(EncoderSkew(delay=float(d["skew_ms"]) * 1e-3, ratio=160.0))
    if d["with"] == "hysteresis":
        # behind the play the residual loop gives the state on TRAIN (its encoder noise)
        sig = pipeline_signals(train, float(JOINT.ratio), 1.0, "difference").sig
        h = twist_play(sig, K1)
        terms.append(
            TwistHysteresis(
                torque_scale=d["hyst_fraction"] * RATED, compliance=K1, initial=-1.0, play=h
            )
        )
    if d["with"] == "harmonic":
        terms.append(Harmonics("theta_m", (2.0,)))
    return terms


def run_draw(
    d: dict, train_speeds: tuple[float, ...] = (0.4,), fourier_order: int | None = None
) -> dict:
    """One draw: discover on its TRAIN and TEST logs, the true structure refitted from the same
    starting model, the checks."""
    start = time.perf_counter()
    train, test = _logs(d, train_speeds)
    options = DiscoverOptions(max_effects=3)
    if fourier_order is not None:
        options = dataclasses.replace(options, fourier_order=fourier_order)
    res = discover(train, test, JOINT, options)
    r = res.aux
    true = refit_structure(train, test, JOINT, _true_terms(d, train), options)
    delay, delay_ci = None, None
    for step in r.steps:
        amp = step.amplitude or {}
        if "delay_ms" in amp:
            delay, delay_ci = float(amp["delay_ms"]), amp.get("delay_ms_ci95")
    out = dict(d)
    out |= {
        "effects": list(r.effects),
        "start_rms": float(r.baseline.rms),
        "final_rms": float(r.final.rms),
        "start_max": float(r.baseline.max),
        "final_max": float(r.final.max),
        "true_rms": float(true.rms),
        "found_delay_ms": delay,
        "found_delay_ms_ci95": delay_ci,
        "seconds": time.perf_counter() - start,
    }
    out["test_ok"] = out["final_rms"] <= TEST_RATIO * out["true_rms"]
    if d["skew_ms"]:
        fd = out["found_delay_ms"]
        out["delay_ok"] = fd is not None and abs(fd - d["skew_ms"]) <= DELAY_RTOL * abs(
            d["skew_ms"]
        )
    else:
        out["not_worse"] = out["final_rms"] <= out["start_rms"] * (1 + 1e-9)
    return out


def _run_setting(kinds, draws, seed, speeds, fourier_order) -> list[dict]:
    """Every draw of every kind with TRAIN at `speeds`, progress on stderr."""
    rows = []
    for kind in kinds:
        for i in range(draws):
            row = run_draw(draw(kind, i, seed), speeds, fourier_order)
            rows.append(row)
            # each draw's logs have their own lengths, so their programs are compiled anew:
            # dropping the last draw's keeps a long run's compiled code (and the process's
            # memory mappings) bounded
            jax.clear_caches()
            print(
                f"[real_log_cases] TRAIN at {','.join(map(str, speeds))} rad/s, {kind} "
                f"{i + 1}/{draws}: {row['effects']} {row['start_rms']:.3g} -> "
                f"{row['final_rms']:.3g} (true {row['true_rms']:.3g}) delay "
                f"{row.get('found_delay_ms')} / {row['skew_ms']:.3g} ms",
                file=sys.stderr,
                flush=True,
            )
    return rows


def _summary(kinds, rows) -> dict:
    """Per kind, the share of draws that pass each check, whether every draw does, and the
    worst TEST error over the true structure's."""
    summary = {}
    for kind in kinds:
        sel = [r for r in rows if r["kind"] == kind]
        checks = ("delay_ok", "test_ok") if kind == "skew" else ("test_ok", "not_worse")
        summary[kind] = {c: f"{sum(r[c] for r in sel)} of {len(sel)}" for c in checks}
        for c in checks:  # a target is met when every draw passes it
            summary[kind][c.removesuffix("_ok") + "_met"] = all(r[c] for r in sel)
        summary[kind]["test_over_true_max"] = max(r["final_rms"] / r["true_rms"] for r in sel)
    return summary


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--draws", type=int, default=10, help="draws of each kind")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kinds", default="skew,hysteresis")
    ap.add_argument(
        "--train-speeds",
        default=None,
        help="comma-separated cruise speeds [rad/s] of TRAIN's sweeps (one log per speed, "
        "joined; TEST sweeps at 0.3 rad/s); default: both settings, 0.4 and 0.25,0.4",
    )
    ap.add_argument(
        "--fourier-order",
        type=int,
        default=None,
        help="order of the paper's kinematic columns (products theta*omega) in the starting "
        "model; 0 starts without them (default: DiscoverOptions' own)",
    )
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out")
    args = ap.parse_args()
    t0 = time.perf_counter()
    kinds = args.kinds.split(",")
    settings = (
        [(0.4,), TWO_SPEEDS]
        if args.train_speeds is None
        else [tuple(float(v) for v in args.train_speeds.split(","))]
    )
    out = {
        "precision": "float64",
        "draws_per_kind": args.draws,
        "seed": args.seed,
        "fourier_order": (
            DiscoverOptions().fourier_order if args.fourier_order is None else args.fourier_order
        ),
        "targets": {"delay_rtol": DELAY_RTOL, "test_over_true": TEST_RATIO},
    }
    for speeds in settings:
        rows = _run_setting(kinds, args.draws, args.seed, speeds, args.fourier_order)
        result = {"train_speeds": list(speeds), "summary": _summary(kinds, rows), "draws": rows}
        if len(speeds) == 1:
            out |= result  # one speed: the setting, at the top level as before
        else:
            out["two_speeds"] = result
    out["seconds"] = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    name = "real_log_cases"
    if args.train_speeds is not None and len(settings[0]) > 1:
        name += "_speeds"
    if args.fourier_order is not None:
        name += f"_fourier{args.fourier_order}"
    name += ".json"
    (args.out / name).write_text(json.dumps(out, indent=2, default=str))
    print(json.dumps(out, indent=2, default=str))


if __name__ == "__main__":
    main()
