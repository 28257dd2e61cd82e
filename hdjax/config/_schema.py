"""The experiment-file schema: tables, keys, defaults and checks.

An experiment file is TOML with the tables `[experiment]`, `[joint]`, `[data]`, `[model]`,
`[fit]`, `[network]`, `[sweep]` and `[outputs]`. Every key has a default (except the joint's
`ratio` and `rated_torque`), every value is checked before anything runs, and unknown tables or
keys get a "did you mean" answer. [`hdjax.config.resolve`][] returns the fully resolved
configuration (defaults filled in), which each result directory keeps as
`config.resolved.toml` so a run can be repeated exactly.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping

from .._errors import ConfigError, check_keys, did_you_mean
from .._io import check_encoding
from .._joint import Joint
from ..reference import check_reference

Check = Callable[[str, object], object]


# ---------------------------------------------------------------------------------------------
# Value checks: each takes the dotted key (for messages) and the value, returns the clean value.


def _int(minimum: int | None = None, maximum: int | None = None) -> Check:
    def check(key, v):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(f"{key} must be an integer, got {v!r}")
        if minimum is not None and v < minimum:
            raise ConfigError(f"{key} must be >= {minimum}, got {v}")
        if maximum is not None and v > maximum:
            raise ConfigError(f"{key} must be <= {maximum}, got {v}")
        return v

    return check


def _num(*, positive: bool = False, lo: float | None = None, hi: float | None = None) -> Check:
    def check(key, v):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ConfigError(f"{key} must be a finite number, got {v!r}")
        if positive and v <= 0:
            raise ConfigError(f"{key} must be positive, got {v}")
        if lo is not None and v < lo:
            raise ConfigError(f"{key} must be >= {lo}, got {v}")
        if hi is not None and v > hi:
            raise ConfigError(f"{key} must be <= {hi}, got {v}")
        return float(v)

    return check


def _bool(key, v):
    if not isinstance(v, bool):
        raise ConfigError(f"{key} must be true or false, got {v!r}")
    return v


def _str(key, v):
    if not isinstance(v, str):
        raise ConfigError(f"{key} must be a string, got {v!r}")
    return v


def _choice(*options: str) -> Check:
    def check(key, v):
        if v not in options:
            hint = did_you_mean(str(v), options)
            raise ConfigError(f"{key} must be one of {', '.join(options)}, got {v!r}{hint}")
        return v

    return check


def _list(item: Check, *, nonempty: bool = False) -> Check:
    def check(key, v):
        if not isinstance(v, list):
            raise ConfigError(f"{key} must be a list, got {v!r}")
        if nonempty and not v:
            raise ConfigError(f"{key} must not be empty")
        return [item(f"{key}[{i}]", x) for i, x in enumerate(v)]

    return check


def _table(key, v):
    if not isinstance(v, Mapping):
        raise ConfigError(f"{key} must be a table, got {v!r}")
    return dict(v)


def _encoding(key, v):
    return check_encoding(v, where=key)


def _current_scale(key, v):
    if v == "auto":
        return v
    return _num(positive=True)(key, v)


def _test_files(key, v):
    if isinstance(v, list):
        return _list(_str)(key, v)
    if isinstance(v, Mapping):
        return {str(k): _str(f"{key}.{k}", x) for k, x in v.items()}
    raise ConfigError(f"{key} must be a list of files or a table name -> file, got {v!r}")


def _sweeps(key, v):
    """A non-empty list of `[from, to]` link angles [rad], each a sweep that moves."""
    ok = (
        isinstance(v, list)
        and v
        and all(
            isinstance(p, list)
            and len(p) == 2
            and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                for x in p
            )
            and p[0] != p[1]
            for p in v
        )
    )
    if not ok:
        raise ConfigError(
            f"{key} must be a non-empty list of [from, to] finite link angles in rad that differ, "
            f"e.g. [[-1.2, 1.2]], got {v!r}"
        )
    return [[float(a), float(b)] for a, b in v]


def _optional(check: Check, none_value=0) -> Check:
    """`none_value` (TOML has no null) means "not set"."""

    def inner(key, v):
        return v if v == none_value and not isinstance(v, bool) else check(key, v)

    return inner


SCENARIOS = ("slow", "fast", "sudden", "static")
DATA_KINDS = ("plant", "files", "synthetic", "real_log")

# table -> key -> (default, check). The default `...` means "required".
SCHEMA: dict[str, dict[str, tuple[object, Check]]] = {
    "experiment": {
        "name": ("experiment", _str),
        "description": ("", _str),
        "seed": (0, _int(0)),
    },
    "data": {
        "kind": ("plant", _choice(*DATA_KINDS)),
        # plant
        "preset": ("song", _choice("song", "hashimoto")),
        "scenarios": (list(SCENARIOS), _list(_choice(*SCENARIOS), nonempty=True)),
        "duration": (60.0, _num(positive=True)),
        "train_seed_offset": (1000, _int(1)),
        "settle": (0.0, _num(lo=0.0)),
        "effects": ({}, _table),
        # files
        "train": ([], _list(_str)),
        "test": ([], _test_files),
        "split": (0.0, _num(lo=0.0, hi=0.95)),
        "split_blocks": (0, _optional(_int(2))),
        "format": ("auto", _choice("auto", "csv", "npz")),
        "columns": ({}, _table),
        "extras": ({}, _table),
        "check_units": (True, _bool),
        # the reference torque: a column (default) or built from a wrench ([data.reference])
        "reference": ({"kind": "column"}, check_reference),
        "encoding": ("utf-8", _encoding),
        # synthetic (generated from the compliance model itself; no plant needed)
        "n_samples": (20000, _int(100)),
        "noise_arcsec": (1.0, _num(lo=0.0)),
        # real_log: the plant (preset, effects) on one-way sweeps, read as a real log reads it
        "sweeps": ([[-1.2, 1.2]], _sweeps),
        "speed": (0.4, _num(positive=True)),
        "test_sweeps": ([[-1.0, 1.1]], _sweeps),
        "test_speed": (0.3, _num(positive=True)),
        "sample_period": (1e-3, _num(lo=2.5e-4)),  # the real-log plant steps at 0.25 ms
        "jitter": (0.2, _num(lo=0.0, hi=0.49)),
        "drop": (0.01, _num(lo=0.0, hi=0.49)),
        "skew_ms": (0.0, _num()),
        "encoder_bits": (24, _int(8, 32)),
        "hold": (1, _int(1)),
    },
    "model": {
        "n_segments": (5, _int(1, 20)),
        "poly_order": (6, _int(0, 12)),
        "current_scale": ("auto", _current_scale),
        "kinematic": ("paper", _choice("paper", "harmonic", "none")),
        "fourier_order": (3, _int(0, 12)),
        "harmonic_orders_m": ([1.0, 2.0], _list(_num(positive=True))),
        "harmonic_orders_l": ([1.0, 2.0], _list(_num(positive=True))),
        "per_segment": (True, _bool),
        "velocity": ("difference", _choice("difference", "smoothed")),
        # a saved model (model.json, e.g. written by hdjax discover) whose structure (segments,
        # terms, effects) is calibrated instead of the one the keys above build; "" = none
        "structure": ("", _str),
    },
    "fit": {
        "method": ("lstsq", _choice("lstsq", "rls")),
        "forgetting": (1.0, _num(lo=1e-6, hi=1.0)),
        "block": (256, _int(1)),
        "init_samples": (0, _optional(_int(1))),
        # > 0: least squares accumulated over chunks of this many samples (memory bounded by
        # the chunk, not the log); 0: the whole design at once
        "chunk": (0, _optional(_int(16))),
    },
    "network": {
        "enabled": (True, _bool),
        "hidden": ([20], _list(_int(1), nonempty=True)),
        "periodic": (False, _bool),
        "orders": ([1, 2], _list(_int(1), nonempty=True)),
        "kalman": (True, _bool),
        "trainer": ("optax", _choice("optax", "backprop")),
        "optimizer": ("adam", _choice("adam", "adamw", "sgd")),
        "learning_rate": (0.01, _num(positive=True)),
        "eta": (0.01, _num(positive=True)),
        "steps": (3000, _int(1)),
        "batch_size": (0, _optional(_int(1))),
        "max_train_samples": (20000, _int(10)),
    },
    "sweep": {
        "setting": ("model.poly_order", _str),
        "values": ([1, 2, 3, 4, 5, 6, 7, 8], _list(lambda k, v: v, nonempty=True)),
    },
    "outputs": {
        "figures": (True, _bool),
        "save_model": (True, _bool),
        "save_logs": (False, _bool),
        "timing": (True, _bool),
        "timing_repeats": (20, _int(1)),
        "paper_reference": (False, _bool),
    },
}

TABLES = ("experiment", "joint") + tuple(k for k in SCHEMA if k != "experiment")

# Settings a sweep may vary: every schema key of these tables, plus network width/depth.
SWEEPABLE_TABLES = ("model", "fit", "network", "data")
VIRTUAL_SETTINGS = ("network.width", "network.depth")


def sweepable_settings() -> tuple[str, ...]:
    keys = [f"{t}.{k}" for t in SWEEPABLE_TABLES for k in SCHEMA[t]]
    return tuple(keys) + VIRTUAL_SETTINGS


def all_settings() -> tuple[str, ...]:
    return tuple(f"{t}.{k}" for t in SCHEMA for k in SCHEMA[t])


def resolve(doc: Mapping, *, where: str = "config") -> dict:
    """Validate a parsed experiment document and fill in every default.

    **Arguments:**

    - `doc`: the parsed TOML (a nested mapping).
    - `where`: the file name, for messages.

    **Returns:** a new nested `dict` with every table and key of the schema (the `[joint]`
    table as [`hdjax.Joint.to_dict`][] gives it).

    **Raises:** [`hdjax.ConfigError`][] naming the table and key, with a "did you mean" answer
    for a misspelt table or key.
    """
    for table in doc:
        if table not in TABLES:
            raise ConfigError(
                f"{where}: unknown table [{table}]{did_you_mean(table, TABLES)}; known tables: "
                f"{', '.join(f'[{t}]' for t in TABLES)}"
            )
    if "joint" not in doc:
        raise ConfigError(
            f"{where}: no [joint] table; it needs at least ratio and rated_torque, e.g. "
            "[joint] ratio = 160, rated_torque = 400"
        )
    out: dict = {}
    joint_table = doc["joint"]
    if not isinstance(joint_table, Mapping):
        raise ConfigError(f"{where}: [joint] must be a table")
    joint = Joint.from_dict(joint_table, where=f"{where} [joint]")
    out["joint"] = joint.to_dict()
    for table, spec in SCHEMA.items():
        given = doc.get(table, {})
        if not isinstance(given, Mapping):
            raise ConfigError(f"{where}: [{table}] must be a table, got {given!r}")
        check_keys(given, spec, where, inside=f" in [{table}]")
        clean = {}
        for key, (default, check) in spec.items():
            if key in given:
                clean[key] = check(f"{where} [{table}] {key}", given[key])
            else:
                clean[key] = _copy(default)
        out[table] = clean
    _cross_checks(out, where)
    check_used(doc.get("model", {}), out["model"], where)
    return out


_ENABLED_BY = {
    "harmonic_orders_m": "harmonic",
    "harmonic_orders_l": "harmonic",
    "fourier_order": "paper",
}
"""`[model]` keys that one `kinematic` form alone reads (Song et al. 2019, eq. (9), or the
harmonic series of the residual loop)."""


def check_used(given: Mapping, model: Mapping, where: str) -> None:
    """Refuse a `[model]` key set away from its default that the chosen `kinematic` form
    ignores, naming the setting that reads it (a key silently ignored would leave the model
    other than the user thinks; a resolved config, which lists every key at its default, is
    accepted)."""
    spec = SCHEMA["model"]
    if model["structure"]:
        for key in STRUCTURE_KEYS:
            if key in given and model[key] != spec[key][0]:
                raise ConfigError(
                    f"{where} [model] {key}: not read when structure is given (the saved "
                    f"model {model['structure']!r} sets the structure); remove {key}, or "
                    "remove structure to build the model from the keys"
                )
    for key, form in _ENABLED_BY.items():
        set_ = key in given and model[key] != spec[key][0]
        if set_ and model["kinematic"] != form:
            raise ConfigError(
                f'{where} [model] {key}: read only with kinematic = "{form}", but kinematic = '
                f'"{model["kinematic"]}"; set kinematic = "{form}" to use it, or remove {key}'
            )


def _copy(v):
    """A default's own copy, nested lists and tables included (a resolved config never shares
    a list with the schema)."""
    return copy.deepcopy(v)


def _cross_checks(cfg: dict, where: str) -> None:
    data = cfg["data"]
    if data["kind"] == "files":
        if not data["train"]:
            raise ConfigError(
                f'{where} [data]: kind = "files" needs train = ["file.csv", ...] (recordings '
                "with a reference torque to calibrate on)"
            )
        if not data["test"] and data["split"] <= 0:
            raise ConfigError(
                f"{where} [data]: give test files (test = [...]) or a split fraction (e.g. "
                "split = 0.3 keeps the last 30% of each train file for testing)"
            )
    if data["reference"]["kind"] == "wrench":
        if data["kind"] != "files":
            raise ConfigError(
                f'{where} [data.reference]: kind = "wrench" needs [data] kind = "files" (a log '
                "with the wrench and joint-angle columns)"
            )
        if "torque" in data["columns"]:
            raise ConfigError(
                f'{where} [data.reference]: kind = "wrench" builds the reference torque; remove '
                "torque from [data.columns]"
            )
    if cfg["fit"]["chunk"] and cfg["fit"]["method"] != "lstsq":
        raise ConfigError(
            f"{where} [fit]: chunk = {cfg['fit']['chunk']} streams the least-squares fit; "
            f'method = "{cfg["fit"]["method"]}" already runs block by block (use block = ...) '
            "or set chunk = 0"
        )
    sweep = cfg["sweep"]
    check_sweep_setting(sweep["setting"], where=f"{where} [sweep] setting")


def check_sweep_setting(setting: str, *, where: str = "sweep") -> str:
    """Refuse a sweep over a setting that does not exist (with a "did you mean" answer)."""
    options = sweepable_settings()
    if setting not in options:
        raise ConfigError(
            f"{where}: cannot sweep over unknown setting {setting!r}"
            f"{did_you_mean(setting, options)}; settings are dotted keys such as "
            "model.poly_order, model.fourier_order, model.n_segments, network.width, network.depth"
        )
    return setting


def apply_setting(cfg: dict, setting: str, value, *, where: str = "override") -> dict:
    """A copy of a resolved config with one dotted setting changed and re-validated: the value
    by its key's check, the whole config by the cross-table checks of the file itself."""
    new = _apply_setting(cfg, setting, value, where=where)
    try:
        _cross_checks(new, where=f"{where} {setting} = {value!r}:")
    except ConfigError as err:
        raise ConfigError(" ".join(str(err).split())) from None
    return new


def _apply_setting(cfg: dict, setting: str, value, *, where: str) -> dict:
    import copy

    new = copy.deepcopy(cfg)
    table, _, key = setting.partition(".")
    if setting == "network.width":
        depth = len(new["network"]["hidden"])
        value = _int(1)(f"{where} network.width", value)
        new["network"]["hidden"] = [value] * depth
        return new
    if setting == "network.depth":
        width = new["network"]["hidden"][0]
        value = _int(1)(f"{where} network.depth", value)
        new["network"]["hidden"] = [width] * value
        return new
    if table == "joint":
        j = dict(new["joint"])
        j[key] = value
        new["joint"] = Joint.from_dict(j, where=f"{where} [joint]").to_dict()
        return new
    if table not in SCHEMA or key not in SCHEMA[table]:
        options = all_settings() + VIRTUAL_SETTINGS + tuple(f"joint.{k}" for k in _joint_keys())
        raise ConfigError(f"{where}: unknown setting {setting!r}{did_you_mean(setting, options)}")
    _, check = SCHEMA[table][key]
    new[table][key] = check(f"{where} {setting}", value)
    if table == "sweep" and key == "setting":
        check_sweep_setting(value, where=where)
    return new


def _joint_keys():
    import dataclasses

    return [f.name for f in dataclasses.fields(Joint)]


def joint_of(cfg: Mapping) -> Joint:
    """The [`hdjax.Joint`][] of a resolved config."""
    return Joint.from_dict(cfg["joint"])


STRUCTURE_KEYS = (  # the [model] settings that set the paper model's structure
    "n_segments",
    "poly_order",
    "kinematic",
    "fourier_order",
    "harmonic_orders_m",
    "harmonic_orders_l",
    "per_segment",
    "velocity",
)


def structure_settings(table: Mapping) -> dict:
    """The keyword arguments of `hdjax.compliance.ComplianceModel.paper` (Song et al. 2019,
    eqs. (7)-(10)) that a validated `[model]` table sets (`STRUCTURE_KEYS`, those it holds: a
    fleet manifest's table holds fewer, and the others take `paper`'s defaults)."""
    kw = {k: table[k] for k in STRUCTURE_KEYS if k in table}
    for k in ("harmonic_orders_m", "harmonic_orders_l"):
        if k in kw:
            kw[k] = tuple(kw[k])
    return kw
