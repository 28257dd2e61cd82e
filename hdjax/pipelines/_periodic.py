r"""How much the periodic angle features help, measured on plant data.

[`hdjax.network.build_features`][] can feed the angles as $\sin(k\theta)$, $\cos(k\theta)$
instead of unwrapped radians. What they are meant to carry is the kinematic error of Song et al.
eq. (9), periodic in the motor and output angles. The measurement trains the same architecture,
seed and number of steps with and without them, on the plant with its kinematic error switched
on and off (`harmonic_m`, `harmonic_l`), fitted on one recording of each of the four scenarios
and tested on fresh recordings, for two models:

- `network`: the network alone on the paper's input vector (after eq. (28)), trained by the
  jitted optax trainer;
- `residual`: a compliance model *without* kinematic terms (eq. (10) with $\theta_{err} = 0$,
  no current polynomial) plus a network on its residual with the dynamic inputs of
  [`hdjax.fit.hybrid_inputs`][], so that the kinematic error is left to the network.
"""

from __future__ import annotations

import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .. import compliance as hc, network as hn, plant
from .._features import signals
from .._joint import Joint
from .._metrics import error_metrics
from ..fit import (
    HybridEstimator,
    NetworkEstimator,
    dahl_scales,
    fit_hybrid,
    hybrid_inputs,
    make_hybrid,
)
from ..report import markdown_table
from ._compare import _concat, _join

KINEMATIC_EFFECTS = ("harmonic_m", "harmonic_l")
"""The plant effects that make up its kinematic error (switched off for the 'off' case)."""


def periodic_features_effect(
    *,
    duration: float = 60.0,
    hidden: tuple[int, ...] = (32,),
    steps: int = 4000,
    seeds: tuple[int, ...] = (0, 1),
    verbose: bool = False,
) -> dict:
    """Held-out torque error with and without periodic angle features (see module docstring).

    **Arguments:**

    - `duration`: seconds per scenario recording.
    - `hidden`, `steps`: network widths and Adam steps (learning rate 0.01, batches of 1024),
      the same for every case.
    - `seeds`: network initialisation / minibatch seeds; every case runs every seed.

    **Returns:** a dict with `rows` (per model, kinematic error on/off, periodic or not, seed
    and scenario: `rms_pct`, `max_pct` of rated torque), `summary` (the same averaged over
    seeds, with `rms_ratio` = RMS without / with periodic features) and `settings`.
    """
    params = plant.song_params()
    joint = Joint(ratio=float(params.ratio), rated_torque=float(params.rated_torque))
    tau0 = joint.rated_torque
    say = print if verbose else (lambda *a, **k: None)
    structure = hc.ComplianceModel.paper(joint, per_segment=False, kinematic="none", poly_order=0)
    rows = []
    for kin in (True, False):
        effects = None if kin else {name: None for name in KINEMATIC_EFFECTS}
        sim = lambda s, k: plant.simulate_scenario(
            s, key=jax.random.key(k), duration=duration, effects=effects
        )
        train = [sim(s, 0) for s in plant.SCENARIOS]
        test = {s: sim(s, 1) for s in plant.SCENARIOS}
        train_all = _join(train)
        sig = _concat([signals(r, joint) for r in train])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ls = hc.calibrate_lstsq(structure, (sig, jnp.concatenate([r.torque for r in train])))
        ls = ls.value
        scales = dahl_scales(ls)
        for periodic in (False, True):
            feats = hn.build_features(train_all, joint, periodic=periodic)

            residual_options = dict(periodic=periodic, twist_rate=True, hysteresis=scales)
            inp = _concat(
                [hybrid_inputs(r, joint, compliance=ls, **residual_options) for r in train]
            )
            for seed in seeds:
                t0 = time.perf_counter()
                net = hn.Network(feats.layout, hidden, key=jax.random.key(10 + seed))
                res = hn.train_optax(
                    net,
                    feats.x,
                    train_all.torque,
                    learning_rate=1e-2,
                    steps=steps,
                    batch_size=1024,
                    key=jax.random.key(11 + seed),
                )
                model = make_hybrid(
                    inp, compliance=ls, hidden=hidden, key=jax.random.key(20 + seed)
                )
                hyb = fit_hybrid(
                    model,
                    inp,
                    steps=steps,
                    learning_rate=1e-2,
                    batch_size=1024,
                    key=jax.random.key(21 + seed),
                ).value
                estimators = {
                    "network": NetworkEstimator(res.value, joint),
                    "residual": HybridEstimator(hyb, ls, joint, tuple(residual_options.items())),
                }
                for name, estimator in estimators.items():
                    for s, rec in test.items():
                        m = error_metrics(np.asarray(estimator.estimate(rec)), rec.torque, tau0)
                        rows.append(
                            {
                                "model": name,
                                "kinematic_error": kin,
                                "periodic": periodic,
                                "seed": seed,
                                "scenario": s,
                                "rms_pct": m.rms_pct,
                                "max_pct": m.max_pct,
                            }
                        )
                say(
                    f"kinematic error {'on' if kin else 'off'}, periodic={periodic}, seed {seed}: "
                    f"{time.perf_counter() - t0:.1f} s"
                )
    return {
        "rows": rows,
        "summary": summarise(rows),
        "settings": {
            "duration_s": duration,
            "hidden": list(hidden),
            "steps": steps,
            "optimizer": "adam lr 0.01, batch 1024",
            "seeds": list(seeds),
            "orders": [1, 2],
            "plant": "hdjax.plant.song_params() defaults; 'off' removes "
            + ", ".join(KINEMATIC_EFFECTS),
            "residual_compliance": "shared coefficients, 5 segments, no kinematic terms, no "
            "current polynomial",
            "train": "one recording of each scenario (key 0)",
            "test": "fresh recordings (key 1)",
            "rated_torque": tau0,
        },
    }


def summarise(rows: list[dict]) -> list[dict]:
    """Mean RMS and maximum error over seeds per (model, kinematic error, scenario), without and
    with periodic features, and their ratio."""
    keys = list(dict.fromkeys((r["model"], r["kinematic_error"], r["scenario"]) for r in rows))
    out = []
    for model, kin, s in keys:

        def mean(periodic, field, model=model, kin=kin, s=s):
            sel = [
                r[field]
                for r in rows
                if (r["model"], r["kinematic_error"], r["scenario"], r["periodic"])
                == (model, kin, s, periodic)
            ]
            return float(np.mean(sel))

        out.append(
            {
                "model": model,
                "kinematic_error": kin,
                "scenario": s,
                "rms_pct_plain": mean(False, "rms_pct"),
                "rms_pct_periodic": mean(True, "rms_pct"),
                "max_pct_plain": mean(False, "max_pct"),
                "max_pct_periodic": mean(True, "max_pct"),
                "rms_ratio": mean(False, "rms_pct") / mean(True, "rms_pct"),
            }
        )
    return out


def format_periodic_table(result: dict) -> str:
    """The summary of [`hdjax.pipelines.periodic_features_effect`][] as a Markdown table."""
    header = ["model", "kinematic error", "scenario", "RMS % plain", "RMS % periodic"]
    header += ["max % plain", "max % periodic", "RMS plain / periodic"]
    rows = [
        [r["model"], "on" if r["kinematic_error"] else "off", r["scenario"]]
        + [f"{r['rms_pct_plain']:.3f}", f"{r['rms_pct_periodic']:.3f}"]
        + [f"{r['max_pct_plain']:.2f}", f"{r['max_pct_periodic']:.2f}", f"{r['rms_ratio']:.2f}"]
        for r in result["summary"]
    ]
    return markdown_table(header, rows)
