r"""The four load experiments of Song et al. (2019), Section IV.B, as named scenarios.

- `slow`: the joint follows a sinusoidal trajectory while weights hang at the link end, at arm
  lengths changed once per period, so the gravity load changes slowly (their Fig. 9). The link
  swings ±80° about the vertical, so the load takes both signs, up to 0.95 of the rated torque.
- `fast`: the link is held horizontal, without weights, and pushed by hand in both directions
  irregularly (their Fig. 10): low-pass filtered noise (2nd order, 1.5 Hz) softly limited (tanh)
  at 0.95 of the rated torque; its 99th percentile is about 0.75 of the rated torque.
- `sudden`: the link is held horizontal with weights giving 0.8 of the rated torque, and the rope
  is cut at half the duration: the load vanishes at one instant (their Fig. 11).
- `static`: the link is held horizontal and the rope is moved outward in six steps (each moved
  over 0.5 s or 30 % of a hold, then held), from 0.16 to 0.95 of the rated torque (their
  Fig. 12).

All loads scale with `params.rated_torque`, so the same scenarios run on the Hashimoto preset.
"""

from __future__ import annotations

import inspect
import math
import types
from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import PRNGKeyArray
from .._errors import ConfigError, did_you_mean
from .._lazy import scipy_signal
from .._recording import Recording
from ._controller import default_gains
from ._effects import _concrete
from ._params import PlantParams, song_params, with_effects
from ._sensors import SensorConfig
from ._simulate import (
    DEFAULT_MEMORY_LIMIT,
    Drive,
    _check_finite,
    _integrate_batch,
    check_memory,
    check_step,
    simulate,
    spread_batch,
    to_recording,
)

SCENARIOS = ("slow", "fast", "sudden", "static")
"""Names of the Song et al. Section IV.B experiments."""


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _hold(n, theta=0.0):
    z = np.zeros(n)
    return z + theta, z, z.copy()


def scenario_drive(
    name: str, params: PlantParams, *, duration: float, dt: float, key: PRNGKeyArray
) -> Drive:
    """The bench's commanded trajectory and loads for one named scenario (see module docs).

    **Arguments:**

    - `name`: one of `SCENARIOS`.
    - `params`: the plant (its `rated_torque` scales the loads).
    - `duration`: length [s]; `dt`: integration step [s].
    - `key`: PRNG key (used by `fast`), keyword-only.

    **Returns:** a [`hdjax.plant.Drive`][].
    """
    _check_name(name)
    rated = float(np.asarray(_concrete(params.rated_torque)))
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    gravity = np.zeros(n)
    external = np.zeros(n)
    if name == "slow":
        theta, omega, alpha, gravity = _swing(t, rated, amplitude=1.4, period=20.0, rope_time=2.0)
    elif name == "fast":
        theta, omega, alpha = _hold(n)
        seed = int(jax.random.randint(key, (), 0, 2**31 - 1))
        white = np.random.default_rng(seed).standard_normal(n)
        signal = scipy_signal()
        b, a = signal.butter(2, 1.5, fs=1.0 / dt)
        push = signal.lfilter(b, a, white)
        push = push - push[0]
        push = push * _smoothstep(t / 0.5)
        # scale the 99th percentile of |push| to the rated torque, then limit softly at 0.95
        # rated (the 99th percentile of the load ends near 0.75 rated)
        level = np.percentile(np.abs(push), 99)
        push = rated * push / (level if level > 0 else 1.0)
        external = 0.95 * rated * np.tanh(push / (0.95 * rated))
    elif name == "sudden":
        theta, omega, alpha = _hold(n)
        gravity = np.where(t < 0.5 * duration, -0.8 * rated, 0.0)
    else:  # static
        theta, omega, alpha = _hold(n)
        n_pos = 6
        hold = duration / n_pos
        k = np.minimum(np.floor(t / hold), n_pos - 1)
        ramp = min(0.5, 0.3 * hold)
        frac = (k + 1 + _smoothstep((t - k * hold) / ramp) * (k > 0) - (k > 0)) / n_pos
        gravity = -0.95 * rated * frac
    f = lambda x: jnp.asarray(x, jnp.float64)
    return Drive(f(theta), f(omega), f(alpha), f(gravity), f(external))


def _swing(t, rated: float, *, amplitude: float, period: float, rope_time: float):
    # the link follows pi/2 - A cos(w t); the arm length cycles 0.5, 0.75, 1.0 of the longest,
    # the rope moved over `rope_time` at the start of each period (while the load is at its
    # largest, as when re-hanging weights)
    w = 2.0 * math.pi / period
    theta = math.pi / 2 - amplitude * np.cos(w * t)
    omega = amplitude * w * np.sin(w * t)
    alpha = amplitude * w * w * np.cos(w * t)
    arms = np.array([0.5, 0.75, 1.0])
    k = np.floor(t / period).astype(int)
    frac = arms[k % 3]
    prev = arms[(k - 1) % 3]
    blend = _smoothstep((t - k * period) / rope_time)
    arm = np.where(k == 0, frac, prev + (frac - prev) * blend)
    return theta, omega, alpha, -0.95 * rated * arm


def swing_drive(
    params: PlantParams,
    *,
    amplitude: float,
    period: float,
    duration: float,
    dt: float,
    rope_time: float = 2.0,
) -> Drive:
    r"""The `slow` scenario's drive with a swing of its own.

    The link follows $\pi/2 - A\cos(2\pi t/P)$ under weights at arm lengths that change once
    per period (0.5, 0.75, 1.0 of the longest, loads up to 0.95 of the rated torque), so the
    gravity load is a smooth function of the output angle times a slowly changing arm; `slow`
    is $A$ = 1.4 rad, $P$ = 20 s.

    **Arguments:** `params` (its `rated_torque` scales the loads), `amplitude` $A$ [rad],
    `period` $P$ [s], `duration` [s], `dt` the integration step [s], `rope_time` the time [s]
    over which the arm changes at the start of each period.

    **Returns:** a [`hdjax.plant.Drive`][].
    """
    rated = float(np.asarray(_concrete(params.rated_torque)))
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    theta, omega, alpha, gravity = _swing(
        t, rated, amplitude=amplitude, period=period, rope_time=rope_time
    )
    f = lambda x: jnp.asarray(x, jnp.float64)
    return Drive(f(theta), f(omega), f(alpha), f(gravity), f(np.zeros(n)))


def _check_name(name):
    if name not in SCENARIOS:
        raise ConfigError(
            f"unknown scenario {name!r}{did_you_mean(name, SCENARIOS)}; known scenarios: "
            f"{', '.join(SCENARIOS)}"
        )


def _prepare(names, params, effects, duration, dt) -> PlantParams:
    """Checks shared by the single and batched runs; the plant with its effects applied."""
    for name in names:
        _check_name(name)
    params = song_params() if params is None else params
    if effects:
        params = with_effects(params, effects)
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise ConfigError(
            f"scenario duration must be a positive number of seconds, got {duration!r}"
        )
    check_step(params, dt)
    return params


def simulate_scenario(
    name: str,
    *,
    key: PRNGKeyArray,
    duration: float = 60.0,
    effects: Mapping | None = None,
    params: PlantParams | None = None,
    dt: float = 5e-4,
    output_period: float = 5e-4,
    sensors: SensorConfig | None = None,
    truth: bool = False,
    memory_limit: int = DEFAULT_MEMORY_LIMIT,
) -> Recording:
    """Simulate one of Song et al.'s four experiments (Section IV.B) and return the recording.

    **Arguments:**

    - `name`: `"slow"`, `"fast"`, `"sudden"` or `"static"`.
    - `key`: PRNG key (load noise of `fast`, sensor noise), keyword-only, no default.
    - `duration`: length [s] (default 60 s as the paper's runs).
    - `effects`: effects to switch on, off (`None`) or re-parametrise (see `with_effects`).
    - `params`: the plant (default `song_params()`; `hashimoto_params()` works too).
    - `dt`, `output_period`, `sensors`, `truth`, `memory_limit`: see `simulate`.

    **Returns:** an [`hdjax.Recording`][] with `source` set to `"scenario:<name>"`.
    """
    params = _prepare((name,), params, effects, duration, dt)
    n_steps = int(round(duration / dt))
    if n_steps < 4:
        raise ConfigError(f"duration {duration} s gives only {n_steps} steps of {dt} s")
    check_memory(n_steps, n_steps // max(1, int(round(output_period / dt))), limit=memory_limit)
    # same key use as `simulate_scenarios`, so a batch member equals its single run
    drive = scenario_drive(name, params, duration=duration, dt=dt, key=jax.random.fold_in(key, 0))
    return simulate(
        params,
        drive,
        key=jax.random.fold_in(key, 1),
        dt=dt,
        output_period=output_period,
        sensors=sensors,
        truth=truth,
        memory_limit=memory_limit,
        source=f"scenario:{name}",
    )


def _scenario_options(options: dict) -> types.SimpleNamespace:
    """`simulate_scenario`'s keywords with its defaults filled in (its signature is the one list
    of them); a keyword it does not take is a `TypeError`, as in a call."""
    try:
        bound = inspect.signature(simulate_scenario).bind("", key=None, **options)
    except TypeError as err:
        raise TypeError(f"simulate_scenarios: {err} (it takes simulate_scenario's)") from None
    bound.apply_defaults()
    return types.SimpleNamespace(**bound.arguments)


def simulate_scenarios(
    names: Sequence[str] = SCENARIOS, *, key: PRNGKeyArray, **options
) -> dict[str, Recording]:
    """Several scenarios at once, run as one `vmap`-ed batch (one compilation, one loop).

    Takes the keyword arguments of [`hdjax.plant.simulate_scenario`][] (`duration`, `effects`,
    `params`, `dt`, `output_period`, `sensors`, `truth`, `memory_limit`, with the same
    defaults), with `names` a sequence of scenario names; scenario `j` gets the key
    `jax.random.split(key, len(names))[j]` and the same recording as
    `simulate_scenario(names[j], key=that_key, ...)`.

    **Returns:** a dict name -> [`hdjax.Recording`][].
    """
    names = tuple(names)
    o = _scenario_options(options)
    params = _prepare(names, o.params, o.effects, o.duration, o.dt)
    stride = o.output_period / o.dt
    if not (abs(stride - round(stride)) < 1e-9 and round(stride) >= 1):
        raise ConfigError(
            f"output_period {o.output_period:g} s must be a positive multiple of dt {o.dt:g} s"
        )
    stride = int(round(stride))
    n_steps = int(round(o.duration / o.dt))
    n_out = n_steps // stride
    check_memory(n_steps, n_out, batch=len(names), limit=o.memory_limit)
    keys = jax.random.split(key, len(names))
    drives = []
    for name, k in zip(names, keys):
        k0 = jax.random.fold_in(k, 0)
        d = scenario_drive(name, params, duration=o.duration, dt=o.dt, key=k0)
        drives.append(jax.tree.map(lambda x: x[: n_out * stride], d))
    stack = lambda xs: jax.tree.map(lambda *a: jnp.stack(a), *xs)
    drives_b = spread_batch(stack(drives))  # over the local devices, when there are several
    _, outs = _integrate_batch(params, default_gains(params), None, drives_b, o.dt, stride, 1)
    t = np.arange(n_out) * o.output_period
    sensors = SensorConfig() if o.sensors is None else o.sensors
    result = {}
    for j, (name, k) in enumerate(zip(names, keys)):
        out = jax.tree.map(lambda x: x[j], outs)
        _check_finite(out, t)
        result[name] = to_recording(
            params,
            out,
            t,
            sensors=sensors,
            key=jax.random.fold_in(k, 1),
            truth=o.truth,
            theta_ref=drives[j].theta_ref[::stride] if o.truth else None,
            source=f"scenario:{name}",
        )
    return result
