"""CSV, read whole (through `hdjax._io`) or in chunks of rows for logs larger than memory."""

from __future__ import annotations

import codecs
import contextlib
import csv
import io
import itertools
from pathlib import Path

import numpy as np

from .._errors import DataError
from .._io import (
    _read_csv_table,
    bad_byte_error,
    nul_byte_error,
    nul_position,
    parse_cells,
    text_codec,
)

TEXT = True
"""The readers take the column map's `encoding` (see [`hdjax.ColumnMap`][])."""
_BLOCK = 1 << 20  # bytes per read when locating a byte that does not decode


def _header(path: Path, fh, locate) -> list[str]:
    try:
        header = [h.strip() for h in next(csv.reader([fh.readline()]))]
    except StopIteration:
        raise DataError(f"{path}: the file is empty; expected a header row") from None
    if any("\x00" in h for h in header):
        raise locate()
    if not any(header):
        raise DataError(f"{path}: the first line is empty; expected a header row")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise DataError(f"{path}: duplicated column name(s) in the header: {', '.join(dup)}")
    return header


@contextlib.contextmanager
def _open(path: Path, encoding: str | None):
    """The file as text under the rules of `hdjax._io.decode_text` (UTF-8 with or without a
    byte-order mark, or the named encoding) and a function giving the error for text that is
    not (a NUL character); a byte that does not decode is reported as the whole-file reader
    reports it: the file, the byte and its position."""
    with path.open("rb") as raw:
        codec, start = text_codec(raw.read(4), path, encoding)
        raw.seek(start)
        fh = io.TextIOWrapper(raw, encoding=codec, newline="")
        try:
            yield fh, lambda: _decoding_error(path, codec, start, encoding)
        except UnicodeDecodeError:
            raise _decoding_error(path, codec, start, encoding) from None
        except csv.Error as err:
            raise DataError(f"{path}: not a readable CSV file ({err}); check the file") from None
        finally:
            fh.detach()


def _decoding_error(path: Path, codec: str, start: int, encoding) -> DataError:
    """The first byte that does not decode (or the first NUL), found by a pass over the bytes
    in blocks (memory bounded by a block), with the message of `hdjax._io.decode_text`."""
    decoder = codecs.getincrementaldecoder(codec)()
    at, lines = start, 0  # bytes fed to the decoder so far, and the newlines among them
    nul = None  # a NUL is reported only if every byte decodes, as decode_text does
    with path.open("rb") as fh:
        fh.seek(start)
        while True:
            block = fh.read(_BLOCK)
            pending = decoder.getstate()[0]  # bytes of a character split by the last block
            try:
                text = decoder.decode(block, final=not block)
            except UnicodeDecodeError as err:
                data = err.object  # the pending bytes, then this block
                pos = at - len(pending) + err.start
                line = lines - pending.count(b"\n") + data.count(b"\n", 0, err.start) + 1
                return bad_byte_error(path, encoding, data[err.start], pos, line)
            i = text.find("\x00")
            if nul is None and i >= 0:
                nul = nul_position(text, i, codec, at - len(pending))
            if not block:
                break
            at += len(block)
            lines += block.count(b"\n")
    if nul is not None:
        return nul_byte_error(path, nul)
    return DataError(f"{path}: not readable as {codec} text")  # pragma: no cover


def column_names(path, encoding: str | None = None) -> list[str]:
    path = Path(path)
    with _open(path, encoding) as (fh, locate):
        return _header(path, fh, locate)


def read_table(path, names=None, encoding: str | None = None) -> dict[str, np.ndarray]:
    """The whole file (the checks of [`hdjax.load_csv`][])."""
    header, body = _read_csv_table(Path(path), encoding)
    keep = header if names is None else names
    return {name: body[:, header.index(name)] for name in keep}


def iter_tables(path, chunk: int, names=None, encoding: str | None = None):
    """Consecutive tables of at most `chunk` rows; memory is bounded by the chunk."""
    path = Path(path)
    with _open(path, encoding) as (fh, locate):
        header = _header(path, fh, locate)
        keep = [header.index(n) for n in (header if names is None else names)]
        reader = csv.reader(fh)
        line = 2
        while True:
            block = list(itertools.islice(reader, chunk))
            if not block:
                return
            n_lines = len(block)
            rows = [r for r in block if r and any(c.strip() for c in r)]
            body = parse_cells(path, header, rows, line, locate)
            line += n_lines
            yield {header[j]: np.ascontiguousarray(body[:, j]) for j in keep}
