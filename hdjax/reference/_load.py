"""Loading a recording whose reference torque is built from a wrench (`[data.reference]`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from .._custom_types import PathLike
from .._errors import ConfigError
from .._formats import load_recording
from .._io import ColumnMap, ColumnSpec
from .._recording import Recording
from ._builder import WrenchReference, build_wrench_reference
from ._spec import check_reference, needed_columns

_PREFIX = "__reference__:"


def describe_column_reference(columns: ColumnMap | Mapping | None, data_kind: str = "files") -> str:
    """One line naming the reference of a `kind = "column"` experiment."""
    if data_kind == "plant":
        return "reference: the simulated output torque of the built-in plant (column)"
    if data_kind == "synthetic":
        return "reference: the torque the synthetic recordings were generated from (column)"
    spec = None
    if isinstance(columns, ColumnMap):
        spec = columns.columns.get("torque")
        name = spec.source if spec is not None else "torque"
    else:
        entry = (columns or {}).get("torque", "torque")
        name = entry if isinstance(entry, str) else entry.get("source", "torque")
    return f"reference: the log column {name!r} ([data.columns] torque)"


def load_with_reference(
    path: PathLike,
    columns: ColumnMap,
    spec: Mapping,
    loader: Callable[..., Recording],
    *,
    base_dir: PathLike,
    check_units: bool = True,
) -> tuple[Recording, WrenchReference]:
    """Load `path` through `loader(path, columns, check_units=...)` and replace its torque by
    the wrench reference of `spec`, keeping only the rows where a new wrench arrived.

    The raw columns the reference needs are read alongside (never kept as extras, so that the
    reference's ingredients cannot leak into a model's inputs).

    **Raises:** [`hdjax.ConfigError`][] when `[data.columns]` also maps `torque`.
    """
    if "torque" in columns.columns:
        raise ConfigError(
            f'{path}: [data.reference] kind = "wrench" builds the reference torque; remove '
            "torque from [data.columns]"
        )
    names = needed_columns(spec)
    private = {f"{_PREFIX}{n}": ColumnSpec(source=n) for n in names}
    if columns.extras is None:  # "keep every other column": read the raw columns separately
        rec = loader(path, columns, check_units=check_units)
        raw_rec = loader(path, dataclasses.replace(columns, extras=private), check_units=False)
    else:
        both = dataclasses.replace(columns, extras={**columns.extras, **private})
        raw_rec = rec = loader(path, both, check_units=check_units)
    raw = {n: np.asarray(raw_rec.extras[f"{_PREFIX}{n}"]) for n in names}
    ref = build_wrench_reference(
        spec, raw, np.asarray(rec.t), base_dir=Path(base_dir), source=str(path)
    )
    import equinox as eqx

    extras = {k: v for k, v in rec.extras.items() if not k.startswith(_PREFIX)}
    rec = eqx.tree_at(lambda r: r.extras, rec, extras)
    full = np.zeros(rec.n_samples)
    full[ref.fresh] = ref.torque
    rec = rec.with_torque(full).select(ref.fresh)
    return rec, ref


def load_referenced(
    path: PathLike,
    columns: ColumnMap | None,
    table: Mapping | None,
    *,
    base_dir: PathLike,
    where: str = "[data]",
) -> tuple[Recording, str]:
    """Load a recording with the reference a `[data.reference]` table (or `None`) describes.

    **Returns:** `(recording, description)`, the description being one line for reports.
    """
    spec = check_reference(f"{where}.reference", table if table is not None else {})
    if spec["kind"] == "column":
        rec = load_recording(path, columns)
        return rec, describe_column_reference(columns or ColumnMap())
    rec, ref = load_with_reference(
        path, columns or ColumnMap(), spec, load_recording, base_dir=base_dir
    )
    return rec, ref.description
