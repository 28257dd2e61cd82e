"""`hdjax run CONFIG`: calibrate, estimate, score and report one experiment."""

from __future__ import annotations

import time
from pathlib import Path

# compliance.estimate_torque is looked up at each call (a test stops the command there)
from .. import compliance
from .._errors import ConfigError, InversionError
from .._io import csv_bytes
from ..compliance import calibration_messages, check_invertible
from ..config import dumps_toml, load_experiment, with_absolute_paths
from ..modelfile import save_model
from ..network import predict_torque as net_estimate
from ..pipelines import StreamedDataset, build_dataset, internal as P, preflight
from ..pipelines.internal import check_angles
from ..report import (
    ResultDir,
    environment,
    error_rate_figure,
    error_rate_title,
    markdown_table,
    torque_figure,
)
from ._common import (
    Progress,
    add_experiment_command,
    experiment_inputs,
    model_file,
    parse_overrides,
)

HELP = "run an experiment config: calibrate, estimate, score, write figures and a report"
EXAMPLE = """\
example:
  hdjax run experiments/song2019.toml --out runs/song2019 --overwrite
  hdjax run experiments/synthetic.toml --set model.poly_order=3 --out runs/p3

writes OUT/metrics.json, OUT/report.md, OUT/figures/*.png, OUT/config.resolved.toml and
OUT/model.json (the calibrated model, for 'hdjax estimate'); OUT appears only when complete.
"""


def add_parser(sub) -> None:
    add_experiment_command(
        sub,
        "run",
        HELP,
        EXAMPLE,
        config="experiment file (TOML), e.g. experiments/song2019.toml",
        out="result directory (default runs/NAME with NAME from [experiment] name); refused if "
        "it exists, unless --overwrite",
        flags={
            "--no-figures": "skip the figures (faster)",
            "--no-network": "skip the network method",
        },
        options={
            "--model": "calibrate the structure of this saved model (a model.json, or the result "
            "folder holding it, e.g. hdjax discover's) instead of the one [model] builds; same "
            "as --set model.structure=M",
        },
    )


def command(args, parser) -> int:
    progress = Progress(args.quiet)
    overrides = parse_overrides(args.set)
    if args.no_figures:
        overrides["outputs.figures"] = False
    if args.no_network:
        overrides["network.enabled"] = False
    if args.model:
        overrides["model.structure"] = str(model_file(args.model).resolve())
    exp = load_experiment(args.config, overrides)
    preflight(exp, base_dir=exp.base_dir, where=str(args.config))
    structure = exp["model"]["structure"]
    if structure:  # relative to the experiment file, like its data paths
        path = exp.base_dir / Path(structure).expanduser()
        if not path.is_file():
            raise ConfigError(
                f"{args.config} [model] structure = {structure!r}: no such file ({path}); give "
                "the model.json written by hdjax run or hdjax discover"
            )
        exp["model"]["structure"] = str(path)
    out = Path(args.out) if args.out else Path("runs") / exp["experiment"]["name"]
    inputs = experiment_inputs(exp)
    with ResultDir(out, overwrite=args.overwrite, inputs=inputs, command="run") as rd:
        summary = run_experiment(exp, rd, progress, force=args.force)
    progress(f"wrote {out}")
    print(summary)
    return 0


# ---------------------------------------------------------------------------------------------


def run_experiment(exp, rd, progress, *, force: bool = False) -> str:
    """Carry out an experiment into a [`hdjax.report.ResultDir`][]; returns a text summary."""
    import numpy as np

    t_start = time.perf_counter()
    cfg = exp
    seed = cfg["experiment"]["seed"]
    ds = build_dataset(exp, progress)
    forced = check_angles(ds, force=force)  # reported below, once the calibration is known
    joint = ds.joint
    rated = joint.rated_torque
    outputs = cfg["outputs"]
    metrics: dict = {
        "experiment": cfg["experiment"]["name"],
        "environment": environment(seed),
        "data": {"provenance": ds.provenance, "n_train": ds.n_train, "reference": ds.reference},
    }

    # -- the model-based method --------------------------------------------------------------
    progress(f"calibrating the compliance model on {ds.n_train} samples ({cfg['fit']['method']})")
    scale = P.current_scale(cfg, ds.train)
    t0 = time.perf_counter()
    notes: list[str] = []
    if cfg["model"]["structure"]:  # a saved model's structure (e.g. hdjax discover's)
        cal = P.calibrate_saved(cfg, ds.train, warn=notes.append)
    else:
        model0 = P.build_model(cfg, joint, scale)
        cal = P.calibrate(cfg, model0, ds.train, warn=notes.append)
    fit_s = time.perf_counter() - t0
    not_invertible = check_invertible(cal.value)
    if not_invertible:  # one line: the estimate would fail on it, so say it once, as the error
        cause = f" Likely cause (run with --force): {forced}" if forced else ""
        raise InversionError(f"{not_invertible}{cause}")
    if forced:
        progress.warn(f"{forced} (--force: running anyway; the results may be wrong)")
    said = " ".join(notes)  # a term the calibration's warning named is not said again
    messages = [m for m in calibration_messages(cal) if m.removeprefix("left out: ") not in said]
    for msg in notes + messages:
        progress.warn(msg)
    progress("estimating torque with the model (eqs. 26-27)")
    est_m = P.estimate_model(cal.value, ds.test)
    metrics["model"] = {
        "calibration": {
            "method": cfg["fit"]["method"],
            "n_terms": cal.stats["n_terms"],
            "rank": cal.stats["rank"],
            "condition": cal.stats["condition"],
            "residual_rms_arcsec": cal.stats["residual_rms"] * 648000.0 / np.pi,
            "segment_counts": list(cal.stats["segment_counts"]),
            "dropped": list(cal.stats["dropped"]),
            "messages": messages,
            "current_scale": scale,
            "fit_s": fit_s,
        },
        "scenarios": P.metrics_of(est_m, ds.test, rated),
    }
    first_test = P.first_samples(next(iter(ds.test.values())), 100)
    if outputs["timing"]:
        metrics["model"]["timing"] = P.time_per_100(
            lambda r: compliance.estimate_torque(cal.value, r).torque,
            first_test,
            outputs["timing_repeats"],
        )

    # -- the network method ------------------------------------------------------------------
    net, est_n = None, None
    why = "" if cfg["network"]["enabled"] else "disabled in [network] (enabled = false)"
    why = why or P.network_available()
    if why:
        progress(f"network method skipped: {why}")
        metrics["network"] = {"available": False, "reason": why}
    else:
        n_cfg = cfg["network"]
        progress(
            f"training the BP network {n_cfg['hidden']} ({n_cfg['trainer']}, {n_cfg['steps']} "
            f"steps, at most {n_cfg['max_train_samples']} samples)"
        )
        net, info = P.train_network(cfg, joint, ds.train, seed)
        est_n = P.estimate_network(net, joint, ds.test)
        metrics["network"] = {
            "available": True,
            "training": info,
            "scenarios": P.metrics_of(est_n, ds.test, rated),
        }
        if outputs["timing"]:
            metrics["network"]["timing"] = P.time_per_100(
                lambda r: net_estimate(net, r, joint), first_test, outputs["timing_repeats"]
            )
    if outputs["paper_reference"]:
        metrics["paper"] = {
            "errors_max_rms_Nm": {
                m: {s: list(v) for s, v in d.items()} for m, d in P.PAPER_ERRORS.items()
            },
            "ms_per_100": P.PAPER_MS_PER_100,
            "rated_torque": 400.0,
            "source": "Song et al. 2019, Section IV.B and Figs. 9-17",
        }

    # -- figures -----------------------------------------------------------------------------
    figures: list[tuple[str, str]] = []
    if outputs["figures"]:
        progress("drawing figures")
        for method, est in (("model", est_m), ("network", est_n)):
            if est is None:
                continue
            for name, rec in ds.test.items():
                t, measured, torque, errors = P.figure_series(est[name], rec)
                label = "model-based method" if method == "model" else "BP network"
                rel = f"figures/{method}_{name}.png"
                rd.write_bytes(
                    rel,
                    torque_figure(
                        t,
                        measured,
                        torque,
                        title=f"{label}, {name}: estimated vs measured torque",
                        rated=rated,
                        errors=errors,
                    ),
                )
                figures.append((rel, f"{label}, {name}"))
        rates = {"model": metrics["model"]["scenarios"]}
        rates["network"] = metrics["network"].get("scenarios")
        paper = P.PAPER_ERRORS if outputs["paper_reference"] else None
        rd.write_bytes("figures/error_rate.png", error_rate_figure(rates, paper=paper, rated=rated))
        figures.append(("figures/error_rate.png", error_rate_title(rates)))

    # -- files -------------------------------------------------------------------------------
    if outputs["save_model"]:
        save_model(
            rd.path("model.json"),
            joint,
            compliance=cal.value,
            network=net,
            meta={"experiment": cfg["experiment"]["name"], "seed": seed, "data": ds.provenance},
        )
        rd.files.append("model.json")
    if outputs["save_logs"]:
        metrics["logs"] = save_logs(rd, ds, cfg)
        logs = metrics["logs"]
        progress(
            "wrote the logs and discover.toml: next, hdjax discover --config OUT/discover.toml"
            if logs["written"]
            else f"logs not written ([outputs] save_logs): {logs['why']}"
        )
    metrics["wall_s"] = time.perf_counter() - t_start
    header = (
        f"Resolved configuration of experiment {cfg['experiment']['name']!r} "
        f"(hdjax {metrics['environment']['hdjax_version']}, seed {seed}).\n"
        f"Source: {exp.path}\nRe-run: hdjax run config.resolved.toml --out OTHER"
    )
    rd.write_text("config.resolved.toml", dumps_toml(with_absolute_paths(exp), header=header))
    report = render_report(cfg, metrics, figures)
    rd.write_text("report.md", report)
    rd.write_json("metrics.json", metrics)
    return summary_text(metrics)


def _row(metrics: dict, method: str, scenario: str):
    d = metrics.get(method, {}).get("scenarios") or {}
    m = d.get(scenario)
    return (None, None, None) if m is None else (m["max"], m["rms"], m["max_pct"])


def save_logs(rd: ResultDir, ds, cfg: dict) -> dict:
    """`[outputs] save_logs`: the run's recordings as CSV in `logs/` (hdjax's own columns, full
    precision) and `discover.toml`, the residual loop on the first calibration and the first
    test recording with the run's starting structure. **Returns:** what was written."""
    if isinstance(ds, StreamedDataset):
        return {"written": False, "why": "the recordings were streamed from files, not held"}
    names = {}
    for i, rec in enumerate(ds.train):
        names[f"logs/train_{i}.csv" if len(ds.train) > 1 else "logs/train.csv"] = rec
    for name, rec in ds.test.items():
        names[f"logs/test_{name}.csv"] = rec
    for rel, rec in names.items():
        rd.write_bytes(rel, csv_bytes(rec.to_numpy()))
    train, test = next(iter(names)), next(k for k in names if k.startswith("logs/test_"))
    model = cfg["model"]
    doc = {
        "joint": ds.joint.to_dict(),
        "data": {"train": train, "test": test},
        "discover": {k: model[k] for k in ("n_segments", "poly_order", "fourier_order")},
    }
    header = (
        f"The residual loop on the logs of experiment {cfg['experiment']['name']!r} (written by "
        "hdjax run with [outputs] save_logs = true).\n"
        "Run: hdjax discover --config THIS_FILE --out OTHER"
    )
    rd.write_text("discover.toml", dumps_toml(doc, header=header))
    return {"written": True, "files": list(names), "discover": "discover.toml"}


def render_report(cfg: dict, metrics: dict, figures: list[tuple[str, str]]) -> str:
    """The `report.md` of a run: what ran, the error table (with the paper's), figures."""
    env = metrics["environment"]
    lines = [
        f"# {cfg['experiment']['name']}",
        "",
        cfg["experiment"]["description"] or "",
        "",
        f"hdjax {env['hdjax_version']}, JAX {env['jax_version']} ({env['backend']}, "
        f"{env['precision']}), seed {env['seed']}, {env['cpu_count']} CPUs; wall time "
        f"{metrics['wall_s']:.1f} s. Resolved configuration: `config.resolved.toml`.",
        "",
        "## Data",
        "",
    ]
    lines += [f"- {p}" for p in metrics["data"]["provenance"]]
    scenarios = list(metrics["model"]["scenarios"])
    paper = metrics.get("paper")
    header = ["experiment", "model max", "model RMS", "network max", "network RMS"]
    if paper:
        header += ["paper model max/RMS", "paper network max/RMS"]
    rows = []
    for s in scenarios:
        mm, mr, _ = _row(metrics, "model", s)
        nm, nr, _ = _row(metrics, "network", s)
        row = [s, mm, mr, nm, nr]
        if paper:
            pm = P.PAPER_ERRORS["model"].get(s)
            pn = P.PAPER_ERRORS["network"].get(s)
            row += [
                f"{pm[0]:g} / {pm[1]:g}" if pm else "n/a",
                f"{pn[0]:g} / {pn[1]:g}" if pn else "n/a",
            ]
        rows.append(row)
    lines += ["", "## Torque error [N·m] on the test recordings", "", markdown_table(header, rows)]
    lines += [
        "",
        "Errors are estimate minus reference over every test sample (the paper's definition); "
        "% of rated torque is in `metrics.json` (`max_pct`, `rms_pct`).",
    ]
    net = metrics.get("network", {})
    if not net.get("available", False):
        lines += ["", f"Network method: not available ({net.get('reason', '')})."]
    cal = metrics["model"]["calibration"]
    lines += [
        "",
        "## Calibration",
        "",
        f"{cal['method']} on {metrics['data']['n_train']} samples: {cal['n_terms']} terms, rank "
        f"{cal['rank']}, condition number {cal['condition']:.3g}, twist residual "
        f"{cal['residual_rms_arcsec']:.3g} arcsec RMS, {cal['fit_s']:.2f} s.",
    ]
    for msg in cal["dropped"] + cal["messages"]:
        lines.append(f"- {msg}")
    if "timing" in metrics["model"]:
        rows = []
        for method in ("model", "network"):
            t = metrics.get(method, {}).get("timing")
            paper_ms = P.PAPER_MS_PER_100[method] if paper else None
            if t:
                ratio = paper_ms / t["ms_per_100"] if paper_ms else None
                rows.append([method, t["ms_per_100"], t["first_call_ms"], paper_ms, ratio])
            else:
                rows.append([method, None, None, paper_ms, None])
        lines += [
            "",
            "## Time to estimate 100 samples",
            "",
            markdown_table(
                [
                    "method",
                    "ms per 100 (steady)",
                    "first call incl. compile [ms]",
                    "paper [ms]",
                    "speed-up",
                ],
                rows,
            ),
            "",
            "One call from Python on 100 samples (signals, checks and the jitted estimate), best "
            "of the repeats; the paper's numbers are from an i7-7700H.",
        ]
    logs = metrics.get("logs") or {}
    if logs.get("written"):
        lines += [
            "",
            "## The logs",
            "",
            f"The recordings of this run are in `logs/` ({', '.join(logs['files'])}). "
            "`discover.toml` runs the residual loop on them, from the starting structure of "
            "`[model]` (its paths are relative to it): `hdjax discover --config "
            "OUT/discover.toml --out DISCOVER_DIR`, with OUT this folder.",
        ]
    elif logs:
        lines += ["", "## The logs", "", f"Not written ([outputs] save_logs): {logs['why']}."]
    if figures:
        lines += ["", "## Figures", ""]
        for rel, caption in figures:
            lines += [f"### {caption}", "", f"![{caption}]({rel})", ""]
    return "\n".join(lines) + "\n"


def summary_text(metrics: dict) -> str:
    """A few lines for stdout: error per method and scenario."""
    lines = [f"{'experiment':<12}{'model max':>12}{'model RMS':>12}{'net max':>12}{'net RMS':>12}"]
    for s in metrics["model"]["scenarios"]:
        mm, mr, _ = _row(metrics, "model", s)
        nm, nr, _ = _row(metrics, "network", s)
        f = lambda v: f"{v:12.4g}" if v is not None else f"{'n/a':>12}"
        lines.append(f"{s:<12}{f(mm)}{f(mr)}{f(nm)}{f(nr)}")
    lines.append(f"(N·m; wall time {metrics['wall_s']:.1f} s)")
    return "\n".join(lines)
