"""LARA8 joint 3 against its flange force/torque sensor: the comparison table and its page.

Run from the repository root: `python benchmarks/lara8_reference.py [--seeds 5] [--out DIR]`.
It reads experiments/lara8_fts.toml (data ../shared/data/lara8/validate.csv, reference
tau_3 = target_joint_torque_3 + J_3^T W), calibrates on the calibration blocks, scores every
method on the held-out blocks against that reference, prints JSON (machine, precision, date)
and writes docs/lara8-reference.md with the table and its reading.
"""

from __future__ import annotations

import argparse
import copy
import datetime
import json
import os
import platform
import time
import warnings
from pathlib import Path

import jax
import numpy as np

import hdjax
from hdjax.config import load_experiment
from hdjax.pipelines import build_dataset, internal as P
from hdjax.reference import (
    detect_holds,
    fit_offset_with_payload,
    jacobian_columns,
    joint_torque,
    load_dh_table,
    tool_rotations,
)

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "experiments" / "lara8_fts.toml"
THESIS = {"current_rms": 6.48, "gru_rms": 2.67}
"""The thesis' figures on this sweep against the F/T-derived external torque [N·m]."""
ISSUE_DIRECT = {"rms": 19.9, "bias": 4.7}
"""The direct computation from the log quoted with the task: current vs model + J^T W [N·m]."""


def _err(est, ref) -> dict:
    e = np.asarray(est, np.float64) - np.asarray(ref, np.float64)
    return {
        "rms": float(np.sqrt(np.mean(e**2))),
        "max": float(np.max(np.abs(e))),
        "bias": float(np.mean(e)),
        "std": float(np.std(e)),
        "n": int(e.size),
    }


def _raw_columns(path: Path, names: list[str]) -> dict[str, np.ndarray]:
    # theta_m, theta_l, current are not used here; any numeric columns will do
    cmap = hdjax.ColumnMap.from_dict(
        {
            "columns": {
                "t": "Timestamp",
                "theta_m": "joint_angles_3",
                "theta_l": "joint_angles_3",
                "current": "joint_torque_current_3",
            },
            "extras": {n: n for n in names},
        }
    )
    rec = hdjax.load_csv(path, cmap, check_units=False)
    return {"t": np.asarray(rec.t), **{n: np.asarray(rec.extras[n]) for n in names}}


def whole_log(exp) -> dict:
    """The current-based torque against several references over the whole log (no split)."""
    spec = exp["data"]["reference"]
    path = (exp.base_dir / exp["data"]["train"][0]).resolve()
    cur = "joint_torque_current_3"
    raw = _raw_columns(path, spec["angles"] + spec["wrench"] + [spec["model_torque"], cur])
    q = np.stack([raw[c] for c in spec["angles"]], 1)
    w = np.stack([raw[c] for c in spec["wrench"]], 1)
    arm = load_dh_table(exp.base_dir / spec["dh"])
    j = spec["joint"] - 1
    tool = np.asarray(jacobian_columns(arm, q, j, frame="tool"))
    base = np.asarray(jacobian_columns(arm, q, j, frame="base"))
    tau_model = raw[spec["model_torque"]]
    holds = detect_holds(w, raw["t"])
    fresh = holds.fresh
    ref_tool = joint_torque(tool, w, tau_model)
    ref_base = joint_torque(base, w, tau_model)
    offset = fit_offset_with_payload(w[fresh], np.asarray(tool_rotations(arm, q[fresh])))
    ref_fit = joint_torque(tool, w, tau_model, offset=offset.wrench)
    c = raw[cur]
    return {
        "rows": int(q.shape[0]),
        "fresh_rows": holds.n_fresh,
        "update_period_ms": 1e3 * holds.median_period_s,
        "current_vs_tool_all_rows": _err(c, ref_tool),
        "current_vs_tool_fresh_rows": _err(c[fresh], ref_tool[fresh]),
        "current_vs_base_all_rows": _err(c, ref_base),
        "current_vs_fit_offset_fresh_rows": _err(c[fresh], ref_fit[fresh]),
        "current_vs_model_torque_only": _err(c[fresh], tau_model[fresh]),
        "external_torque_range": [
            float(np.min(ref_tool - tau_model)),
            float(np.max(ref_tool - tau_model)),
        ],
        "offset_fit": offset.as_dict(),
    }


def deformation_rows(exp) -> tuple[dict, dict]:
    """The deterministic rows of the held-out table (the compliance model as configured, the
    residual loop's start and end, the current-based torque), and the per-row curves the
    figure draws. A test recomputes these to check the page is not stale."""
    from hdjax.discover import DiscoverOptions, discover

    ds = build_dataset(exp)
    joint = ds.joint
    train, (test_name, test) = ds.train[0], next(iter(ds.test.items()))
    ref = np.asarray(test.torque)
    rows: dict = {}
    # -- the compliance model as configured in the experiment's [model] -----------------------
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model0 = P.build_model(exp, joint, P.current_scale(exp, ds.train))
        cal = P.calibrate(exp, model0, ds.train)
    est = P.estimate_model(cal.value, {test_name: test})[test_name]
    rows["song_config"] = _err(est.torque, ref)
    rows["song_config"]["notes"] = [str(w.message) for w in caught] + list(cal.stats["dropped"])
    e = np.asarray(est.torque) - ref
    worst = int(np.argmax(np.abs(e)))
    rows["song_config"]["worst"] = {
        "t_s": float(test.t[worst] - train.t[0]),
        "reference": float(ref[worst]),
        "estimate": float(est.torque[worst]),
    }
    rows["song_config"]["out_of_range"] = int(np.sum(~np.asarray(est.in_range)))
    rows["song_config"]["calibrated_range"] = [float(v) for v in cal.value.torque_range]
    # -- the residual loop on the same calibration blocks -------------------------------------
    opts = DiscoverOptions(
        n_segments=exp["model"]["n_segments"],
        poly_order=exp["model"]["poly_order"],
        fourier_order=exp["model"]["fourier_order"],
    )
    # TRAIN and TEST are cut from one log: the loop sees it whole (its memory states and
    # differences run through the held-out rows), and scores each part on its own rows
    whole_exp = copy.deepcopy(exp)
    whole_exp["data"]["split"] = 0.0
    whole = build_dataset(whole_exp).train[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = discover(train, test, joint, opts, context=whole)
    rows["song_discover_start"] = _err(res.aux.baseline_estimate, ref)
    final_est = res.aux.steps[-1].torque_estimate if res.aux.steps else res.aux.baseline_estimate
    rows["song_discover_final"] = _err(final_est, ref)
    rows["song_discover_final"]["effects"] = list(res.aux.effects)
    rows["song_discover_final"]["start"] = res.aux.start_structure.get("label", "")
    rows["current"] = _err(np.asarray(test.current), ref)
    curves = {
        "reference": ref,
        "as configured": np.asarray(est.torque),
        "after discover": np.asarray(final_est),
        "current-based": np.asarray(test.current),
    }
    extra = {"train": train, "test": test, "ds": ds, "notes": list(res.aux.notes)}
    return rows, {"curves": curves, **extra}


def held_out(exp, seeds: int) -> dict:
    """Every method calibrated on the calibration blocks, scored on the held-out blocks."""
    rows, kept = deformation_rows(exp)
    ds, train, test = kept["ds"], kept["train"], kept["test"]
    joint, test_name = ds.joint, next(iter(ds.test))
    ref = kept["curves"]["reference"]
    # -- the network, over several seeds ------------------------------------------------------
    nets = []
    for seed in range(seeds):
        net, _ = P.train_network(exp, joint, ds.train, seed)
        nets.append(_err(P.estimate_network(net, joint, {test_name: test})[test_name], ref))
    rows["network"] = {
        k: float(np.median([n[k] for n in nets])) for k in ("rms", "max", "bias", "std")
    }
    rows["network"]["rms_range"] = [min(n["rms"] for n in nets), max(n["rms"] for n in nets)]
    rows["network"]["seeds"] = seeds
    rows["network"]["n"] = nets[0]["n"]
    tw = np.asarray(hdjax.twist(train.theta_m, train.theta_l, joint.ratio, joint.twist_sign))
    corr = {
        "twist_vs_reference": float(np.corrcoef(tw, np.asarray(train.torque))[0, 1]),
        "twist_vs_current": float(np.corrcoef(tw, np.asarray(train.current))[0, 1]),
    }
    return {
        "rows": rows,
        "n_train": train.n_samples,
        "n_test": test.n_samples,
        "reference": ds.reference["description"],
        "discover_notes": kept["notes"],
        "correlation_train": corr,
        "_curves": kept["curves"],
    }


FIGURE = "img/lara8_reference_held_out.png"
"""The held-out figure, relative to docs/."""


def held_out_figure(curves: dict, path: Path) -> None:
    """Estimate against reference on the held-out rows, one panel per method, with y = x."""
    from hdjax._plotting import fixed_margins, pyplot, save_figure

    plt = pyplot()
    ref = np.asarray(curves["reference"])
    methods = {k: v for k, v in curves.items() if k != "reference"}
    lo, hi = float(ref.min()), float(ref.max())
    fig, axes = plt.subplots(1, len(methods), figsize=(2.6 * len(methods), 3.0), sharey=True)
    for ax, (name, est) in zip(axes, methods.items(), strict=True):
        e = np.asarray(est) - ref
        ax.plot([lo, hi], [lo, hi], color="gray", lw=0.8)
        ax.scatter(ref, np.asarray(est), s=4, alpha=0.6)
        ax.set_title(f"{name}\nRMS {np.sqrt(np.mean(e**2)):.2f} N·m", fontsize=9)
        ax.set_xlabel("reference [N·m]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("estimate [N·m]")
    fixed_margins(fig, left=0.7, bottom=0.55, top=0.5, wspace=0.12)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)


def skew_reading(notes: list[str]) -> str:
    """The residual loop's own sentence on the encoders' time skew (its delay in ms), from its
    notes."""
    said = [n for n in notes if n.startswith("skew:encoders,") or "skew, not friction" in n]
    if not said:
        return "The residual loop said nothing about a skew (its family was not offered)."
    return f"From the residual loop's notes: {said[0]}."


def page(result: dict) -> str:
    """docs/lara8-reference.md from the numbers of this run (no number is typed by hand)."""
    h, w = result["held_out"], result["whole_log"]
    r = h["rows"]
    f = lambda x: f"{x:.2f}"
    line = lambda name, m: f"| {name} | {f(m['rms'])} | {f(m['max'])} | {f(m['bias'])} |"
    eff = ", ".join(f"`{e}`" for e in r["song_discover_final"]["effects"]) or "none"
    net = r["network"]
    cur, song, disc = r["current"], r["song_discover_start"], r["song_discover_final"]
    dev = [r["song_config"]["rms"], song["rms"], disc["rms"]]
    if max(dev) < cur["rms"]:
        verdict = "beats"
    elif min(dev) >= cur["rms"]:
        verdict = "does not beat"
    else:
        verdict = "does not consistently beat"
    worst = r["song_config"]["worst"]
    lo, hi = r["song_config"]["calibrated_range"]
    tool_all, tool_fresh = w["current_vs_tool_all_rows"], w["current_vs_tool_fresh_rows"]
    base_all, fit_fresh = w["current_vs_base_all_rows"], w["current_vs_fit_offset_fresh_rows"]
    off = w["offset_fit"]
    offs = ", ".join(f"{v:.2f}" for v in off["wrench"])
    com = ", ".join(f"{1e3 * v:.0f}" for v in off["payload_com_m"])
    corr = h["correlation_train"]
    lines = [
        "# LARA8 joint 3 against its force/torque sensor",
        "",
        "<!-- generated by benchmarks/lara8_reference.py; do not edit by hand -->",
        "",
        "The LARA8 log `validate.csv` has a six-axis force/torque sensor at the flange. Joint 3's "
        "reference torque is built from it as",
        "",
        "$$\\tau_3 = \\tau_{\\text{model},3} + J_3(q)^\\top W,$$",
        "",
        "with $\\tau_\\text{model}$ the controller's model torque (`target_joint_torque_3`: the "
        "arm's gravity and inertia), $W$ the sensor's wrench in its own frame and $J_3$ joint "
        "3's column of the geometric Jacobian at the sensor, in the sensor frame, from the DH "
        "table `experiments/lara8_dh.toml`. Unlike the current-based torque "
        "(`joint_torque_current_3`) this reference does not carry the joint's friction.",
        "",
        f"Reference used: {h['reference']}.",
        "",
        "## Held-out blocks",
        "",
        f"Calibrated on {h['n_train']} rows (blocks of about 0.4 s), scored on the "
        f"{h['n_test']} rows of every 4th block; error = estimate − reference [N·m].",
        "",
        "| method | RMS | max | bias |",
        "|---|---|---|---|",
        line(
            "deformation: Song model as configured (`[model]` of lara8_fts.toml)", r["song_config"]
        ),
        line("deformation: Song model, starting model of the residual loop", song),
        line(
            f"deformation: after `discover` (added: {eff}"
            + (f"; from the {disc['start']}" if disc.get("start") else "")
            + ")",
            disc,
        ),
        line(
            f"network (BP, twist + current inputs; median of {net['seeds']} seeds, RMS "
            f"{f(net['rms_range'][0])}..{f(net['rms_range'][1])})",
            net,
        ),
        line("current-based torque `joint_torque_current_3`", cur),
        "",
        f"![Estimate against reference on the held-out rows, per method]({FIGURE})",
        "",
        "*Each point is one held-out row; the grey line is estimate = reference. Drawn with this "
        "page by `python benchmarks/lara8_reference.py`.*",
        "",
        "## The same comparison over the whole log",
        "",
        "| current-based torque against | rows | RMS | bias |",
        "|---|---|---|---|",
        f"| model torque + J₃ᵀW, sensor frame | all {w['rows']} | {f(tool_all['rms'])} | "
        f"{f(tool_all['bias'])} |",
        f"| model torque + J₃ᵀW, sensor frame | {w['fresh_rows']} fresh | {f(tool_fresh['rms'])} | "
        f"{f(tool_fresh['bias'])} |",
        f"| model torque + J₃ᵀW, base-frame Jacobian with the sensor-frame wrench | all "
        f"{w['rows']} | {f(base_all['rms'])} | {f(base_all['bias'])} |",
        f"| model torque + J₃ᵀ(W − w₀), offset fitted | {w['fresh_rows']} fresh | "
        f"{f(fit_fresh['rms'])} | {f(fit_fresh['bias'])} |",
        f"| model torque alone | {w['fresh_rows']} fresh | "
        f"{f(w['current_vs_model_torque_only']['rms'])} | "
        f"{f(w['current_vs_model_torque_only']['bias'])} |",
        "",
        "## Reading",
        "",
        f"- **Relation to the thesis.** The thesis reports {THESIS['current_rms']} N·m RMS for "
        "the current-based torque against the F/T-derived torque on this sweep. Over all rows "
        f"with the Jacobian in the sensor frame hdjax gets {f(tool_all['rms'])} N·m: the same "
        "computation. On the fresh rows only (hdjax never uses a held wrench) it is "
        f"{f(tool_fresh['rms'])} N·m. The bias of {f(tool_fresh['bias'])} N·m is the joint's "
        "friction in the current: the sweep runs in one direction, so Coulomb friction is a "
        "near-constant offset.",
        f"- **Relation to the direct log computation** ({ISSUE_DIRECT['rms']} N·m RMS, bias "
        f"{ISSUE_DIRECT['bias']} N·m). hdjax reproduces it ({f(base_all['rms'])} N·m, bias "
        f"{f(base_all['bias'])} N·m) only by pairing the base-frame Jacobian with the wrench "
        "the sensor reports in its own frame. That mixes frames: the sensor turns with joint "
        "3, and in its frame joint 3's column is constant, while in base axes it turns with "
        "θ3.",
        f"- **Sensor offset.** Fitting a constant offset plus a payload's static wrench to the "
        f"fresh readings gives w₀ = [{offs}] (N, N·m) and a payload of "
        f"{abs(off['payload_mass_kg']):.2f} kg with its centre of mass at [{com}] mm in the "
        f"sensor frame (fitted mass {off['payload_mass_kg']:.2f} kg: the sensor reports the "
        "wrench the arm applies to the payload, hence `wrench_sign = 1`); residual RMS "
        f"{', '.join(f'{v:.2g}' for v in off['residual_rms'])}. Removing w₀ changes the "
        f"current-based RMS to {f(fit_fresh['rms'])} N·m. The table above keeps the thesis' "
        "processing (no offset removed).",
        f"- **Does the twist beat the current?** The deformation estimates have held-out RMS "
        f"errors of {f(min(dev))} to {f(max(dev))} N·m; the current-based torque has "
        f"{f(cur['rms'])} N·m. On this reference the twist **{verdict}** the current. The "
        f"current's error is mostly its friction bias ({f(cur['bias'])} N·m), with a maximum "
        f"of {f(cur['max'])} N·m. The twist's error is spread and peaks at "
        f"{f(r['song_config']['max'])} N·m, at t = {worst['t_s']:.1f} s, where the reference "
        f"is {worst['reference']:.0f} N·m. The model was calibrated on "
        f"{lo:.0f}..{hi:.0f} N·m, and {r['song_config']['out_of_range']} held-out estimates "
        "fall outside that range (the inversion extrapolates there). On the calibration rows "
        "the twist correlates with the reference "
        f"at r = {corr['twist_vs_reference']:.3f}, and with the current-based torque at "
        f"r = {corr['twist_vs_current']:.3f}. The residual loop added "
        f"{'nothing' if not r['song_discover_final']['effects'] else eff} under its stopping "
        "rule.",
        f"- **Encoder time skew.** {skew_reading(h['discover_notes'])}",
        "- **What the reference itself carries.** The arm's own share of the reference is the "
        "controller's model torque, not a measurement, so any error in that model is an error "
        "of the reference too. Only the payload's share comes from the sensor.",
        f"- **Network and GRU.** The thesis' GRU reaches {THESIS['gru_rms']} N·m RMS. It was "
        "trained on many other sweeps with loads and scored on all of validate.csv. hdjax's "
        "network is trained on three quarters of this one sweep, and its inputs include the "
        "current-based torque, so its number measures something else.",
        "",
        f"Generated {result['date']} on {result['machine']['platform']} "
        f"({result['machine']['cpus']} CPUs, JAX {result['machine']['jax']}, float64) by "
        "`python benchmarks/lara8_reference.py`.",
    ]
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="network seeds (median reported)")
    ap.add_argument("--docs", default=str(REPO / "docs" / "lara8-reference.md"))
    args = ap.parse_args()
    t0 = time.perf_counter()
    exp = load_experiment(CONFIG)
    result = {
        "config": str(CONFIG.relative_to(REPO)),
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": {
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "jax": jax.__version__,
            "backend": jax.default_backend(),
        },
        "precision": "float64",
        "thesis": THESIS,
        "issue_direct": ISSUE_DIRECT,
        "whole_log": whole_log(exp),
        "held_out": held_out(exp, args.seeds),
    }
    result["wall_s"] = time.perf_counter() - t0
    from hdjax._io import atomic_write_bytes

    held_out_figure(result["held_out"].pop("_curves"), REPO / "docs" / FIGURE)
    atomic_write_bytes(args.docs, page(result).encode())
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
