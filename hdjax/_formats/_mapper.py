"""A column map applied chunk by chunk, its state carried from one chunk to the next."""

from __future__ import annotations

import numpy as np

from .._errors import DataError
from .._io import ColumnMap, ColumnSpec, no_source_error, schema_spec
from .._recording import SIGNAL_COLUMNS, make_recording
from ._columns import as_float_column


def _plan(columns: ColumnMap | None, available: list[str], source: str) -> dict[str, ColumnSpec]:
    """Schema or extra name -> spec, or `None` extras meaning every other column."""
    columns = columns or ColumnMap()
    plan: dict[str, ColumnSpec] = {}
    for name in SIGNAL_COLUMNS:
        spec = schema_spec(columns, name, available, source)
        if spec is not None:
            plan[name] = spec
    if columns.extras is not None:
        plan.update(columns.extras)
    for name, spec in plan.items():
        if spec.source not in available:
            raise no_source_error(source, spec, name, available)
    return plan


def needed_sources(columns: ColumnMap | None, available: list[str], source: str, mod=None):
    """The source columns a map reads (`None`: all of them, when extras are kept wholesale;
    a reader with `default_columns` narrows "all" to what fits with the mapped columns)."""
    used = sorted({spec.source for spec in _plan(columns, available, source).values()})
    if columns is not None and columns.extras is not None:
        return used
    if mod is not None and hasattr(mod, "default_columns"):
        return mod.default_columns(source, used)
    return None


class ChunkMapper:
    """Turns consecutive raw tables into validated recording chunks.

    Carried across chunks: the last unwrapped value of each counter column (so a wrap at a
    chunk boundary is removed as it would be in one pass), the first raw value of each
    `offset = "first"` column, and the last time stamp (to check `t` keeps increasing).
    """

    def __init__(self, columns: ColumnMap | None, available: list[str], source, check_units):
        self.columns = columns or ColumnMap()
        self.plan = _plan(self.columns, list(available), source)
        used = {spec.source for spec in self.plan.values()}
        self.keep_all = self.columns.extras is None
        self.available = list(available)
        self.unused = [c for c in available if c not in used and c not in SIGNAL_COLUMNS]
        self.source = source
        self.check_units = check_units
        self.first: dict[str, float] = {}
        self.last_unwrapped: dict[str, float] = {}
        self.last_t: float | None = None
        self.n_rows = 0

    def _apply(self, name: str, spec: ColumnSpec, raw: np.ndarray) -> np.ndarray:
        x = np.asarray(raw, dtype=np.float64)
        if spec.modulus is not None:
            prev = self.last_unwrapped.get(name)
            if prev is None:
                x = np.unwrap(x, period=spec.modulus)
            else:
                x = np.unwrap(np.r_[prev, x], period=spec.modulus)[1:]
            if x.size:
                self.last_unwrapped[name] = float(x[-1])
        if spec.offset == "first":
            if name not in self.first:
                self.first[name] = float(x[0])
            return (x - self.first[name]) * spec.scale
        if spec.scale == 1.0 and spec.offset == 0.0:
            return x  # identity: skip two passes over the column
        return x * spec.scale + float(spec.offset)

    def __call__(self, table: dict[str, np.ndarray]):
        cols = {
            name: self._apply(name, spec, table[spec.source]) for name, spec in self.plan.items()
        }
        signals = {k: cols[k] for k in SIGNAL_COLUMNS if k in cols}
        extras = {k: v for k, v in cols.items() if k not in SIGNAL_COLUMNS}
        if self.keep_all:
            extras.update({k: as_float_column(k, table[k], self.source) for k in self.unused})
        start = self.n_rows
        t = signals["t"]
        if self.last_t is not None and t.size and not t[0] > self.last_t:
            raise DataError(
                f"{self.source}: time column 't' must be strictly increasing, but it is not at "
                f"row {start} (t={self.last_t!r} then {t[0]!r}); sort the rows and drop "
                "duplicated time stamps"
            )
        rec = make_recording(
            t,
            signals["theta_m"],
            signals["theta_l"],
            signals["current"],
            signals.get("torque"),
            extras,
            source=self.source,
            check_units=self.check_units and start == 0,
        )
        self.last_t = float(t[-1])
        self.n_rows += t.size
        return rec
