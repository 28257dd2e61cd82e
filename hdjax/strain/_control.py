r"""Joint torque control, feedforward plus torque feedback: Hashimoto et al. (1993), eqs. (15)-(20).

The drive is the two-inertia model of eqs. (15)-(17) (link inertia $J_L$, rotor inertia $J_M$,
joint stiffness $K$, ratio $N$, Coulomb friction $\tau_F$ at the motor), whose joint torque
$T_J = K(q_M/N - q_L)$ obeys eq. (18):

$$N\tau_M = N^2 J_M K^{-1}\ddot T_J + T_J + N\tau_F + N^2 J_M J_L^{-1} T_J.$$

The control law of eq. (19) inverts this model and closes a PD loop on the torque error:

$$N\tau_M = N^2 J_M K^{-1}\{\ddot T_d + K_d(\dot T_d - \dot T_J) + K_p(T_d - T_J)\} +
T_d(1 + N^2 J_M J_L^{-1}),$$

so that the error $e = T_d - T_J$ obeys
$N^2 J_M K^{-1}(\ddot e + K_d\dot e + K_p e) + (1 + N^2J_MJ_L^{-1})e = N\tau_F$ and settles at
the eq. (20) value. Here it is run as the paper's DSP ran it: sampled every $T_s$ = 0.5 ms, the
torque rate $\dot T_J$ taken as the backward difference of two sensor readings, the motor torque
held over the period.

**References:** Hashimoto, Kiyosawa & Paul (1993), Section IV and Table I.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, Float, RealLike, Scalar
from .._errors import ConfigError

# Table I and Section IV of the paper.
TABLE_I = {
    "link_inertia": 0.88,  # J_L [kg m^2]
    "motor_inertia": 0.000094,  # J_M [kg m^2]
    "stiffness": 8800.0,  # K [N m / rad]
    "torque_constant": 0.1,  # K_t [N m / V]
    "ratio": 100.0,  # N
}
KP_PAPER = 46808.0
"""$K_p$ [1/s²] selected for the 0.5 ms sampling period (Sec. IV)."""
KD_PAPER = 234.0
"""$K_d$ [1/s] selected for the 0.5 ms sampling period (Sec. IV; printed "234 s")."""
SAMPLE_PERIOD_PAPER = 0.5e-3
"""Sampling period of the torque servo [s]."""
RATED_TORQUE_PAPER = 40.0
"""Rated torque of the paper's 49 mm harmonic drive [N·m] (Sec. III-B)."""


def _positive(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    if math.isnan(value) or value <= 0:
        raise ConfigError(f"{name} must be positive, got {value!r}")


def _nonnegative(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value) or value < 0:
        raise ConfigError(f"{name} must be a non-negative finite number, got {value!r}")


class TorqueController(eqx.Module):
    r"""The discrete-time joint torque controller of eq. (19).

    **Arguments:**

    - `kp`: proportional gain $K_p$ [1/s²] (paper: 46808). Zero with `kd` zero gives the
      open-loop (feedforward-only) controller of Figs. 15(a)-17(a).
    - `kd`: derivative gain $K_d$ [1/s] (paper: 234).
    - `sample_period`: $T_s$ [s] (paper: 0.5e-3).
    - `ratio`: $N$.
    - `motor_inertia`: $J_M$ [kg·m²] used by the model inversion.
    - `stiffness`: $K$ [N·m/rad] used by the model inversion.
    - `link_inertia`: $J_L$ [kg·m²]; `math.inf` for the constrained (immobilised) link, "the
      limit as the inertia becomes infinite" (Sec. IV).
    - `motor_torque_limit`: saturation of $\tau_M$ [N·m], or `None` for none. The paper does not
      give one; with $K_t$ = 0.1 N·m/V a ±10 V command would be 1 N·m.
    - `delay_samples`: 0 (the command computed from sample $k$ is applied at once) or 1 (one
      period of computation delay).
    - `accel_feedforward`: keep the $N^2J_MK^{-1}\ddot T_d$ term of eq. (19). The open-loop
      runs drop it (`hashimoto_controller(feedback=False)`): the paper's open loop commands the
      motor torque $T_d(1 + N^2J_M/J_L)/N$ from the desired torque alone, and only that reading
      explains its "very poor" 20 Hz response (Fig. 17(a)).

    Raises [`hdjax.ConfigError`][] for negative gains or non-positive physical constants.
    """

    kp: Scalar = KP_PAPER
    kd: Scalar = KD_PAPER
    sample_period: Scalar = SAMPLE_PERIOD_PAPER
    ratio: Scalar = TABLE_I["ratio"]
    motor_inertia: Scalar = TABLE_I["motor_inertia"]
    stiffness: Scalar = TABLE_I["stiffness"]
    link_inertia: Scalar = math.inf
    motor_torque_limit: Scalar | None = None
    delay_samples: int = eqx.field(default=0, static=True)
    accel_feedforward: bool = True

    def __check_init__(self):
        _nonnegative("TorqueController.kp", self.kp)
        _nonnegative("TorqueController.kd", self.kd)
        for name in ("sample_period", "ratio", "motor_inertia", "stiffness", "link_inertia"):
            _positive(f"TorqueController.{name}", getattr(self, name))
        if self.motor_torque_limit is not None:
            _positive("TorqueController.motor_torque_limit", self.motor_torque_limit)
        if self.delay_samples not in (0, 1):
            raise ConfigError(f"delay_samples must be 0 or 1, got {self.delay_samples!r}")

    @property
    def torque_inertia(self) -> Scalar:
        r"""$a = N^2 J_M / K$ [s²], the coefficient of $\ddot T_J$ in eq. (18)."""
        return self.ratio**2 * self.motor_inertia / self.stiffness

    @property
    def static_gain(self) -> Scalar:
        r"""$c = 1 + N^2 J_M / J_L$, the coefficient of $T_J$ in eq. (18) (1 when constrained)."""
        return 1.0 + self.ratio**2 * self.motor_inertia / self.link_inertia

    @property
    def is_open_loop(self) -> bool:
        return self.kp == 0 and self.kd == 0


def hashimoto_controller(
    *, feedback: bool = True, constrained: bool = True, **overrides
) -> TorqueController:
    r"""The paper's controller: Table I, $K_p$ = 46808, $K_d$ = 234, 0.5 ms sampling.

    **Arguments:**

    - `feedback`: `False` sets $K_p = K_d = 0$ and drops the $\ddot T_d$ feedforward (open
      loop: the motor torque follows the desired torque statically).
    - `constrained`: `True` for the immobilised link of the experiments ($J_L \to \infty$),
      `False` for the free link with $J_L$ = 0.88 kg·m².
    - `overrides`: any other [`hdjax.strain.TorqueController`][] field.
    """
    fields = dict(
        kp=KP_PAPER if feedback else 0.0,
        kd=KD_PAPER if feedback else 0.0,
        sample_period=SAMPLE_PERIOD_PAPER,
        ratio=TABLE_I["ratio"],
        motor_inertia=TABLE_I["motor_inertia"],
        stiffness=TABLE_I["stiffness"],
        link_inertia=math.inf if constrained else TABLE_I["link_inertia"],
        accel_feedforward=feedback,
    )
    fields.update(overrides)
    return TorqueController(**fields)


def control_law(
    controller: TorqueController,
    t_d: RealLike,
    dt_d: RealLike,
    ddt_d: RealLike,
    t_meas: RealLike,
    t_meas_prev: RealLike,
) -> Float[Array, ""]:
    r"""Motor torque $\tau_M$ commanded by eq. (19) at one sampling instant.

    $\dot T_J$ is the backward difference $(T_k - T_{k-1})/T_s$ of the sensed torque, as a
    sampled controller must form it; $\dot T_d$, $\ddot T_d$ come from the reference.

    **Arguments:**

    - `controller`: the [`hdjax.strain.TorqueController`][].
    - `t_d`, `dt_d`, `ddt_d`: desired torque and its first two derivatives at the sample.
    - `t_meas`, `t_meas_prev`: sensed joint torque at this and the previous sample [N·m].

    **Returns:** $\tau_M$ [N·m] (motor side), saturated if `motor_torque_limit` is set.
    """
    c = controller
    rate = (t_meas - t_meas_prev) / c.sample_period
    # a weight rather than a branch, so open and closed loop share one compiled loop
    ff = jnp.asarray(c.accel_feedforward, jnp.float64)
    inner = ff * ddt_d + c.kd * (dt_d - rate) + c.kp * (t_d - t_meas)
    n_tau = c.torque_inertia * inner + c.static_gain * t_d
    tau_m = n_tau / c.ratio
    if c.motor_torque_limit is not None:
        tau_m = jnp.clip(tau_m, -c.motor_torque_limit, c.motor_torque_limit)
    return tau_m


def steady_state_error(controller: TorqueController, friction: Scalar) -> Scalar:
    r"""Steady-state torque error from Coulomb friction, eq. (20).

    $$E_T = \frac{N\tau_F}{N^2 J_M K^{-1} K_p + 1 + N^2 J_M J_L^{-1}}.$$

    For the open loop ($K_p = 0$) this is $N\tau_F/(1 + N^2J_M/J_L)$: with a constrained link,
    the whole friction torque reflected through the gear. It is the largest error at which the
    motor can stick: the error at rest lies in $[-E_T, E_T]$, its sign set by the direction of the
    last motion.

    **Arguments:**

    - `controller`: the [`hdjax.strain.TorqueController`][].
    - `friction`: Coulomb friction $\tau_F$ at the motor [N·m].

    **Returns:** $E_T$ [N·m].
    """
    _nonnegative("friction", friction)
    c = controller
    return c.ratio * friction / (c.torque_inertia * c.kp + c.static_gain)
