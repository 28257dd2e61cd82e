r"""The sampled torque loop on a simulated joint: sense, control (eq. (19)), hold, integrate.

Every $T_s$ the sensor is read at the joint's current state, the control law of eq. (19) gives
the motor torque, and the joint is integrated over the period under that held torque in
`substeps` Runge-Kutta steps. The loop is a `lax.scan` over the samples of the reference.

**References:** Hashimoto, Kiyosawa & Paul (1993), Section IV.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Float, Scalar
from .._errors import ConfigError, DivergenceError
from ._bridge_sensor import AbstractTorqueSensor
from ._control import TorqueController, control_law
from ._stability import check_loop


class TorqueReference(NamedTuple):
    """Desired joint torque and its first two derivatives, one value per control sample."""

    t: Float[Array, " n"]
    """Sample times [s]."""
    torque: Float[Array, " n"]
    """$T_d$ [N·m]."""
    rate: Float[Array, " n"]
    r"""$\dot T_d$ [N·m/s]."""
    accel: Float[Array, " n"]
    r"""$\ddot T_d$ [N·m/s²]."""


def _times(duration: Scalar, sample_period: Scalar):
    if not (duration > 0 and sample_period > 0):
        raise ConfigError(
            f"duration and sample_period must be positive, got {duration!r}, {sample_period!r}"
        )
    n = int(round(duration / sample_period))
    if n < 2:
        raise ConfigError(f"duration {duration!r} s holds fewer than 2 samples")
    return jnp.arange(n, dtype=jnp.float64) * sample_period


def step_reference(
    amplitude: Scalar, duration: Scalar, sample_period: Scalar = 0.5e-3, t_step: Scalar = 0.0
) -> TorqueReference:
    """A torque step of `amplitude` [N·m] at `t_step` (derivatives zero: the impulse is left
    out, as a sampled controller cannot apply it). Fig. 16."""
    t = _times(duration, sample_period)
    td = jnp.where(t >= t_step, amplitude, 0.0)
    z = jnp.zeros_like(t)
    return TorqueReference(t, td, z, z)


def sine_reference(
    amplitude: Scalar, frequency: Scalar, duration: Scalar, sample_period: Scalar = 0.5e-3
) -> TorqueReference:
    """$T_d = A\\sin(2\\pi f t)$ with exact derivatives (Fig. 17: 5 N·m, 20 Hz)."""
    t = _times(duration, sample_period)
    w = 2 * math.pi * frequency
    return TorqueReference(
        t,
        amplitude * jnp.sin(w * t),
        amplitude * w * jnp.cos(w * t),
        -amplitude * w**2 * jnp.sin(w * t),
    )


def triangle_reference(
    amplitude: Scalar, period: Scalar, cycles: Scalar, sample_period: Scalar = 0.5e-3
) -> TorqueReference:
    """A slow triangle $0 \\to A \\to -A \\to 0$, repeated, for the static characteristic
    (Fig. 15). Derivatives are the exact slope and zero."""
    t = _times(cycles * period, sample_period)
    phase = jnp.mod(t / period + 0.25, 1.0)  # 0 at the trough ... starts at 0 rising
    tri = 4.0 * jnp.abs(phase - 0.5) - 1.0  # +1 at phase 0, -1 at 0.5
    slope = jnp.where(phase < 0.5, -4.0, 4.0) * amplitude / period
    return TorqueReference(t, -amplitude * tri, -slope, jnp.zeros_like(t))


class ControlRun(NamedTuple):
    """Signals of a simulated torque-control run, one value per control sample."""

    t: Float[Array, " n"]
    reference: Float[Array, " n"]
    """$T_d$ [N·m]."""
    torque: Float[Array, " n"]
    """True transmitted joint torque at the sampling instant [N·m]."""
    measured: Float[Array, " n"]
    """Sensor reading used by the controller [N·m]."""
    motor_torque: Float[Array, " n"]
    r"""Motor torque $\tau_M$ applied over the following period [N·m]."""
    q_m: Float[Array, " n"]
    q_l: Float[Array, " n"]


@eqx.filter_jit
def _run(controller, joint, sensor, reference, state0, substeps):
    dt = controller.sample_period / substeps

    def _step(carry, ref_k):
        state, meas_prev, u_prev = carry
        td, dtd, ddtd = ref_k
        # sense
        q_m, q_l, torque = joint.observe(state)
        meas = sensor.read(torque, q_m, q_l)
        # control, eq. (19)
        u = control_law(controller, td, dtd, ddtd, meas, meas_prev)
        u_apply = u if controller.delay_samples == 0 else u_prev
        # hold the command over the period and integrate the joint
        state = jax.lax.fori_loop(0, substeps, lambda _, s: joint.step(s, u_apply, dt), state)
        return (state, meas, u), (torque, meas, u_apply, q_m, q_l)

    q_m0, q_l0, torque0 = joint.observe(state0)
    meas0 = sensor.read(torque0, q_m0, q_l0)
    carry0 = (state0, meas0, jnp.zeros((), jnp.float64))
    xs = (reference.torque, reference.rate, reference.accel)
    _, ys = jax.lax.scan(_step, carry0, xs)
    return ys


def simulate_torque_control(
    controller: TorqueController,
    joint,
    sensor: AbstractTorqueSensor,
    reference: TorqueReference,
    *,
    substeps: int | None = None,
    state0=None,
    on_unstable: str = "raise",
) -> ControlRun:
    r"""Run the sampled torque loop of eq. (19) on a simulated joint.

    **Arguments:**

    - `controller`: the [`hdjax.strain.TorqueController`][] (its `sample_period` must match the
      reference's sample spacing).
    - `joint`: the simulated drive: an object with `initial_state()`, `observe(state) -> (q_m,
      q_l, torque)` and `step(state, motor_torque, dt)`, such as
      [`hdjax.strain.IdealJoint`][] or [`hdjax.strain.PlantJoint`][].
    - `sensor`: the torque feedback, an [`hdjax.strain.AbstractTorqueSensor`][] (the strain
      gauge bridge, the deformation estimate, or the ideal sensor).
    - `reference`: a [`hdjax.strain.TorqueReference`][].
    - `substeps`: Runge-Kutta steps per sampling period; by default enough to keep
      $|\lambda|\,dt \le 0.5$ for the joint's fastest rate (if it reports one), at least 4.
    - `state0`: initial joint state (default: `joint.initial_state()`).
    - `on_unstable`: what to do when the linear sampled loop has poles outside the unit circle
      (`"raise"`, `"warn"`, `"ignore"`); see [`hdjax.strain.check_loop`][], which also refuses
      a sampling period too long for the fastest mode.

    **Returns:** a [`hdjax.strain.ControlRun`][]. Raises [`hdjax.DivergenceError`][] if the
    simulated torque becomes non-finite.
    """
    check_loop(controller, on_unstable=on_unstable)
    ref_dt = float(reference.t[1] - reference.t[0])
    if not math.isclose(ref_dt, controller.sample_period, rel_tol=1e-9):
        raise ConfigError(
            f"the reference is sampled every {ref_dt:g} s but the controller every "
            f"{controller.sample_period:g} s; build the reference with "
            f"sample_period={controller.sample_period:g}"
        )
    if substeps is None:
        rate = float(joint.fastest_rate()) if hasattr(joint, "fastest_rate") else 0.0
        substeps = max(4, math.ceil(rate * controller.sample_period / 0.5))
    if not isinstance(substeps, int) or substeps < 1:
        raise ConfigError(f"substeps must be a positive int, got {substeps!r}")
    if state0 is None:
        state0 = joint.initial_state()
    # Python floats would be static under filter_jit (one compile per gain or inertia); as
    # float64 arrays they are traced, and the loop compiles once per sensor type and length.
    to_array = lambda tree: jax.tree.map(
        lambda x: jnp.asarray(x, jnp.float64) if isinstance(x, (bool, float)) else x, tree
    )
    torque, meas, u, q_m, q_l = _run(
        to_array(controller), to_array(joint), to_array(sensor), reference, state0, substeps
    )
    if not np.all(np.isfinite(np.asarray(torque))):
        raise DivergenceError(
            "the simulated joint torque became non-finite; the loop is unstable or the joint "
            "needs more substeps per sampling period"
        )
    return ControlRun(reference.t, reference.torque, torque, meas, u, q_m, q_l)
