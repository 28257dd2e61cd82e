"""The residual loop on the plant cases: what it finds and how close it gets to the truth.

For each case the plant (`hdjax.plant`) simulates TRAIN and TEST (different seeds) with one or
more effects the starting model does not declare; the loop runs on TRAIN and reports on TEST,
and the true structure (the starting model plus the true effects' terms) is refitted by the same
pipeline for reference. Writes `benchmarks/out/discover_cases.json` and the Markdown table
`docs/discover-cases.md` (included by the docs; the numbers are this run's, never pasted).

    python benchmarks/discover_cases.py [--duration 30] [--cases a,b,...] [--lara8]

With `--lara8`, also joint 3 of the LARA8 log under three TRAIN/TEST splits.
"""

import argparse
import datetime
import json
import math
import os
import platform
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
from hdjax.effects import (  # noqa: E402
    Backlash,
    Column,
    ColumnTimesTorque,
    Coulomb,
    Harmonics,
    Ripple,
    Stribeck,
    TwistHysteresis,
    TwistRate,
    Viscous,
    twist_compliance,
)

ARCMIN = math.pi / (180 * 60)
JOINT = hdjax.Joint(ratio=160, rated_torque=400)
RATED, K1 = 400.0, 1.0 / 6.7e4


def _hyst(model, amp_arcmin, frac):
    level = amp_arcmin * ARCMIN / K1
    tc = frac * RATED
    if model == "dahl":
        return dict(model="dahl", sigma=level / (tc * K1), level=level)
    beta = 1.0 / (tc * K1)
    return dict(model="bouc_wen", a=level * beta, beta=beta, gamma=0.0, n=1)


# name: (scenario, plant effects, plant overrides, true terms (callable of TRAIN data))
CASES = {
    "clean": ("slow", {}, {"damping": 0.0}, lambda d: []),
    "harmonic_m 2/rev 0.3 arcmin": (
        "slow",
        {"harmonic_m": dict(orders=[2.0], amplitudes=[0.3 * ARCMIN], phases=[0.3])},
        {},
        lambda d: [Harmonics("theta_m", (2.0,))],
    ),
    "harmonic_m 2/rev 0.25 arcmin": (
        "slow",
        {"harmonic_m": dict(orders=[2.0], amplitudes=[0.25 * ARCMIN], phases=[0.3])},
        {},
        lambda d: [Harmonics("theta_m", (2.0,))],
    ),
    "harmonic_m 2-2/N": (
        "slow",
        {"harmonic_m": dict(orders=[2 - 2 / 160], amplitudes=[0.3 * ARCMIN], phases=[0.3])},
        {},
        lambda d: [Harmonics("theta_m", (2 - 2 / 160,))],
    ),
    "harmonic_l order 4": (
        "slow",
        {"harmonic_l": dict(orders=[4.0], amplitudes=[0.3 * ARCMIN], phases=[0.5])},
        {},
        lambda d: [Harmonics("theta_l", (4.0,))],
    ),
    "coulomb_l": (
        "fast",
        {"coulomb_l": dict(level=8.0, smoothing=5e-3)},
        {},
        lambda d: [Coulomb("omega_l", 5e-3)],
    ),
    "ripple_m 2/rev 3 %": (
        "slow",
        {"ripple_m": dict(orders=[2.0], amplitudes=[0.03], phases=[0.4])},
        {},
        lambda d: [Ripple("theta_m", 2.0, RATED)],
    ),
    "stribeck_l": (
        "fast",
        {
            "coulomb_l": dict(level=6.0, smoothing=5e-3),
            "stribeck_l": dict(peak=15.0, speed=0.03, smoothing=5e-3),
        },
        {},
        lambda d: [Coulomb("omega_l", 5e-3), Stribeck("omega_l", 5e-3, 0.03)],
    ),
    "viscous_l": (
        "slow",
        {"viscous_l": dict(coefficient=20.0)},
        {},
        lambda d: [Viscous("omega_l")],
    ),
    "backlash": ("slow", {"backlash": True}, {}, lambda d: [Backlash(8.0)]),
    "damping": ("fast", {}, {"damping": 200.0}, lambda d: [TwistRate(ratio=160.0)]),
    "temperature compliance": (
        "slow",
        {"temperature": dict(alpha=0.02, drift=0.1, heating=0.0)},
        {},
        lambda d: [
            ColumnTimesTorque("temperature", *_moments(d, "temperature"), torque_scale=float(RATED))
        ],
    ),
    "temperature offset": (
        "slow",
        {"temperature": dict(alpha=0.0, beta=2e-5, drift=0.3, heating=0.0)},
        {},
        lambda d: [Column("temperature", *_moments(d, "temperature"))],
    ),
    "hysteresis Dahl 1 arcmin 10 %": (
        "fast",
        {"hysteresis": _hyst("dahl", 1.0, 0.10)},
        {},
        lambda d: [TwistHysteresis(0.10 * RATED, _k(d))],
    ),
    "hysteresis Dahl 0.5 arcmin 3 %": (
        "fast",
        {"hysteresis": _hyst("dahl", 0.5, 0.03)},
        {},
        lambda d: [TwistHysteresis(0.03 * RATED, _k(d))],
    ),
    "hysteresis Bouc-Wen 2 arcmin 20 %": (
        "fast",
        {"hysteresis": _hyst("bouc_wen", 2.0, 0.20)},
        {},
        lambda d: [TwistHysteresis(0.20 * RATED, _k(d))],
    ),
    "two: harmonic_m 3 + backlash": (
        "slow",
        {
            "harmonic_m": dict(orders=[3.0], amplitudes=[0.3 * ARCMIN], phases=[0.1]),
            "backlash": True,
        },
        {},
        lambda d: [Harmonics("theta_m", (3.0,)), Backlash(8.0)],
    ),
    "three: hysteresis + harmonic_m 2 + temperature": (
        "slow",
        {
            "hysteresis": _hyst("dahl", 1.0, 0.10),
            "harmonic_m": dict(orders=[2.0], amplitudes=[0.3 * ARCMIN], phases=[0.3]),
            "temperature": dict(alpha=0.02, drift=0.1, heating=0.0),
        },
        {},
        lambda d: [
            TwistHysteresis(0.10 * RATED, _k(d)),
            Harmonics("theta_m", (2.0,)),
            ColumnTimesTorque("temperature", *_moments(d, "temperature"), torque_scale=RATED),
        ],
    ),
}


def _moments(rec, name):
    x = np.asarray(rec.extras[name])
    return float(x.mean()), float(x.std())


def _k(rec):
    data = pipeline_signals(rec, JOINT.ratio, JOINT.twist_sign, "difference")
    return twist_compliance(data.sig, data.torque, RATED)


def run_case(name, duration):
    scenario, effects, overrides, truth = CASES[name]
    params = plant.song_params(
        defaults=False, effects={"wg_compliance": True, **effects}, **overrides
    )
    train, test = _two(scenario, params, duration)
    t0 = time.perf_counter()
    res = discover(train, test, JOINT, DiscoverOptions(max_effects=3))
    seconds = time.perf_counter() - t0
    terms = truth(train)
    true = refit_structure(train, test, JOINT, terms) if terms else res.aux.baseline
    return dict(
        case=name,
        scenario=scenario,
        train_samples=train.n_samples,
        effects=res.aux.effects,
        test_rms_start=res.aux.baseline.rms,
        test_rms_end=res.aux.final.rms,
        test_max_start=res.aux.baseline.max,
        test_max_end=res.aux.final.max,
        cv_torque_rms=[res.aux.baseline_cv_torque_rms] + [s.cv_torque_rms for s in res.aux.steps],
        true_structure_rms=true.rms,
        ratio_to_true=res.aux.final.rms / true.rms,
        amplitudes=[s.amplitude for s in res.aux.steps],
        unexplained=res.aux.unexplained,
        loop_seconds=seconds,
    )


def _two(scenario, params, duration):
    out = []
    for seed in (11, 12):
        r = plant.simulate_scenario(
            scenario,
            key=jax.random.PRNGKey(seed),
            duration=duration,
            params=params,
            output_period=2e-3,
        )
        out.append(r.select(np.asarray(r.t) >= 0.5))
    return out


def lara8_splits():
    """Joint 3 of the LARA8 log under the three TRAIN/TEST splits of `lara8_splits.py`."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from lara8_splits import load, splits

    full, joint, opts = load()
    rows = []
    for name, is_test in splits(full).items():
        train, test = full.select(~is_test), full.select(is_test)
        res = discover(train, test, joint, opts)
        rows.append(
            dict(
                split=name,
                train_samples=train.n_samples,
                test_samples=test.n_samples,
                effects=res.aux.effects,
                test_rms_start=res.aux.baseline.rms,
                test_rms_end=res.aux.final.rms,
                reduction=1.0 - res.aux.final.rms / res.aux.baseline.rms,
                cv_torque_rms=[res.aux.baseline_cv_torque_rms]
                + [s.cv_torque_rms for s in res.aux.steps],
            )
        )
    return rows


def markdown(out) -> str:
    lines = [
        "<!-- generated by benchmarks/discover_cases.py; do not edit by hand -->",
        "",
        f"Plant cases ({out['duration_s']:g} s records at 2 ms, TRAIN and TEST from different "
        f"seeds; run {out['date']}, {out['machine']}, {out['cpu_count']} CPUs, float64).",
        "",
        "| case | effects added | TEST RMS start → end [N·m] | true structure [N·m] | end / true |",
        "|---|---|---|---|---|",
    ]
    for r in out["cases"]:
        eff = ", ".join(f"`{e}`" for e in r["effects"]) or "none"
        lines.append(
            f"| {r['case']} | {eff} | {r['test_rms_start']:.3g} → {r['test_rms_end']:.3g} | "
            f"{r['true_structure_rms']:.3g} | {r['ratio_to_true']:.2f} |"
        )
    if out.get("lara8"):
        lines += [
            "",
            "LARA8 joint 3 (`validate.csv`), three TRAIN/TEST splits:",
            "",
            "| split | effects added | TEST RMS start → end [N·m] | reduction |",
            "|---|---|---|---|",
        ]
        for r in out["lara8"]:
            eff = ", ".join(f"`{e}`" for e in r["effects"]) or "none"
            lines.append(
                f"| {r['split']} | {eff} | {r['test_rms_start']:.3g} → "
                f"{r['test_rms_end']:.3g} | {r['reduction']:.0%} |"
            )
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--cases", default="", help="comma-separated case names (default all)")
    ap.add_argument("--lara8", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out")
    ap.add_argument("--markdown", type=Path, default=ROOT / "docs" / "discover-cases.md")
    args = ap.parse_args()
    names = [c for c in args.cases.split(",") if c] or list(CASES)
    t0 = time.perf_counter()
    out = dict(
        benchmark="discover plant cases",
        date=datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        machine=platform.processor() or platform.machine(),
        cpu_count=os.cpu_count(),
        load_average=os.getloadavg()[0],
        precision="float64",
        duration_s=args.duration,
        cases=[],
    )
    for name in names:
        row = run_case(name, args.duration)
        out["cases"].append(row)
        print(
            json.dumps(
                {
                    k: row[k]
                    for k in (
                        "case",
                        "effects",
                        "test_rms_start",
                        "test_rms_end",
                        "true_structure_rms",
                    )
                }
            ),
            flush=True,
        )
    if args.lara8:
        out["lara8"] = lara8_splits()
    out["seconds"] = time.perf_counter() - t0
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "discover_cases.json").write_text(json.dumps(out, indent=2, default=str))
    args.markdown.write_text(markdown(out))
    print(json.dumps({"seconds": out["seconds"], "markdown": str(args.markdown)}))


if __name__ == "__main__":
    main()
