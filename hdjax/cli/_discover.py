"""`hdjax discover`: the residual loop from the command line.

    hdjax discover --train TRAIN.csv --test TEST.csv --joint JOINT.toml --out DIR

The command shares the parser and the result-folder writer of the other commands
([`hdjax.report.ResultDir`][]): `--out` appears only when complete, is never an input, and
`--overwrite` replaces only an earlier hdjax result. Exit code 0 on success; on bad input 2 and
a one-line reason on stderr.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import equinox as eqx

from .. import __version__
from .._errors import DataError
from .._formats import load_recording
from .._io import read_toml
from .._joint import load_joint
from .._memory import check_read_memory
from ..discover import (
    DiscoverOptions,
    check_inputs,
    internal as loop,  # `loop.discover` looked up at call time, where a test stops it
)
from ..discover.internal import (
    SELECT_BLOCKS,
    check_chunk,
    discover_options,
    experiment_toml,
    load_discover_config,
    load_selection,
    refit_on_whole_log,
    write_report,
)
from ..report import ResultDir
from ._common import Parser

MIN_SELECT = 10_000
"""The fewest samples `--select-samples` takes."""

DEFAULTS = DiscoverOptions()
"""The command line's defaults are the loop's own."""

HELP = "residual loop: find, trace and add missing effects, report the torque error before/after"


def add_parser(sub) -> None:
    """Register `discover` with the `hdjax` command's sub-parsers."""
    build_parser(sub.add_parser("discover", help=HELP))


def command(args: argparse.Namespace, parser=None) -> int:
    """The `hdjax discover` handler (the `hdjax` command turns errors into one line)."""
    return run(args)


def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    if parser is None:
        parser = Parser(prog="hdjax discover")
    p = parser
    p.description = (
        "Find what a calibrated compliance model gets wrong on TRAIN, name the physical effect, "
        "add it, refit, and report the torque error on TEST before and after. Example: hdjax "
        "discover --train train.csv --test test.csv --joint joint.toml --out runs/discover"
    )
    p.add_argument(
        "--train",
        type=Path,
        help="training recording (CSV, .npz, Parquet, HDF5, MATLAB v7.3 or MCAP, chosen by the "
        "suffix; columns t, theta_m, theta_l, current, torque [+ extras])",
    )
    p.add_argument(
        "--test",
        type=Path,
        help="test recording, same columns; used for reporting only, never to select",
    )
    p.add_argument(
        "--joint",
        type=Path,
        help="TOML file with a [joint] table (ratio, rated_torque, optional twist_sign)",
    )
    p.add_argument(
        "--config",
        type=Path,
        help="instead of --train/--test/--joint: a discover experiment TOML with "
        "[joint], [data] (files, column map) and [discover] tables, e.g. "
        "experiments/lara8_discover.toml",
    )
    p.add_argument(
        "--out",
        required=True,
        type=Path,
        help="output folder (absent or empty, or an earlier result with --overwrite) for "
        "report.json, report.md and figures/",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier hdjax result at --out (never any other folder, an input or the "
        "current directory)",
    )
    p.add_argument(
        "--max-effects",
        type=int,
        default=None,
        help=f"most effects to add (default {DEFAULTS.max_effects}; given, it overrides "
        "[discover] max_effects of --config)",
    )
    p.add_argument(
        "--min-gain",
        type=float,
        default=None,
        help="least cross-validated share of the twist error an effect must remove, in the "
        f"standard folds and in at least {100 * DEFAULTS.min_stability:.0f} %% of resampled fold "
        f"assignments (default {DEFAULTS.min_gain:g}; given, it overrides [discover] min_gain "
        "of --config)",
    )
    p.add_argument(
        "--chunk",
        type=int,
        default=None,
        metavar="N",
        help="accumulate the loop's least-squares fits (calibration, cross-validation, "
        "candidate scores, intervals) over chunks of N samples (at least 16), so no design of "
        "the whole record is held, and parse --train and --test N rows at a time; 0: the whole "
        "record at once (default: the discover file's [discover] chunk, else 0)",
    )
    p.add_argument(
        "--select-samples",
        type=int,
        default=None,
        metavar="M",
        help="with --chunk, for a --train log longer than memory allows: choose the effects on "
        f"M of its samples ({SELECT_BLOCKS} whole blocks, one centred in each of as many equal "
        "parts of the log), then "
        "calibrate the starting and the final model on every row, streamed; memory then grows "
        "with M, not with the log (default: all of TRAIN)",
    )
    p.add_argument(
        "--ignore-column",
        action="append",
        default=[],
        metavar="NAME",
        help="leave an extra column out of the analysis (repeatable)",
    )
    p.add_argument("--no-figures", action="store_true", help="write report.json and report.md only")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return p


def run(args: argparse.Namespace) -> int:
    """Carry out a parsed `discover` command; raises `HdjaxError` on bad input."""
    out: Path = args.out
    if args.max_effects is not None and args.max_effects < 0:
        raise DataError(f"--max-effects must be >= 0, got {args.max_effects}")
    if args.min_gain is not None and not 0.0 < args.min_gain < 1.0:
        raise DataError(f"--min-gain must lie in (0, 1), got {args.min_gain}")
    if args.config is not None and (args.train or args.test or args.joint):
        raise DataError("give either --config or --train/--test/--joint, not both")
    missing = [f"--{k}" for k in ("train", "test", "joint") if getattr(args, k) is None]
    if args.config is None and missing:
        raise DataError(f"missing {', '.join(missing)} (or give --config)")
    inputs = [args.train, args.test, args.joint, args.config]
    if args.config is not None:
        inputs += _config_inputs(args.config)
    if args.chunk is not None:
        check_chunk(args.chunk, "--chunk")
    if args.select_samples is not None:
        _check_select(args)
    # the memory guard counts whole-file parsing even with --chunk: the loop itself needs about
    # as much per sample as a parse (measured), so the guard stays conservative
    # a selection sample reads --train chunk by chunk and keeps M rows: the guard leaves it out
    whole = inputs[1:2] if args.select_samples else inputs[:2]
    check_read_memory(
        whole + inputs[4:],
        fix="give shorter --train and --test logs, or --chunk N --select-samples M",
    )
    with ResultDir(out, overwrite=args.overwrite, inputs=inputs, command="discover") as rd:
        return _run_into(rd, args)


def _check_select(args) -> None:
    m = args.select_samples
    if m < MIN_SELECT:
        raise DataError(
            f"--select-samples must be at least {MIN_SELECT} (the loop's folds need whole "
            f"blocks of its samples), got {m}"
        )
    if args.config is not None:
        raise DataError("--select-samples works with --train/--test/--joint, not --config")
    if not args.chunk:
        raise DataError(
            "--select-samples needs --chunk N: the final calibration streams over the whole "
            "--train log N rows at a time"
        )


def _experiment(args, joint, context_split: bool) -> tuple[str, str]:
    """The `experiment.toml` text that reproduces the final model with `hdjax run`, or `""`
    and why there is none."""
    if context_split:
        return "", (
            "TRAIN and TEST are blocks of one log ([data] test_blocks), which hdjax run does "
            "not cut the same way; use hdjax run --model with TRAIN and TEST logs of your own"
        )
    if args.config is None:
        data, train, test = {}, args.train, args.test
    else:
        data = read_toml(args.config).get("data", {})
        here = args.config.parent
        train, test = here / data["train"], here / data["test"]
    return experiment_toml(
        joint,
        train.resolve(),
        test.resolve(),
        data,
        name=f"{args.out.name}_run",
        out=str(args.out),
    ), ""


def _config_inputs(path: Path) -> list[Path]:
    """The data files a discover config names (for the output rules)."""
    data = read_toml(path).get("data", {})
    names = [data.get(k) for k in ("path", "train", "test")] if isinstance(data, dict) else []
    return [path.parent / n for n in names if isinstance(n, str) and n]


def _run_into(rd, args: argparse.Namespace) -> int:
    cfg_notes, cfg, context, selection = [], {}, None, {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if args.config is not None:
            train, test, joint, cfg, cfg_notes, context = load_discover_config(
                args.config, with_context=True
            )
        else:
            joint = load_joint(args.joint)
            # every log format, by suffix, through the loader the other commands use; with
            # --chunk parsed chunk by chunk (the parser's memory bounded by the chunk)
            if args.select_samples:
                train, selection = load_selection(args.train, args.select_samples, args.chunk)
            else:
                train = load_recording(args.train, chunk=args.chunk or None)
            test = load_recording(args.test, chunk=args.chunk or None)
            cfg_notes = ["reference: the 'torque' column of the --train and --test files"]
    say = (lambda s: None) if args.quiet else (lambda s: print(f"[discover] {s}", file=sys.stderr))
    if args.select_samples and not selection:
        cfg_notes.append(
            f"--select-samples {args.select_samples}: TRAIN holds no more samples, so the loop "
            "used all of them"
        )
    for w in caught:
        say(f"warning: {w.message}")
    options = discover_options(
        cfg,
        max_effects=args.max_effects,
        min_gain=args.min_gain,
        # the command line's --chunk, when given, over the file's (checked where each was read)
        chunk=args.chunk if args.chunk is not None else cfg.get("chunk", 0),
    )
    ignore = tuple(args.ignore_column) + tuple(cfg.get("ignore_columns", ()))
    notes = check_inputs(
        train, test, joint, min_order_m=options.library.orders_m[0], ignore_columns=ignore
    )
    if ignore:
        drop = lambda r: eqx.tree_at(
            lambda x: x.extras, r, {k: v for k, v in r.extras.items() if k not in ignore}
        )
        train, test = drop(train), drop(test)
        context = None if context is None else drop(context)
    context_split = context is not None
    # one log cut into TRAIN and TEST: the loop sees it whole (not chunk by chunk)
    context = context if not options.chunk else None
    result = loop.discover(train, test, joint, options, progress=say, context=context)
    result.aux.notes[:0] = cfg_notes + notes + [f"input warning: {w.message}" for w in caught]
    if selection:
        say(
            f"calibrating the starting and the final model on all {selection['samples_total']} "
            "TRAIN samples (streamed)"
        )
        result = refit_on_whole_log(result, args.train, test, joint, args.chunk, selection)
    say("writing report" + ("" if args.no_figures else " and figures"))
    experiment, missing = _experiment(args, joint, context_split)
    write_report(
        result,
        rd,
        joint=joint,
        train=train,
        figures=not args.no_figures,
        experiment=experiment,
        extra={
            "experiment_missing": missing,
            "train": train.source,
            "test": test.source,
            "joint": joint.to_dict(),
            "config": None if args.config is None else str(args.config),
            "version": __version__,
        },
    )
    say(
        f"done in {result.stats['fit_time_s']:.1f} s: effects {result.aux.effects or 'none'}; "
        f"TEST torque RMS {result.aux.baseline.rms:.4g} -> {result.aux.final.rms:.4g} N·m; "
        f"next: read {rd.out}/report.md, or estimate with hdjax estimate --model "
        f"{rd.out}/model.json --data LOG --out torque.csv"
    )
    return 0
