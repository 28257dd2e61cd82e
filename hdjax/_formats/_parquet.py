"""Apache Parquet through pyarrow: one column per signal, read in row batches.

Parquet stores each column compressed and typed, and a reader fetches only the columns it
needs, so it is the recommended format for long logs (`hdjax convert log.csv log.parquet`).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .._errors import DataError
from .._io import file_mode
from ._columns import as_float_column, require


def _pq():
    require("pyarrow", "parquet")
    import pyarrow.parquet as pq

    return pq


def _open(path: Path):
    pq = _pq()
    try:
        # pre_buffer (pyarrow's default) keeps every row group read so far in its memory pool,
        # so a long log's read would grow without bound (measured); without it memory stays
        # at about one row group
        return pq.ParquetFile(path, pre_buffer=False)
    except Exception as err:  # pyarrow raises its own ArrowInvalid / OSError family
        raise DataError(
            f"{path}: not a readable Parquet file ({' '.join(str(err).split())})"
        ) from None


def column_names(path) -> list[str]:
    return list(_open(Path(path)).schema_arrow.names)


def _columns(path: Path, batch, names) -> dict[str, np.ndarray]:
    out = {}
    for name in names or batch.schema.names:
        col = batch.column(name)
        if col.null_count:
            col = col.to_numpy(zero_copy_only=False)  # nulls become NaN, refused downstream
        out[name] = as_float_column(name, np.asarray(col), str(path))
    return out


def read_table(path, names=None) -> dict[str, np.ndarray]:
    path = Path(path)
    table = _open(path).read(columns=names)
    return _columns(path, table, names)


def iter_tables(path, chunk: int, names=None):
    path = Path(path)
    for batch in _open(path).iter_batches(batch_size=chunk, columns=names):
        yield _columns(path, batch, names)


class ParquetWriter:
    """Write a table chunk by chunk (one row group each) into a temporary file beside `path`,
    renamed into place by `close()`; `abort()` (or an exception in a `with` block) removes it,
    so a half-written file never appears under the final name."""

    def __init__(self, path, names: list[str]):
        require("pyarrow", "parquet")
        import pyarrow as pa

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, self.tmp = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.")
        os.close(fd)
        self.schema = pa.schema([(n, pa.float64()) for n in names])
        self.writer = _pq().ParquetWriter(self.tmp, self.schema, compression="zstd")
        self.n_rows = 0

    def write(self, table: dict[str, np.ndarray]) -> None:
        import pyarrow as pa

        arrays = [pa.array(np.asarray(table[n], np.float64)) for n in self.schema.names]
        self.writer.write_table(pa.Table.from_arrays(arrays, schema=self.schema))
        self.n_rows += len(arrays[0]) if arrays else 0

    def close(self) -> None:
        self.writer.close()
        os.chmod(self.tmp, file_mode())  # mkstemp makes 0600; results follow the umask
        os.replace(self.tmp, self.path)

    def abort(self) -> None:
        try:
            self.writer.close()
        finally:
            if os.path.exists(self.tmp):
                os.unlink(self.tmp)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False
