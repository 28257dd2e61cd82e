r"""The geometric Jacobian of a DH arm, in the base frame or in the tool (sensor) frame.

For revolute joint $i$ turning about the unit axis $z_i$ through the point $o_i$ (both in the
base frame, from [`hdjax.reference.forward_kinematics`][]), the column of the geometric
Jacobian at the tool point $p$ is (Spong et al. 2006, eq. (4.63))

$$J_i = \begin{bmatrix} z_i \times (p - o_i) \\ z_i \end{bmatrix},$$

linear rows first, so $\begin{bmatrix}v\\ \omega\end{bmatrix} = J\dot q$ and, by the
principle of virtual work, a wrench $W = [F; M]$ acting at $p$ gives the joint torques
$\tau = J^\top W$ (eq. (4.110)). $W$ and $J$ must be expressed in the same frame:

- `frame="base"`: base-frame axes at the tool point (pinocchio's `LOCAL_WORLD_ALIGNED`);
- `frame="tool"`: the tool frame's axes at the tool point (pinocchio's `LOCAL`),
  $J_{\text{tool}} = \operatorname{diag}(R^\top, R^\top)\,J_{\text{base}}$ with $R$ the tool's
  base-frame orientation. A force/torque sensor reports its wrench in this frame.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike, Float
from .._errors import ConfigError
from ._dh import DHArm, forward_kinematics

FRAMES = ("tool", "base")


def _check_frame(frame: str) -> None:
    if frame not in FRAMES:
        raise ConfigError(f"Jacobian frame must be one of {', '.join(FRAMES)}, got {frame!r}")


def _angles(arm: DHArm, q) -> Float[Array, "n_samples n_joints"]:
    """`q` as float64 of shape `(n_samples, n_joints)`, or a ConfigError saying what it is."""
    q = jnp.asarray(q, jnp.float64)
    if q.ndim != 2 or q.shape[1] != arm.n_joints:
        raise ConfigError(
            f"joint angles must have shape (n_samples, {arm.n_joints}), got {tuple(q.shape)}"
        )
    return q


def geometric_jacobian(
    arm: DHArm, q: Float[ArrayLike, " n_joints"], *, frame: str = "tool"
) -> Float[Array, "6 n_joints"]:
    r"""The $6\times n$ geometric Jacobian of `arm` at `q` (module docstring), float64.

    **Arguments:** `arm`, joint angles `q` [rad], `frame` (`"tool"` or `"base"`).
    """
    _check_frame(frame)
    axes, tool = forward_kinematics(arm, q)
    p = tool[:3, 3]
    z = axes[:, :3, 2]
    o = axes[:, :3, 3]
    lin = jnp.cross(z, p[None, :] - o)
    jac = jnp.concatenate([lin, z], axis=1).T
    if frame == "tool":
        rt = tool[:3, :3].T
        jac = jnp.concatenate([rt @ jac[:3], rt @ jac[3:]], axis=0)
    return jac


@jax.jit
def _columns_tool(arm, q, joint):
    return jax.vmap(lambda qk: geometric_jacobian(arm, qk, frame="tool")[:, joint])(q)


@jax.jit
def _columns_base(arm, q, joint):
    return jax.vmap(lambda qk: geometric_jacobian(arm, qk, frame="base")[:, joint])(q)


def jacobian_columns(
    arm: DHArm, q: Float[ArrayLike, " ..."], joint: int, *, frame: str = "tool"
) -> Float[Array, "n_samples 6"]:
    """Column `joint` (0-based) of the Jacobian at every sample of `q`, one jitted call."""
    _check_frame(frame)
    q = _angles(arm, q)
    if not 0 <= joint < arm.n_joints:
        raise ConfigError(f"joint index {joint} outside 0..{arm.n_joints - 1}")
    fn = _columns_tool if frame == "tool" else _columns_base
    return fn(arm, q, jnp.asarray(joint))


@jax.jit
def _rotations(arm, q):
    return jax.vmap(lambda qk: forward_kinematics(arm, qk)[1][:3, :3])(q)


def tool_rotations(arm: DHArm, q: Float[ArrayLike, " ..."]) -> Float[Array, "n_samples 3 3"]:
    """The tool frame's base-frame orientation $R$ at every sample of `q`."""
    q = _angles(arm, q)
    return _rotations(arm, q)


@jax.jit
def _all_tool(arm, q):
    return jax.vmap(lambda qk: geometric_jacobian(arm, qk, frame="tool"))(q)


@jax.jit
def _all_base(arm, q):
    return jax.vmap(lambda qk: geometric_jacobian(arm, qk, frame="base"))(q)


def jacobians(
    arm: DHArm, q: Float[ArrayLike, " ..."], *, frame: str = "tool"
) -> Float[Array, "n_samples 6 n_joints"]:
    """The whole Jacobian at every sample of `q`, one jitted call."""
    _check_frame(frame)
    q = _angles(arm, q)
    return (_all_tool if frame == "tool" else _all_base)(arm, q)
