r"""Closed-loop simulation: controller + plant in `lax.scan`, then sensors, then a `Recording`.

[`hdjax.plant.integrate`][] is the pure, jittable, `vmap`-able core (fixed-step RK4, see
`rk4_step`); [`hdjax.plant.simulate`][] adds the checks that must happen in plain Python before
anything is traced (RK4 stability of the stiffest mode, memory), the sensor models and the
conversion to an [`hdjax.Recording`][].
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _trig
from .._custom_types import Array, ArrayLike, Float, PRNGKeyArray, PyTree, Real
from .._errors import ConfigError, DivergenceError
from .._recording import Recording, make_recording
from ..effects import in_slot
from ._controller import ControllerGains, default_gains
from ._dynamics import (
    PlantState,
    compliance_deflection,
    equilibrium_state,
    flexspline_torque,
    kinematic_error,
    output_friction,
    reciprocals,
    rk4_step,
)
from ._effects import _concrete
from ._params import PlantParams
from ._sensors import SensorConfig

DEFAULT_MEMORY_LIMIT = 2 * 1024**3
"""Default cap [bytes] on the memory a simulation may use (see `estimate_memory`)."""

# RK4 stability limit along the imaginary axis is 2*sqrt(2); along the real axis 2.785.
_RK4_IMAG_LIMIT = 2.0 * math.sqrt(2.0)


class Drive(eqx.Module):
    r"""What the bench does to the joint, one value per integration step (state frame).

    **Arguments:**

    - `theta_ref`, `omega_ref`, `alpha_ref`: commanded link angle [rad], speed, acceleration.
    - `gravity`: $G_k$ [N·m]; the weights add $G_k \cos\theta_l$ to the load torque (link angle
      measured from the horizontal, $G_k = -m g r_k$ for a weight $m$ at arm $r_k$).
    - `external`: a further external torque on the link [N·m] (a hand pushing, Song IV.B).
    """

    theta_ref: Float[Array, " n"]
    omega_ref: Float[Array, " n"]
    alpha_ref: Float[Array, " n"]
    gravity: Float[Array, " n"]
    external: Float[Array, " n"]

    @property
    def n_steps(self) -> int:
        return int(self.theta_ref.shape[-1])


class Outputs(eqx.Module):
    """Noiseless signals at the output samples (state frame).

    **Arguments:**

    - `state`: the [`hdjax.plant.PlantState`][] at each output sample (each leaf of shape `(n,)`).
    - `joint_torque`: the flexspline torque $T_J$ [N·m].
    - `sensor_torque`: what a torque sensor on the output shaft reads, $T_J$ less the output
      friction [N·m].
    - `load`: the external load torque on the link [N·m].
    - `kinematic_error`: the reducer's kinematic error [rad].
    """

    state: PlantState
    joint_torque: Float[Array, " n"]
    sensor_torque: Float[Array, " n"]
    load: Float[Array, " n"]
    kinematic_error: Float[Array, " n"]


def load_torque(drive_k, theta_l):
    """External torque on the link at one step: gravity of the weights plus a push [N·m]."""
    gravity, external = drive_k
    return gravity * _trig.cos(theta_l) + external


def _measure(params: PlantParams, state: PlantState, load, inv) -> Outputs:
    t_j = flexspline_torque(params, state, inv=inv)
    return Outputs(
        state=state,
        joint_torque=t_j,
        sensor_torque=t_j - output_friction(params, state.omega_l, inv=inv),
        load=load,
        kinematic_error=kinematic_error(params, state.theta_m, state.theta_l),
    )


def integrate(
    params: PlantParams,
    gains: ControllerGains,
    state0: PlantState,
    drive: Drive,
    dt: float,
    *,
    stride: int = 1,
    checkpoint: bool = False,
    unroll: int = 1,
) -> tuple[PlantState, Outputs]:
    r"""Run controller and plant over the drive with fixed-step RK4 (pure; jit and vmap freely).

    The outer `lax.scan` runs over output samples, the inner over the `stride` integration steps
    between them. Sample $k$ is the state at $t_k = k\,\text{stride}\,dt$, before stepping.

    **Arguments:**

    - `params`, `gains`, `state0`: plant, controller and initial state.
    - `drive`: a [`hdjax.plant.Drive`][] with `stride * n_out` steps.
    - `dt`: integration step [s].
    - `stride`: integration steps per output sample (static).
    - `checkpoint`: `jax.checkpoint` the output step (long horizons under `grad`).
    - `unroll`: unrolling of the inner scan (speed only).

    **Returns:** `(final_state, outputs)`, outputs an [`Outputs`][] of shape `(n_out,)`.
    """
    n = drive.n_steps
    if n % stride:
        raise ConfigError(f"drive length {n} is not a multiple of the output stride {stride}")
    per_output = jax.tree.map(lambda x: x.reshape(n // stride, stride), drive)
    inv = reciprocals(params)  # once, outside the loop (see `reciprocals`)

    def _step(state, d_k):
        # controller (ZOH over the step), load from the current link angle, one RK4 step
        theta_ref, omega_ref, alpha_ref, gravity, external = d_k
        tau = gains(params.ratio, theta_ref, omega_ref, alpha_ref, state.theta_m, state.omega_m)
        load = load_torque((gravity, external), state.theta_l)
        return rk4_step(params, state, tau, load, dt, inv=inv), None

    def _output(state, d_out):
        # record the state (one stacked write per sample), then step `stride` times;
        # torques are computed from the recorded states after the loop, vectorised
        load = load_torque((d_out[3][0], d_out[4][0]), state.theta_l)
        y = jnp.stack(jax.tree.leaves(state) + [load])
        state, _ = jax.lax.scan(_step, state, d_out, unroll=min(unroll, stride))
        return state, y

    if checkpoint:
        _output = jax.checkpoint(_output)
    xs = (
        per_output.theta_ref,
        per_output.omega_ref,
        per_output.alpha_ref,
        per_output.gravity,
        per_output.external,
    )
    if stride == 1:  # one flat loop (nested scans cost compile time, above all under AD)

        def _flat(state, d_k):
            load = load_torque((d_k[3], d_k[4]), state.theta_l)
            y = jnp.stack(jax.tree.leaves(state) + [load])
            return _step(state, d_k)[0], y

        final, ys = jax.lax.scan(
            jax.checkpoint(_flat) if checkpoint else _flat,
            state0,
            tuple(x[:, 0] for x in xs),
            unroll=unroll,
        )
    else:
        final, ys = jax.lax.scan(_output, state0, xs)
    cols = list(jnp.moveaxis(ys, -1, 0))
    states = jax.tree.unflatten(jax.tree.structure(state0), cols[:-1])
    return final, _measure(params, states, cols[-1], inv)


_integrate_jit = eqx.filter_jit(integrate)


def _initial(params, drive, gains):
    """Closed-loop equilibrium at the start: the PD's static error supplies the holding torque.

    The link rests where the weights' load is held by the joint torque, and the motor angle lags
    the reference by exactly the error the PD needs to command that torque (no start transient).
    """
    th_ref = drive.theta_ref[0]
    th = th_ref
    for _ in range(3):
        load0 = drive.gravity[0] * jnp.cos(th) + drive.external[0]
        st = equilibrium_state(params, theta_l=th, load_torque=load0)
        tau = -load0 / params.ratio  # motor torque holding the load (no friction at rest)
        theta_m_pd = params.ratio * th_ref - tau / gains.kp
        th = th + (theta_m_pd - st.theta_m) / params.ratio
    load0 = drive.gravity[0] * jnp.cos(th) + drive.external[0]
    return equilibrium_state(params, theta_l=th, load_torque=load0)


_initial_jit = eqx.filter_jit(_initial)


def spread_batch(tree: PyTree) -> PyTree:
    r"""Place a batch (leading axis of every array leaf) across the local devices, evenly.

    A `vmap`-ed simulation is one XLA loop; on a CPU that loop runs on one core. When JAX has
    several devices (on CPU: `jax.config.update("jax_num_cpu_devices", n)` before JAX is first
    used, e.g. `n = os.cpu_count()`), splitting the batch over them runs the parts in parallel
    (XLA partitions the `vmap` along the batch axis). With one device, or a batch that does not
    divide evenly, `tree` is returned as it is.
    """
    devices = jax.local_devices()
    leaves = [x for x in jax.tree.leaves(tree) if hasattr(x, "shape") and x.ndim]
    if len(devices) < 2 or not leaves or leaves[0].shape[0] % len(devices):
        return tree
    if any(x.shape[0] != leaves[0].shape[0] for x in leaves):
        return tree
    mesh = jax.sharding.Mesh(np.asarray(devices), ("batch",))
    spec = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))
    return jax.tree.map(lambda x: jax.device_put(x, spec) if getattr(x, "ndim", 0) else x, tree)


@eqx.filter_jit
def _integrate_batch(params, gains, states0, drives, dt, stride, unroll):
    """vmap of `integrate` over drives (and initial states; None: equilibrium at the start)."""

    def run(s0, d):
        s0 = _initial(params, d, gains) if s0 is None else s0
        return integrate(params, gains, s0, d, dt, stride=stride, unroll=unroll)

    if states0 is None:
        return jax.vmap(lambda d: run(None, d))(drives)
    return jax.vmap(run)(states0, drives)


# ---------------------------------------------------------------------------------------------
# Checks before running
# ---------------------------------------------------------------------------------------------


def _rk4_gain(z: complex) -> float:
    return abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)


def _num(x) -> float:
    return float(np.max(np.asarray(_concrete(x))))


def stiffest_modes(params: PlantParams) -> dict[str, complex]:
    r"""Eigenvalues [1/s] of the fastest linearised modes (plain Python, concrete params).

    The joint mode uses the stiffest flexspline segment plus the hysteresis reversal stiffness
    and the cubic stiffening at 1.2 rated torque, with the structural damping; friction gives
    real modes $-F'(0)/J$ on each side.
    """
    n = _num(params.ratio)
    jm, jl = _num(params.inertia_m), _num(params.inertia_l)
    m_inv = 1.0 / jl + 1.0 / (n * n * jm)
    k = 1.0 / float(np.min(np.asarray(_concrete(params.compliance))))
    e = params.effects
    for name in in_slot(e, "compliance_ripple_m") + in_slot(e, "compliance_ripple_l"):
        k /= 1.0 - _num(e[name].max_change())  # a ripple stiffens the joint where it dips
    for name in in_slot(e, "hysteresis"):
        k += _num(e[name].initial_stiffness())
    if "stiffening" in e:
        d = _num(
            compliance_deflection(params, 1.2 * params.rated_torque, jnp.asarray(25.0, jnp.float64))
        )
        k += 3.0 * _num(e["stiffening"].cubic) * d * d
    c = _num(params.damping)
    disc = complex((c * m_inv) ** 2 - 4.0 * k * m_inv)
    lam_joint = (-c * m_inv - disc**0.5) / 2.0

    def slope(slot):
        return sum((_num(e[name].max_slope()) for name in in_slot(e, slot)), 0.0)

    return {
        "joint": lam_joint,
        "motor friction": complex(-slope("motor_friction") / jm),
        "output friction": complex(-slope("output_friction") / jl),
    }


def check_step(params: PlantParams, dt: float) -> None:
    """Raise `ConfigError` when `dt` is outside RK4's stability region for the stiffest mode."""
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ConfigError(f"integration step dt must be a positive number of seconds, got {dt!r}")
    modes = stiffest_modes(params)
    for name, lam in modes.items():
        if _rk4_gain(lam * dt) > 1.0:
            lo, hi = 0.0, dt
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if _rk4_gain(lam * mid) <= 1.0:
                    lo = mid
                else:
                    hi = mid
            raise ConfigError(
                f"integration step dt = {dt:g} s is too large for the {name} mode "
                f"(eigenvalue {lam.real:.4g}{lam.imag:+.4g}j 1/s, "
                f"|lambda*dt| = {abs(lam) * dt:.3g}): fixed-step RK4 is unstable there and would "
                f"return NaN. Use dt <= {0.9 * lo:.3g} s "
                f"(RK4 limit on the imaginary axis |lambda*dt| = {_RK4_IMAG_LIMIT:.3f})."
            )


def estimate_memory(n_steps: int, n_out: int, *, batch: int = 1, truth: bool = True) -> int:
    """Bytes a simulation needs: 5 drive inputs per step, ~12 signals per output, with copies."""
    per_out = (12 if truth else 8) * 8 * 3  # outputs, noisy copies and the NumPy recording
    return int(batch * (n_steps * 5 * 8 * 2 + n_out * per_out))


def check_memory(n_steps: int, n_out: int, *, batch=1, limit=DEFAULT_MEMORY_LIMIT) -> None:
    """Raise `ConfigError` when the simulation would need more than `limit` bytes."""
    need = estimate_memory(n_steps, n_out, batch=batch)
    if need > limit:
        raise ConfigError(
            f"this simulation needs about {need / 2**30:.3g} GiB ({n_steps} integration steps, "
            f"{n_out} output samples) but the memory limit is {limit / 2**30:.3g} GiB; shorten "
            "the duration, raise output_period, or pass memory_limit=... if the machine has the "
            "memory"
        )


# ---------------------------------------------------------------------------------------------
# Sensors and the recording
# ---------------------------------------------------------------------------------------------


@eqx.filter_jit
def _sense(out: Outputs, t, key, motor_q, load_q, i_sigma, i_hold, tq_sigma, temp_q, noise):
    k1, k2 = jax.random.split(key)
    # recorded angles count the other way round (see _dynamics): twist_rec = theta_m/N - theta_l
    th_m, th_l = -out.state.theta_m, -out.state.theta_l
    if noise:
        th_m = jnp.floor(th_m / motor_q) * motor_q
        th_l = jnp.floor(th_l / load_q) * load_q
    # current: a fresh noisy sample every driver period, held in between
    n = t.shape[0]
    idx = (jnp.arange(n) // i_hold) * i_hold
    cur = out.state.current[idx]
    if noise:
        cur = cur + i_sigma * jax.random.normal(k1, (n,), jnp.float64)[idx]
        tq = out.sensor_torque + tq_sigma * jax.random.normal(k2, (n,), jnp.float64)
        temp = out.state.temperature
        temp = jnp.round(temp / temp_q) * temp_q if temp_q > 0 else temp
    else:
        tq, temp = out.sensor_torque, out.state.temperature
    return th_m, th_l, cur, tq, temp


def to_recording(
    params: PlantParams,
    out: Outputs,
    t: Real[ArrayLike, " n"],
    *,
    sensors: SensorConfig,
    key: PRNGKeyArray,
    truth: bool = False,
    theta_ref: Float[Array, " n"] | None = None,
    source: str = "plant",
) -> Recording:
    """Turn noiseless outputs into a recording through the sensor models (plain Python)."""
    out_period = float(t[1] - t[0]) if len(t) > 1 else sensors.current_period
    hold = sensors.current_period / out_period
    i_hold = max(1, int(round(hold)))
    if hold >= 1 and abs(hold - i_hold) > 1e-6:
        raise ConfigError(
            f"the output period {out_period:g} s must divide the current feedback period "
            f"{sensors.current_period:g} s, or be a multiple of it"
        )
    tq_sigma = (
        0.002 * _num(params.rated_torque) if sensors.torque_noise is None else sensors.torque_noise
    )
    th_m, th_l, cur, tq, temp = _sense(
        out,
        jnp.asarray(t),
        key,
        sensors.motor_step(),
        sensors.load_step(),
        float(sensors.current_noise),
        i_hold,
        float(tq_sigma),
        float(sensors.temperature_resolution),
        sensors.noise,
    )
    extras = {}
    if params.has("temperature"):
        extras["temperature"] = temp
    if truth:
        extras.update(
            true_torque=out.sensor_torque,
            true_joint_torque=out.joint_torque,
            true_current=out.state.current,
            true_theta_m=-out.state.theta_m,
            true_theta_l=-out.state.theta_l,
            true_hysteresis=out.state.z,
            true_kinematic_error=out.kinematic_error,
            true_load=-out.load,
            true_temperature=out.state.temperature,
        )
        if theta_ref is not None:
            extras["reference_theta_l"] = -theta_ref
    return make_recording(t, th_m, th_l, cur, tq, extras, source=source, check_units=False)


def _check_finite(out: Outputs, t) -> None:
    bad = np.zeros(len(t), bool)
    for leaf in jax.tree.leaves(out):
        bad |= ~np.isfinite(np.asarray(leaf))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise DivergenceError(
            f"the plant simulation diverged: non-finite state at t = {float(t[k]):.6g} s "
            f"(sample {k}). The step may be too large for the stiffness, or an effect parameter is "
            "extreme (a very small friction smoothing, a huge hysteresis stiffness); reduce dt or "
            "check the parameters"
        )


def simulate(
    params: PlantParams,
    drive: Drive,
    *,
    key: PRNGKeyArray,
    dt: float = 5e-4,
    output_period: float = 5e-4,
    sensors: SensorConfig | None = None,
    gains: ControllerGains | None = None,
    initial_state: PlantState | None = None,
    truth: bool = False,
    memory_limit: int = DEFAULT_MEMORY_LIMIT,
    source: str = "plant",
) -> Recording:
    """Simulate the closed-loop bench over `drive` and return a sensor recording.

    **Arguments:**

    - `params`: [`hdjax.plant.PlantParams`][].
    - `drive`: a [`hdjax.plant.Drive`][] (one entry per integration step).
    - `key`: PRNG key for the sensor noise (keyword-only, no default).
    - `dt`: integration step [s] (default 0.5 ms); checked against RK4's stability limit.
    - `output_period`: sampling period of the recording [s], a multiple of `dt`.
    - `sensors`: [`hdjax.plant.SensorConfig`][] (default: 21-bit encoders, realistic noise).
    - `gains`: controller gains (default `default_gains(params)`).
    - `initial_state`: default: equilibrium holding the first step's load at the first reference.
    - `truth`: add noiseless `true_*` columns to the extras (keep them out of feature sets).
    - `memory_limit`: refuse runs needing more bytes than this.
    - `source`: label of the recording.

    **Returns:** an [`hdjax.Recording`][]: `t`, `theta_m`, `theta_l` (quantised, recorded sign
    convention), `current`, `torque` and extras (`temperature` when that effect is on).
    """
    sensors = SensorConfig() if sensors is None else sensors
    check_step(params, dt)
    stride = output_period / dt
    if not (output_period > 0 and abs(stride - round(stride)) < 1e-9 and round(stride) >= 1):
        raise ConfigError(
            f"output_period {output_period:g} s must be a positive multiple of dt {dt:g} s"
        )
    stride = int(round(stride))
    n_steps = drive.n_steps
    n_out = n_steps // stride
    check_memory(n_steps, n_out, limit=memory_limit)
    drive = jax.tree.map(lambda x: x[: n_out * stride], drive)
    gains = default_gains(params) if gains is None else gains
    if initial_state is None:
        initial_state = _initial_jit(params, drive, gains)
    _, out = _integrate_jit(params, gains, initial_state, drive, dt, stride=stride)
    t = np.arange(n_out) * output_period
    _check_finite(out, t)
    return to_recording(
        params,
        out,
        t,
        sensors=sensors,
        key=key,
        truth=truth,
        theta_ref=drive.theta_ref[::stride] if truth else None,
        source=source,
    )
