r"""The `hdjax.plant` joint seen by the sampled torque loop.

Wraps [`hdjax.plant.rk4_step`][] so that [`hdjax.strain.simulate_torque_control`][] can drive it:
`observe` gives the motor angle $q_M$ (the wave-generator angle), the link angle $q_L$ and the
torque the flexspline transmits, [`hdjax.plant.flexspline_torque`][] — what gauges on the
flexspline's diaphragm feel (hysteresis torque and structural damping included). The
constrained-link condition of the paper ("considering the limit as the inertia becomes
infinite") is imposed exactly, by holding $q_L$ and $\dot q_L$ at their initial values.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float, Real, RealLike, Scalar
from .._errors import ConfigError
from ..plant import PlantParams, PlantState, flexspline_torque, rk4_step, zero_state


class PlantJoint(eqx.Module):
    r"""An `hdjax.plant` joint driven by motor torque, for the torque-control simulations.

    **Arguments:**

    - `params`: [`hdjax.plant.PlantParams`][], e.g. [`hdjax.plant.hashimoto_params`][].
    - `constrained`: immobilise the link ($J_L \to \infty$): $q_L$, $\dot q_L$ stay at 0.
    - `load_torque`: external torque on the link [N·m] (free link only).
    """

    params: object  # a PlantParams, checked in __check_init__ with a ConfigError
    constrained: bool = eqx.field(default=True, static=True)
    load_torque: Scalar = 0.0

    def __check_init__(self):
        if not isinstance(self.params, PlantParams):
            raise ConfigError(
                f"PlantJoint.params must be hdjax.plant.PlantParams, got {type(self.params)}"
            )

    def initial_state(self) -> PlantState:
        return zero_state()

    def observe(
        self, state: PlantState
    ) -> tuple[Float[Array, " ..."], Float[Array, " ..."], Float[Array, " ..."]]:
        return state.theta_m, state.theta_l, flexspline_torque(self.params, state)

    def step(self, state: PlantState, tau_m: RealLike, dt: Real[ArrayLike, ""]) -> PlantState:
        new = rk4_step(self.params, state, tau_m, self.load_torque, dt)
        if self.constrained:
            new = eqx.tree_at(
                lambda s: (s.theta_l, s.omega_l), new, (state.theta_l, jnp.zeros_like(new.omega_l))
            )
        return new

    def stiffness(self) -> Scalar:
        """Largest small-signal joint stiffness $1/\\min k_i$ [N·m/rad] of the flexspline."""
        return float(1.0 / np.min(np.asarray(self.params.compliance)))

    def fastest_rate(self) -> Scalar:
        r"""A bound on the fastest rate of the mechanics [1/s], for the RK4 step.

        The torsional mode $\sqrt{K/(N^2J_M) + K/J_L}$ with the stiffest segment, and the
        friction slopes at the motor ($F_c/\omega_s$, viscous) and structural damping over $J_M$.
        """
        p = self.params
        n, jm, jl = (float(np.asarray(x)) for x in (p.ratio, p.inertia_m, p.inertia_l))
        k = self.stiffness()
        wn = math.sqrt(k / (n**2 * jm) + (0.0 if self.constrained else k / jl))
        slope = float(np.asarray(p.damping)) / n**2
        if p.has("coulomb_m"):
            c = p.effects["coulomb_m"]
            slope += float(np.asarray(c.level)) / float(np.asarray(c.smoothing))
        if p.has("viscous_m"):
            slope += float(np.asarray(p.effects["viscous_m"].coefficient))
        return max(wn, slope / jm)
