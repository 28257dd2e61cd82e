"""Sample-and-hold wrench streams: which rows carry a new measurement.

A force/torque sensor read slower than the controller logs it repeats its last value until the
next one arrives (the LARA8 logs: a new wrench about every 10 ms in rows 4 ms apart). A held
row is not a measurement at its own time stamp, and interpolating between two fresh rows would
invent values the sensor never produced. hdjax therefore keeps **only the rows where a new
value arrives** (a row is fresh when any of the six channels differs from the row before; the
first row is fresh) and evaluates everything else (kinematics, twist, model torque) at those
rows' own time stamps. Nothing is interpolated across a hold.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._custom_types import ArrayLike, Bool, Real
from .._errors import DataError


@dataclasses.dataclass(frozen=True)
class Holds:
    """Where a sample-and-hold stream updates.

    **Fields:** `fresh` (bool per row: a new value arrives), `n_fresh`, `n_rows`,
    `median_period_s` and `max_period_s` (time between fresh rows).
    """

    fresh: Bool[np.ndarray, " n"]
    n_fresh: int
    n_rows: int
    median_period_s: float
    max_period_s: float

    @property
    def held(self) -> bool:
        """Whether any row repeats the previous one."""
        return self.n_fresh < self.n_rows

    def describe(self) -> str:
        if not self.held:
            return f"every one of the {self.n_rows} rows carries a new wrench (no holds)"
        return (
            f"sample-and-hold wrench: {self.n_fresh} of {self.n_rows} rows carry a new value "
            f"(median {1e3 * self.median_period_s:.1f} ms apart, longest hold "
            f"{1e3 * self.max_period_s:.1f} ms); only those rows are used, nothing is "
            "interpolated across a hold"
        )


def detect_holds(
    values: Real[ArrayLike, "n_rows k"], t: Real[ArrayLike, " n"], *, source: str = "wrench"
) -> Holds:
    """The fresh rows of a sample-and-hold stream (module docstring).

    **Arguments:** `values` of shape `(n, k)` (e.g. the six wrench channels), time stamps `t`
    of shape `(n,)` [s], `source` for messages.

    **Raises:** [`hdjax.DataError`][] for non-finite values or mismatched lengths.
    """
    w = np.asarray(values, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if w.ndim != 2 or w.shape[0] != t.shape[0] or w.shape[0] < 2:
        raise DataError(
            f"{source}: expected values of shape (n, k) with n = {t.shape[0]} rows (n >= 2), "
            f"got {w.shape}"
        )
    bad = ~np.isfinite(w)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise DataError(
            f"{source}: non-finite value in channel {col + 1} at row {row + 1}; a reference "
            "cannot be built across missing wrench samples (cut the recording)"
        )
    fresh = np.concatenate([[True], np.any(np.diff(w, axis=0) != 0.0, axis=1)])
    tf = t[fresh]
    gaps = np.diff(tf) if tf.size > 1 else np.array([np.nan])
    return Holds(
        fresh=fresh,
        n_fresh=int(fresh.sum()),
        n_rows=int(w.shape[0]),
        median_period_s=float(np.median(gaps)),
        max_period_s=float(np.max(gaps)),
    )
