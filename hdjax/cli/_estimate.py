"""`hdjax estimate`: apply a saved model to a new recording."""

from __future__ import annotations

from pathlib import Path

# compliance.estimate_torque is looked up at each call (a test stops the command there)
from .. import compliance
from .._errors import DataError, ModelMismatchError, UnitWarning
from .._formats import SUFFIXES, load_recording
from .._io import atomic_write_bytes, csv_bytes
from .._joint import load_joint
from .._memory import check_read_memory
from .._metrics import error_metrics
from ..modelfile import check_compatible, load_model
from ..modelfile.internal import angle_ratio_mismatch
from ..network import predict_torque as net_estimate
from ..report import check_output_file
from ._common import (
    Progress,
    add_flag,
    add_model_command,
    model_file,
    read_column_map,
)

HELP = "estimate torque on a new recording with a saved model (any log format in, CSV out)"
EXAMPLE = """\
example:
  hdjax estimate --model runs/song2019/model.json --data new.csv --out torque.csv
  hdjax estimate --model M.json --data log.csv --columns lara8.toml --joint lara8.toml --out E.csv

The output CSV has the columns t, torque_estimate and (model method) in_range; when the data has
a reference torque, torque_measured is added and the RMS / maximum error go to stderr.
"""


def add_parser(sub) -> None:
    p = add_model_command(sub, "estimate", HELP, EXAMPLE, "use")
    p.add_argument(
        "--data",
        required=True,
        help=f"the recording, in any format hdjax reads ({', '.join(SUFFIXES)}; chosen by the "
        "suffix)",
    )
    p.add_argument("--out", required=True, help="where to write the estimate (.csv)")
    p.add_argument(
        "--columns",
        help="TOML file whose [data] table maps the file's columns (columns/extras, as in an "
        "experiment config); default: the file has t, theta_m, theta_l, current in SI units",
    )
    p.add_argument(
        "--joint",
        help="TOML file with the data's [joint] table; refused if its ratio differs from the "
        "model's",
    )
    add_flag(
        p,
        "--overwrite",
        "replace an estimate written earlier by hdjax at --out (never an input or another file)",
    )
    add_flag(
        p,
        "--force",
        "estimate even when the angles look wrong for the model (degrees instead of radians, "
        "or a motor/output angle ratio other than the model's); refused by default",
    )
    add_flag(
        p,
        "--causal",
        "estimate each sample from it and earlier ones only, as a controller does (what the C "
        "code of 'hdjax export' computes): the first sample at rest, a smoothed velocity over "
        "the window ending at the sample",
    )


def command(args, parser) -> int:
    import warnings

    import numpy as np

    progress = Progress(args.quiet)
    out = Path(args.out)
    model_path = Path(args.model)
    inputs = [model_path, args.data, args.columns, args.joint]
    check_output_file(
        out, inputs=inputs, overwrite=args.overwrite, ours=is_estimate, example="torque.csv"
    )
    model_path = model_file(model_path)
    check_read_memory([args.data], fix="split the log into shorter files and estimate each")
    saved = load_model(model_path)
    cmap = read_column_map(args.columns)
    joint = load_joint(args.joint) if args.joint else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UnitWarning)
        try:
            rec = load_recording(args.data, cmap)
        except DataError as err:
            if cmap is None and "[data.columns]" in str(err):  # say where such a table goes
                raise DataError(f"{err} in a TOML file given with --columns FILE") from None
            raise
    for w in caught:
        if not issubclass(w.category, UnitWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        elif args.force:
            progress.warn(f"{w.message} (--force: estimating anyway; the torques may be wrong)")
        else:
            raise DataError(
                f"{w.message}; the estimate would be wrong, so none is written (pass "
                "--force to estimate anyway)"
            )
    check_compatible(saved, rec, joint, check_angles=False)
    why = angle_ratio_mismatch(saved, rec)
    if why and not args.force:
        raise ModelMismatchError(f"{why}; pass --force to estimate anyway")
    if why:
        progress.warn(f"{why} (--force: estimating anyway; the torques may be wrong)")
    progress(f"estimating {rec.n_samples} samples with the {args.method} of {model_path}")
    cols = {"t": np.asarray(rec.t)}
    if args.method == "network":
        if saved.network is None:
            raise ModelMismatchError(f"{model_path}: holds no network; use --method model")
        net = net_estimate(saved.network, rec, saved.joint, causal=args.causal)
        cols["torque_estimate"] = np.asarray(net)
    else:
        if saved.compliance is None:
            raise ModelMismatchError(
                f"{model_path}: holds no compliance model; use --method network"
            )
        est = compliance.estimate_torque(saved.compliance, rec, causal=args.causal)
        cols["torque_estimate"] = np.asarray(est.torque)
        cols["in_range"] = np.asarray(est.in_range).astype(np.float64)
    if rec.torque is not None:
        cols["torque_measured"] = np.asarray(rec.torque)
        m = error_metrics(
            cols["torque_estimate"], cols["torque_measured"], saved.joint.rated_torque
        )
        progress(
            f"error against the measured torque: RMS {m.rms:.4g} N·m, max {m.max:.4g} N·m "
            f"({m.max_pct:.3g} % of rated)"
        )
    data = csv_bytes(cols)
    check_output_file(out, inputs=inputs, overwrite=args.overwrite, ours=is_estimate)
    atomic_write_bytes(out, data)
    progress(f"wrote {out}")
    return 0


ESTIMATE_HEADER = "t,torque_estimate"


def is_estimate(path: Path) -> bool:
    """Whether `path` is an estimate CSV written by `hdjax estimate` (its header says so)."""
    try:
        with open(path, "rb") as fh:
            first = fh.read(256)
    except OSError:
        return False
    return first.startswith(ESTIMATE_HEADER.encode())
