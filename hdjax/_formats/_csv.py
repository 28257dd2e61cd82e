"""CSV, read whole (through `hdjax._io`) or in chunks of rows for logs larger than memory."""

from __future__ import annotations

import csv
import itertools
import math
from pathlib import Path

import numpy as np

from .._errors import DataError


def _header(path: Path, fh) -> list[str]:
    try:
        header = [h.strip() for h in next(csv.reader([fh.readline()]))]
    except StopIteration:
        raise DataError(f"{path}: the file is empty; expected a header row") from None
    if not any(header):
        raise DataError(f"{path}: the first line is empty; expected a header row")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise DataError(f"{path}: duplicated column name(s) in the header: {', '.join(dup)}")
    return header


def _open(path: Path):
    # UTF-8 with or without a byte-order mark; a bad byte is reported by the callers
    return path.open(newline="", encoding="utf-8-sig")


def _not_utf8(path: Path, line: int) -> DataError:
    return DataError(
        f"{path}: not valid UTF-8 text near line {line}; save the file as UTF-8 (or read it "
        "whole, through a column map with an encoding setting)"
    )


def column_names(path) -> list[str]:
    path = Path(path)
    try:
        with _open(path) as fh:
            return _header(path, fh)
    except UnicodeDecodeError:
        raise _not_utf8(path, 1) from None


def read_table(path, names=None) -> dict[str, np.ndarray]:
    """The whole file (the checks of [`hdjax.load_csv`][])."""
    from .._io import _read_csv_table

    header, body = _read_csv_table(Path(path))
    keep = header if names is None else names
    return {name: body[:, header.index(name)] for name in keep}


def _parse(path: Path, header: list[str], rows: list[list[str]], first_line: int) -> np.ndarray:
    body = np.empty((len(rows), len(header)), dtype=np.float64)
    for i, row in enumerate(rows):
        if len(row) != len(header):
            raise DataError(
                f"{path}: line {first_line + i} has {len(row)} cells but the header has "
                f"{len(header)}; columns of different lengths cannot form a recording"
            )
        try:
            body[i] = [float(c) if c.strip() != "" else math.nan for c in row]
        except ValueError:
            for j, cell in enumerate(row):
                try:
                    float(cell)
                except ValueError:
                    raise DataError(
                        f"{path}: non-numeric cell {cell!r} in column {header[j]!r} at line "
                        f"{first_line + i}; every cell must be a number"
                    ) from None
    return body


def iter_tables(path, chunk: int, names=None):
    """Consecutive tables of at most `chunk` rows; memory is bounded by the chunk."""
    path = Path(path)
    with _open(path) as fh:
        try:
            header = _header(path, fh)
        except UnicodeDecodeError:
            raise _not_utf8(path, 1) from None
        keep = [header.index(n) for n in (header if names is None else names)]
        reader = csv.reader(fh)
        line = 2
        while True:
            try:
                block = list(itertools.islice(reader, chunk))
            except UnicodeDecodeError:
                raise _not_utf8(path, line) from None
            if not block:
                return
            n_lines = len(block)
            rows = [r for r in block if r and any(c.strip() for c in r)]
            body = _parse(path, header, rows, line)
            line += n_lines
            yield {header[j]: np.ascontiguousarray(body[:, j]) for j in keep}
