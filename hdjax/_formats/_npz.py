"""`.npz` archives (one array per column); chunks are slices of the loaded arrays."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import DataError


def _open(path: Path):
    import zipfile

    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise DataError(f"{path}: not a readable .npz archive ({err})") from None


def column_names(path) -> list[str]:
    with _open(Path(path)) as archive:
        return list(archive.files)


def read_table(path, names=None) -> dict[str, np.ndarray]:
    with _open(Path(path)) as archive:
        return {k: np.asarray(archive[k]) for k in (names or archive.files)}


def iter_tables(path, chunk: int, names=None):
    table = read_table(path, names)
    n = min(len(v) for v in table.values()) if table else 0
    for i in range(0, n, chunk):
        yield {k: v[i : i + chunk] for k, v in table.items()}
