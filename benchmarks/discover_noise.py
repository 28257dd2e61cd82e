"""The residual loop on clean joints with white encoder noise: false discoveries and the
coverage of a true effect's interval, through `discover` as a user runs it.

Each joint is simulated by `hdjax.plant.simulate` (the bench's `slow` or `fast` scenario in
turn for the clean joints, `slow` for the coverage joints; 21-bit encoders), sampled at 1, 2
or 4 kHz (drawn), and its load encoder reads white noise of 0.3-2 arcsec (drawn) before it is
quantised. TRAIN and TEST are cut from the recording by blocks (every 4th block of 100 samples
held out).

- `false`: `--joints` joints with nothing undeclared (compliance and wave-generator compliance
  drawn, no damping). Target: at most 1 in 20 gets an effect.
- `coverage`: `--joints` joints with one θ_m order-2 harmonic of 0.1-0.5 arcmin (drawn
  amplitude and phase). Target: the 95 % interval of `harmonic:theta_m:2` that `discover`
  reports covers the true amplitude in 90-99 % of the joints (a joint where the harmonic is not
  found counts as not covered), and every interval contains its own estimate.

Precision: float64 (x64 on). Prints JSON; writes `benchmarks/out/discover_noise.json`.

    python benchmarks/discover_noise.py [--joints 20] [--coverage-joints 50] [--seed 0]
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import hdjax  # noqa: E402
from hdjax import plant  # noqa: E402
from hdjax.discover import DiscoverOptions, discover  # noqa: E402

ARCMIN = math.pi / (180 * 60)
ARCSEC = ARCMIN / 60
JOINT = hdjax.Joint(ratio=160, rated_torque=400)
OPTIONS = DiscoverOptions(max_effects=3, current_scale=10.0)
RATES = (1000.0, 2000.0, 4000.0)
DT = 2.5e-4
HARMONIC = "harmonic:theta_m:2"


def noisy_joint(rng: np.random.Generator, i: int, harmonic: bool, duration: float):
    """One drawn joint's recording and what was drawn (noise, rate, the harmonic's amplitude
    [rad] when `harmonic`)."""
    eff = {"wg_compliance": dict(coefficients=[rng.uniform(0.01, 0.03), 0.0, 0.002])}
    amp = None
    if harmonic:
        amp = float(rng.uniform(0.1, 0.5) * ARCMIN)
        phase = float(rng.uniform(0, 2 * np.pi))
        eff["harmonic_m"] = dict(orders=[2.0], amplitudes=[amp], phases=[phase])
    p = plant.song_params(defaults=False, effects=eff, damping=0.0)
    p = eqx.tree_at(lambda q: q.compliance, p, p.compliance * rng.uniform(0.85, 1.15))
    rate = float(rng.choice(RATES))
    noise = float(rng.uniform(0.3, 2.0))
    key = jax.random.key(int(rng.integers(2**31)))
    k_drive, k_sim = jax.random.split(key)
    # the coverage joints all move slowly (many motor turns at moderate speed, as the interval
    # tests of the suite); the clean joints alternate
    scenario = "slow" if harmonic or i % 2 else "fast"
    drive = plant.scenario_drive(scenario, p, duration=duration, dt=DT, key=k_drive)
    rec = plant.simulate(p, drive, key=k_sim, dt=DT, output_period=1.0 / rate)
    # white noise on the load encoder, read through its 21-bit quantiser
    q = 2 * np.pi / 2**21
    th = np.asarray(rec.theta_l) + noise * ARCSEC * rng.standard_normal(rec.n_samples)
    rec = eqx.tree_at(lambda r: r.theta_l, rec, jnp.asarray(np.round(th / q) * q))
    return rec, {"scenario": scenario, "rate_hz": rate, "noise_arcsec": noise, "amp_rad": amp}


def split(rec, block=100, every=4):
    """TRAIN and TEST by blocks: every `every`-th block of `block` samples held out."""
    idx = np.arange(rec.n_samples) // block
    return rec.select(idx % every != every - 1), rec.select(idx % every == every - 1)


def harmonic_interval(res) -> dict | None:
    """The reported amplitude and 95 % interval [arcsec] of the order-2 θ_m harmonic, if
    `discover` added it."""
    for step in res.aux.steps:
        amp = step.amplitude or {}
        if step.key == HARMONIC and "arcsec" in amp:
            return {"arcsec": float(amp["arcsec"]), "ci95": [float(v) for v in amp["arcsec_ci95"]]}
    return None


def run(kind: str, joints: int, seed: int, duration: float) -> dict:
    """Run `joints` draws of `kind` ("false" or "coverage") and count the checks."""
    rng = np.random.default_rng([seed, 0 if kind == "false" else 1])
    rows = []
    for i in range(joints):
        rec, drawn = noisy_joint(rng, i, kind == "coverage", duration)
        train, test = split(rec)
        res = discover(train, test, JOINT, OPTIONS)
        row = drawn | {"effects": list(res.aux.effects)}
        if kind == "coverage":
            iv = harmonic_interval(res)
            truth = drawn["amp_rad"] / ARCSEC
            row |= {"truth_arcsec": truth, "interval": iv}
            row["covers"] = iv is not None and iv["ci95"][0] <= truth <= iv["ci95"][1]
            row["contains_estimate"] = iv is None or iv["ci95"][0] <= iv["arcsec"] <= iv["ci95"][1]
            row["others"] = [e for e in res.aux.effects if e != HARMONIC]
        rows.append(row)
        print(f"[discover_noise] {kind} {i + 1}/{joints}: {row['effects']}", file=sys.stderr)
    if kind == "false":
        n = sum(bool(r["effects"]) for r in rows)
        return {"joints_with_an_effect": n, "of": joints, "met": n <= joints / 20, "draws": rows}
    cov = float(np.mean([r["covers"] for r in rows]))
    own = all(r["contains_estimate"] for r in rows)
    other = sum(bool(r["others"]) for r in rows)
    return {
        "coverage": cov,
        "covered": int(sum(r["covers"] for r in rows)),
        "of": joints,
        "every_interval_contains_its_estimate": own,
        "joints_with_another_effect": other,
        "met": 0.90 <= cov <= 0.99 and own,
        "draws": rows,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--joints", type=int, default=20, help="clean joints (false discoveries)")
    ap.add_argument("--coverage-joints", type=int, default=50)
    ap.add_argument("--duration", type=float, default=10.0, help="seconds per joint")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out")
    args = ap.parse_args()
    t0 = time.perf_counter()
    out = {
        "precision": "float64",
        "seed": args.seed,
        "duration_s": args.duration,
        "targets": {"false": "at most 1 in 20", "coverage": "90-99 %, own estimate inside"},
        "false": run("false", args.joints, args.seed, args.duration),
        "coverage": run("coverage", args.coverage_joints, args.seed, args.duration),
    }
    out["seconds"] = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "discover_noise.json").write_text(json.dumps(out, indent=2, default=str))
    print(json.dumps(out, indent=2, default=str))


if __name__ == "__main__":
    main()
