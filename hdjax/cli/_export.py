"""`hdjax export`: a saved model as dependency-free C code with a causal per-sample step.

The result folder follows the rules of every command ([`hdjax.report.ResultDir`][]): it is
checked before any work, filled in a staging folder and renamed into place only when complete,
so a model that cannot be exported (a term without C code, a velocity that reads ahead) gets one
line on stderr, exit code 2, and nothing written.
"""

from __future__ import annotations

from pathlib import Path

from ._common import (
    RESULT_OVERWRITE,
    Progress,
    add_flag,
    add_model_command,
    model_file,
    read_column_map,
)

HELP = "export a saved model as C99 code with a per-sample step (no heap, libm only)"
EXAMPLE = """\
example:
  hdjax export --model runs/song2019/model.json --out runs/song2019_c
  hdjax export --model runs/song2019 --method network --precision single --out runs/net_c
  hdjax export --model runs/song2019 --counts-per-rev-m 2097152 --counts-per-rev-l 524288 \\
      --out runs/song2019_c

OUT holds hdjax_estimator.h and hdjax_estimator.c (call hdjax_init, then hdjax_step once per
sample; hdjax_sample_from_counts fills a sample from 64-bit encoder counts as hdjax reads them,
when both encoders' counts per revolution are known: the joint's encoder_bits_motor and
encoder_bits_load, or --counts-per-rev-m/-l), README.md with the calling sequence,
test_vectors.csv (inputs and the torque hdjax computes for them) and hdjax_check.c,
which checks a build against the vectors:
  cc -std=c99 -O2 hdjax_estimator.c hdjax_check.c -lm -o hdjax_check
  ./hdjax_check test_vectors.csv
The step uses the present sample and earlier ones only; it equals 'hdjax estimate --causal'.
"""


def add_parser(sub) -> None:
    """Register `export` with the `hdjax` command's sub-parsers."""
    p = add_model_command(sub, "export", HELP, EXAMPLE, "export")
    p.add_argument("--out", required=True, help="the folder to write the C code into")
    p.add_argument(
        "--precision",
        choices=("double", "single"),
        default="double",
        help="the C type of the model's arithmetic: double (equals hdjax's estimate to "
        "rounding) or single (float; angles, time and twist stay double)",
    )
    add_flag(
        p,
        "--causal",
        'export the causal form of a velocity that reads ahead (velocity = "smoothed": the '
        "line over the window ending at each sample), refused otherwise",
    )
    p.add_argument(
        "--data",
        help="a recording whose first --vectors samples become the test vectors (default: "
        "samples that sweep the calibrated torque range)",
    )
    p.add_argument(
        "--columns",
        help="TOML file whose [data] table maps the --data file's columns (as for estimate)",
    )
    p.add_argument(
        "--vectors", type=int, default=2000, help="samples in test_vectors.csv (default 2000)"
    )
    for suffix, name, field in (("m", "motor", "motor"), ("l", "load", "load")):
        p.add_argument(
            f"--counts-per-rev-{suffix}",
            metavar="N",
            help=f"{name} encoder counts per revolution (a positive whole number; default "
            f"2^encoder_bits_{field} of the model's joint): with both encoders' resolutions "
            "known the estimator gets hdjax_sample_from_counts",
        )
    add_flag(p, "--overwrite", RESULT_OVERWRITE)


def command(args, parser) -> int:
    """Run `hdjax export` (see the module docstring)."""
    from .._errors import ConfigError
    from .._formats import load_recording
    from ..export import check_counts_per_rev, export_files
    from ..modelfile import check_compatible, load_model
    from ..report import ResultDir

    progress = Progress(args.quiet)
    if args.columns and not args.data:
        raise ConfigError("--columns maps the --data file's columns; give --data too")
    if args.vectors < 2:
        raise ConfigError(f"--vectors must be at least 2 samples, got {args.vectors}")
    cpr = {
        suffix: None if value is None else check_counts_per_rev(value, f"--counts-per-rev-{suffix}")
        for suffix, value in (("m", args.counts_per_rev_m), ("l", args.counts_per_rev_l))
    }
    out = Path(args.out)
    inputs = [Path(args.model), args.data, args.columns]
    with ResultDir(out, overwrite=args.overwrite, inputs=inputs, command="export") as rd:
        path = model_file(args.model)
        saved = load_model(path)
        recording = None
        if args.data:
            cmap = read_column_map(args.columns)
            recording = load_recording(args.data, cmap)
            check_compatible(saved, recording)
        progress(f"exporting the {args.method} of {path} ({args.precision} precision)")
        files = export_files(
            saved,
            method=args.method,
            precision=args.precision,
            causal=args.causal,
            recording=recording,
            n_vectors=args.vectors,
            source=str(path),
            counts_per_rev_m=cpr["m"],
            counts_per_rev_l=cpr["l"],
        )
        for name, data in files.items():
            rd.write_bytes(name, data)
    progress(f"wrote {out}")
    return 0
