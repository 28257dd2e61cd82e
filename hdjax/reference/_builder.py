r"""The joint-torque reference from a measured wrench and the arm's kinematics.

$$\tau_j = \tau_{\text{model},j} + s\,J_j(q)^\top (W - w_0),$$

with $J_j$ the column of joint $j$ of the geometric Jacobian at the sensor, in the frame $W$
is expressed in ([`hdjax.reference.geometric_jacobian`][]), $W$ the measured wrench
$[F; M]$, $w_0$ the sensor offset ([`hdjax.reference.fit_offset_with_payload`][]), $s = \pm 1$
the sensor's sign convention ($+1$ when $W$ is the wrench the arm exerts on what it carries,
so the joint must supply $J^\top W$ on top of its own dynamics) and $\tau_\text{model}$ the
arm's own dynamics (a controller's model-torque column, or RNEA over a URDF).

This is the usual way to get joint torques without joint torque sensors that Song et al.
2019 name in their introduction: a multi-axis sensor at the end of the arm and a
transformation by the Jacobian (their refs. [9], [10]).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .._custom_types import ArrayLike, Bool, Float, PathLike, Real
from .._errors import DataError
from ._dh import DHArm, load_dh_table
from ._holds import Holds, detect_holds
from ._jacobian import jacobian_columns, tool_rotations
from ._offset import SensorOffset, fit_offset_with_payload, no_offset, offset_from_rest
from ._urdf import UrdfArm


def joint_torque(
    jac_column: Real[ArrayLike, "n 6"],
    wrench: Real[ArrayLike, "n 6"],
    tau_model: Real[ArrayLike, " n"] | None = None,
    *,
    sign: int = 1,
    offset: Real[ArrayLike, " 6"] | None = None,
) -> Float[np.ndarray, " n"]:
    r"""$\tau = \tau_\text{model} + s\,J_j^\top (W - w_0)$ per sample (module docstring).

    **Arguments:** `jac_column` `(n, 6)`, `wrench` `(n, 6)` in the same frame, `tau_model`
    `(n,)` or `None` (zero), `sign` $s$, `offset` $w_0$ `(6,)` or `None`.
    """
    jc = np.asarray(jac_column, dtype=np.float64)
    w = np.asarray(wrench, dtype=np.float64)
    if offset is not None:
        w = w - np.asarray(offset, dtype=np.float64)
    ext = sign * np.einsum("nk,nk->n", jc, w)
    return ext if tau_model is None else np.asarray(tau_model, dtype=np.float64) + ext


@dataclasses.dataclass
class WrenchReference:
    """A joint-torque reference built from a wrench, at the rows where a new wrench arrived.

    **Fields:** `torque` and `external` ($s J^\\top(W - w_0)$) and `model` ($\\tau_\\text{model}$),
    each at the fresh rows; `fresh` (bool per input row), `holds`, `offset`, `description`.
    """

    torque: Float[np.ndarray, " n_fresh"]
    external: Float[np.ndarray, " n_fresh"]
    model: Float[np.ndarray, " n_fresh"]
    fresh: Bool[np.ndarray, " n"]
    holds: Holds
    offset: SensorOffset
    description: str

    def as_dict(self) -> dict:
        return {
            "kind": "wrench",
            "description": self.description,
            "holds": {
                "fresh_rows": self.holds.n_fresh,
                "rows": self.holds.n_rows,
                "median_period_s": self.holds.median_period_s,
                "max_period_s": self.holds.max_period_s,
            },
            "offset": self.offset.as_dict(),
        }


def _arm(spec: Mapping, base_dir: Path):
    if "dh" in spec:
        path = Path(spec["dh"]).expanduser()
        path = path if path.is_absolute() else base_dir / path
        return load_dh_table(path), f"DH table {path.name}"
    path = Path(spec["urdf"]).expanduser()
    path = path if path.is_absolute() else base_dir / path
    arm = UrdfArm(path, spec["frame"], gravity=spec["gravity"])
    return arm, f"URDF {path.name} frame {spec['frame']!r}"


def build_wrench_reference(
    spec: Mapping,
    columns: Mapping[str, Real[ArrayLike, " n"]],
    t: Real[ArrayLike, " n"],
    *,
    base_dir: PathLike = ".",
    source: str = "log",
) -> WrenchReference:
    """Build the reference of a validated `[data.reference]` table of kind `"wrench"`.

    **Arguments:** `spec` (from [`hdjax.reference.check_reference`][]), `columns` (raw log
    column name -> values, every name in `needed_columns(spec)`), `t` [s], `base_dir` for
    the kinematics file, `source` for messages.

    Steps: detect the wrench's holds and keep the fresh rows only; estimate the offset on
    them; evaluate the Jacobian column, the model torque and $\\tau$ there.

    **Raises:** [`hdjax.DataError`][] / [`hdjax.ConfigError`][] for missing columns, a bad
    kinematics file, non-finite values or an unknown frame.
    """
    import jax.numpy as jnp

    for name in spec["angles"] + spec["wrench"]:
        if name not in columns:
            raise DataError(f"{source}: no column {name!r} for [data.reference]")
    t = np.asarray(t, dtype=np.float64)
    arm, arm_text = _arm(spec, Path(base_dir))
    n_arm = arm.n_joints
    if len(spec["angles"]) != n_arm:
        raise DataError(
            f"{source}: [data.reference] angles names {len(spec['angles'])} columns but the "
            f"{arm_text} has {n_arm} joints"
        )
    scale = np.pi / 180.0 if spec["angle_unit"] == "deg" else 1.0
    q = np.stack([np.asarray(columns[c], np.float64) for c in spec["angles"]], axis=1) * scale
    w = np.stack([np.asarray(columns[c], np.float64) for c in spec["wrench"]], axis=1)
    if not np.all(np.isfinite(q)):
        raise DataError(f"{source}: non-finite joint angles in the [data.reference] columns")
    holds = detect_holds(w, t, source=f"{source} wrench")
    fresh = holds.fresh
    qf, wf, tf = q[fresh], w[fresh], t[fresh]
    joint = spec["joint"] - 1
    dh = isinstance(arm, DHArm)

    # -- the sensor offset, on the fresh readings only --------------------------------------
    if spec["offset"] == "rest":
        offset = offset_from_rest(wf, tf, tuple(spec["rest"]))
    elif spec["offset"] == "fit":
        rot = np.asarray(tool_rotations(arm, jnp.asarray(qf))) if dh else arm.tool_rotation(qf)
        offset = fit_offset_with_payload(wf, rot, spec["gravity"])
    else:
        offset = no_offset()

    # -- the Jacobian column and the model torque at the fresh rows --------------------------
    if dh:
        jc = np.asarray(jacobian_columns(arm, jnp.asarray(qf), joint, frame=spec["wrench_frame"]))
    else:
        jc = arm.jacobian_columns(qf, joint, frame=spec["wrench_frame"])
    model_name = spec["model_torque"]
    if model_name == "none":
        tau_model, model_text = np.zeros(qf.shape[0]), "no model torque"
    elif model_name == "rnea":
        v = np.stack([np.asarray(columns[c], np.float64) for c in spec["velocities"]], axis=1)
        if spec["accelerations"] == "difference":
            a = np.gradient(v, t, axis=0)
        else:
            a = np.stack([np.asarray(columns[c], np.float64) for c in spec["accelerations"]], 1)
        tau_model = arm.rnea(qf, v[fresh], a[fresh])[:, joint]
        model_text = "RNEA over the URDF's inertias"
    else:
        if model_name not in columns:
            raise DataError(f"{source}: no column {model_name!r} for [data.reference] model_torque")
        tau_model = np.asarray(columns[model_name], np.float64)[fresh]
        model_text = f"model torque column {model_name!r}"
    ext = joint_torque(jc, wf, None, sign=spec["wrench_sign"], offset=offset.wrench)
    sign = "+" if spec["wrench_sign"] > 0 else "-"
    j = spec["joint"]
    desc = (
        f"reference from the force/torque sensor: tau_{j} = tau_model {sign} J_{j}(q)^T (W - w0), "
        f"J from the {arm_text} in the {spec['wrench_frame']} frame, "
        f"W = {', '.join(spec['wrench'])}, tau_model = {model_text}; {offset.describe()}; "
        f"{holds.describe()}"
    )
    return WrenchReference(
        model=tau_model,
        external=ext,
        torque=tau_model + ext,
        fresh=fresh,
        holds=holds,
        offset=offset,
        description=desc,
    )
