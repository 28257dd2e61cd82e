"""`hdjax sweep CONFIG`: vary one setting, score each member on held-out data, mark the knee."""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

from .._errors import ConfigError, HdjaxError
from ..compliance import estimate_torque_arrays
from ..compliance.internal import batched_estimates, estimable, member_message, nested_fit
from ..config import (
    Experiment,
    apply_setting,
    check_sweep_setting,
    dumps_toml,
    load_experiment,
    parse_value,
    with_absolute_paths,
)
from ..pipelines import build_dataset, internal as P, preflight
from ..pipelines.internal import StreamedEstimate, check_angles
from ..reference import describe_column_reference
from ..report import environment, find_knee, markdown_table, sweep_figure
from ..report.internal import KNEE_RULE
from ._common import (
    Progress,
    add_experiment_command,
    experiment_inputs,
    parse_overrides,
    resumable_result,
)

HELP = "sweep one setting (e.g. the polynomial order 1-8): held-out error and time, knee marked"
EXAMPLE = """\
example:
  hdjax sweep experiments/synthetic.toml --out runs/synthetic-poly
  hdjax sweep experiments/song2019.toml --setting model.fourier_order --values 0:6
  hdjax sweep experiments/song2019.toml --setting network.width --values 5,10,20,40

Settings are dotted keys of the config (model.poly_order, model.fourier_order, model.n_segments,
model.per_segment, fit.method, network.width, network.depth, network.hidden, ...). Polynomial and
Fourier orders are fitted together from one pass over the data and scored in one batched
(vmapped) estimate; other settings are run one after the other. Each member's result is kept in
OUT.partial/members/ while the sweep runs, so an interrupted sweep resumes where it stopped when
the same command is run again; OUT appears only when the sweep is complete.
"""

NESTED = ("model.poly_order", "model.fourier_order")


def add_parser(sub) -> None:
    p = add_experiment_command(
        sub,
        "sweep",
        HELP,
        EXAMPLE,
        config="experiment file (TOML); its [sweep] table gives the defaults",
        out="result directory (default runs/NAME-sweep-SETTING)",
        flags={"--fresh": "ignore member results cached by an earlier, interrupted run"},
    )
    p.add_argument("--setting", help="the dotted setting to vary (default: [sweep] setting)")
    p.add_argument(
        "--values",
        help="values: a list '1,2,4', an integer range 'A:B' (inclusive) or a TOML list "
        "'[[10], [10, 10]]' (default: [sweep] values)",
    )


def parse_values(text: str) -> list:
    """`"1:8"` -> 1..8, `"1,2,4"` -> [1, 2, 4], `"[[10],[20]]"` -> [[10], [20]]."""
    text = text.strip()
    if text.startswith("["):
        v = parse_value(text)
        if not isinstance(v, list) or not v:
            raise ConfigError(f"--values: cannot read {text!r} as a TOML list")
        return v
    if ":" in text:
        a, _, b = text.partition(":")
        try:
            lo, hi = int(a), int(b)
        except ValueError:
            raise ConfigError(f"--values: a range is A:B with integers, got {text!r}") from None
        if hi < lo:
            raise ConfigError(f"--values: empty range {text!r}")
        return list(range(lo, hi + 1))
    vals = [parse_value(x.strip()) for x in text.split(",") if x.strip()]
    if not vals:
        raise ConfigError("--values: no values given")
    return vals


def command(args, parser) -> int:
    progress = Progress(args.quiet)
    exp = load_experiment(args.config, parse_overrides(args.set))
    setting = check_sweep_setting(args.setting or exp["sweep"]["setting"], where="--setting")
    values = parse_values(args.values) if args.values is not None else list(exp["sweep"]["values"])
    name = exp["experiment"]["name"]
    out = Path(args.out) if args.out else Path("runs") / f"{name}-sweep-{setting.replace('.', '-')}"
    summary = run_sweep(
        exp, setting, values, out, args.overwrite, progress, fresh=args.fresh, force=args.force
    )
    print(summary)
    return 0


# ---------------------------------------------------------------------------------------------


def _fingerprint(cfg: dict, setting: str) -> str:
    base = {k: v for k, v in cfg.items() if k not in ("sweep", "outputs")}
    text = json.dumps([base, setting], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _member_file(i: int, value) -> str:
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in json.dumps(value))
    return f"members/{i:03d}_{safe[:40]}.json"


def run_sweep(
    exp,
    setting: str,
    values: list,
    out: Path,
    overwrite: bool,
    progress,
    *,
    fresh=False,
    force=False,
):
    """Run a sweep into `out` (atomically, resumable); returns a text summary."""
    cfgs = [apply_setting(dict(exp), setting, v, where="sweep member") for v in values]
    if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
        raise ConfigError(f"sweep values repeat: {values}")
    for v, c in zip(values, cfgs):  # every member is checked before the first one runs
        preflight(c, base_dir=exp.base_dir, where=f"sweep member {setting} = {v!r}")
    inputs = experiment_inputs(exp)
    for c in cfgs:
        inputs += experiment_inputs(_with_path(c, exp))
    rd = resumable_result(out, overwrite=overwrite, inputs=inputs, command="sweep")
    try:
        summary_rows = _sweep_into(rd, exp, setting, values, cfgs, progress, fresh, force)
    except BaseException:
        rd.abort()  # keeps finished members for resuming; an empty staging folder goes
        raise
    progress(f"wrote {out}")
    return summary_rows


def _sweep_into(rd, exp, setting, values, cfgs, progress, fresh, force):
    import numpy as np

    staging = rd.staging

    fp = _fingerprint(dict(exp), setting)
    cached: dict[int, dict] = {}
    for i, v in enumerate(values):
        p = staging / _member_file(i, v)
        if p.exists() and not fresh:
            try:
                rec = json.loads(p.read_text())
            except json.JSONDecodeError:
                continue
            if rec.get("fingerprint") == fp and rec.get("value") == v:
                cached[i] = rec
    if cached:
        progress(f"resuming: {len(cached)} of {len(values)} members cached in {staging}")
    t_start = time.perf_counter()
    todo = [i for i in range(len(values)) if i not in cached]
    shared = {}
    reference = None  # the reference torque of the data the members were scored against
    if todo:
        method = "network" if setting.startswith("network.") else "model"
        if setting.startswith("data."):
            results = {}
            for i in todo:
                progress(f"member {i + 1}/{len(values)}: {setting} = {values[i]!r}")
                ds = build_dataset(_with_path(cfgs[i], exp), progress)
                check_angles(ds, force=force, warn=progress.warn)
                results[i] = _member_loop(cfgs[i], ds, method, exp["experiment"]["seed"])
                results[i]["reference"] = _reference_of(ds)
                reference = reference or ds.reference
                _save_member(rd, i, values[i], fp, results[i])
        else:
            ds = build_dataset(exp, progress)
            check_angles(ds, force=force, warn=progress.warn)
            reference = ds.reference
            nested = (
                setting in NESTED
                and all(
                    isinstance(values[i], int) and not isinstance(values[i], bool) for i in todo
                )
                and not (setting == "model.fourier_order" and exp["model"]["kinematic"] != "paper")
                and not exp["fit"]["chunk"]  # streamed: each member by its own chunked fit
            )
            if nested:
                results, shared = _members_nested(exp, setting, values, todo, cfgs, ds, progress)
                for i in todo:
                    results[i]["reference"] = _reference_of(ds)
                    _save_member(rd, i, values[i], fp, results[i])
            else:
                for i in todo:
                    progress(f"member {i + 1}/{len(values)}: {setting} = {values[i]!r}")
                    res = _member_loop(cfgs[i], ds, method, exp["experiment"]["seed"])
                    res["reference"] = _reference_of(ds)
                    _save_member(rd, i, values[i], fp, res)
                    cached[i] = {"result": res}
                results = {}
        for i, res in results.items():
            cached[i] = {"result": res}
    rows = [
        cached[i]["result"] if "result" in cached[i] else cached[i]["metrics"]
        for i in range(len(values))
    ]
    err = [r.get("rms", float("nan")) if r.get("rms") is not None else float("nan") for r in rows]
    secs = [r.get("fit_s", float("nan")) for r in rows]
    knee = find_knee([v if isinstance(v, int | float) else i for i, v in enumerate(values)], err)
    described = [r.get("reference") or _reference_of_config(c) for r, c in zip(rows, cfgs)]
    reference = reference or described[0]
    metrics = {
        "setting": setting,
        "values": values,
        "metric": "held-out torque RMS error over all test samples [N·m]",
        "reference": reference,
        "members": [{"value": v, **r} for v, r in zip(values, rows)],
        "knee": None if knee is None else {"index": knee, "value": values[knee]},
        "shared": shared,
        "wall_s": time.perf_counter() - t_start,
        "environment": environment(exp["experiment"]["seed"]),
    }
    if exp["outputs"]["figures"]:
        png = sweep_figure(values, err, secs, setting=setting, knee=knee, metric="RMS")
        rd.write_bytes("figures/sweep.png", png)
    header = [
        "value",
        "held-out RMS [N·m]",
        "held-out max [N·m]",
        "terms / parameters",
        "fit time [s]",
        "note",
    ]
    table = [
        [
            json.dumps(v),
            r.get("rms"),
            r.get("max"),
            r.get("n_terms"),
            r.get("fit_s"),
            r.get("message", ""),
        ]
        for v, r in zip(values, rows)
    ]
    lines = [
        f"# Sweep over `{setting}` ({exp['experiment']['name']})",
        "",
        f"Held-out error: the torque RMS over every sample of the test recordings; the knee "
        f"({KNEE_RULE}) is "
        f"{'`' + json.dumps(values[knee]) + '`' if knee is not None else 'not defined'}.",
        "",
        markdown_table(header, table),
        "",
    ]
    kinds = {d["description"] for d in described}
    if len(kinds) == 1:
        lines += [f"Torque {reference['description']}.", ""]
    else:  # a sweep over a data setting may change the reference between members
        lines += ["Torque reference per member:", ""]
        lines += [f"- `{json.dumps(v)}`: {d['description']}" for v, d in zip(values, described)]
        lines += [""]
    if shared:
        lines += [
            f"Nested fit: one Gram pass of the largest model ({shared['gram_s']:.3f} s) shared by "
            f"all members; the fit time column is each member's own solve and refinement; the "
            f"held-out estimates of all members ran in one vmapped call "
            f"({shared['estimate_s']:.3f} s).",
            "",
        ]
    if exp["outputs"]["figures"]:
        lines += ["![sweep](figures/sweep.png)", ""]
    rd.write_text("report.md", "\n".join(lines))
    rd.write_text(
        "config.resolved.toml",
        dumps_toml(
            with_absolute_paths(exp), header=f"Sweep over {setting} = {values!r}; source {exp.path}"
        ),
    )
    rd.write_json("metrics.json", metrics)
    rd.commit()
    f = lambda v: f"{v:.4g}" if isinstance(v, float) and np.isfinite(v) else "n/a"
    text = [f"{setting:>24}  {'held-out RMS':>14}  {'fit s':>8}"]
    for v, r in zip(values, rows):
        mark = "  <- knee" if knee is not None and values[knee] == v else ""
        text.append(f"{json.dumps(v):>24}  {f(r.get('rms')):>14}  {f(r.get('fit_s')):>8}{mark}")
    return "\n".join(text)


def _reference_of(ds) -> dict:
    """The kind and one-line description of a dataset's reference torque (for each member)."""
    return {k: ds.reference[k] for k in ("kind", "description") if k in ds.reference}


def _reference_of_config(cfg: dict) -> dict:
    """The same, from the config alone (members cached by a sweep that did not record it)."""
    kind = cfg["data"]["reference"]["kind"]
    if kind == "column":
        desc = describe_column_reference(cfg["data"]["columns"], cfg["data"]["kind"])
    else:
        desc = 'reference: built from a wrench ([data.reference] kind = "wrench")'
    return {"kind": kind, "description": desc}


def _with_path(cfg: dict, exp):
    new = Experiment(cfg)
    new.path = exp.path
    return new


def _save_member(rd, i, value, fp, result) -> None:
    rd.write_json(_member_file(i, value), {"fingerprint": fp, "value": value, "result": result})


def _pooled(torques: dict, ds) -> dict:
    import numpy as np

    if any(isinstance(e, StreamedEstimate) for e in torques.values()):
        return _pooled_streamed(torques, ds)
    est = np.concatenate([np.asarray(torques[k]) for k in ds.test])
    ref = np.concatenate([np.asarray(r.column("torque")) for r in ds.test.values()])
    err = est - ref
    if not np.all(np.isfinite(err)):
        return {"rms": None, "max": None, "message": "non-finite estimate"}
    out = {"rms": float(np.sqrt(np.mean(err**2))), "max": float(np.max(np.abs(err)))}
    out["per_recording"] = {}
    i = 0
    for k, r in ds.test.items():
        e = err[i : i + r.n_samples]
        i += r.n_samples
        out["per_recording"][k] = float(np.sqrt(np.mean(e**2)))
    return out


def _pooled_streamed(estimates: dict, ds) -> dict:
    """`_pooled` of streamed parts: their error sums merged."""
    sums = [estimates[k].errors for k in ds.test]
    total = sums[0]
    for s in sums[1:]:
        total = total.merged(s)
    if not total.finite:
        return {"rms": None, "max": None, "message": "non-finite estimate"}
    out = {"rms": total.rms, "max": total.peak}
    out["per_recording"] = {k: e.rms for k, e in zip(ds.test, sums)}
    return out


def _member_loop(cfg: dict, ds, method: str, seed: int) -> dict:
    """Fit and score one member on its own (any setting)."""
    t0 = time.perf_counter()
    try:
        if method == "network":
            why = P.network_available()
            if why:
                return {"rms": None, "max": None, "message": why}
            net, info = P.train_network(cfg, ds.joint, ds.train, seed)
            fit_s = time.perf_counter() - t0
            torques = P.estimate_network(net, ds.joint, ds.test)
            return {**_pooled(torques, ds), "fit_s": fit_s, "n_terms": info["n_parameters"]}
        model = P.build_model(cfg, ds.joint, P.current_scale(cfg, ds.train))
        cal = P.calibrate(cfg, model, ds.train)
        fit_s = time.perf_counter() - t0
        torques = {
            k: e if isinstance(e, StreamedEstimate) else e.torque
            for k, e in P.estimate_model(cal.value, ds.test).items()
        }
        res = {**_pooled(torques, ds), "fit_s": fit_s, "n_terms": cal.stats["n_terms"]}
        res["condition"] = cal.stats["condition"]
        return res
    except HdjaxError as err:
        return {
            "rms": None,
            "max": None,
            "fit_s": time.perf_counter() - t0,
            "message": " ".join(str(err).split()),
        }


def _members_nested(exp, setting, values, todo, cfgs, ds, progress):
    """Polynomial / Fourier orders: one Gram pass, per-member solves, one batched estimate."""
    import numpy as np

    scale = P.current_scale(exp, ds.train)
    vmax = max(values[i] for i in todo)
    big = P.build_model(apply_setting(dict(exp), setting, vmax), ds.joint, scale)
    members = [P.build_model(cfgs[i], ds.joint, scale) for i in todo]
    progress(
        f"nested fit of {len(todo)} members ({setting} = {[values[i] for i in todo]}) on "
        f"{ds.n_train} samples, one pass of the largest design ({big.n_coef} terms)"
    )
    sig, torque = P.stacked_signals(big, ds.train)
    fits, gram_s = nested_fit(big, members, sig, torque)
    progress("scoring every member on the test recordings in one batched estimate")
    test_sig, _ = P.stacked_signals(big, list(ds.test.values()))
    t0 = time.perf_counter()
    torques = batched_estimates(big, fits, test_sig)
    est_s = time.perf_counter() - t0
    results = {}
    lengths = [r.n_samples for r in ds.test.values()]
    splits = np.cumsum(lengths)[:-1]
    for k, i in enumerate(todo):
        f = fits[k]
        tq = torques[k]
        if tq is None and estimable(f):
            tq = np.asarray(estimate_torque_arrays(f.value, test_sig))
        if tq is None:
            res = {"rms": None, "max": None, "message": member_message(f) or "not estimable"}
        else:
            parts = np.split(np.asarray(tq), splits)
            res = _pooled(dict(zip(ds.test, parts)), ds)
            if member_message(f):
                res["message"] = member_message(f)
        st = f.stats
        res.update(
            {
                "fit_s": st["fit_time_s"],
                "n_terms": st["n_terms"],
                "condition": st["condition"],
                "residual_rms_arcsec": st["residual_rms"] * 648000.0 / np.pi,
            }
        )
        results[i] = res
    return results, {"gram_s": gram_s, "estimate_s": est_s, "largest_terms": big.n_coef}
