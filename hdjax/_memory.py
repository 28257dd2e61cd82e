"""Free-memory checks made before a command reads or allocates anything large.

Light on purpose (no JAX, no hdjax sub-package): `hdjax discover` and `hdjax estimate` check
their logs before importing what reads them.
"""

from __future__ import annotations

import os
from pathlib import Path

from ._errors import ConfigError

# Bytes per sample, beyond the design matrix: the recording, its signals and velocities, the
# estimate and its error (about 40 float64 arrays of the recording's length).
BYTES_PER_SAMPLE = 40 * 8
# A CSV file read whole holds its text and one Python string per cell: about ten times the
# file's size.
CSV_FACTOR = 10


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


def size_text(n: float) -> str:
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
            f"{what} needs about {size_text(n_bytes)} of memory but only {size_text(free)} is "
            f"free; {fix}"
        )


def file_size(p: Path) -> int:
    try:
        return p.expanduser().stat().st_size
    except OSError:
        return 0


def check_read_memory(paths, *, fix: str, free: int | None = None) -> None:
    """Refuse, in one line, to read logs whose estimated in-memory size (a CSV's text and
    cells, the recording and its signals) exceeds the free memory, before any is read.

    **Arguments:**

    - `paths`: the files to be read whole (missing ones are left to the reader's message).
    - `fix`: what to do instead.
    - `free`: the free memory in bytes (default `available_memory`).
    """
    files = [Path(p) for p in paths if p is not None]
    sizes = [file_size(p) for p in files]
    need = 0.0
    for p, size in zip(files, sizes):
        text = p.suffix.lower() == ".csv"
        # about 60 bytes per CSV row; a binary log at least 40 (5 float64 columns)
        per_row = 60.0 if text else 40.0
        need += size * (CSV_FACTOR if text else 1) + size / per_row * BYTES_PER_SAMPLE
    if need:
        names = ", ".join(str(p) for p, n in zip(files, sizes) if n)
        check_memory(need, f"reading {names} ({size_text(sum(sizes))})", fix, free=free)
