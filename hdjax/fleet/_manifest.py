"""The fleet manifest: joints, their logs with dates, and what to run on each.

```toml
[fleet]
task = "calibrate+discover"   # or "calibrate", "estimate"
split = 0.3                   # the last 30 % of each log is its TEST part (discover)
max_effects = 3
chunk = 0                     # > 0: every task reads and fits its log this many samples at a time

[model]                       # the calibrated structure (defaults: the paper's)
n_segments = 5
poly_order = 6

[[joints]]
name = "robot1-j2"
ratio = 160
rated_torque = 400
columns = "maps/robot1.toml"  # a file with a [data] column map, or an inline table
model = "models/robot1-j2.json"   # the saved model, for task = "estimate"
logs = [
  { path = "logs/robot1-j2-2026-01-05.parquet", date = 2026-01-05 },
  { path = "logs/robot1-j2-2026-02-02.parquet", date = 2026-02-02 },
]
```

Paths are relative to the manifest. Each (joint, log) pair is one [`Task`][], identified by a
fingerprint of everything that decides its result (the settings, the joint, the column map and
the log file's size and modification time), so a finished task is recognised on a later run.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import json
from pathlib import Path

from .._errors import ConfigError, check_keys, did_you_mean
from .._io import ColumnMap, read_toml
from .._joint import Joint
from ..compliance.internal import MIN_CHUNK

TASKS = ("calibrate", "calibrate+discover", "estimate")

FLEET_KEYS = {
    "name": "fleet",
    "task": "calibrate+discover",
    "split": 0.3,
    "max_effects": 3,
    "min_gain": 0.05,
    "chunk": 0,
}
MODEL_KEYS = {
    "n_segments": 5,
    "poly_order": 6,
    "fourier_order": 3,
    "kinematic": "paper",
    "per_segment": True,
}
JOINT_EXTRA = ("columns", "model", "logs")


@dataclasses.dataclass(frozen=True)
class Task:
    """One (joint, log) pair and everything a worker needs to run it (plain data)."""

    task_id: str
    joint: str
    log: str
    date: str
    spec: dict


@dataclasses.dataclass
class Manifest:
    """A checked manifest: its settings and its tasks in manifest order."""

    path: Path
    settings: dict
    model: dict
    joints: dict[str, dict]
    tasks: list[Task]


def _merged(defaults: dict, given: dict, where: str) -> dict:
    check_keys(given, defaults, where)
    out = dict(defaults)
    for key, value in given.items():
        want = type(defaults[key])
        ok = isinstance(value, want) or (want is float and isinstance(value, int))
        if isinstance(value, bool) != (want is bool) or not ok:
            raise ConfigError(f"{where} {key}: expected a {want.__name__}, got {value!r}")
        out[key] = value
    return out


def _columns(entry, base: Path, where: str) -> dict:
    """A column-map table (checked), from a file name or an inline table."""
    if entry is None:
        return {}
    if isinstance(entry, str):
        p = Path(entry).expanduser()
        p = p if p.is_absolute() else base / p
        doc = read_toml(p)
        table = doc.get("data", doc)
        where = f"{p} [data]"
    elif isinstance(entry, dict):
        table = entry
    else:
        raise ConfigError(f"{where}: columns must be a file name or a table, got {entry!r}")
    table = {k: v for k, v in table.items() if k in ("columns", "extras")}
    ColumnMap.from_dict(table, where=where)  # check now, before any worker starts
    return table


def _fingerprint(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def load_manifest(path) -> Manifest:
    """Read and check a fleet manifest (see the module docstring for the format).

    **Raises:** [`hdjax.ConfigError`][] naming the table and key of anything wrong: unknown
    keys (with "did you mean"), a joint without logs, a duplicated joint name or log, a log
    without a date, `task = "estimate"` without a model file.
    """
    path = Path(path)
    doc = read_toml(path)
    check_keys(doc, ("fleet", "model", "joints"), str(path))
    settings = _merged(FLEET_KEYS, doc.get("fleet", {}), f"{path} [fleet]")
    if settings["task"] not in TASKS:
        raise ConfigError(
            f"{path} [fleet] task: must be one of {', '.join(TASKS)}, got {settings['task']!r}"
            f"{did_you_mean(str(settings['task']), TASKS)}"
        )
    if not 0.05 <= settings["split"] <= 0.9:
        raise ConfigError(f"{path} [fleet] split: must lie in [0.05, 0.9], got {settings['split']}")
    if settings["chunk"] and settings["chunk"] < MIN_CHUNK:
        raise ConfigError(
            f"{path} [fleet] chunk: 0 (in memory) or >= {MIN_CHUNK}, got {settings['chunk']}"
        )
    model = _merged(MODEL_KEYS, doc.get("model", {}), f"{path} [model]")
    joints_doc = doc.get("joints")
    if not isinstance(joints_doc, list) or not joints_doc:
        raise ConfigError(
            f"{path}: no [[joints]]; list each joint with name, ratio, rated_torque and logs"
        )
    base = path.parent
    joints, tasks, seen = {}, [], set()
    for i, jt in enumerate(joints_doc):
        where = f"{path} [[joints]] #{i + 1}"
        if not isinstance(jt, dict) or not isinstance(jt.get("name"), str) or not jt["name"]:
            raise ConfigError(f"{where}: every joint needs a name (a string)")
        name = jt["name"]
        where = f"{path} joint {name!r}"
        if name in joints:
            raise ConfigError(f"{where}: the name is used by two joints; names must be unique")
        joint = Joint.from_dict({k: v for k, v in jt.items() if k not in JOINT_EXTRA}, where=where)
        columns = _columns(jt.get("columns"), base, f"{where} columns")
        model_file = jt.get("model")
        if settings["task"] == "estimate":
            if not isinstance(model_file, str):
                raise ConfigError(f'{where}: task = "estimate" needs model = "model.json"')
            model_file = str(_resolve(base, model_file))
        logs = jt.get("logs")
        if not isinstance(logs, list) or not logs:
            raise ConfigError(f'{where}: no logs; give logs = [{{ path = "...", date = ... }}]')
        joints[name] = {"joint": joint.to_dict(), "columns": columns, "model": model_file}
        for k, log in enumerate(logs):
            lw = f"{where} logs[{k}]"
            if not isinstance(log, dict):
                raise ConfigError(f"{lw}: expected {{ path = ..., date = ... }}, got {log!r}")
            check_keys(log, ("path", "date"), lw)
            if not isinstance(log.get("path"), str):
                raise ConfigError(f"{lw}: missing path (the log file)")
            date = log.get("date")
            if not isinstance(date, dt.date | dt.datetime | str):
                raise ConfigError(f"{lw}: missing date (a TOML date such as 2026-01-05)")
            log_path = _resolve(base, log["path"])
            if (name, str(log_path)) in seen:
                raise ConfigError(f"{lw}: {log_path} is listed twice for this joint")
            seen.add((name, str(log_path)))
            spec = {
                "task": settings["task"],
                "settings": settings,
                "model_structure": model,
                "joint_name": name,
                "joint": joints[name]["joint"],
                "columns": columns,
                "model_file": model_file,
                "log": str(log_path),
                "date": date.isoformat() if hasattr(date, "isoformat") else str(date),
            }
            stamp = _file_stamp(log_path) + _file_stamp(model_file)
            task_id = f"{_safe(name)}-{_fingerprint([spec, stamp])}"
            tasks.append(Task(task_id, name, str(log_path), spec["date"], spec))
    return Manifest(path=path, settings=settings, model=model, joints=joints, tasks=tasks)


def _resolve(base: Path, name: str) -> Path:
    p = Path(name).expanduser()
    return p if p.is_absolute() else base / p


def _file_stamp(path) -> list:
    """Size and modification time (a changed log is a new task); missing files are run and
    fail with their own message."""
    if path is None:
        return []
    try:
        st = Path(path).stat()
    except OSError:
        return ["missing"]
    return [st.st_size, st.st_mtime_ns]


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)[:40]
