r"""Fitting plant parameters to a recording by gradient (optax) or least squares (optimistix).

The model is the closed-loop simulation of [`hdjax.plant.integrate`][] driven by the same bench
[`hdjax.plant.Drive`][] as the recording (the commanded trajectory and the loads are what the
experimenter controls). Residuals compare the simulated and the recorded sensor signals, each
scaled to a typical size: torque by the rated torque, current by the current at rated torque,
twist by the twist at a third of rated torque, and the link angle by 10 mrad.

Selected parameters are fitted in log coordinates, $p = p_0 e^{u}$, so they stay positive and are
equally scaled. Long horizons are cut into windows with the state carried across but its
gradient stopped at each boundary (truncated back-propagation), so gradients do not grow with the
horizon while the simulation itself stays one continuous run.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from .._custom_types import Array, Float
from .._errors import ConfigError
from .._recording import Recording
from .._solution import RESULTS, Solution
from ._controller import ControllerGains
from ._dynamics import PlantState
from ._effects import _concrete
from ._params import PlantParams
from ._simulate import Drive, _initial, check_step, integrate


def _parse(path: str):
    """'compliance[0]' -> ('compliance', 0); 'effects.coulomb_l.level' -> (..., None)."""
    if path.endswith("]") and "[" in path:
        head, idx = path[:-1].split("[", 1)
        try:
            return head, int(idx)
        except ValueError:
            raise ConfigError(f"bad index in parameter name {path!r}") from None
    return path, None


def _getter(path: str):
    head, idx = _parse(path)
    parts = head.split(".")

    def get(p):
        x = p
        for part in parts:
            x = x[part] if isinstance(x, dict) else getattr(x, part)
        return x if idx is None else x[idx]

    return get


def _check_names(params: PlantParams, names) -> None:
    if not names:
        raise ConfigError("fit_plant needs at least one parameter name to fit")
    for name in names:
        try:
            value = _getter(name)(params)
        except (AttributeError, KeyError, TypeError, IndexError):
            raise ConfigError(
                f"cannot fit {name!r}: no such plant parameter. Use a field of PlantParams "
                "('compliance', 'compliance[0]', 'damping', 'inertia_l', ...) or "
                "'effects.<effect>.<parameter>' for a switched-on effect (on: "
                f"{', '.join(params.effect_names) or 'none'})"
            ) from None
        arr = _concrete(value)
        if arr is None or not np.all(arr > 0):
            raise ConfigError(
                f"cannot fit {name!r}: it is fitted in log coordinates and must start positive, "
                f"got {arr}"
            )


def _with_values(params, names, values):
    for name, value in zip(names, values):
        head, idx = _parse(name)
        whole = _getter(head)
        new = value if idx is None else whole(params).at[idx].set(value)
        params = eqx.tree_at(whole, params, new)
    return params


def simulate_signals(
    params: PlantParams,
    gains: ControllerGains,
    drive: Drive,
    dt: float,
    *,
    window: int | None = None,
    state0: PlantState | None = None,
) -> tuple[Float[Array, " n"], Float[Array, " n"], Float[Array, " n"], Float[Array, " n"]]:
    """Noiseless recorded-frame signals (torque, current, twist, theta_l) over the drive.

    With `window`, the state's gradient is stopped every `window` steps (truncated
    back-propagation through time).
    """
    s0 = _initial(params, drive, gains) if state0 is None else state0
    n = drive.n_steps
    if window is None or window >= n:
        _, out = integrate(params, gains, s0, drive, dt)
    else:
        if n % window:
            raise ConfigError(f"window {window} must divide the number of steps {n}")
        chunks = jax.tree.map(lambda x: x.reshape(n // window, window), drive)

        def _window(state, d):
            state = jax.lax.stop_gradient(state)
            state, out = integrate(params, gains, state, Drive(*d), dt, checkpoint=True)
            return state, out

        xs = (chunks.theta_ref, chunks.omega_ref, chunks.alpha_ref, chunks.gravity, chunks.external)
        _, out = jax.lax.scan(_window, s0, xs)
        out = jax.tree.map(lambda x: x.reshape(-1), out)
    twist = out.state.theta_m / params.ratio - out.state.theta_l
    return out.sensor_torque, out.state.current, twist, -out.state.theta_l


def _scales(params: PlantParams):
    rated = params.rated_torque
    return (
        rated,
        rated / (params.ratio * params.torque_constant),
        params.compliance[0] * rated / 3.0,
        jnp.asarray(0.01, jnp.float64),
    )


def _targets(recording: Recording, ratio):
    if recording.torque is None:
        raise ConfigError("fit_plant needs a recording with a 'torque' column")
    twist = recording.theta_l - recording.theta_m / ratio
    return recording.torque, recording.current, twist, recording.theta_l


def fit_plant(
    params: PlantParams,
    recording: Recording,
    drive: Drive,
    names: Sequence[str],
    *,
    gains: ControllerGains,
    dt: float = 5e-4,
    method: str = "lm",
    steps: int = 200,
    learning_rate: float = 0.05,
    window: int | None = None,
    state0: PlantState | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-8,
) -> Solution:
    r"""Fit the named plant parameters so the simulated bench matches the recording.

    **Arguments:**

    - `params`: starting parameters (also fixes every parameter not named).
    - `recording`: a recording sampled at every integration step (`output_period == dt`).
    - `drive`: the bench drive that produced it (see `scenario_drive`).
    - `gains`: the bench controller's gains (known on a real bench; `simulate` and the scenarios
      use `default_gains(params)` of the simulated plant). Keyword-only, no default: gains
      derived from the *starting* parameters would differ from the bench's and bias the fit.
    - `names`: parameter paths: `"compliance"`, `"damping"`, `"inertia_l"`,
      `"effects.coulomb_l.level"`, ...
    - `dt`: integration step [s].
    - `method`: `"lm"` (optimistix Levenberg-Marquardt on the residual vector) or `"adam"`
      (optax Adam on the mean squared residual, `steps` iterations at `learning_rate`).
    - `window`: truncate gradients every `window` steps (long horizons).
    - `state0`: initial state (default: equilibrium at the start, as `simulate` uses).
    - `rtol`, `atol`: Levenberg-Marquardt tolerances.

    **Returns:** an [`hdjax.Solution`][] whose `value` is the fitted
    [`hdjax.plant.PlantParams`][]; `stats` holds `names` (the fitted parameter paths),
    `values` (their fitted values, one array per name), `loss` (final mean squared scaled
    residual), `steps` and `fit_time_s`. The result is `RESULTS.max_steps_reached` when
    Levenberg-Marquardt stopped at `steps` before its tolerance.
    """
    t0 = time.perf_counter()
    names = tuple(names)
    _check_names(params, names)
    check_step(params, dt)
    n = drive.n_steps
    if recording.n_samples != n:
        raise ConfigError(
            f"the recording has {recording.n_samples} samples but the drive {n} steps; fit_plant "
            "needs one sample per integration step (simulate with output_period == dt)"
        )
    if method not in ("lm", "adam"):
        raise ConfigError(f"method must be 'lm' or 'adam', got {method!r}")
    getters = [_getter(nm) for nm in names]
    base = [jnp.asarray(g(params), jnp.float64) for g in getters]
    targets = _targets(recording, params.ratio)
    scales = _scales(params)

    def residuals(u, _):
        p = _with_values(params, names, [b * jnp.exp(ui) for b, ui in zip(base, u)])
        sim = simulate_signals(p, gains, drive, dt, window=window, state0=state0)
        return jnp.concatenate([(s - y) / c for s, y, c in zip(sim, targets, scales)])

    u0 = [jnp.zeros_like(b) for b in base]
    if method == "lm":
        solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
        sol = optx.least_squares(residuals, solver, u0, max_steps=steps, throw=False)
        u = sol.value
        n_steps = int(sol.stats["num_steps"])
        result = RESULTS.successful if sol.result == optx.RESULTS.successful else None
    else:
        opt = optax.adam(learning_rate)
        loss_fn = lambda u: jnp.mean(residuals(u, None) ** 2)

        @eqx.filter_jit
        def update(u, state):
            loss, grad = jax.value_and_grad(loss_fn)(u)
            upd, state = opt.update(grad, state, u)
            return optax.apply_updates(u, upd), state, loss

        # optax's bias correction mixes its int32 step count with floats; allow that even
        # under strict dtype promotion (the test suite's setting)
        with jax.numpy_dtype_promotion("standard"):
            u, state = u0, opt.init(u0)
            for _ in range(steps):
                u, state, _ = update(u, state)
        n_steps = steps
        result = RESULTS.successful
    values = tuple(b * jnp.exp(ui) for b, ui in zip(base, u))
    fitted = _with_values(params, names, values)
    loss = jnp.mean(residuals(u, None) ** 2)
    stats = dict(
        names=names, values=values, loss=loss, steps=n_steps, fit_time_s=time.perf_counter() - t0
    )
    return Solution(fitted, RESULTS.max_steps_reached if result is None else result, stats)
