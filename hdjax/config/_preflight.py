"""Checks of a resolved experiment that need more than one table, run before any work starts.

`hdjax run`, every `--set` and every sweep member pass through [`preflight`][]: the model the
`[model]` table describes must be constructible, and the data it asks for must fit in the
machine's free memory. A problem is one [`hdjax.ConfigError`][] naming the setting.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from .._custom_types import PathLike
from .._errors import ConfigError, HdjaxError, ModelMismatchError
from ._saved_model import ratio_mismatch
from ._schema import joint_of, model_of

# Bytes per sample, beyond the design matrix: the recording, its signals and velocities, the
# estimate and its error (about 40 float64 arrays of the recording's length).
_BYTES_PER_SAMPLE = 40 * 8
# The least-squares fit holds the design matrix about three times (the matrix, its QR factor
# and the scaled copy).
_DESIGN_COPIES = 3
# A CSV file read whole holds its text and one Python string per cell: about ten times the
# file's size.
_CSV_FACTOR = 10
_PLANT_DT = 5e-4


def available_memory() -> int | None:
    """Bytes of memory free for this process (`MemAvailable` on Linux), or `None` if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _size(n: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} PB"  # pragma: no cover


def check_memory(n_bytes: float, what: str, fix: str, *, free: int | None = None) -> None:
    """Refuse an allocation of `n_bytes` larger than the free memory, in one line.

    **Arguments:**

    - `n_bytes`: the estimated size.
    - `what`: what needs it ("[data] n_samples = 2000000000").
    - `fix`: what to do instead.
    - `free`: the free memory in bytes (default `available_memory`).
    """
    free = available_memory() if free is None else free
    if free is not None and n_bytes > free:
        raise ConfigError(
            f"{what} needs about {_size(n_bytes)} of memory but only {_size(free)} is free; {fix}"
        )


def check_read_memory(paths, *, fix: str, free: int | None = None) -> None:
    """Refuse, in one line, to read logs whose estimated in-memory size (a CSV's text and
    cells, the recording and its signals) exceeds the free memory, before any is read.

    **Arguments:**

    - `paths`: the files to be read whole (missing ones are left to the reader's message).
    - `fix`: what to do instead.
    - `free`: the free memory in bytes (default `available_memory`).
    """
    files = [Path(p) for p in paths if p is not None]
    sizes = [_stat(p) for p in files]
    need = 0.0
    for p, size in zip(files, sizes):
        text = p.suffix.lower() == ".csv"
        # about 60 bytes per CSV row; a binary log at least 40 (5 float64 columns)
        per_row = 60.0 if text else 40.0
        need += size * (_CSV_FACTOR if text else 1) + size / per_row * _BYTES_PER_SAMPLE
    if need:
        names = ", ".join(str(p) for p, n in zip(files, sizes) if n)
        check_memory(need, f"reading {names} ({_size(sum(sizes))})", fix, free=free)


def _n_coef(cfg: dict, where: str) -> int:
    """The number of model terms of a `[model]` table (the model is built to count them)."""
    try:
        model = model_of(cfg, joint_of(cfg), 1.0)
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
        return n, f"[data] n_samples = {n}", "use fewer samples", 2.0 * n * _BYTES_PER_SAMPLE
    if data["kind"] == "plant":
        per = data["duration"] / _PLANT_DT
        n = per * len(data["scenarios"])
        what = f"[data] duration = {data['duration']:g} s ({len(data['scenarios'])} scenarios)"
        return n, what, "use a shorter duration", 2.0 * n * _BYTES_PER_SAMPLE
    at = lambda name: _stat(Path(name) if base_dir is None else base_dir / Path(name))
    tests = data["test"]
    tests = list(tests.values()) if isinstance(tests, dict) else list(tests)
    train_bytes = sum(at(n) for n in data["train"])
    total = train_bytes + sum(at(n) for n in tests)
    n = train_bytes / 60.0  # at least about 60 bytes per CSV row (6 columns of 10 characters)
    return n, "the data files", "read a shorter part of the log", _CSV_FACTOR * total


def _stat(p: Path) -> int:
    try:
        return p.expanduser().stat().st_size
    except OSError:
        return 0


def preflight(cfg: dict, *, base_dir: PathLike | None = None, where: str = "config") -> None:
    """Check a resolved config before any work: its model can be built and its data fits in
    memory.

    **Raises:** [`hdjax.ConfigError`][] in one line naming the setting.
    """
    n_coef = _n_coef(cfg, where)
    n, what, fix, read_bytes = _n_samples(cfg, None if base_dir is None else Path(base_dir))
    fit = cfg["fit"]
    if fit["method"] == "rls":
        design = fit["block"] * n_coef * 8 * _DESIGN_COPIES + n * _BYTES_PER_SAMPLE
    else:
        design = n * (n_coef * 8 * _DESIGN_COPIES + _BYTES_PER_SAMPLE)
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
