"""`hdjax convert IN OUT.parquet`: rewrite a log as Parquet, chunk by chunk."""

from __future__ import annotations

from pathlib import Path

from .._errors import ConfigError, DataError
from .._formats import ParquetWriter, check_exists, iter_recordings, reader
from ..report import check_output_file
from ._common import Progress, add_command, add_flag, add_quiet, read_column_map as read_column_map

HELP = "convert a log (CSV, .npz, HDF5, MATLAB v7.3, MCAP) to Parquet, chunk by chunk"
EXAMPLE = """\
example:
  hdjax convert log.csv log.parquet
  hdjax convert log.csv log.parquet --columns lara8.toml

Without --columns every numeric column is copied under its own name; with --columns the [data]
column map is applied first (names, scales, offsets, unwrapping), so OUT holds t, theta_m,
theta_l, current, torque and the mapped extras in SI units. The input is read in chunks of
--chunk rows, so logs larger than memory convert; OUT appears only when complete.
"""


def add_parser(sub) -> None:
    p = add_command(sub, "convert", HELP, EXAMPLE)
    p.add_argument("input", help="the log to read (.csv, .npz, .parquet, .h5, .mat, .mcap)")
    p.add_argument("output", help="the Parquet file to write (.parquet)")
    p.add_argument(
        "--columns",
        help="TOML file whose [data] table maps the log's columns (as in an experiment config)",
    )
    p.add_argument("--chunk", type=int, default=1 << 20, help="rows per chunk (default 1048576)")
    add_flag(p, "--overwrite", "replace an existing output file")
    add_quiet(p)


def convert(src, dst, columns=None, *, chunk: int = 1 << 20, progress=None) -> int:
    """Write the log `src` to the Parquet file `dst` (atomically); returns the row count.

    With a [`hdjax.ColumnMap`][] the chunks are mapped recordings (schema columns in SI
    units); without, the raw numeric columns are copied.
    """
    src, dst = Path(src), Path(dst)
    if dst.suffix.lower() not in (".parquet", ".pq"):
        raise ConfigError(f"{dst}: the output must be a .parquet file")
    if src.resolve() == dst.resolve():
        raise ConfigError(f"{dst}: the output would replace the input; choose another name")
    if chunk < 2:
        raise ConfigError(f"--chunk must be >= 2 rows, got {chunk}")
    check_exists(src)
    if columns is None:
        mod = reader(src)
        tables = mod.iter_tables(src, chunk, None)
    else:
        tables = (r.to_numpy() for r in iter_recordings(src, columns, chunk=chunk))
    writer = None
    try:
        for table in tables:
            if writer is None:
                writer = ParquetWriter(dst, list(table))
            elif list(table) != writer.schema.names:
                raise DataError(f"{src}: the columns changed between chunks")
            writer.write(table)
            if progress:
                progress(f"{writer.n_rows} rows")
        if writer is None:
            raise DataError(f"{src}: the log has no data rows")
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    writer.close()
    return writer.n_rows


def _is_parquet(path: Path) -> bool:
    """Only a Parquet file is replaced under --overwrite (never a log or another file)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(4) == b"PAR1"
    except OSError:
        return False


def command(args, parser) -> int:
    progress = Progress(args.quiet)
    out = Path(args.output)
    check_output_file(
        out,
        inputs=[args.input, args.columns],
        overwrite=args.overwrite,
        flag="OUTPUT",
        ours=_is_parquet,
        example="log.parquet",
    )
    cmap = read_column_map(args.columns)
    n = convert(args.input, out, cmap, chunk=args.chunk, progress=progress)
    progress(f"wrote {out} ({n} rows)")
    return 0
