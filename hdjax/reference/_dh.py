r"""Denavit-Hartenberg arms: the link table, its forward kinematics, and reading it from TOML.

Two conventions, both with one row $(a, \alpha, d, \theta_0)$ per revolute joint and joint
angle $q_i$ added to $\theta_0$:

- **standard** (distal, Denavit and Hartenberg 1955; Spong et al. 2006, eq. (3.10)):
  $T_{i-1,i} = R_z(\theta_i)\,T_z(d_i)\,T_x(a_i)\,R_x(\alpha_i)$; joint $i$ turns about
  $z_{i-1}$.
- **modified** (proximal, Craig 2005, eq. (3.6)):
  $T_{i-1,i} = R_x(\alpha_{i-1})\,T_x(a_{i-1})\,R_z(\theta_i)\,T_z(d_i)$, the row of joint $i$
  holding $(a_{i-1}, \alpha_{i-1}, d_i, \theta_{0,i})$; joint $i$ turns about $z_i$.

A fixed tool transform $T_{n,\text{tool}}$ (translation `xyz`, rotation `rpy` as in URDF:
$R = R_z(\text{yaw})R_y(\text{pitch})R_x(\text{roll})$) places the frame the wrench is measured
in (the force/torque sensor's) relative to the last link frame.

Everything is float64 JAX, so the kinematics jit, vmap over samples and differentiate.

References: Spong, Hutchinson, Vidyasagar, *Robot Modeling and Control* (2006), Sections 3.2
and 4.6; Craig, *Introduction to Robotics* (2005), Section 3.4.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayInput, ArrayLike, Float, PathLike, Real
from .._errors import ConfigError, check_keys, did_you_mean
from .._io import read_toml

CONVENTIONS = ("standard", "modified")
_TABLE_KEYS = ("name", "convention", "angle_unit", "links", "tool", "source")


def link_transform(
    a: Real[ArrayLike, ""],
    alpha: Real[ArrayLike, ""],
    d: Real[ArrayLike, ""],
    theta: Real[ArrayLike, ""],
    *,
    modified: bool = False,
) -> Float[Array, "4 4"]:
    r"""One link's homogeneous transform $T_{i-1,i}$ (see the module docstring), in closed form.

    **Arguments:** `a` [m], `alpha` [rad], `d` [m], `theta` [rad] (offset plus joint angle);
    `modified` picks Craig's convention.
    """
    a, alpha, d, theta = (jnp.asarray(v, jnp.float64) for v in (a, alpha, d, theta))
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    zero, one = jnp.zeros_like(ct), jnp.ones_like(ct)
    if modified:  # Rx(alpha) Tx(a) Rz(theta) Tz(d)
        rows = [
            [ct, -st, zero, a + zero],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
        ]
    else:  # Rz(theta) Tz(d) Tx(a) Rx(alpha)
        rows = [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [zero, sa, ca, d + zero],
        ]
    rows.append([zero, zero, zero, one])
    return jnp.stack([jnp.stack(r) for r in rows])


def rpy_matrix(roll: float, pitch: float, yaw: float) -> Float[np.ndarray, "3 3"]:
    """$R_z(\\text{yaw}) R_y(\\text{pitch}) R_x(\\text{roll})$, the URDF `rpy` convention."""
    cr, sr, cp, sp, cy, sy = (f(v) for v in (roll, pitch, yaw) for f in (math.cos, math.sin))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


class DHArm(eqx.Module):
    """A serial arm of revolute joints described by a DH table and a tool transform.

    **Arguments:**

    - `a`, `alpha`, `d`, `theta_offset`: one value per joint [m, rad, m, rad].
    - `tool`: the 4x4 transform from the last link frame to the tool (sensor) frame.
    - `convention`: `"standard"` or `"modified"` (module docstring).
    - `name`: a label.
    """

    a: Float[Array, " n_joints"]
    alpha: Float[Array, " n_joints"]
    d: Float[Array, " n_joints"]
    theta_offset: Float[Array, " n_joints"]
    tool: Float[Array, "4 4"]
    convention: str = eqx.field(static=True, default="standard")
    name: str = eqx.field(static=True, default="arm")

    def __check_init__(self):
        if self.convention not in CONVENTIONS:
            raise ConfigError(
                f"DH convention must be one of {', '.join(CONVENTIONS)}, got {self.convention!r}"
            )

    @property
    def n_joints(self) -> int:
        return int(self.a.shape[0])


def dh_arm(
    links: ArrayInput,
    *,
    convention: str = "standard",
    tool_xyz: Real[ArrayLike, " 3"] | Sequence[float] = (0.0, 0.0, 0.0),
    tool_rpy: Real[ArrayLike, " 3"] | Sequence[float] = (0.0, 0.0, 0.0),
    name: str = "arm",
) -> DHArm:
    """A [`hdjax.reference.DHArm`][] from rows `(a, alpha, d, theta_offset)` (radians)."""
    rows = np.asarray(links, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 4 or rows.shape[0] < 1:
        raise ConfigError(
            f"a DH table needs rows of 4 numbers (a, alpha, d, theta_offset), got shape "
            f"{rows.shape}"
        )
    if not np.all(np.isfinite(rows)):
        raise ConfigError("a DH table must hold finite numbers only")
    tool = np.eye(4)
    tool[:3, :3] = rpy_matrix(*(float(v) for v in tool_rpy))
    tool[:3, 3] = np.asarray(tool_xyz, dtype=np.float64)
    f = lambda col: jnp.asarray(rows[:, col], jnp.float64)
    return DHArm(f(0), f(1), f(2), f(3), jnp.asarray(tool), convention=convention, name=name)


def forward_kinematics(
    arm: DHArm, q: Float[ArrayLike, " n_joints"]
) -> tuple[Float[Array, "n_joints 4 4"], Float[Array, "4 4"]]:
    r"""Joint-axis frames and the tool pose of `arm` at joint angles `q`.

    **Returns:** `(axes, tool)`: `axes[i]` is the 4x4 base-frame pose of the frame whose $z$
    axis joint $i$ turns about ($T_{0,i-1}$ in the standard convention, $T_{0,i}$ in the
    modified one), and `tool` is $T_{0,\text{tool}} = T_{0,n} T_{n,\text{tool}}$.
    """
    q = jnp.asarray(q, jnp.float64)
    modified = arm.convention == "modified"
    pose = jnp.eye(4, dtype=jnp.float64)
    axes = []
    for i in range(arm.n_joints):
        link = link_transform(
            arm.a[i], arm.alpha[i], arm.d[i], arm.theta_offset[i] + q[i], modified=modified
        )
        if modified:
            pose = pose @ link
            axes.append(pose)
        else:
            axes.append(pose)
            pose = pose @ link
    return jnp.stack(axes), pose @ arm.tool


# ---------------------------------------------------------------------------------------------
# Reading a DH table from TOML


def _angles(values, unit: str) -> list[float]:
    scale = math.pi / 180.0 if unit == "deg" else 1.0
    return [float(v) * scale for v in values]


def dh_arm_from_table(table: Mapping, *, where: str = "[arm]") -> DHArm:
    """Build from a TOML-like `[arm]` table (see [`hdjax.reference.load_dh_table`][])."""
    check_keys(table, _TABLE_KEYS, where)
    convention = table.get("convention", "standard")
    if convention not in CONVENTIONS:
        raise ConfigError(
            f"{where} convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}"
            f"{did_you_mean(str(convention), CONVENTIONS)}"
        )
    unit = table.get("angle_unit", "rad")
    if unit not in ("rad", "deg"):
        raise ConfigError(f'{where} angle_unit must be "rad" or "deg", got {unit!r}')
    links = table.get("links")
    if not isinstance(links, list) or not links:
        raise ConfigError(
            f"{where}: 'links' must be a list of rows [a, alpha, d, theta_offset], one per joint"
        )
    rows = []
    for i, row in enumerate(links):
        ok = isinstance(row, list) and len(row) == 4
        ok = ok and all(isinstance(v, int | float) and not isinstance(v, bool) for v in row)
        if not ok:
            raise ConfigError(
                f"{where} links[{i}] must be 4 numbers [a, alpha, d, theta_offset], got {row!r}"
            )
        a, alpha, d, theta = row
        alpha, theta = _angles((alpha, theta), unit)
        rows.append([float(a), alpha, float(d), theta])
    tool = table.get("tool", {})
    if not isinstance(tool, Mapping):
        raise ConfigError(f"{where} tool must be a table {{ xyz = [..], rpy = [..] }}")
    check_keys(tool, ("xyz", "rpy"), f"{where} tool")
    vecs = {}
    for key in ("xyz", "rpy"):
        v = tool.get(key, [0.0, 0.0, 0.0])
        if (
            not isinstance(v, list)
            or len(v) != 3
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        ):
            raise ConfigError(f"{where} tool.{key} must be 3 numbers, got {v!r}")
        vecs[key] = _angles(v, unit) if key == "rpy" else [float(x) for x in v]
    return dh_arm(
        rows,
        convention=convention,
        tool_xyz=vecs["xyz"],
        tool_rpy=vecs["rpy"],
        name=str(table.get("name", "arm")),
    )


def load_dh_table(path: PathLike) -> DHArm:
    """Read a DH arm from the `[arm]` table of a TOML file.

    ```toml
    [arm]
    name = "my arm"
    convention = "standard"      # or "modified"
    angle_unit = "deg"           # alpha, theta_offset and tool.rpy in degrees (or "rad")
    links = [                    # a [m], alpha, d [m], theta_offset; one row per joint
      [0.0, -90, 0.26, 0],
      [0.48, 0, 0, -90],
    ]
    tool = { xyz = [0, 0, 0], rpy = [0, 0, 0] }   # last link frame -> sensor frame
    ```

    **Raises:** [`hdjax.ConfigError`][] naming the file and key.
    """
    path = Path(path)
    doc = read_toml(path)
    if "arm" not in doc:
        raise ConfigError(f"{path}: no [arm] table (it needs convention and links)")
    return dh_arm_from_table(doc["arm"], where=f"{path} [arm]")
