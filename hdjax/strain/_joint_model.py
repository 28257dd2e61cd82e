r"""The idealised drive of eqs. (15)-(17): two inertias, a linear spring, Coulomb friction.

$$J_L\ddot q_L = T_J,\qquad NJ_M\ddot q_M + T_J + N\tau_F = N\tau_M,\qquad
T_J = K(q_M/N - q_L),$$

with $\tau_F = F_c\tanh(\dot q_M/\omega_s)$ (a smooth sign, so that gradients exist) and an
optional viscous term $b\,\dot q_M$ at the motor. This is the paper's own model, kept as the
reference that eq. (20) and the pole analysis of [`hdjax.strain.loop_poles`][] describe; the
richer joint of `hdjax.plant` (hysteresis, nonlinear stiffness, wave-generator ripple) is used
through [`hdjax.strain.PlantJoint`][].

**References:** Hashimoto, Kiyosawa & Paul (1993), eqs. (15)-(17), Table I.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike, Float, Real, Scalar
from .._errors import ConfigError
from ._control import TABLE_I


class IdealJoint(eqx.Module):
    r"""The two-inertia drive of eqs. (15)-(17) with smooth Coulomb friction at the motor.

    **Arguments:**

    - `ratio`, `motor_inertia`, `stiffness`, `link_inertia`: $N$, $J_M$, $K$, $J_L$ (Table I);
      `link_inertia=math.inf` immobilises the link (the constrained-link experiments).
    - `coulomb`: Coulomb friction level $F_c$ at the motor [N·m].
    - `smoothing`: $\omega_s$ of the smooth sign [rad/s at the motor].
    - `viscous`: viscous friction at the motor [N·m·s/rad] (0 in the paper's model).

    The state is $(q_M, \dot q_M, q_L, \dot q_L)$.
    """

    ratio: Scalar = TABLE_I["ratio"]
    motor_inertia: Scalar = TABLE_I["motor_inertia"]
    stiffness: Scalar = TABLE_I["stiffness"]
    link_inertia: Scalar = math.inf
    coulomb: Scalar = 0.0
    smoothing: Scalar = 0.05
    viscous: Scalar = 0.0

    def __check_init__(self):
        for name in ("ratio", "motor_inertia", "stiffness", "link_inertia", "smoothing"):
            v = getattr(self, name)
            if isinstance(v, (int, float)) and not v > 0:
                raise ConfigError(f"IdealJoint.{name} must be positive, got {v!r}")
        for name in ("coulomb", "viscous"):
            v = getattr(self, name)
            if isinstance(v, (int, float)) and not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"IdealJoint.{name} must be >= 0, got {v!r}")

    @property
    def constrained(self) -> bool:
        """Whether the link is immobilised (infinite link inertia)."""
        return math.isinf(self.link_inertia)

    def initial_state(self) -> Float[Array, " 4"]:
        return jnp.zeros(4, jnp.float64)

    def observe(
        self, state: Float[Array, " 4"]
    ) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
        """Motor angle, link angle and joint torque $T_J$ (eq. (17))."""
        q_m, _, q_l, _ = state
        return q_m, q_l, self.stiffness * (q_m / self.ratio - q_l)

    def _rhs(self, state, tau_m):
        q_m, w_m, q_l, w_l = state
        torque = self.stiffness * (q_m / self.ratio - q_l)  # eq. (17)
        friction = self.coulomb * jnp.tanh(w_m / self.smoothing) + self.viscous * w_m
        a_m = (tau_m - friction - torque / self.ratio) / self.motor_inertia  # eq. (16) / N
        a_l = torque / self.link_inertia  # eq. (15); 0 when J_L is infinite
        return jnp.stack([w_m, a_m, w_l, a_l])

    def step(
        self, state: Float[Array, " 4"], tau_m: Real[ArrayLike, ""], dt: Real[ArrayLike, ""]
    ) -> Float[Array, " 4"]:
        """One classical Runge-Kutta step of length `dt` under motor torque `tau_m`."""
        k1 = self._rhs(state, tau_m)
        k2 = self._rhs(state + 0.5 * dt * k1, tau_m)
        k3 = self._rhs(state + 0.5 * dt * k2, tau_m)
        k4 = self._rhs(state + dt * k3, tau_m)
        return state + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def fastest_rate(self) -> Scalar:
        """Largest eigenvalue magnitude of the linearised dynamics [1/s] (sets the RK4 step)."""
        wn = math.sqrt(
            self.stiffness / (self.ratio**2 * self.motor_inertia)
            + (0.0 if math.isinf(self.link_inertia) else self.stiffness / self.link_inertia)
        )
        friction_rate = (self.coulomb / self.smoothing + self.viscous) / self.motor_inertia
        return max(wn, friction_rate)
