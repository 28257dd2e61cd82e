"""Log formats beyond CSV and `.npz`: one reader per format, all read through a column map.

| suffix | format | extra to install |
|---|---|---|
| `.csv` | CSV, read whole or in chunks (logs larger than memory) | none |
| `.parquet`, `.pq` | Apache Parquet (recommended for long logs) | `hdjax[parquet]` |
| `.h5`, `.hdf5`, `.mat` | HDF5, MATLAB v7.3 (HDF5 inside) | `hdjax[hdf5]` |
| `.mcap` | MCAP (ROS 2 bags and others), a topic and field path per column | `hdjax[mcap]` |

Every reader offers the same three functions on a *table* (column name to 1-D float64 array):
`column_names(path)`, `read_table(path, names)` and `iter_tables(path, chunk, names)`. The
public entry points here turn tables into [`hdjax.Recording`][]s through a
[`hdjax.ColumnMap`][]: [`load`][] reads a whole file, [`iter_recordings`][] streams it chunk by
chunk with the map's state (multi-turn unwrapping, `offset = "first"`) carried across chunks, so
the chunks together equal the whole file read at once.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .._custom_types import PathLike
from .._errors import DataError
from .._io import ColumnMap, load_csv, load_npz, table_recording
from .._recording import Recording, make_recording
from ._columns import as_float_column as as_float_column, require as require
from ._mapper import ChunkMapper, needed_sources
from ._parquet import ParquetWriter as ParquetWriter  # pyarrow is imported on first use

SUFFIXES = {
    ".csv": "_csv",
    ".npz": "_npz",
    ".parquet": "_parquet",
    ".pq": "_parquet",
    ".h5": "_hdf5",
    ".hdf5": "_hdf5",
    ".mat": "_hdf5",
    ".mcap": "_mcap",
}
"""File suffix -> reader module."""


def reader(path):
    """The reader module for `path`, chosen by its suffix."""
    suffix = Path(path).suffix.lower()
    name = SUFFIXES.get(suffix)
    if name is None:
        known = ", ".join(sorted(SUFFIXES))
        raise DataError(f"{path}: unknown recording format {suffix!r}; use one of {known}")
    return importlib.import_module(f"{__name__}.{name}")


def _text(mod, columns) -> dict:
    """The keyword arguments of a text reader (CSV): the column map's `encoding`."""
    return {"encoding": getattr(columns, "encoding", None)} if getattr(mod, "TEXT", False) else {}


def check_exists(path: Path) -> None:
    if not path.exists():
        raise DataError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise DataError(f"{path}: the file is empty")


def load(path, columns=None, *, check_units: bool = True):
    """Load a whole recording from any supported format (see the module table).

    **Arguments:**

    - `path`: the log file; its suffix chooses the reader.
    - `columns`: an optional [`hdjax.ColumnMap`][].
    - `check_units`: warn on angles that look like degrees.

    **Returns:** a [`hdjax.Recording`][].
    """
    path = Path(path)
    mod = reader(path)
    check_exists(path)
    kw = _text(mod, columns)
    names = needed_sources(columns, mod.column_names(path, **kw), str(path), mod)
    table = mod.read_table(path, names, **kw)
    return table_recording(table, columns, str(path), check_units)


def iter_recordings(path, columns=None, *, chunk: int, check_units: bool = True) -> Iterator:
    """Stream a log as consecutive [`hdjax.Recording`][] chunks of at most `chunk` samples.

    Only the columns the map needs are read. The column map's state carries across chunks
    (counter unwrapping continues from the previous chunk, `offset = "first"` subtracts the
    file's first sample), and the time column is checked to increase across chunk boundaries,
    so concatenating the chunks gives the recording [`load`][] returns.
    """
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 2:
        raise DataError(f"chunk must be an integer >= 2 samples, got {chunk!r}")
    path = Path(path)
    mod = reader(path)
    check_exists(path)
    kw = _text(mod, columns)
    available = mod.column_names(path, **kw)
    names = needed_sources(columns, available, str(path), mod)
    mapper = ChunkMapper(columns, available if names is None else names, str(path), check_units)
    for table in _at_least_two(mod.iter_tables(path, chunk, names, **kw)):
        yield mapper(table)
    if mapper.n_rows == 0:
        raise DataError(f"{path}: the file has no data rows")


def _rows(table: dict) -> int:
    return next(iter(table.values())).shape[0] if table else 0


def _at_least_two(tables):
    """Drop empty tables and fold a one-row last table into the one before it (a recording
    chunk needs two samples)."""
    held = None
    for table in tables:
        if _rows(table) == 0:
            continue
        if held is not None:
            if _rows(table) < 2:
                table = {k: np.concatenate([held[k], table[k]]) for k in held}
            else:
                yield held
        held = table
    if held is not None:
        yield held


def load_recording(
    path: PathLike,
    columns: ColumnMap | None = None,
    *,
    check_units: bool = True,
    chunk: int | None = None,
) -> Recording:
    """Load a recording chosen by the file's suffix: `.csv` ([`hdjax.load_csv`][]), `.npz`
    ([`hdjax.load_npz`][]), or Parquet, HDF5 / MATLAB v7.3 or MCAP through their readers (the
    column map applied as for CSV).

    With `chunk` (rows, at least 2) the file is parsed `chunk` rows at a time and the chunks
    joined: the same recording, while the parser's working memory is bounded by the chunk
    instead of the file (a CSV's text and cells take about ten times the recording).
    """
    if Path(path).is_dir():
        raise DataError(f"{path}: is a folder; give a recording file (.csv, .npz, ...)")
    if chunk is not None:
        return _joined(iter_recordings(path, columns, chunk=chunk, check_units=False), check_units)
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        return load_csv(path, columns, check_units=check_units)
    if suffix == ".npz":
        return load_npz(path, columns, check_units=check_units)
    return load(path, columns, check_units=check_units)


def _joined(chunks: Iterator[Recording], check_units: bool, keep=None) -> Recording:
    """One recording of consecutive chunks (units checked once, on the whole, as a whole-file
    load does); with `keep(start, n)`, only the rows it selects (a mask per chunk)."""
    parts, start, source = [], 0, None
    for rec in chunks:  # iter_recordings yields at least one
        cols, n = rec.to_numpy(), rec.n_samples
        source = rec.source if source is None else source
        if keep is not None:
            mask = keep(start, n)
            cols = {k: v[mask] for k, v in cols.items()}
        start += n
        parts.append(cols)
    whole = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    core = [whole.pop(k) for k in ("t", "theta_m", "theta_l", "current")]
    torque = whole.pop("torque", None)
    return make_recording(*core, torque, whole, source=source, check_units=check_units)


def load_rows(path: PathLike, keep, *, chunk: int, check_units: bool = True) -> Recording:
    """The rows of a log that `keep(start, n)` selects (a boolean mask of the rows
    `start .. start + n`), the file read `chunk` rows at a time: memory follows the rows
    kept and the chunk, not the file."""
    return _joined(iter_recordings(path, chunk=chunk, check_units=False), check_units, keep)


def count_rows(path: PathLike, columns: ColumnMap | None = None, *, chunk: int) -> int:
    """The number of data rows of a log, read `chunk` rows at a time."""
    return sum(r.n_samples for r in iter_recordings(path, columns, chunk=chunk, check_units=False))
