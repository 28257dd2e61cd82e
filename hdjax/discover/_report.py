"""The discover report: `report.json`, `report.md` and figures, written into a result folder
([`hdjax.report.ResultDir`][]) with the JSON encoder of every hdjax result."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .. import effects
from .._custom_types import PathLike
from .._features import find_gaps
from .._joint import Joint
from .._plotting import fixed_margins, pyplot
from .._solution import Solution
from ..compliance.internal import CalibrationData
from ..modelfile import save_model
from ..report import ResultDir
from ._evaluate import ARCSEC, residual
from ._options import DiscoverOptions, stopping_rule
from ._pipeline import PipelineData, pipeline_signals
from ._record import DiscoveryRecord
from ._refit import residual_spectra


def report_dict(solution: Solution, *, extra: dict | None = None) -> dict:
    """The JSON report (the `hdjax discover` contract plus diagnostics) of the
    [`hdjax.Solution`][] that [`hdjax.discover.discover`][] returns."""
    result = solution.aux
    b, f = result.baseline, result.final
    d = {
        "baseline": {
            "rms": b.rms,
            "max": b.max,
            "rms_pct": b.rms_pct,
            "max_pct": b.max_pct,
            "twist_rms_arcsec": result.baseline_twist_rms_arcsec,
            "cv_torque_rms": result.baseline_cv_torque_rms,
            "cv_twist_rms_arcsec": result.baseline_cv_twist_rms_arcsec,
        },
        "steps": [
            {
                "effect": s.key,
                "rms": s.test.rms,
                "max": s.test.max,
                "rms_pct": s.test.rms_pct,
                "max_pct": s.test.max_pct,
                "twist_rms_arcsec": s.twist_rms_arcsec,
                "cv_gain": s.cv_gain,
                "fold_gains": s.fold_gains,
                "stability": s.stability,
                "cv_torque_rms": s.cv_torque_rms,
                "cv_twist_rms_arcsec": s.cv_twist_rms_arcsec,
                "amplitude": s.amplitude,
                "term": s.term.names(),
                "ranking": s.ranking,
                "aliases": s.aliases,
                **({"carried": True} if s.carried else {}),
            }
            for s in result.steps
        ],
        **({"start_structure": result.start_structure} if result.start_structure else {}),
        "final": {"rms": f.rms, "max": f.max, "rms_pct": f.rms_pct, "max_pct": f.max_pct},
        "effects": result.effects,
        "vocabulary": effects.vocabulary(),
        "stopping_rule": result.stopping_rule or stopping_rule(DiscoverOptions()),
        **({"selection": result.selection} if result.selection else {}),
        "last_ranking": result.final_ranking,
        "unexplained": result.unexplained,
        "cv_block_samples": result.cv_block_samples,
        "cv_test_ratio": result.cv_test_ratio,
        "reference_checks": result.reference_checks,
        "notes": list(dict.fromkeys(result.notes)),  # a note raised on every fold: once
        "final_model": solution.value.to_dict(),
        "seconds": solution.stats["fit_time_s"],
    }
    if extra:
        d.update(extra)
    return d


def _plot_spectra(spectra, chosen, title, path):
    plt = pyplot()

    fig, axes = plt.subplots(len(spectra) or 1, 1, figsize=(8, 2.6 * max(1, len(spectra))))
    axes = np.atleast_1d(axes)
    for ax, (signal, spec) in zip(axes, spectra.items()):
        ax.plot(spec.orders, 100 * spec.power, lw=0.8)
        for key in chosen:
            parts = key.split(":")
            if parts[0] == "harmonic" and parts[1] == signal:
                ax.axvline(float(parts[2]), color="C3", ls="--", lw=1, label=key)
        ax.set_xlabel(f"order of {signal}")
        ax.set_ylabel("explained variance [%]")
        ax.set_title(f"{title}: {signal}", fontsize=9)  # every panel names its signal
        ax.legend(loc="upper right", fontsize=8) if ax.get_legend_handles_labels()[0] else None
    fixed_margins(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_residual_vs_angle(model, data: PipelineData, title, path):
    plt = pyplot()

    # the loop's own TEST signals (gaps honoured), so the design reuses its compiled programs
    r = residual(model, data, None, 0) * ARCSEC
    idx = np.linspace(0, r.size - 1, min(r.size, 6000)).astype(int)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
    for ax, name in zip(axes, ("theta_m", "theta_l")):
        th = np.mod(np.asarray(data.sig.get(name))[idx], 2 * np.pi)
        ax.plot(th, r[idx], ".", ms=1.5, alpha=0.5)
        ax.set_xlabel(f"{name} mod 2π [rad]")
        ax.set_ylabel("twist residual [arcsec]")
        ax.set_title(f"{title}, against {name}", fontsize=9)
    fixed_margins(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_torque(result: DiscoveryRecord, path):
    plt = pyplot()

    test = result.test
    final = result.steps[-1].torque_estimate if result.steps else result.baseline_estimate
    series = [
        np.asarray(x, float)
        for x in (
            np.asarray(test.t) - float(test.t[0]),
            test.torque,
            result.baseline_estimate,
            final,
        )
    ]
    # break the lines across gaps in the record (held-out blocks, lost samples)
    gaps = find_gaps(series[0]) + 1
    t, ref, base, final = (np.insert(x, gaps, np.nan) for x in series)
    fig, axes = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    axes[0].plot(t, ref, "k", lw=1, label="measured")
    axes[0].plot(t, base, lw=0.8, label="estimated, starting model")
    axes[0].plot(t, final, lw=0.8, label="estimated, final model")
    axes[0].set_ylabel("torque [N·m]")
    axes[0].legend(fontsize=8)
    axes[1].plot(t, base - ref, lw=0.6, label="starting model")
    axes[1].plot(t, final - ref, lw=0.6, label="final model")
    axes[1].set_ylabel("error [N·m]")
    axes[1].set_xlabel("time [s]")
    axes[1].legend(fontsize=8)
    axes[0].set_title("TEST: estimated against measured torque, before and after")
    fixed_margins(fig, hspace=0.15)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_progress(result: DiscoveryRecord, path):
    plt = pyplot()

    labels = ["start"] + [s.key for s in result.steps]
    rms = [result.baseline.rms] + [s.test.rms for s in result.steps]
    mx = [result.baseline.max] + [s.test.max for s in result.steps]
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(max(5, 1.6 * len(labels)), 3.2))
    ax.bar(x - 0.2, rms, 0.4, label="RMS")
    ax.bar(x + 0.2, mx, 0.4, label="max")
    ax.set_xticks(x, labels, rotation=15, fontsize=8)
    ax.set_ylabel("TEST torque error [N·m]")
    ax.legend()
    fixed_margins(fig, bottom=0.75, top=0.15)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_figures(solution: Solution, train, folder: Path) -> list[tuple[str, str]]:
    """All report figures of a [`hdjax.discover.discover`][] solution into `folder`; returns
    (caption, file name) pairs."""
    result = solution.aux
    folder.mkdir(parents=True, exist_ok=True)
    figs = []
    models = [result.baseline_model] + [s.model for s in result.steps]
    m0 = result.baseline_model  # every step keeps the joint and the velocity signal
    test = pipeline_signals(result.test, m0.ratio, m0.twist_sign, m0.velocity)
    for i, m in enumerate(models):
        nxt = result.steps[i].key if i < len(result.steps) else None
        spectra = result.steps[i].spectra if i < len(result.steps) else result.final_spectra
        if not spectra:
            spectra = residual_spectra(m, train)
        name = f"spectrum_{i}.png"
        title = f"order spectrum of the training residual before step {i + 1}" + (
            f" (added {nxt})" if nxt else " (nothing added)"
        )
        _plot_spectra(spectra, [nxt] if nxt else [], title, folder / name)
        figs.append((title, name))
        name = f"residual_{i}.png"
        label = "starting model" if i == 0 else f"after {result.steps[i - 1].key}"
        _plot_residual_vs_angle(m, test, f"TEST twist residual, {label}", folder / name)
        figs.append((f"TEST twist residual against each angle, {label}", name))
    _plot_torque(result, folder / "torque.png")
    figs.append(("estimated against measured torque on TEST, before and after", "torque.png"))
    _plot_progress(result, folder / "errors.png")
    figs.append(("TEST torque error after each step", "errors.png"))
    return figs


def report_markdown(d: dict, figures: list[tuple[str, str]], use: str | None = None) -> str:
    """The `report.md` of a report dict and its (caption, file name) figures; with `use`
    (the result folder holding `model.json`), a last section giving the commands that use
    the model."""
    lines = ["# hdjax discover", ""]
    # two tables, each narrow enough for the page: the errors, then each step's evidence
    lines.append(
        "| step | effect | TEST RMS [N·m] | TEST max [N·m] | CV torque RMS [N·m] | "
        "CV twist RMS [arcsec] |"
    )
    lines.append("|---|---|---|---|---|---|")
    b = d["baseline"]
    lines.append(
        f"| 0 | starting model | {b['rms']:.4g} | {b['max']:.4g} | {b['cv_torque_rms']:.4g} | "
        f"{b['cv_twist_rms_arcsec']:.4g} |"
    )
    if d.get("start_structure"):
        # the steps start from another structure: its row, so each step reads from its start
        a = d["start_structure"]
        lines.append(
            f"| 0b | {a['label']} | {a['rms']:.4g} | {a['max']:.4g} | {a['cv_torque_rms']:.4g} | "
            f"{a['cv_twist_rms_arcsec']:.4g} |"
        )
    details = []
    for i, s in enumerate(d["steps"], 1):
        a = s.get("amplitude") or {}
        amp = _parameter_text(a) + (
            f"{a['arcsec']:.3g} arcsec [{a['arcsec_ci95'][0]:.3g}, {a['arcsec_ci95'][1]:.3g}]; "
            f"{a['nm']:.3g} N·m [{a['nm_ci95'][0]:.3g}, {a['nm_ci95'][1]:.3g}]"
            if a
            else ""
        )
        carried = " (carried over)" if s.get("carried") else ""
        lines.append(
            f"| {i} | `{s['effect']}`{carried} | {s['rms']:.4g} | {s['max']:.4g} | "
            f"{s['cv_torque_rms']:.4g} | {s['cv_twist_rms_arcsec']:.4g} |"
        )
        details.append(f"| {i} | {s['cv_gain']:.1%} | {s['stability']:.0%} | {amp} |")
    if details:
        lines += [
            "",
            "Each step's evidence (CV twist gain: the share of the cross-validated twist error"
            " it removes; stability: the share of resampled fold assignments in which it is"
            " eligible):",
            "",
            "| step | CV twist gain | stability | amplitude (95 % interval) |",
            "|---|---|---|---|",
            *details,
        ]
    aliased = [(i, s) for i, s in enumerate(d["steps"], 1) if s.get("aliases")]
    if aliased:
        lines += ["", "Effects TRAIN cannot tell apart (columns spanning the same directions):", ""]
        for i, s in aliased:
            alt = ", ".join(f"`{a['key']}` (cosine {a['cosine']:.4f})" for a in s["aliases"])
            lines.append(f"- step {i}, `{s['effect']}`: indistinguishable from {alt}")
    lines += ["", f"Stopping rule: {d['stopping_rule']}.", ""]
    if d.get("unexplained"):
        lines += ["Left unexplained (structure above the noise in the final TRAIN residual):", ""]
        for u in d["unexplained"]:
            what = f"order {u['order']:g}" if u["kind"] == "order" else "shape"
            lines.append(
                f"- {u['signal']}: {what}, amplitude {u['amplitude_arcsec']:.3g} arcsec "
                f"({u['explained']:.1%} of the residual variance)"
            )
        lines.append("")
    lines += _checks_lines(d)
    notes = list(dict.fromkeys(d["notes"]))
    if notes:
        lines += ["## Notes", ""] + [f"- {note}" for note in notes] + [""]
    for caption, name in figures:
        lines += [f"![{caption}](figures/{name})", ""]
    if use is not None:
        lines += _use_lines(use, d)
    return "\n".join(lines)


def _parameter_text(a: dict) -> str:
    """An effect's own physical parameter with its interval, where its coefficient is one (an
    encoder skew's delay: `delay_ms` -> "delay 2.1 ms [1.9, 2.3]; "), else ""."""
    out = ""
    for key in a:
        if key in ("arcsec", "nm") or key + "_ci95" not in a or "_" not in key:
            continue
        name, unit = key.rsplit("_", 1)
        lo, hi = a[key + "_ci95"]
        out += f"{name} {a[key]:.3g} {unit} [{lo:.3g}, {hi:.3g}]; "
    return out


def _checks_lines(d: dict) -> list[str]:
    """The cross-validated against the TEST error, and the reference checks that found
    something (markdown lines)."""
    last = d["steps"][-1] if d["steps"] else d["baseline"]
    final_cv, final_test = last["cv_torque_rms"], d.get("final", last)["rms"]
    ratio = d.get("cv_test_ratio", float("nan"))
    out = [
        f"Cross-validated torque RMS on TRAIN {final_cv:.4g} N·m, TEST RMS {final_test:.4g} "
        f"N·m (ratio {ratio:.2g}"
        + (
            "; cross-validation does not represent TEST)."
            if np.isfinite(ratio) and not 0.5 <= ratio <= 2.0
            else ")."
        ),
        "",
    ]
    found = [
        (part, f) for part, fs in d.get("reference_checks", {}).items() for f in fs if f["flagged"]
    ]
    if found:
        out += ["Reference checks (what the estimate is scored against):", ""]
        out += [f"- {part}, {f['check']}: {f['message']}" for part, f in found]
        out.append("")
    return out


def write_report(
    solution: Solution,
    out: PathLike | ResultDir,
    *,
    train: CalibrationData | None = None,
    figures: bool = True,
    extra: dict[str, Any] | None = None,
    overwrite: bool = False,
    joint: Joint | None = None,
    experiment: str = "",
) -> dict[str, Any]:
    """Write `report.json`, `report.md`, `figures/` and (given the `joint`) `model.json` of
    a [`hdjax.discover.discover`][] solution into the result folder `out`, atomically, by the
    rules of every hdjax result folder ([`hdjax.report.ResultDir`][]: `out` absent or empty,
    or an earlier hdjax result with `overwrite`), or into an open `ResultDir` (the command
    line's, which commits it); returns the report dict.

    The model and the report are written first, then the figures in one pass, `report.md`
    naming them last. The model file is the one `hdjax estimate`, `hdjax run --model` and
    `hdjax export` read ([`hdjax.modelfile.save_model`][]); `experiment`, when given, is
    written as `experiment.toml` (the lines that reproduce the final model with `hdjax run`,
    from `hdjax.discover._experiment`); `report.md` ends with the commands that use them."""
    if not isinstance(out, ResultDir):
        with ResultDir(out, overwrite=overwrite, command="discover") as rd:
            return write_report(
                solution, rd, train=train, figures=figures, extra=extra, joint=joint,
                experiment=experiment,
            )  # fmt: skip
    rd = out
    d = report_dict(solution, extra=extra)
    if experiment:
        rd.write_text("experiment.toml", experiment)
        d["experiment"] = "experiment.toml"
    use = None
    if joint is not None:
        save_model(
            rd.path("model.json"),
            joint,
            compliance=solution.value,
            meta={"written_by": "hdjax discover", "effects": solution.aux.effects},
        )
        use = str(rd.out)
    rd.write_json("report.json", d)
    rd.write_text("report.md", report_markdown(d, [], use=use))
    if figures:
        figs = write_figures(solution, train, rd.path("figures/.keep").parent)
        rd.write_text("report.md", report_markdown(d, figs, use=use))
    return d


def _use_lines(out: str, d: dict) -> list[str]:
    """The "Use it" section: the commands that apply the final model."""
    model = f"{out}/model.json"
    effects = ", ".join(f"`{e}`" for e in d["effects"]) or "no added effect"
    config = d.get("config")
    columns = f" --columns {config} --joint {config}" if config else ""
    run = [f"hdjax run {out}/experiment.toml --out {out}_run"] if d.get("experiment") else []
    lines = [
        "## Use it",
        "",
        f"The final model ({effects}) is in `{model}`:",
        "",
        "```",
        f"hdjax estimate --model {model} --data LOG.csv{columns} --out torque.csv",
        *run,
        f"hdjax export --model {model} --out {out}_c",
        "```",
        "",
        "The first estimates the torque of another log of this joint"
        + (" (the config maps its columns)" if config else "")
        + "; "
        + (
            "the second calibrates the model's structure again on TRAIN with `hdjax run` "
            "(`experiment.toml`: the same model and TEST error, with run's figures and report; "
            "edit it, or run `hdjax run YOUR.toml --model "
            f"{model}` to calibrate this structure on other logs); the third"
            if run
            else "the second"
        )
        + " writes the estimator as C for the controller, with test vectors to check the build "
        "against.",
        "",
    ]
    if not run and d.get("experiment_missing"):
        lines += [f"No `experiment.toml`: {d['experiment_missing']}.", ""]
    return lines
