"""Helpers every reader shares: optional imports and the check of one column."""

from __future__ import annotations

import importlib

import numpy as np

from .._errors import DataError


def require(package: str, extra: str):
    """Import an optional dependency, or raise a one-line `DataError` naming the extra."""
    try:
        return importlib.import_module(package)
    except ImportError:
        raise DataError(
            f"reading this format needs the {package!r} package; install it with "
            f"pip install 'hdjax[{extra}]'"
        ) from None


def as_float_column(name: str, values, source: str) -> np.ndarray:
    """A 1-D float64 column (a `(n, 1)` or `(1, n)` MATLAB vector is flattened)."""
    arr = np.asarray(values)
    if arr.ndim == 2 and 1 in arr.shape:
        arr = arr.reshape(-1)
    if arr.ndim != 1:
        raise DataError(f"{source}: column {name!r} must be one-dimensional, got shape {arr.shape}")
    try:
        return arr.astype(np.float64, copy=False)
    except (TypeError, ValueError):
        raise DataError(f"{source}: column {name!r} is not numeric (dtype {arr.dtype})") from None
