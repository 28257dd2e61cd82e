"""Discover experiments from a TOML file: joint, data (one or two logs, column map), options.

```toml
[joint]
ratio = 101
rated_torque = 150
twist_sign = -1

[data]
train = "path/to/train.csv"         # relative to this file
test = "path/to/test.csv"           # or, with one log, test_blocks below
# path = "one.csv"
# test_blocks = { block = 100, every = 4 }   # every 4th block of 100 samples is TEST
[data.columns]                       # optional column map (see hdjax.ColumnMap)
t = "Timestamp"

[discover]
max_effects = 5
min_gain = 0.05
chunk = 0                            # > 0: fits accumulated over chunks of this many samples
```
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .._errors import ConfigError, check_keys, did_you_mean
from .._io import ColumnMap, read_toml
from .._joint import Joint
from ..reference import load_referenced
from ._chunked import check_chunk
from ._options import DiscoverOptions

_DATA_KEYS = ("path", "train", "test", "test_blocks", "columns", "extras", "encoding", "reference")
_DISCOVER_KEYS = (
    "max_effects",
    "min_gain",
    "ignore_columns",
    "n_segments",
    "poly_order",
    "fourier_order",
    "families",
    "chunk",
)


def load_discover_config(path, with_context: bool = False):
    """Read a discover experiment: returns `(train, test, joint, options dict, notes)`, and
    with `with_context` also the log TRAIN and TEST were cut from (`test_blocks`; `None` for
    two logs), for [`hdjax.discover.discover`][]'s `context`."""
    path = Path(path)
    doc = read_toml(path)
    for key in doc:
        if key not in ("joint", "data", "discover"):
            raise ConfigError(
                f"{path}: unknown table [{key}]{did_you_mean(key, ['joint', 'data', 'discover'])}"
            )
    if "joint" not in doc:
        raise ConfigError(f"{path}: no [joint] table")
    joint = Joint.from_dict(doc["joint"], where=f"{path} [joint]")
    data = doc.get("data")
    if not data:
        raise ConfigError(f"{path}: no [data] table")
    check_keys(data, _DATA_KEYS, f"{path} [data]")
    colmap = None
    if "columns" in data or "extras" in data or "encoding" in data:
        colmap = ColumnMap.from_dict(
            {k: data[k] for k in ("columns", "extras", "encoding") if k in data},
            where=f"{path} [data]",
        )
    here = path.parent
    notes = []
    ref = data.get("reference")
    load = lambda p: load_referenced(p, colmap, ref, base_dir=here, where=f"{path} [data]")
    if "path" in data:
        rec, described = load(here / data["path"])
        notes.append(described)
        context = rec
        block, every = _test_blocks(data.get("test_blocks", {}), f"{path} [data] test_blocks")
        n = rec.n_samples
        if n <= (every - 1) * block:
            # blocks 0 .. every-2 are TRAIN: TEST starts at row (every - 1) * block
            raise ConfigError(
                f"{path} [data] test_blocks: the log has {n} samples, but every {every}th block "
                f"of {block} samples is TEST, so TEST would start at row {(every - 1) * block} "
                f"and is empty; give a smaller block (at most {max(1, n // every)} for every = "
                f"{every}), or separate 'train' and 'test' logs"
            )
        idx = np.arange(n) // block
        train, test = rec.select(idx % every != every - 1), rec.select(idx % every == every - 1)
        notes.append(
            f"one log split into TRAIN and TEST: every {every}th block of {block} samples is TEST"
        )
    elif "train" in data and "test" in data:
        (train, described), (test, _) = load(here / data["train"]), load(here / data["test"])
        notes.append(described)
        context = None
    else:
        raise ConfigError(f"{path} [data]: give either 'path' or both 'train' and 'test'")
    options = check_discover_table(doc.get("discover", {}), path)
    if with_context:
        return train, test, joint, options, notes, context
    return train, test, joint, options, notes


def discover_options(
    cfg: dict, *, max_effects: int | None = None, min_gain: float | None = None, chunk: int = 0
) -> DiscoverOptions:
    """The loop's settings from a discover file's `[discover]` table (as
    [`load_discover_config`][] returns it): `max_effects` and `min_gain` when given (the
    command line's) override the table's, and what neither sets is
    [`hdjax.discover.DiscoverOptions`][]' default."""
    d = DiscoverOptions()
    pick = lambda given, key, kind: kind(
        given if given is not None else cfg.get(key, getattr(d, key))
    )
    return DiscoverOptions(
        max_effects=pick(max_effects, "max_effects", int),
        min_gain=pick(min_gain, "min_gain", float),
        n_segments=pick(None, "n_segments", int),
        poly_order=pick(None, "poly_order", int),
        fourier_order=pick(None, "fourier_order", int),
        library=dataclasses.replace(d.library, families=cfg.get("families", d.library.families)),
        chunk=chunk,
    )


_WHOLE = {
    "max_effects": (0, None),
    "n_segments": (1, 20),
    "poly_order": (0, 12),
    "fourier_order": (0, 12),
}
"""Whole-number settings of `[discover]`: (least, most) allowed (as `[model]`'s for the last
three)."""


def check_discover_table(table, path) -> dict:
    """The `[discover]` table of a discover file, every value checked before anything runs: a
    [`hdjax.ConfigError`][] names the key, the value and what it must be."""
    where = f"{path} [discover]"
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: expected a table of settings, got {table!r}")
    check_keys(table, _DISCOVER_KEYS, where)
    out = dict(table)
    for key, (lo, hi) in _WHOLE.items():
        v = table.get(key, lo)
        if isinstance(v, bool) or not isinstance(v, int) or v < lo or (hi is not None and v > hi):
            span = f"from {lo} to {hi}" if hi is not None else f">= {lo}"
            raise ConfigError(f"{where} {key} must be a whole number {span}, got {v!r}")
    v = table.get("min_gain", 0.05)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 < v < 1.0:
        raise ConfigError(f"{where} min_gain must be a number in (0, 1), got {v!r}")
    v = table.get("ignore_columns", [])
    if not isinstance(v, list) or not all(isinstance(c, str) and c for c in v):
        raise ConfigError(
            f'{where} ignore_columns must be a list of column names, e.g. ["temp"], got {v!r}'
        )
    if "chunk" in table:
        out["chunk"] = check_chunk(table["chunk"], f"{where} chunk")
    if "families" in table:
        out["families"] = check_families(table["families"], path)
    return out


def check_families(value, path) -> tuple[str, ...]:
    """`[discover] families`, checked: a non-empty list of the registered discover families
    ([`hdjax.discover.FAMILIES`][], e.g. `"hysteresis:torque"`), each named once."""
    from ..effects import discover_families

    known = discover_families()
    where = f"{path} [discover] families"
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise ConfigError(
            f"{where}: expected a non-empty list of family names such as "
            f'["harmonic:theta_m", "hysteresis:torque"], got {value!r}; known: {", ".join(known)}'
        )
    for v in value:
        if v not in known:
            raise ConfigError(
                f"{where}: unknown family {v!r}{did_you_mean(v, known)}; known: {', '.join(known)}"
            )
    if len(set(value)) != len(value):
        raise ConfigError(f"{where}: a family is named twice in {value!r}")
    return tuple(value)


def _test_blocks(blocks, where: str) -> tuple[int, int]:
    """`(block, every)` of a `test_blocks = { block = B, every = E }` table (100 and 4 by
    default), checked: whole numbers, `block >= 1`, `every >= 2`."""
    if not isinstance(blocks, dict):
        raise ConfigError(f"{where}: expected a table like {{ block = 100, every = 4 }}")
    check_keys(blocks, ("block", "every"), where)
    out = []
    for key, default, least in (("block", 100, 1), ("every", 4, 2)):
        v = blocks.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < least:
            raise ConfigError(f"{where}: {key} must be a whole number >= {least}, got {v!r}")
        out.append(v)
    return out[0], out[1]
