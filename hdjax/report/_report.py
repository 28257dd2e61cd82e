"""Result directories written atomically: `metrics.json`, `figures/*.png`, `report.md`,
`config.resolved.toml` and the version and seed that produced them.

Everything is written into a staging directory beside the target and renamed into place only
when complete, so a crash never leaves a half-written result that looks complete: either the
target holds a full result (with `metrics.json`) or it does not exist. A sweep keeps its
staging directory (`OUT.partial`) after an interruption, so the next run resumes from the
member results cached there.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
from pathlib import Path

from .._errors import ConfigError


def _clean(obj):
    """JSON-ready copy: NaN/inf become `null`, tuples lists, numpy scalars floats."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
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
    import jax

    from .. import __version__

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
    - `overwrite`: replace an existing `out` (otherwise refuse before any work is done).
    - `staging`: the staging directory (default a hidden `.NAME.tmp-PID` beside `out`).
    - `keep_staging_on_error`: leave the staging directory after an exception (for resumable
      sweeps); by default it is removed.

    Use as a context manager: leaving the block normally commits, an exception aborts.

    **Raises:** [`hdjax.ConfigError`][] when `out` exists and `overwrite` is false, or is a file.
    """

    def __init__(self, out, *, overwrite: bool = False, staging=None, keep_staging_on_error=False):
        self.out = Path(out)
        if self.out.exists() and not self.out.is_dir():
            raise ConfigError(f"output {self.out} exists and is not a directory")
        if self.out.exists() and not overwrite:
            raise ConfigError(
                f"output directory {self.out} already exists; choose another --out or pass "
                "--overwrite to replace it"
            )
        self.overwrite = overwrite
        self.keep = keep_staging_on_error
        default = self.out.parent / f".{self.out.name}.tmp-{os.getpid()}"
        self.staging = Path(staging) if staging is not None else default
        self.staging.mkdir(parents=True, exist_ok=True)
        self.files: list[str] = []

    def path(self, rel: str) -> Path:
        """Where `rel` lives inside the staging directory (parents created)."""
        p = self.staging / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def write_bytes(self, rel: str, data: bytes) -> None:
        from .._io import atomic_write_bytes

        atomic_write_bytes(self.path(rel), data)
        if rel not in self.files:
            self.files.append(rel)

    def write_text(self, rel: str, text: str) -> None:
        self.write_bytes(rel, text.encode())

    def write_json(self, rel: str, obj) -> None:
        self.write_bytes(rel, json_bytes(obj))

    def commit(self) -> Path:
        """Move the finished result into place (replacing the old one under `overwrite`)."""
        old = None
        if self.out.exists():
            if not self.overwrite:
                raise ConfigError(
                    f"output directory {self.out} appeared while running; not replaced"
                )
            old = self.out.parent / f".{self.out.name}.old-{os.getpid()}"
            os.replace(self.out, old)
        self.out.parent.mkdir(parents=True, exist_ok=True)
        os.replace(self.staging, self.out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.out

    def abort(self) -> None:
        if not self.keep:
            shutil.rmtree(self.staging, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.commit()
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
