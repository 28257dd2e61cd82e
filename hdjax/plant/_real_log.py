r"""What a real robot's log brings that a bench simulation does not: the scenario and the sensors.

**Motion** ([`sweep_drive`][]): slow one-way sweeps from rest under a gravity load, with pauses,
as a robot's joint moves between poses. Before the first sweep the joint makes a short move the
other way and stops, so the recording starts with the joint at rest and its hysteresis state
loaded the other way (the state its last motion left), and that run-in is cut off.

**Sensors** ([`real_log`][]), applied to the noiseless outputs of a simulation sampled finely:

- *timestamps* jitter around the nominal period (uniformly, `jitter` of a period either way) and
  samples drop out (a fraction `drop`, some in bursts): the log is read at its own timestamps;
- *encoder skew*: the load encoder is read `skew` seconds after the motor encoder (negative:
  before);
- *white encoder noise* of `noise_arcsec` on the load angle (the motor angle's noise, divided
  by the ratio, is negligible beside it);
- *quantised multi-turn encoders* of `bits` bits per revolution with unknown offsets (the load
  encoder's offset is not a whole number of counts of the motor's), as integers converted to
  radians in float64;
- a *sample-and-hold reference*: the torque sensor delivers a new value every `hold` samples;
- `twist_sign = -1` joints count both encoders the other way.

The encoders' offsets belong to the joint (`offset_seed`), so a TRAIN and a TEST log of one
joint share them, as two logs of one robot do. The true signals are returned beside the
recording on request (`with_truth`), never inside it: a recording's extras are columns the
residual loop may read.

References: the LARA8 logs of `shared/data/lara8` (2^24-count encoders, about 2 ms of skew,
4 ms steps with jitter, a sensor held for 10 ms); Song et al. 2019, Section IV.B.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Float, PRNGKeyArray
from .._errors import ConfigError
from .._recording import Recording
from ._params import PlantParams
from ._sensors import SensorConfig
from ._simulate import Drive, simulate


def _profile(t, t0, distance, speed, ramp):
    """Position of a move of `distance` [rad] starting at `t0`: speed ramps up over `ramp` s
    (smoothstep), cruises at `speed`, ramps down; returns (theta, omega, alpha) offsets and the
    move's end time."""
    sgn = math.copysign(1.0, distance)
    d = abs(distance)
    if d == 0.0:  # no move (a sweep that starts where the last one ended)
        zero = np.zeros_like(t)
        return zero, zero, zero, t0
    ramp = min(ramp, d / speed)  # a short move never reaches full speed
    cruise = max(0.0, d / speed - ramp)
    dur = cruise + 2.0 * ramp

    def vel(x):  # speed profile of the move at time x from its start
        up = np.clip(x / ramp, 0.0, 1.0)
        down = np.clip((dur - x) / ramp, 0.0, 1.0)
        s = lambda u: u * u * (3.0 - 2.0 * u)
        return speed * np.minimum(s(up), s(down)) * (x >= 0) * (x <= dur)

    x = t - t0
    w = vel(x)
    dt = t[1] - t[0] if t.size > 1 else 1.0
    th = np.cumsum(w) * dt
    th = th * (d / th[-1]) if th[-1] > 0 else th  # exact distance despite the discrete sum
    a = np.gradient(w, dt)
    return sgn * th, sgn * w, sgn * a, t0 + dur


def sweep_drive(
    params: PlantParams,
    *,
    sweeps: tuple[tuple[float, float], ...] = ((-1.2, 1.2),),
    speed: float = 0.3,
    ramp: float = 0.5,
    pause: float = 1.0,
    load: float = 0.6,
    run_in: float = 0.3,
    dt: float = 2.5e-4,
) -> tuple[Drive, float]:
    """One-way sweeps from rest under gravity, with pauses (see the module docstring).

    **Arguments:**

    - `params`: the plant (its rated torque scales the load).
    - `sweeps`: `(from, to)` link angles [rad, from the horizontal]; the joint moves from each
      `to` to the next `from` at the same speed (a repositioning sweep), so every sweep starts
      from rest.
    - `speed` [rad/s], `ramp` [s]: cruise speed and the time to reach it.
    - `pause` [s]: rest before, between and after the sweeps.
    - `load`: the gravity torque at the horizontal, as a fraction of the rated torque.
    - `run_in` [rad]: the move the other way before the first sweep (its end is the
      recording's start time, the second value returned).
    - `dt`: integration step [s].

    **Returns:** `(drive, t_start)`: the [`hdjax.plant.Drive`][] and the time [s] the
    recording should start at (after the run-in and its pause).
    """
    if not sweeps:
        raise ConfigError("sweep_drive: give at least one (from, to) sweep")
    if not (speed > 0 and ramp > 0 and pause >= 0 and dt > 0):
        raise ConfigError("sweep_drive: speed, ramp and dt must be positive, pause non-negative")
    rated = float(np.asarray(params.rated_torque))
    first_dir = math.copysign(1.0, sweeps[0][1] - sweeps[0][0])
    start = sweeps[0][0] + first_dir * abs(run_in)  # the run-in ends at the first sweep's start
    moves = [(start, sweeps[0][0])]
    for i, (a, b) in enumerate(sweeps):
        if i:
            moves.append((sweeps[i - 1][1], a))
        moves.append((a, b))
    total = pause
    for a, b in moves:
        total += abs(b - a) / speed + 2.0 * ramp + pause
    n = int(math.ceil(total / dt)) + 1
    t = np.arange(n) * dt
    theta = np.full(n, start)
    omega = np.zeros(n)
    alpha = np.zeros(n)
    t0 = pause
    t_start = None
    for i, (a, b) in enumerate(moves):
        th, w, al, end = _profile(t, t0, b - a, speed, ramp)
        theta += th
        omega += w
        alpha += al
        t0 = end + pause
        if i == 0:
            t_start = end + 0.5 * pause
    gravity = np.full(n, -load * rated)
    f = lambda x: jnp.asarray(x, jnp.float64)
    return Drive(f(theta), f(omega), f(alpha), f(gravity), f(np.zeros(n))), float(t_start)


@dataclasses.dataclass(frozen=True)
class RealLogSensors:
    """The sensor model of a real robot's log (see the module docstring).

    **Arguments:** `period` (nominal sample period [s]), `jitter` (fraction of a period either
    way), `drop` (fraction of samples lost), `skew` (load-encoder read delay [s], signed),
    `noise_arcsec` (white noise on the load angle), `bits` (encoder counts per revolution =
    2**bits), `hold` (samples a reference value is held), `current_noise` [A],
    `torque_noise` [N·m], `twist_sign` (+1, or -1: the encoders count the other way),
    `offset_seed` (draws the encoders' unknown offsets: the same for every log of one joint).
    """

    period: float = 1e-3
    jitter: float = 0.2
    drop: float = 0.01
    skew: float = 0.0
    noise_arcsec: float = 1.0
    bits: int = 24
    hold: int = 1
    current_noise: float = 0.05
    torque_noise: float = 0.5
    twist_sign: float = 1.0
    offset_seed: int = 0

    def __post_init__(self):
        for name in ("period", "jitter", "drop", "noise_arcsec", "current_noise", "torque_noise"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"RealLogSensors: {name} must be a number >= 0, got {v!r}")
        if not self.period > 0 or not self.jitter < 0.5 or not self.drop < 0.5:
            raise ConfigError(
                "RealLogSensors: period must be positive, jitter below half a period and drop "
                "below one half"
            )
        if not (isinstance(self.hold, int) and self.hold >= 1):
            raise ConfigError(f"RealLogSensors: hold must be an integer >= 1, got {self.hold!r}")
        if not (isinstance(self.bits, int) and 8 <= self.bits <= 32):
            raise ConfigError(
                f"RealLogSensors: bits must be an integer in 8..32, got {self.bits!r}"
            )
        if self.twist_sign not in (1.0, -1.0, 1, -1):
            raise ConfigError("RealLogSensors: twist_sign must be +1 or -1")


def real_log(
    truth: Recording,
    sensors: RealLogSensors,
    *,
    key: PRNGKeyArray,
    t_start: float = 0.0,
    source: str = "real-log plant",
    with_truth: bool = False,
) -> Recording | tuple[Recording, dict[str, Float[np.ndarray, " n"]]]:
    """Read a finely sampled noiseless simulation (`truth`, with `true_*` extras: a
    [`hdjax.plant.simulate`][] run with `truth=True` and noise off) through the sensors of a
    real log, from `t_start` on (see the module docstring).

    **Returns:** an [`hdjax.Recording`][] on the log's own timestamps (starting near 0); with
    `with_truth`, the pair `(recording, truth)`, `truth` the `true_*` signals at the log's
    timestamps (the load angle at the motor encoder's instant).
    """
    for name in ("true_theta_m", "true_theta_l", "true_torque", "true_current"):
        if name not in truth.extras:
            raise ConfigError(
                f"real_log needs the simulation's true signals ({name} missing): simulate with "
                "truth=True"
            )
    seed = int(jax.random.randint(key, (), 0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    tf = np.asarray(truth.t, np.float64)
    p = sensors.period
    n = int((tf[-1] - t_start - 2 * abs(sensors.skew)) / p) - 1
    if n < 10:
        raise ConfigError("real_log: the simulation is too short for the sample period")
    nominal = t_start + abs(sensors.skew) + p * np.arange(n)
    t = nominal + sensors.jitter * p * rng.uniform(-1.0, 1.0, n)
    keep = rng.uniform(size=n) >= sensors.drop
    if sensors.drop > 0:  # a few bursts of lost samples too
        for start in rng.integers(0, n, size=max(1, int(n * sensors.drop / 20))):
            keep[start : start + int(rng.integers(3, 12))] = False
    t = t[keep]
    ex = truth.extras
    at = lambda x, when: np.interp(when, tf, np.asarray(x, np.float64))
    th_m = at(ex["true_theta_m"], t)
    th_l = at(ex["true_theta_l"], t + sensors.skew)
    th_l = th_l + np.deg2rad(sensors.noise_arcsec / 3600.0) * rng.standard_normal(t.size)
    # quantised multi-turn counters with unknown offsets, read as integers
    cpr = 2.0**sensors.bits
    s = float(sensors.twist_sign)
    joint = np.random.default_rng(sensors.offset_seed)
    off_m = int(joint.integers(0, 2**30))
    off_l = int(joint.integers(0, 2**sensors.bits)) + float(joint.uniform())
    c_m = np.floor(s * th_m * cpr / (2 * np.pi)) + off_m
    c_l = np.floor(s * th_l * cpr / (2 * np.pi) + off_l)
    theta_m = c_m * (2 * np.pi / cpr)
    theta_l = c_l * (2 * np.pi / cpr)
    torque = at(ex["true_torque"], t) + sensors.torque_noise * rng.standard_normal(t.size)
    held = (np.arange(t.size) // sensors.hold) * sensors.hold
    torque = torque[held]
    current = at(ex["true_current"], t) + sensors.current_noise * rng.standard_normal(t.size)
    rec = Recording(
        t=jnp.asarray(t - t[0]),
        theta_m=jnp.asarray(theta_m),
        theta_l=jnp.asarray(theta_l),
        current=jnp.asarray(current),
        torque=jnp.asarray(torque),
        extras={},
        source=source,
    )
    if not with_truth:
        return rec
    return rec, {k: at(v, t) for k, v in ex.items() if k.startswith("true_")}


def simulate_real_log(
    params: PlantParams,
    sensors: RealLogSensors,
    *,
    key: PRNGKeyArray,
    dt: float = 2.5e-4,
    with_truth: bool = False,
    **drive: float | tuple[tuple[float, float], ...],
) -> Recording | tuple[Recording, dict[str, Float[np.ndarray, " n"]]]:
    """A one-way-sweep scenario ([`sweep_drive`][], keywords `drive`) simulated at step `dt`
    and read through a real log's sensors ([`real_log`][]).

    **Returns:** the [`hdjax.Recording`][] of the log (with `with_truth`, the pair of
    [`real_log`][]).
    """
    k_sim, k_sense = jax.random.split(key)
    drv, t_start = sweep_drive(params, dt=dt, **drive)
    fine = simulate(
        params,
        drv,
        key=k_sim,
        dt=dt,
        output_period=dt,
        sensors=SensorConfig(noise=False),
        truth=True,
    )
    return real_log(fine, sensors, key=k_sense, t_start=t_start, with_truth=with_truth)
