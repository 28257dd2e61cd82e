"""How far the encoder's noise moves a Dahl hysteresis state, on the real-log plant.

The Dahl law (Song et al. Fig. 2) is rate-independent: every change of its driver moves the
state, $z_k = z_{k-1} + \\frac{\\Delta u_k}{T}(1 - z_{k-1}\\,\\mathrm{sgn}\\,\\Delta u_k)$. Driven
by the *measured* twist over the compliance (what `TwistHysteresis` reads), white encoder
noise adds steps that dwarf the motion's own on a slow sweep (a fraction of a N·m per sample,
against hundredths of a N·m per sample of a 0.4 rad/s sweep under gravity): the state
random-walks towards zero at rest and hovers far from saturation while moving, where the
joint's own state holds and saturates.

Each draw of `real_log_cases.py`'s hysteresis kind simulates its TRAIN log with the plant's
noise-free signals (`with_truth`), and compares with the joint's own state (the same law
driven by the noise-free twist, from the same initial state, loaded the other way):

- the state driven by the raw measured twist (no play);
- the same after a play operator (dead band, `hdjax.effects.play`) of half-width $m\\,\\sigma$ on
  the driver, for $m$ in `--widths`: $\\sigma$ the driver's noise per sample as the residual
  loop measures it (`hdjax.effects.driver_noise`, from the second differences; the loop uses
  $m = 3$), checked against the noise measured where the joint rests (a robust MAD of its
  steps, with the plant's truth telling rest from motion), and the ratio of the largest to the
  smallest of its deviations from the second, third and fourth differences
  (`hdjax.effects.noise_deviations`; white noise is read below `WHITE_SPREAD`);
- the carry of the initial state at the motion's start ($P$ of `hdjax.effects.dahl_initial`).

Precision: float64 (x64 on). Prints JSON; writes `benchmarks/out/dahl_noise.json`.

    python benchmarks/dahl_noise.py [--draws 10] [--seed 0] [--widths 2,3,4]
"""

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import real_log_cases as cases  # noqa: E402

from hdjax import plant, twist  # noqa: E402
from hdjax.effects import (  # noqa: E402
    dahl_initial,
    dahl_state_numpy,
    driver_noise,
    noise_deviations,
    play,
)


def state(driver: np.ndarray, width: float) -> np.ndarray:
    """The Dahl state of `driver` started loaded the other way (-1 times the first motion's
    direction), as `TwistHysteresis(initial=-1)` computes it."""
    return dahl_state_numpy(driver, width) - dahl_initial(driver, width)


def one_draw(d: dict, widths: list[float]) -> dict:
    params = cases._plant(d)
    sensors = plant.RealLogSensors(skew=0.0, offset_seed=d["seed"])
    key, _ = jax.random.split(jax.random.key(d["seed"]))
    rec, truth = plant.simulate_real_log(
        params, sensors, key=key, sweeps=((-1.2, 1.2),), speed=0.4, with_truth=True
    )
    width = d["hyst_fraction"] * cases.RATED  # the Dahl width [N·m] of the plant's law
    ratio = float(cases.JOINT.ratio)
    measured = np.asarray(twist(rec.theta_m, rec.theta_l, ratio, 1.0)) / cases.K1
    true = np.asarray(twist(truth["true_theta_m"], truth["true_theta_l"], ratio, 1.0)) / cases.K1
    speed = np.gradient(np.asarray(truth["true_theta_l"]), np.asarray(rec.t))
    rest = np.abs(speed) < 1e-3
    steps = np.diff(measured)[rest[1:]]
    at_rest = float(1.4826 * np.median(np.abs(steps - np.median(steps))) / np.sqrt(2))
    sigma = driver_noise(measured)
    devs = noise_deviations(measured)
    motion = int(np.flatnonzero(~rest)[0])
    z_true, z_meas = state(true, width), state(measured, width)
    rms = lambda z: float(np.sqrt(np.mean((z - z_true) ** 2)))  # noqa: E731
    carry = np.cumprod(
        np.maximum(0.0, 1.0 - np.abs(np.diff(measured, prepend=measured[0])) / width)
    )
    return {
        "index": d["index"],
        "seed": d["seed"],
        "width_nm": width,
        "driver_noise_nm": sigma,
        "driver_noise_at_rest_nm": at_rest,
        "white_spread": max(devs) / min(devs),
        "motion_start_sample": motion,
        "initial_carry_at_motion": float(carry[motion]),
        "state_error_rms_measured": rms(z_meas),
        "state_error_rms_play": {
            f"{m:g}": rms(state(play(measured, m * sigma), width)) for m in widths
        },
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--draws", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--widths", default="2,3,4", help="play half-widths, in driver noise sigmas")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out")
    args = ap.parse_args()
    widths = [float(v) for v in args.widths.split(",")]
    t0 = time.perf_counter()
    rows = []
    for i in range(args.draws):
        rows.append(one_draw(cases.draw("hysteresis", i, args.seed), widths))
        print(f"[dahl_noise] {i + 1}/{args.draws}: {rows[-1]}", file=sys.stderr, flush=True)
    med = lambda key: float(np.median([r[key] for r in rows]))  # noqa: E731
    out = {
        "benchmark": "Dahl state driven by the measured twist against the joint's own",
        "precision": "float64",
        "draws": rows,
        "median": {
            "driver_noise_nm": med("driver_noise_nm"),
            "driver_noise_at_rest_nm": med("driver_noise_at_rest_nm"),
            "white_spread_max": max(r["white_spread"] for r in rows),
            "initial_carry_at_motion": med("initial_carry_at_motion"),
            "state_error_rms_measured": med("state_error_rms_measured"),
            "state_error_rms_play": {
                f"{m:g}": float(np.median([r["state_error_rms_play"][f"{m:g}"] for r in rows]))
                for m in widths
            },
        },
        "seconds": time.perf_counter() - t0,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "dahl_noise.json").write_text(json.dumps(out, indent=2))
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
