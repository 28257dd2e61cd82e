"""Reading and writing recordings: CSV and `.npz`, with an optional column map.

A log in another layout (encoder counts, degrees, other column names, multi-turn counters,
unknown offsets) is read through a [`hdjax.ColumnMap`][]: for each schema column, the source
column, a scale and an offset, and for counters that wrap, their modulus. Counter values are read
as float64, which holds integers exactly up to 2^53, and converted to radians in float64.

Writes are atomic: a file appears complete or not at all.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ._custom_types import ArrayLike, Float, PathLike
from ._errors import ConfigError, DataError, check_keys, did_you_mean as did_you_mean
from ._recording import SIGNAL_COLUMNS, Recording, make_recording

_COLUMN_KEYS = ("source", "scale", "offset", "counts_per_rev", "modulus")
TOML_HINT = "TOML files are UTF-8; save the file as UTF-8"


_ENCODING_HINT = (
    'save the file as UTF-8, or name its encoding in the column map (e.g. encoding = "latin-1" '
    "in the [data] table)"
)


def check_encoding(name, *, where: str = "encoding") -> str:
    """A text encoding name Python knows (`"utf-8"`, `"latin-1"`, `"cp1252"`...), else a
    `ConfigError`."""
    import codecs

    if not isinstance(name, str):
        raise ConfigError(f'{where} must be a string such as "latin-1", got {name!r}')
    try:
        return codecs.lookup(name).name
    except LookupError:
        raise ConfigError(
            f'{where}: unknown text encoding {name!r}; use a name such as "utf-8", "latin-1" or '
            '"cp1252"'
        ) from None


_BOM = b"\xef\xbb\xbf"


def text_codec(head: bytes, where, encoding: str | None = None, *, hint: str = "") -> tuple:
    """How to read a file that starts with the bytes `head`, under the rules of
    [`decode_text`][]: `(codec, start)`, the codec and the number of leading bytes to skip
    (a UTF-8 byte-order mark, as spreadsheets write it), so that byte positions count from
    the file's first byte.

    **Raises:** [`hdjax.DataError`][] for UTF-16/32 text when no encoding is named.
    """
    name = "utf-8" if encoding is None else check_encoding(encoding)
    if name != "utf-8":
        return name, 0
    for bom, what in ((b"\xff\xfe", "UTF-16 or UTF-32"), (b"\xfe\xff", "UTF-16")):
        if head.startswith(bom):
            raise DataError(
                f"{where}: the file is {what} text, not UTF-8; {hint or _ENCODING_HINT}"
            )
    return "utf-8", 3 if head.startswith(_BOM) else 0


def bad_byte_error(where, encoding, byte: int, pos: int, line: int, hint: str = "") -> DataError:
    """The one line for a byte that does not decode: the file, the byte, its position."""
    return DataError(
        f"{where}: not valid {encoding or 'UTF-8'} text: byte 0x{byte:02x} at byte position "
        f"{pos} (line {line}); {hint or _ENCODING_HINT}"
    )


def nul_byte_error(where, pos: int) -> DataError:
    """The one line for a NUL character (the file is not text)."""
    return DataError(
        f"{where}: a NUL byte at byte position {pos}, so this is not a text file; give a text "
        "file (or a .npz / .parquet recording)"
    )


def nul_position(text: str, nul: int, codec: str, start: int = 0) -> int:
    """The byte position of `text[nul]` in a file whose bytes from `start` on decode to `text`
    with `codec`."""
    return start + len(text[:nul].encode(codec))


def decode_text(data: bytes, where, encoding: str | None = None, *, hint: str = "") -> str:
    """Text of a file's bytes: UTF-8 with or without a byte-order mark by default, else the
    named `encoding`.

    **Raises:** [`hdjax.DataError`][] naming the file and the byte position of the first byte
    that does not decode (and the line it is on), for UTF-16/32 text and for NUL bytes.
    """
    name, start = text_codec(data, where, encoding, hint=hint)
    try:
        text = str(memoryview(data)[start:], name)
    except UnicodeDecodeError as err:
        at = start + err.start
        line = data.count(b"\n", 0, at) + 1
        raise bad_byte_error(where, encoding, data[at], at, line, hint) from None
    nul = text.find("\x00")
    if nul >= 0:
        raise nul_byte_error(where, nul_position(text, nul, name, start))
    return text


def read_text(path, *, encoding: str | None = None, what: str = "file", hint: str = "") -> str:
    """The text of a file (see [`decode_text`][]); a missing file or a folder is a
    `DataError`."""
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such {what}")
    if path.is_dir():
        raise DataError(f"{path}: is a folder; give a {what}")
    return decode_text(path.read_bytes(), path, encoding, hint=hint)


def read_toml(path) -> dict:
    """Parse a TOML file; a missing file or a syntax error becomes a `ConfigError` naming the
    file, line and column; text that is not UTF-8 becomes a `DataError` naming the byte."""
    import re
    import tomllib

    path = Path(path)
    if not path.exists():
        raise ConfigError(f"{path}: no such file")
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder; give a TOML file")
    text = read_text(path, what="TOML file", hint=TOML_HINT)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        m = re.search(r"\(at line (\d+), column (\d+)\)", str(err))
        where = f"{path}:{m.group(1)}:{m.group(2)}" if m else str(path)
        raise ConfigError(f"{where}: not valid TOML: {err}") from None


@dataclasses.dataclass(frozen=True)
class ColumnSpec:
    """How one schema column is read from a source column.

    `value = unwrap(raw) * scale + offset`, where `scale` defaults to `2*pi/counts_per_rev` when
    that is given, `unwrap` removes wraps of a counter of period `modulus` counts, and `offset` is
    a number or `"first"` (subtract the first sample, as Song et al. eqs. (11)-(12) do with the
    initial encoder value).
    """

    source: str
    scale: float = 1.0
    offset: float | str = 0.0
    modulus: float | None = None

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """The converted column (float64)."""
        x = np.asarray(raw, dtype=np.float64)
        if self.modulus is not None:
            x = np.unwrap(x, period=self.modulus)
        if self.offset == "first":
            x = x - x[0]
            return x * self.scale
        return x * self.scale + float(self.offset)


@dataclasses.dataclass(frozen=True)
class ColumnMap:
    """Maps the recording schema onto the columns of a log file.

    **Arguments:**

    - `columns`: schema name (`t`, `theta_m`, `theta_l`, `current`, `torque`) to a
      `ColumnSpec`; unmapped schema names are read from a column of the same name.
    - `extras`: extra column name to spec; `None` keeps every other numeric column of the file
      under its own name, an empty mapping keeps none.
    - `encoding`: the text encoding of CSV files (default UTF-8, with or without a byte-order
      mark), e.g. `"latin-1"` for a log whose header holds `temp_°C` in Latin-1.
    """

    columns: Mapping[str, ColumnSpec] = dataclasses.field(default_factory=dict)
    extras: Mapping[str, ColumnSpec] | None = None
    encoding: str | None = None

    @classmethod
    def from_dict(cls, table: Mapping, *, where: str = "[data]") -> ColumnMap:
        """Build from a TOML-like table: `{"columns": {...}, "extras": {...}}`.

        Each entry is either a source column name or a table with `source`, `scale`,
        `offset`, `counts_per_rev`, `modulus`.
        """
        check_keys(sorted(table), ["columns", "extras", "encoding"], where)
        for key in ("columns", "extras"):
            if table.get(key) is not None and not isinstance(table[key], Mapping):
                raise ConfigError(f"{where}.{key} must be a table, got {table[key]!r}")
        columns = {}
        for name, entry in (table.get("columns") or {}).items():
            if name not in SIGNAL_COLUMNS:
                raise ConfigError(
                    f"{where}.columns: {name!r} is not a schema column"
                    f"{did_you_mean(name, SIGNAL_COLUMNS)}; schema columns are "
                    f"{', '.join(SIGNAL_COLUMNS)} (put other columns under extras)"
                )
            columns[name] = _spec(entry, f"{where}.columns.{name}")
        extras = table.get("extras")
        if extras is not None:
            extras = {k: _spec(v, f"{where}.extras.{k}") for k, v in extras.items()}
        encoding = table.get("encoding")
        if encoding is not None:
            encoding = check_encoding(encoding, where=f"{where}.encoding")
        return cls(columns=columns, extras=extras, encoding=encoding)


def _spec(entry, where: str) -> ColumnSpec:
    if isinstance(entry, str):
        return ColumnSpec(source=entry)
    if not isinstance(entry, Mapping):
        raise ConfigError(f"{where}: expected a column name or a table, got {entry!r}")
    check_keys(entry, _COLUMN_KEYS, where)
    if "source" not in entry:
        raise ConfigError(f"{where}: missing 'source' (the column name in the file)")
    scale = entry.get("scale")
    cpr = entry.get("counts_per_rev")
    if scale is not None and cpr is not None:
        raise ConfigError(f"{where}: give either 'scale' or 'counts_per_rev', not both")
    if cpr is not None:
        if not isinstance(cpr, (int, float)) or cpr <= 0:
            raise ConfigError(f"{where}: 'counts_per_rev' must be a positive number, got {cpr!r}")
        scale = 2.0 * math.pi / float(cpr)
    scale = 1.0 if scale is None else scale
    if not isinstance(scale, (int, float)) or scale == 0 or not math.isfinite(scale):
        raise ConfigError(f"{where}: 'scale' must be a finite non-zero number, got {scale!r}")
    offset = entry.get("offset", 0.0)
    if offset != "first" and not isinstance(offset, (int, float)):
        raise ConfigError(f"{where}: 'offset' must be a number or \"first\", got {offset!r}")
    modulus = entry.get("modulus")
    if modulus is not None and (not isinstance(modulus, (int, float)) or modulus <= 0):
        raise ConfigError(f"{where}: 'modulus' must be a positive number, got {modulus!r}")
    return ColumnSpec(
        source=str(entry["source"]), scale=float(scale), offset=offset, modulus=modulus
    )


# ---------------------------------------------------------------------------------------------
# Reading


def _read_csv_table(path: Path, encoding: str | None = None) -> tuple[list[str], np.ndarray]:
    """Header and float64 body of a CSV file, with messages that name the bad cell."""
    import io

    if not path.exists():
        raise DataError(f"{path}: no such file")
    if path.is_dir():
        raise DataError(f"{path}: is a folder; give a recording file (.csv, .npz, ...)")
    if path.stat().st_size == 0:
        raise DataError(f"{path}: the file is empty; expected a header row and data rows")
    text = decode_text(path.read_bytes(), path, encoding)
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise DataError(f"{path}: the file is empty; expected a header row") from None
        body = _plain_body(text, len(header))
        if body is not None and any(header) and len(set(header)) == len(header):
            return header, body
        rows = list(reader)
    except csv.Error as err:
        raise DataError(f"{path}: not a readable CSV file ({err}); check the file") from None
    if not any(header):
        raise DataError(f"{path}: the first line is empty; expected a header row")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise DataError(f"{path}: duplicated column name(s) in the header: {', '.join(dup)}")
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if not rows:
        raise DataError(f"{path}: the file has a header but no data rows")
    return header, parse_cells(path, header, rows, 2)


def _plain_body(text: str, n_columns: int) -> np.ndarray | None:
    """The body of a plain CSV text (no quotes; every row `n_columns` numbers separated by
    commas), read by NumPy's C parser, several times faster than cell by cell; `None` for
    anything else (an empty cell, a quote, a ragged row, a word), which the careful parser then
    reads or refuses with the bad cell named. Both parse a number to the same float64."""
    import io
    import warnings

    if '"' in text:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # "input contained no data" is a fall-back too
            body = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2, comments=None)
    except (ValueError, UserWarning):
        return None
    if body.dtype != np.float64 or body.shape[0] == 0 or body.shape[1] != n_columns:
        return None
    return body


def parse_cells(
    path: Path, header: list[str], rows: list[list[str]], first_line: int, locate=None
) -> np.ndarray:
    """The float64 body of CSV `rows` (the first at line `first_line`), empty cells NaN.

    A row of the wrong length or a non-numeric cell is refused with its line and column; with
    `locate`, a cell holding a NUL byte raises `locate()` instead (the file is not text).
    """
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
                    if locate is not None and "\x00" in cell:
                        raise locate() from None
                    raise DataError(
                        f"{path}: non-numeric cell {cell!r} in column {header[j]!r} at line "
                        f"{first_line + i}; every cell must be a number"
                    ) from None
    return body


def schema_spec(columns: ColumnMap, name: str, available, source) -> ColumnSpec | None:
    """The spec giving schema column `name`: the map's own, else the file's column of that
    name; `None` for an absent torque (optional); a `DataError` listing the file's columns
    otherwise."""
    spec = columns.columns.get(name)
    if spec is not None:
        return spec
    if name in available:
        return ColumnSpec(source=name)
    if name == "torque":
        return None
    raise DataError(
        f"{source}: missing column {name!r}{did_you_mean(name, available)}; the file "
        f"has: {', '.join(available)}. Rename it or map it with a [data.columns] table"
    )


def no_source_error(source, spec: ColumnSpec, name: str, available) -> DataError:
    """The error for a map entry whose source column the file lacks."""
    return DataError(
        f"{source}: no column {spec.source!r} (for {name!r})"
        f"{did_you_mean(spec.source, available)}; the file has: {', '.join(available)}"
    )


def table_recording(
    table: Mapping[str, np.ndarray], columns: ColumnMap | None, source: str, check_units: bool
) -> Recording:
    columns = columns or ColumnMap()
    available = list(table)
    used = set()

    def read(name: str, spec: ColumnSpec) -> np.ndarray:
        if spec.source not in table:
            raise no_source_error(source, spec, name, available)
        used.add(spec.source)
        return spec.apply(table[spec.source])

    signals = {}
    for name in SIGNAL_COLUMNS:
        spec = schema_spec(columns, name, available, source)
        if spec is not None:
            signals[name] = read(name, spec)
    if columns.extras is None:
        extras = {k: np.asarray(v, np.float64) for k, v in table.items() if k not in used}
        extras = {k: v for k, v in extras.items() if k not in SIGNAL_COLUMNS}
    else:
        extras = {k: read(k, spec) for k, spec in columns.extras.items()}
    return make_recording(
        signals["t"],
        signals["theta_m"],
        signals["theta_l"],
        signals["current"],
        signals.get("torque"),
        extras,
        source=source,
        check_units=check_units,
    )


def load_csv(
    path: PathLike, columns: ColumnMap | None = None, *, check_units: bool = True
) -> Recording:
    """Load a [`hdjax.Recording`][] from a CSV file with a header row.

    Without `columns` the header must name `t, theta_m, theta_l, current` (and optionally
    `torque`) in SI units; every other column is kept as an extra. With a
    [`hdjax.ColumnMap`][] the columns are renamed, scaled and offset first.
    """
    path = Path(path)
    header, body = _read_csv_table(path, None if columns is None else columns.encoding)
    table = {name: body[:, j] for j, name in enumerate(header)}
    return table_recording(table, columns, str(path), check_units)


def load_npz(
    path: PathLike, columns: ColumnMap | None = None, *, check_units: bool = True
) -> Recording:
    """Load a [`hdjax.Recording`][] from a `.npz` archive holding one array per column."""
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such file")
    if path.is_dir():
        raise DataError(f"{path}: is a folder; give a recording file (.csv, .npz, ...)")
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as archive:
            table = {k: np.asarray(archive[k]) for k in archive.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise DataError(f"{path}: not a readable .npz archive ({err})") from None
    if not table:
        raise DataError(f"{path}: the archive is empty")
    return table_recording(table, columns, str(path), check_units)


# ---------------------------------------------------------------------------------------------
# Writing


def _umask() -> int:
    """The process's umask (read without changing it where /proc allows)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The mode a new file gets from a plain `open` under this process's umask (0644 under the
    usual 022): give it to a file created by `tempfile.mkstemp` (0600) before renaming it."""
    return 0o666 & ~_umask()


def atomic_write_bytes(path, data: bytes) -> None:
    """Write `data` to `path` through a temporary file and a rename (never half-written); the
    file gets the mode a plain `open` would give it (0644 under the usual umask 022)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, file_mode())  # mkstemp makes 0600; results follow the umask
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _shortest_text(values: Float[np.ndarray, " n"]) -> np.ndarray:
    """Each float64 as the shortest of `%.15g`, `%.16g`, `%.17g` that reads back exactly
    (`0.004`, not `0.0040000000000000001`)."""
    values = np.asarray(values, np.float64)
    out = np.char.mod("%.15g", values).astype("<U32")
    for digits in (16, 17):
        inexact = ~(out.astype(np.float64) == values) & ~np.isnan(values)
        if not inexact.any():
            break
        out[inexact] = np.char.mod(f"%.{digits}g", values[inexact])
    return out


CSV_BLOCK = 65536
"""Rows formatted at a time by [`csv_bytes`][] (its text memory is bounded by the block)."""


def csv_bytes(columns: dict[str, Float[ArrayLike, " n"]]) -> bytes:
    """Columns (name -> values, all of one length) as the bytes of a CSV file: a header of the
    names, then one row per sample, each value in the fewest digits that read back to the same
    float64. Rows are formatted `CSV_BLOCK` at a time."""
    names = list(columns)
    values = [np.asarray(columns[k], np.float64).reshape(-1) for k in names]
    lengths = {v.size for v in values}
    if len(lengths) > 1:
        sizes = ", ".join(f"{k}: {v.size}" for k, v in zip(names, values))
        raise ValueError(f"csv_bytes: the columns differ in length ({sizes})")
    n = lengths.pop() if lengths else 0
    parts = [(",".join(names) + "\n").encode()]
    for lo in range(0, n, CSV_BLOCK):
        texts = [_shortest_text(v[lo : lo + CSV_BLOCK]) for v in values]
        parts.append(("\n".join(",".join(row) for row in zip(*texts)) + "\n").encode())
    return b"".join(parts)


def save_csv(recording: Recording, path: PathLike) -> None:
    """Write a recording as CSV (all columns, full float64 precision), atomically."""
    atomic_write_bytes(path, csv_bytes(recording.to_numpy()))


def save_npz(recording: Recording, path: PathLike) -> None:
    """Write a recording as `.npz`, atomically."""
    import io

    buf = io.BytesIO()
    np.savez(buf, **recording.to_numpy())
    atomic_write_bytes(path, buf.getvalue())
