"""Result directories written atomically: `metrics.json`, `figures/*.png`, `report.md`,
`config.resolved.toml` and the version and seed that produced them.

Everything is written into a staging directory beside the target and renamed into place only
when complete, so a crash never leaves a half-written result that looks complete: either the
target holds a full result (with `metrics.json`) or it does not exist. The result is stamped
with a marker file listing its files, and only such a folder is ever replaced (the rules are in
`hdjax/report/_outputs.py`). A sweep keeps its
staging directory (`OUT.partial`) after an interruption, so the next run resumes from the
member results cached there.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
from collections.abc import Iterable
from pathlib import Path

import jax
import numpy as np

# `_io.atomic_write_bytes` is looked up at each call, so that a test can stand a full disk in
from .. import __version__, _io
from .._custom_types import PathLike
from .._errors import ConfigError
from .._interrupts import check, critical
from ._outputs import MARKER, check_not_input, check_output_dir, marker_bytes, read_marker


def _clean(obj):
    """JSON-ready copy: NaN/inf become `null`, tuples and arrays lists, numpy scalars floats
    (booleans stay booleans)."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return obj
    if isinstance(obj, int):
        return obj
    try:
        f = float(obj)
    except (TypeError, ValueError):
        return str(obj)
    return f if math.isfinite(f) else None


def json_bytes(obj) -> bytes:
    """Pretty, strict JSON (no NaN) for a result file."""
    return (json.dumps(_clean(obj), indent=2, allow_nan=False) + "\n").encode()


def environment(seed: int | None = None) -> dict:
    """Version, seed and machine facts recorded with every result."""

    return {
        "hdjax_version": __version__,
        "jax_version": jax.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "backend": jax.default_backend(),
        "precision": "float64",
        "seed": seed,
    }


class ResultDir:
    """A result directory filled in a staging directory and renamed into place on `commit`.

    **Arguments:**

    - `out`: the final directory.
    - `overwrite`: replace an existing hdjax result at `out` (otherwise refuse before any work
      is done). Only a folder hdjax wrote and stamped with its marker file is ever replaced;
      see [`hdjax.report.check_output_dir`][] for every rule.
    - `inputs`: the paths the command reads; `out` (and the staging folder) may not be, hold or
      lie inside any of them.
    - `staging`: the staging directory (default a hidden `.NAME.tmp-PID` beside `out`).
    - `keep_staging_on_error`: leave the staging directory after an exception (for resumable
      sweeps) when it holds files beyond the marker; by default it is removed.
    - `command`: the command recorded in the marker.

    Use as a context manager: leaving the block normally commits, an exception (or SIGINT /
    SIGTERM) aborts.

    **Raises:** [`hdjax.ConfigError`][] naming `out` and what to do, when the rules refuse it.
    """

    def __init__(
        self,
        out: PathLike,
        *,
        overwrite: bool = False,
        inputs: Iterable[PathLike | None] = (),
        staging: PathLike | None = None,
        keep_staging_on_error: bool = False,
        command: str = "hdjax",
    ) -> None:

        self.out = Path(out)
        self.inputs = tuple(p for p in inputs if p is not None)
        check_output_dir(self.out, inputs=self.inputs, overwrite=overwrite)
        self.overwrite = overwrite
        self.keep = keep_staging_on_error
        self.command = command
        default = self.out.parent / f".{self.out.name}.tmp-{os.getpid()}"
        self.staging = Path(staging) if staging is not None else default
        check_not_input(self.staging, self.inputs, flag="the staging folder of --out")
        if self.staging.is_dir() and any(self.staging.iterdir()):
            if read_marker(self.staging) is None:
                raise ConfigError(
                    f"{self.staging}: the staging folder of --out {self.out} exists and was not "
                    "written by hdjax; move it away or choose another --out"
                )
        elif self.staging.exists() and not self.staging.is_dir():
            raise ConfigError(
                f"{self.staging}: the staging folder of --out {self.out} exists as a file; move "
                "it away or choose another --out"
            )
        self._marker = MARKER
        try:
            self.staging.mkdir(parents=True, exist_ok=True)
            if not (self.staging / MARKER).exists():
                _io.atomic_write_bytes(
                    self.staging / MARKER, marker_bytes(command, [], staging=True)
                )
        except OSError as err:
            raise ConfigError(
                f"{self.out}: cannot create the result folder there "
                f"({(err.strerror or str(err)).lower()}: {err.filename}); choose another --out"
            ) from None
        self.files: list[str] = []

    def path(self, rel: str) -> Path:
        """Where `rel` lives inside the staging directory (parents created)."""
        p = self.staging / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def write_bytes(self, rel: str, data: bytes) -> None:
        check()
        _io.atomic_write_bytes(self.path(rel), data)
        if rel not in self.files:
            self.files.append(rel)

    def write_text(self, rel: str, text: str) -> None:
        self.write_bytes(rel, text.encode())

    def write_json(self, rel: str, obj) -> None:
        self.write_bytes(rel, json_bytes(obj))

    def holds_work(self) -> bool:
        """Whether the staging directory holds any file besides the marker."""
        if not self.staging.is_dir():
            return False
        return any(
            f != self._marker or Path(root) != self.staging
            for root, _dirs, files in os.walk(self.staging)
            for f in files
        )

    def commit(self) -> Path:
        """Move the finished result into place (replacing the old one under `overwrite`)."""
        check()
        # the folder may have changed while the command ran: apply the rules again
        state = check_output_dir(self.out, inputs=self.inputs, overwrite=self.overwrite)
        files = []
        for root, _dirs, names in os.walk(self.staging):
            files += [Path(root, n).relative_to(self.staging).as_posix() for n in names]
        files = [f for f in files if f != self._marker]
        _io.atomic_write_bytes(self.staging / self._marker, marker_bytes(self.command, files))
        with critical():
            old = None
            if state == "result":
                old = self.out.parent / f".{self.out.name}.old-{os.getpid()}"
                os.replace(self.out, old)
            self.out.parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.staging, self.out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.out

    def abort(self) -> None:
        """Remove the staging directory (kept, for resuming, when asked and not empty)."""
        if not self.keep or not self.holds_work():
            shutil.rmtree(self.staging, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            try:
                self.commit()
            except BaseException:
                self.abort()
                raise
        else:
            self.abort()
        return False


def markdown_table(header: list[str], rows: list[list]) -> str:
    """A GitHub-flavoured Markdown table; floats printed with 4 significant digits."""

    def cell(v):
        if v is None:
            return "n/a"
        if isinstance(v, float):
            return "n/a" if not math.isfinite(v) else f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)
