r"""A URDF arm through pinocchio: the Jacobian at a named frame and RNEA for the model torque.

pinocchio is an optional dependency (`pip install hdjax[pin]`) imported only when a URDF is
used. The Jacobian is pinocchio's frame Jacobian (linear rows first, as in
[`hdjax.reference.geometric_jacobian`][]) in `LOCAL` (the named frame's axes: `frame="tool"`)
or `LOCAL_WORLD_ALIGNED` (base axes at the frame's origin: `frame="base"`). The model torque
is the recursive Newton-Euler algorithm over the URDF's inertias,
$\tau_\text{model} = M(q)\ddot q + C(q,\dot q)\dot q + g(q)$ (Featherstone 2008, Table 5.1).

References: Carpentier et al., "The Pinocchio C++ library", SII 2019; Featherstone, *Rigid
Body Dynamics Algorithms* (2008), Section 5.3.
"""

from __future__ import annotations

import types
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .._custom_types import ArrayLike, Float, PathLike, Real
from .._errors import ConfigError, did_you_mean
from ._jacobian import FRAMES


def import_pinocchio() -> types.ModuleType:
    """The `pinocchio` module, or a [`hdjax.ConfigError`][] saying how to install it."""
    try:
        import pinocchio
    except ImportError:
        raise ConfigError(
            "a URDF reference needs pinocchio, which is not installed; install the optional "
            "extra with `pip install hdjax[pin]` (package `pin`), or describe the arm by a DH "
            "table instead"
        ) from None
    return pinocchio


class UrdfArm:
    """A fixed-base serial arm from a URDF file, with a named tool (sensor) frame.

    **Arguments:**

    - `path`: the URDF file.
    - `frame`: the name of the frame (link or fixed joint) the wrench is measured in.
    - `gravity`: base-frame gravity [m/s²] for RNEA (default: the URDF convention, $-z$).

    **Raises:** [`hdjax.ConfigError`][] for a missing file, an unknown frame (with the frames the
    URDF has) or joints other than revolute/prismatic.
    """

    def __init__(
        self,
        path: PathLike,
        frame: str,
        *,
        gravity: Real[ArrayLike, " 3"] | Sequence[float] = (0.0, 0.0, -9.80665),
    ) -> None:
        pin = import_pinocchio()
        self.path = Path(path)
        if not self.path.exists():
            raise ConfigError(f"{self.path}: no such URDF file")
        try:
            self.model = pin.buildModelFromUrdf(str(self.path))
        except (RuntimeError, ValueError) as err:
            raise ConfigError(f"{self.path}: not a readable URDF ({err})") from None
        if self.model.nq != self.model.nv:
            raise ConfigError(
                f"{self.path}: only revolute and prismatic joints are supported (nq = "
                f"{self.model.nq}, nv = {self.model.nv}; a continuous joint has two coordinates)"
            )
        names = [f.name for f in self.model.frames]
        if not self.model.existFrame(frame):
            raise ConfigError(
                f"{self.path}: no frame {frame!r}{did_you_mean(frame, names)}; frames: "
                f"{', '.join(names)}"
            )
        self.frame = frame
        self.frame_id = self.model.getFrameId(frame)
        self.model.gravity.linear = np.asarray(gravity, dtype=np.float64)
        self.data = self.model.createData()
        self._pin = pin

    @property
    def n_joints(self) -> int:
        return int(self.model.nv)

    @property
    def joint_names(self) -> list[str]:
        return list(self.model.names)[1:]

    def _q(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=np.float64)
        if q.shape[-1] != self.n_joints:
            raise ConfigError(
                f"{self.path}: the URDF has {self.n_joints} joints "
                f"({', '.join(self.joint_names)}), got {q.shape[-1]} joint angles"
            )
        return q

    def jacobian(
        self, q: Real[ArrayLike, " n_q"], *, frame: str = "tool"
    ) -> Float[np.ndarray, "6 n_v"]:
        """The 6 x n frame Jacobian at `q` (linear rows first), in `"tool"` or `"base"` axes."""
        if frame not in FRAMES:
            raise ConfigError(f"Jacobian frame must be one of {', '.join(FRAMES)}, got {frame!r}")
        pin = self._pin
        ref = (
            pin.ReferenceFrame.LOCAL if frame == "tool" else pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        return np.array(
            pin.computeFrameJacobian(self.model, self.data, self._q(q), self.frame_id, ref)
        )

    def jacobian_columns(
        self, q: Real[ArrayLike, "n_samples n_q"], joint: int, *, frame: str = "tool"
    ) -> Float[np.ndarray, "n_samples 6"]:
        """Column `joint` (0-based) of the Jacobian at every row of `q`: shape (n, 6)."""
        q = self._q(q)
        if not 0 <= joint < self.n_joints:
            raise ConfigError(f"joint index {joint} outside 0..{self.n_joints - 1}")
        return np.stack([self.jacobian(qk, frame=frame)[:, joint] for qk in q])

    def tool_rotation(self, q: Real[ArrayLike, "... n_q"]) -> Float[np.ndarray, "n_samples 3 3"]:
        """The tool frame's base-frame orientation at every row of `q`: shape (n, 3, 3)."""
        pin = self._pin
        out = []
        for qk in self._q(np.atleast_2d(q)):
            pin.framesForwardKinematics(self.model, self.data, qk)
            out.append(np.array(self.data.oMf[self.frame_id].rotation))
        return np.stack(out)

    def rnea(
        self,
        q: Real[ArrayLike, "... n_q"] | Sequence[float],
        v: Real[ArrayLike, "... n_v"] | Sequence[float],
        a: Real[ArrayLike, "... n_v"] | Sequence[float],
    ) -> Float[np.ndarray, "n_samples n_v"]:
        r"""$\tau = M(q)\ddot q + C(q,\dot q)\dot q + g(q)$ at every row: shape (n, n_joints)."""
        pin = self._pin
        q, v, a = (self._q(np.atleast_2d(x)) for x in (q, v, a))
        return np.stack(
            [np.array(pin.rnea(self.model, self.data, qk, vk, ak)) for qk, vk, ak in zip(q, v, a)]
        )
