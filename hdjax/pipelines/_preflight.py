"""Checks of a resolved experiment that need more than one table, run before any work starts.

`hdjax run`, every `--set` and every sweep member pass through [`preflight`][]: the model the
`[model]` table describes must be constructible, and the data it asks for must fit in the
machine's free memory. A problem is one [`hdjax.ConfigError`][] naming the setting.
"""

from __future__ import annotations

import math
from pathlib import Path

from .._custom_types import PathLike
from .._errors import ConfigError, HdjaxError, ModelMismatchError
from .._memory import BYTES_PER_SAMPLE, CSV_FACTOR, check_memory, file_size
from ..config.internal import joint_of
from ..modelfile.internal import ratio_mismatch
from ._model import build_model

# The least-squares fit holds the design matrix about three times (the matrix, its QR factor
# and the scaled copy).
_DESIGN_COPIES = 3
_PLANT_DT = 5e-4


def _n_coef(cfg: dict, where: str) -> int:
    """The number of model terms of a `[model]` table (the model is built to count them)."""
    try:
        model = build_model(cfg, joint_of(cfg), 1.0)
    except HdjaxError as err:
        raise ConfigError(f"{where} [model]: {' '.join(str(err).split())}") from None
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{where} [model]: cannot build this model ({err})") from None
    return int(model.n_coef)


def _n_samples(cfg: dict, base_dir: Path | None) -> tuple[float, str, str, float]:
    """(samples to calibrate on, what sets it, how to lower it, extra bytes to read files)."""
    data = cfg["data"]
    if data["kind"] == "synthetic":
        n = data["n_samples"]
        return n, f"[data] n_samples = {n}", "use fewer samples", 2.0 * n * BYTES_PER_SAMPLE
    if data["kind"] == "plant":
        per = data["duration"] / _PLANT_DT
        n = per * len(data["scenarios"])
        what = f"[data] duration = {data['duration']:g} s ({len(data['scenarios'])} scenarios)"
        return n, what, "use a shorter duration", 2.0 * n * BYTES_PER_SAMPLE
    at = lambda name: file_size(Path(name) if base_dir is None else base_dir / Path(name))
    tests = data["test"]
    tests = list(tests.values()) if isinstance(tests, dict) else list(tests)
    train_bytes = sum(at(n) for n in data["train"])
    total = train_bytes + sum(at(n) for n in tests)
    n = train_bytes / 60.0  # at least about 60 bytes per CSV row (6 columns of 10 characters)
    return n, "the data files", "read a shorter part of the log", CSV_FACTOR * total


def preflight(cfg: dict, *, base_dir: PathLike | None = None, where: str = "config") -> None:
    """Check a resolved config before any work: its model can be built and its data fits in
    memory.

    **Raises:** [`hdjax.ConfigError`][] in one line naming the setting.
    """
    n_coef = _n_coef(cfg, where)
    n, what, fix, read_bytes = _n_samples(cfg, None if base_dir is None else Path(base_dir))
    fit = cfg["fit"]
    if fit["method"] == "rls":
        design = fit["block"] * n_coef * 8 * _DESIGN_COPIES + n * BYTES_PER_SAMPLE
    else:
        design = n * (n_coef * 8 * _DESIGN_COPIES + BYTES_PER_SAMPLE)
    need = read_bytes + design
    if math.isfinite(need):
        check_memory(need, f"{where}: {what} with {n_coef} model terms", fix)


def check_angles(ds, *, force: bool = False, warn=None) -> str:
    """Refuse recordings whose motor-to-output angle ratio differs from the joint's by more
    than 5 % (another joint's data, or angles scaled differently): a model calibrated on them
    would be wrong. With `force` the mismatches go, as one line, to `warn` instead.

    **Returns:** the mismatch (`""` when every recording matches), for a caller that reports
    it itself (`warn=None`).

    **Raises:** [`hdjax.ModelMismatchError`][] naming the recording, unless `force`.
    """
    whys: dict = {}  # source -> why (a file split into calibration and test parts: once)
    if hasattr(ds, "ratio_mismatches"):  # streamed parts: from the sums of the build pass
        found = ds.ratio_mismatches()
    else:
        found = [
            (rec.source, ratio_mismatch(ds.joint.ratio, rec))
            for rec in list(ds.train) + list(ds.test.values())
        ]
    for source, why in found:
        if not why:
            continue
        if not force:
            raise ModelMismatchError(f"{why}; pass --force to run anyway")
        whys.setdefault(source, why)
    if not whys:
        return ""
    first = next(iter(whys.values()))
    text = f"{first} (and {len(whys) - 1} more file(s))" if len(whys) > 1 else first
    if warn is not None:
        warn(f"{text} (--force: running anyway; the results may be wrong)")
    return text
