"""The `[data.reference]` table: which torque a calibration is scored against, validated.

```toml
[data.reference]
kind = "column"            # default: the reference is the [data.columns] torque column

[data.reference]           # or: built from a flange force/torque sensor
kind = "wrench"
joint = 3                                  # whose torque (1-based, along the chain)
dh = "arm_dh.toml"                         # a DH table (see hdjax.reference.load_dh_table)
# urdf = "arm.urdf"; frame = "ft_sensor"   # or a URDF and the sensor's frame (pinocchio)
angles = ["q1", "q2", "q3", "q4", "q5", "q6"]          # joint angle columns
angle_unit = "rad"                                     # or "deg"
wrench = ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]          # N, N·m
wrench_frame = "tool"                      # the wrench's axes: "tool" (sensor) or "base"
wrench_sign = 1                            # tau = tau_model + wrench_sign * J^T W
model_torque = "tau_ff_3"                  # a column, "rnea" (URDF only) or "none"
# velocities = [...]; accelerations = [...]  # for "rnea" (accelerations default: differences)
offset = "none"                            # "none", "rest" (with rest = [t0, t1] s) or "fit"
gravity = [0.0, 0.0, -9.80665]             # base frame, for "fit" and "rnea"
```

Paths are relative to the experiment file. Every check is plain Python and fails with one
line naming the key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from .._errors import ConfigError, check_keys, did_you_mean

KINDS = ("column", "wrench")
OFFSETS = ("none", "rest", "fit")
_WRENCH_KEYS = (
    "kind",
    "joint",
    "dh",
    "urdf",
    "frame",
    "angles",
    "angle_unit",
    "wrench",
    "wrench_frame",
    "wrench_sign",
    "model_torque",
    "velocities",
    "accelerations",
    "offset",
    "rest",
    "gravity",
)
DEFAULT_GRAVITY = [0.0, 0.0, -9.80665]


def _names(key: str, v, n: int | None = None) -> list[str]:
    if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
        raise ConfigError(f"{key} must be a list of column names, got {v!r}")
    if n is not None and len(v) != n:
        raise ConfigError(f"{key} must name {n} columns, got {len(v)}")
    return list(v)


def _numbers(key: str, v, n: int) -> list[float]:
    ok = isinstance(v, list) and len(v) == n
    ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
    if not ok or not all(math.isfinite(x) for x in v):
        raise ConfigError(f"{key} must be {n} finite numbers, got {v!r}")
    return [float(x) for x in v]


def _one_of(key: str, name: str, value, options) -> str:
    """`value` if it is one of `options`, else a ConfigError with a "did you mean" hint."""
    if value not in options:
        raise ConfigError(
            f"{key} {name} must be one of {', '.join(options)}, got {value!r}"
            f"{did_you_mean(str(value), options)}"
        )
    return value


def check_reference(key: str, v) -> dict:
    """Validate a `[data.reference]` table; returns it with defaults filled in.

    **Raises:** [`hdjax.ConfigError`][] with one line naming the bad key.
    """
    if not isinstance(v, Mapping):
        raise ConfigError(f'{key} must be a table, e.g. {{ kind = "column" }}, got {v!r}')
    kind = _one_of(key, "kind", v.get("kind", "column"), KINDS)
    if kind == "column":
        extra = sorted(set(v) - {"kind"})
        if extra:
            raise ConfigError(
                f'{key}: {extra[0]!r} needs kind = "wrench" (kind = "column" takes no other '
                "keys; the column is [data.columns] torque)"
            )
        return {"kind": "column"}
    check_keys(v, _WRENCH_KEYS, key)
    out: dict = {"kind": "wrench"}
    for req in ("joint", "angles", "wrench", "model_torque"):
        if req not in v:
            raise ConfigError(
                f'{key}: kind = "wrench" needs {req!r} (see the [data.reference] docs)'
            )
    joint = v["joint"]
    if isinstance(joint, bool) or not isinstance(joint, int) or joint < 1:
        raise ConfigError(f"{key} joint must be a positive integer (1-based), got {joint!r}")
    out["joint"] = joint
    has_dh, has_urdf = "dh" in v, "urdf" in v
    if has_dh == has_urdf:
        raise ConfigError(f"{key}: give exactly one of 'dh' (a DH table file) or 'urdf'")
    if has_dh:
        if not isinstance(v["dh"], str) or not v["dh"]:
            raise ConfigError(f"{key} dh must be a file name, got {v['dh']!r}")
        if "frame" in v:
            raise ConfigError(
                f"{key}: 'frame' goes with 'urdf'; a DH table's tool is its [arm] tool"
            )
        out["dh"] = v["dh"]
    else:
        if not isinstance(v["urdf"], str) or not v["urdf"]:
            raise ConfigError(f"{key} urdf must be a file name, got {v['urdf']!r}")
        if not isinstance(v.get("frame"), str) or not v["frame"]:
            raise ConfigError(f"{key}: 'urdf' needs frame = \"NAME\" (the sensor's frame)")
        out["urdf"], out["frame"] = v["urdf"], v["frame"]
    out["angles"] = _names(f"{key} angles", v["angles"])
    if out["joint"] > len(out["angles"]):
        raise ConfigError(
            f"{key} joint = {joint} but angles names only {len(out['angles'])} joints"
        )
    unit = v.get("angle_unit", "rad")
    if unit not in ("rad", "deg"):
        raise ConfigError(f'{key} angle_unit must be "rad" or "deg", got {unit!r}')
    out["angle_unit"] = unit
    out["wrench"] = _names(f"{key} wrench", v["wrench"], 6)
    frame = v.get("wrench_frame", "tool")
    if frame not in ("tool", "base"):
        raise ConfigError(
            f'{key} wrench_frame must be "tool" (the sensor\'s axes) or "base", got {frame!r}'
        )
    out["wrench_frame"] = frame
    sign = v.get("wrench_sign", 1)
    if isinstance(sign, bool) or sign not in (1, -1):
        raise ConfigError(f"{key} wrench_sign must be 1 or -1, got {sign!r}")
    out["wrench_sign"] = int(sign)
    model = v["model_torque"]
    if not isinstance(model, str) or not model:
        raise ConfigError(f'{key} model_torque must be a column name, "rnea" or "none"')
    if model == "rnea" and not has_urdf:
        raise ConfigError(f'{key}: model_torque = "rnea" needs a URDF (its inertias); give urdf')
    out["model_torque"] = model
    if model == "rnea":
        if "velocities" not in v:
            raise ConfigError(f'{key}: model_torque = "rnea" needs velocities = [...] columns')
        n = len(out["angles"])
        out["velocities"] = _names(f"{key} velocities", v["velocities"], n)
        acc = v.get("accelerations", "difference")
        out["accelerations"] = (
            acc if acc == "difference" else _names(f"{key} accelerations", acc, n)
        )
    else:
        for k in ("velocities", "accelerations"):
            if k in v:
                raise ConfigError(f'{key}: {k!r} is used only with model_torque = "rnea"')
    offset = _one_of(key, "offset", v.get("offset", "none"), OFFSETS)
    if offset == "fit" and frame != "tool":
        raise ConfigError(
            f'{key}: offset = "fit" needs wrench_frame = "tool" (a sensor\'s offset is '
            "constant in its own axes, not in the base frame)"
        )
    out["offset"] = offset
    if offset == "rest":
        if "rest" not in v:
            raise ConfigError(
                f'{key}: offset = "rest" needs rest = [t0, t1] (seconds from the start)'
            )
        lo, hi = _numbers(f"{key} rest", v["rest"], 2)
        if not 0 <= lo < hi:
            raise ConfigError(f"{key} rest must satisfy 0 <= t0 < t1, got {v['rest']!r}")
        out["rest"] = [lo, hi]
    elif "rest" in v:
        raise ConfigError(f"{key}: 'rest' is used only with offset = \"rest\"")
    out["gravity"] = _numbers(f"{key} gravity", v.get("gravity", DEFAULT_GRAVITY), 3)
    return out


def needed_columns(spec: Mapping) -> list[str]:
    """The log columns a wrench reference reads (in order, without repeats)."""
    names = list(spec["angles"]) + list(spec["wrench"])
    if spec["model_torque"] not in ("rnea", "none"):
        names.append(spec["model_torque"])
    for k in ("velocities", "accelerations"):
        if isinstance(spec.get(k), list):
            names += spec[k]
    return list(dict.fromkeys(names))
