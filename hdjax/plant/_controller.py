r"""The bench's position controller: PD on the motor angle plus inertia feed-forward.

$\tau_{cmd} = \mathrm{sat}\big(K_p (N\theta_{ref} - \theta_m) + K_d (N\omega_{ref} - \omega_m)
+ J_{ff} N \alpha_{ref}\big)$, run at every integration step (the driver's 0.5 ms period by
default), with $J_{ff} = J_M + J_L/N^2$ the inertia seen at the motor. There is no integral term,
so a gravity load leaves a small static position error, as on a PD-controlled bench; the torque
estimates are not affected. The saturation is the driver's current limit.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float
from .._errors import ConfigError
from ._effects import _concrete
from ._params import PlantParams

_f64 = lambda x: jnp.asarray(x, jnp.float64)


class ControllerGains(eqx.Module):
    """Gains of the PD + feed-forward position controller (motor side).

    **Arguments:**

    - `kp` [N·m/rad], `kd` [N·m·s/rad]: on the motor angle error $N\\theta_{ref} - \\theta_m$.
    - `inertia_ff` [kg·m²]: feed-forward inertia at the motor.
    - `torque_limit` [N·m]: the driver's current limit times $K_t$.
    """

    kp: Float[Array, ""]
    kd: Float[Array, ""]
    inertia_ff: Float[Array, ""]
    torque_limit: Float[Array, ""]

    def __call__(
        self,
        ratio: Float[ArrayLike, ""],
        theta_ref: Float[ArrayLike, " ..."],
        omega_ref: Float[ArrayLike, " ..."],
        alpha_ref: Float[ArrayLike, " ..."],
        theta_m: Float[ArrayLike, " ..."],
        omega_m: Float[ArrayLike, " ..."],
    ) -> Float[Array, " ..."]:
        """Motor torque command [N·m]: PD on the motor angle plus inertia feed-forward, within
        the torque limit."""
        tau = (
            self.kp * (ratio * theta_ref - theta_m)
            + self.kd * (ratio * omega_ref - omega_m)
            + self.inertia_ff * ratio * alpha_ref
        )
        return jnp.clip(tau, -self.torque_limit, self.torque_limit)


def default_gains(
    params: PlantParams,
    *,
    bandwidth: float | None = None,
    damping_ratio: float = 0.7,
    current_limit: float | None = None,
) -> ControllerGains:
    r"""Gains for the bench controller computed once from nominal parameters (plain Python).

    The closed-loop bandwidth defaults to $\min(100, 0.35\,\omega_j)$ rad/s, with
    $\omega_j = \sqrt{K_1 (1/J_L + 1/(N^2 J_M))}$ the joint's first mode, so the loop stays well
    below the flexible mode. The current limit defaults to 2x the current holding the rated
    torque.
    """
    p = {
        k: float(np.asarray(_concrete(getattr(params, k))))
        for k in ("ratio", "rated_torque", "inertia_m", "inertia_l", "torque_constant")
    }
    k1 = float(np.asarray(_concrete(params.compliance))[0])
    n = p["ratio"]
    j_eq = p["inertia_m"] + p["inertia_l"] / n**2
    w_joint = np.sqrt((1.0 / k1) * (1.0 / p["inertia_l"] + 1.0 / (n**2 * p["inertia_m"])))
    wc = min(100.0, 0.35 * w_joint) if bandwidth is None else float(bandwidth)
    if wc <= 0:
        raise ConfigError(f"controller bandwidth must be positive, got {wc}")
    if current_limit is None:
        current_limit = 2.0 * p["rated_torque"] / (n * p["torque_constant"])
    return ControllerGains(
        kp=_f64(j_eq * wc**2),
        kd=_f64(2.0 * damping_ratio * wc * j_eq),
        inertia_ff=_f64(j_eq),
        torque_limit=_f64(current_limit * p["torque_constant"]),
    )
