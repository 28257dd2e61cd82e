"""Reading experiment files (with line:column on parse errors) and writing resolved ones."""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .._custom_types import PathLike
from .._errors import ConfigError
from .._io import TOML_HINT, ColumnMap, read_text
from ._schema import apply_setting, check_used, resolve

_POSITION = re.compile(r"^(?P<msg>.*?)\s*\(at line (?P<line>\d+), column (?P<col>\d+)\)\s*$")


class Experiment(dict):
    """A resolved experiment configuration (a nested `dict`) and the file it came from.

    `path` is the experiment file (or `None`); relative data paths are resolved against
    `base_dir`, the file's folder.
    """

    path: Path | None = None

    @property
    def base_dir(self) -> Path:
        return self.path.parent if self.path is not None else Path.cwd()


def column_map(data: dict) -> ColumnMap:
    """The [`hdjax.ColumnMap`][] of a `[data]` table (its `columns` and `extras`)."""
    table = {"columns": data.get("columns") or {}}
    if data.get("extras"):
        table["extras"] = data["extras"]
    if data.get("encoding") not in (None, "utf-8"):
        table["encoding"] = data["encoding"]
    return ColumnMap.from_dict(table, where="[data]")


def resolve_path(exp: Experiment, name: str) -> Path:
    """A data path of the experiment: `~` expanded, a relative path taken from its folder."""
    p = Path(name).expanduser()
    return p if p.is_absolute() else (exp.base_dir / p)


def parse_toml(text: str, *, where: str) -> dict:
    """Parse TOML text; a syntax error becomes `WHERE:LINE:COLUMN: message`."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        msg = str(err)
        m = _POSITION.match(msg)
        if m:
            line, col = m.group("line"), m.group("col")
            raise ConfigError(
                f"{where}:{line}:{col}: TOML syntax error: {m.group('msg')} (line {line}, "
                f"column {col})"
            ) from None
        raise ConfigError(f"{where}: TOML syntax error: {msg}") from None


def parse_value(text: str) -> Any:
    """A command-line value read as TOML (`4`, `1.5`, `true`, `[1, 2]`, `"x"`), else a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def load_experiment(path: PathLike, overrides: Mapping[str, object] | None = None) -> Experiment:
    """Read, validate and resolve an experiment file.

    **Arguments:**

    - `path`: the TOML file.
    - `overrides`: dotted settings to change after reading (`{"model.poly_order": 4}`), as
      `hdjax run --set` passes them.

    **Returns:** an [`hdjax.config.Experiment`][] (a resolved nested dict with `path`).

    **Raises:** [`hdjax.ConfigError`][] for a missing file, a syntax error (with line and column),
    an unknown table or key (with a "did you mean" answer) or a value out of range.
    """
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"{path}: no such experiment file")
    if path.is_dir():
        raise ConfigError(f"{path}: is a directory; give an experiment .toml file")
    doc = parse_toml(read_text(path, what="experiment file", hint=TOML_HINT), where=str(path))
    cfg = resolve(doc, where=str(path))
    for setting, value in (overrides or {}).items():
        cfg = apply_setting(cfg, setting, value, where="--set")
    if overrides:  # a [model] key set on the command line must be read, like the file's
        # (a structure given there replaces the structure the file's keys build)
        given = {} if "model.structure" in overrides else dict(doc.get("model", {}))
        given.update({k[6:]: v for k, v in overrides.items() if k.startswith("model.")})
        check_used(given, cfg["model"], f"{path} with --set")
    exp = Experiment(cfg)
    exp.path = path.resolve()
    return exp


def experiment_from_dict(
    doc: Mapping, *, base_dir: PathLike | None = None, where: str = "config"
) -> Experiment:
    """An [`hdjax.config.Experiment`][] from an in-memory document (for tests and scripts)."""
    exp = Experiment(resolve(doc, where=where))
    exp.path = None if base_dir is None else Path(base_dir).resolve() / "<memory>.toml"
    return exp


# ---------------------------------------------------------------------------------------------
# Writing (tomllib only reads; the resolved config holds only tables, lists and scalars)


def with_absolute_paths(exp: Experiment) -> dict:
    """A copy of a resolved config whose file settings (`[data]` train and test, the
    `[data.reference]` DH table or URDF, `[model]` structure) are absolute paths, so the
    `config.resolved.toml` a result directory keeps still finds its files when it is run from
    there."""
    import copy
    import os

    base = exp.base_dir
    absolute = lambda name: os.path.normpath(base / Path(name).expanduser())
    cfg = copy.deepcopy(dict(exp))
    data = cfg.get("data", {})
    if isinstance(data.get("train"), list):
        data["train"] = [absolute(n) for n in data["train"]]
    tests = data.get("test")
    if isinstance(tests, list):
        data["test"] = [absolute(n) for n in tests]
    elif isinstance(tests, dict):
        data["test"] = {k: absolute(n) for k, n in tests.items()}
    model = cfg.get("model", {})
    if model.get("structure"):
        model["structure"] = absolute(model["structure"])
    ref = data.get("reference")
    if isinstance(ref, dict):
        for key in ("dh", "urdf"):
            if isinstance(ref.get(key), str) and ref[key]:
                ref[key] = absolute(ref[key])
    return cfg


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _string(k)


def _string(s: str) -> str:
    out = s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
    return f'"{out}"'


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_key(str(k))} = {_value(x)}" for k, x in v.items()) + "}"
    raise ConfigError(f"cannot write {v!r} ({type(v).__name__}) to TOML")


def dumps_toml(doc: Mapping, header: str = "") -> str:
    """TOML text for a nested mapping of tables (sub-tables written inline)."""
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    scalars = {k: v for k, v in doc.items() if not isinstance(v, Mapping)}
    for k, v in scalars.items():
        lines.append(f"{_key(k)} = {_value(v)}")
    for table, body in doc.items():
        if not isinstance(body, Mapping):
            continue
        lines.append("")
        lines.append(f"[{_key(table)}]")
        for k, v in body.items():
            lines.append(f"{_key(str(k))} = {_value(v)}")
    return "\n".join(lines) + "\n"
