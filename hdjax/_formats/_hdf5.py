"""HDF5 and MATLAB v7.3 `.mat` files (which are HDF5) through h5py.

Each column is a numeric dataset holding a vector (`(n,)`, or MATLAB's `(1, n)` / `(n, 1)`),
named by its path below the root: `theta_m` for a top-level dataset or MATLAB variable,
`log/theta_m` for a dataset in a group or a field of a MATLAB struct. Chunks are slices along
the vector, so a file larger than memory is read piece by piece.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import DataError
from ._columns import as_float_column, require

_MATLAB_INTERNAL = ("#refs#", "#subsystem#")


def _open(path: Path):
    h5py = require("h5py", "hdf5")
    try:
        return h5py.File(path, "r")
    except OSError:
        hint = (
            "; a MATLAB file must be saved as v7.3 (save(..., '-v7.3')), which is HDF5"
            if path.suffix.lower() == ".mat"
            else ""
        )
        raise DataError(f"{path}: not a readable HDF5 file{hint}") from None


def _vectors(f) -> dict:
    import h5py

    found = {}

    def visit(name, obj):
        if any(name.startswith(p) for p in _MATLAB_INTERNAL):
            return
        if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "fiub":
            shape = obj.shape
            if len(shape) == 1 or (len(shape) == 2 and 1 in shape):
                found[name] = obj

    f.visititems(visit)
    return found


def column_names(path) -> list[str]:
    path = Path(path)
    with _open(path) as f:
        names = list(_vectors(f))
    if not names:
        raise DataError(f"{path}: no numeric vector datasets found (one per column expected)")
    return names


def _slice(ds, sl: slice) -> np.ndarray:
    if len(ds.shape) == 1:
        return ds[sl]
    return ds[:, sl][0] if ds.shape[0] == 1 else ds[sl, 0]


def _length(ds) -> int:
    return max(ds.shape)


def _table(path: Path, f, names, sl: slice) -> dict[str, np.ndarray]:
    vectors = _vectors(f)
    names = list(vectors) if names is None else names
    lengths = {n: _length(vectors[n]) for n in names}
    if len(set(lengths.values())) > 1:
        detail = ", ".join(f"{k}={v}" for k, v in lengths.items())
        raise DataError(f"{path}: datasets have different lengths ({detail}); they must match")
    return {n: as_float_column(n, _slice(vectors[n], sl), str(path)) for n in names}


def read_table(path, names=None) -> dict[str, np.ndarray]:
    path = Path(path)
    with _open(path) as f:
        return _table(path, f, names, slice(None))


def iter_tables(path, chunk: int, names=None):
    path = Path(path)
    with _open(path) as f:
        vectors = _vectors(f)
        keep = list(vectors) if names is None else names
        n = _length(vectors[keep[0]]) if keep else 0
        for i in range(0, n, chunk):
            yield _table(path, f, keep, slice(i, min(i + chunk, n)))
