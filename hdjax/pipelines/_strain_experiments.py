r"""The paper's torque-control experiments on the simulated joint (Figs. 15-17, eq. (20)).

Each function runs the sampled loop of eq. (19) on the Table I joint of `hdjax.plant`
(constrained link unless told otherwise) and returns its signals with the numbers the paper
quotes: the half-width of the static hysteresis loop (Fig. 15), the steady-state error and
10-90 % rise time of a step (Fig. 16), the tracking error of a 5 N·m, 20 Hz sine (Fig. 17).

Friction: the paper's model has Coulomb friction $\tau_F$ at the motor and no damping
(eqs. (15)-(16)). Its open-loop hysteresis of ±4 N·m (Fig. 15) is $N\tau_F$ = 4 N·m, i.e.
$\tau_F$ = 0.04 N·m; the plant's smooth sign is narrowed to $\omega_s$ = 1e-3 rad/s so that the
motor sticks instead of creeping (the plant preset's 0.2 rad/s acts as a viscous damper of
0.2 N·m·s/rad near rest and lets an open-loop step creep to the target within a second).

**References:** Hashimoto, Kiyosawa & Paul (1993), Section IV, Figs. 15-17.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .._errors import ConfigError
from ..plant import hashimoto_params, with_effects
from ..strain import (
    RATED_TORQUE_PAPER,
    AbstractTorqueSensor,
    ControlRun,
    IdealTorqueSensor,
    PlantJoint,
    TorqueController,
    TorqueReference,
    hashimoto_controller,
    simulate_torque_control,
    sine_reference,
    step_reference,
    triangle_reference,
)

FRICTION_PAPER = 0.04
"""Motor Coulomb friction $\\tau_F$ [N·m] giving the ±4 N·m open-loop hysteresis (Fig. 15)."""
SMOOTHING_STICK = 1e-3
"""Smooth-sign width [rad/s] at which the simulated motor sticks (see the module docstring)."""


def paper_joint(
    *,
    constrained: bool = True,
    friction: float = FRICTION_PAPER,
    smoothing: float = SMOOTHING_STICK,
    effects: dict | None = None,
) -> PlantJoint:
    r"""The Table I joint of [`hdjax.plant.hashimoto_params`][] for the control experiments.

    **Arguments:**

    - `constrained`: immobilised link (the paper's experiments) or free link.
    - `friction`: motor Coulomb friction $\tau_F$ [N·m].
    - `smoothing`: its smooth-sign width $\omega_s$ [rad/s].
    - `effects`: further plant effects (e.g. `{"hysteresis": True}`).
    """
    if not (friction >= 0 and smoothing > 0):
        raise ConfigError(
            f"friction must be >= 0 and smoothing > 0, got {friction!r}, {smoothing!r}"
        )
    params = with_effects(hashimoto_params(), coulomb_m={"level": friction, "smoothing": smoothing})
    if effects:
        params = with_effects(params, effects)
    return PlantJoint(params, constrained=constrained)


class TorqueLoop(NamedTuple):
    """One of the paper's torque loops (eq. (19), Table I gains), which the experiments of
    Figs. 15-17 drive.

    **Fields:**

    - `feedback`: close the loop on the measured torque (`True`) or run it open (`False`).
    - `joint`: the simulated joint (default [`hdjax.pipelines.paper_joint`][]`()`).
    - `sensor`: what the loop reads (default the true torque, `IdealTorqueSensor`).
    """

    feedback: bool
    joint: PlantJoint | None = None
    sensor: AbstractTorqueSensor | None = None

    def run(
        self, reference: Callable[[float], TorqueReference]
    ) -> tuple[TorqueController, TorqueReference, ControlRun]:
        """The loop's controller, the desired torque `reference(sample_period)` and the
        simulated run (eqs. (15)-(19))."""
        joint = paper_joint() if self.joint is None else self.joint
        sensor = IdealTorqueSensor() if self.sensor is None else self.sensor
        ctl = hashimoto_controller(feedback=self.feedback, constrained=joint.constrained)
        ref = reference(ctl.sample_period)
        return ctl, ref, simulate_torque_control(ctl, joint, sensor, ref)


def _checked(loop) -> TorqueLoop:
    """`loop` when it is a [`TorqueLoop`][], else a `ConfigError` that says what to pass."""
    if not isinstance(loop, TorqueLoop):
        raise ConfigError(
            f"the experiment's first argument is the loop it drives, a TorqueLoop such as "
            f"TorqueLoop(feedback=True) or TorqueLoop(False, joint, sensor); got {loop!r}"
        )
    return loop


# ---------------------------------------------------------------------------------------------
# Fig. 15: static characteristic
# ---------------------------------------------------------------------------------------------


class StaticResult(NamedTuple):
    run: ControlRun
    half_width: float
    """Half-width of the hysteresis loop [N·m]: half the gap between the rising and falling
    branches (median torque error over each branch, |T_d| < 75 % of the amplitude)."""
    half_width_pct: float
    """The same in % of the rated torque (40 N·m)."""


def static_characteristic(
    loop: TorqueLoop, *, amplitude: float = 20.0, period: float = 2.0, cycles: float = 1.25
) -> StaticResult:
    """A slow triangle of desired torque, Fig. 15: joint torque against desired torque.

    **Arguments:** `loop` (the [`TorqueLoop`][] driven), `amplitude` [N·m], `period` [s] and
    number of `cycles` of the triangle.
    """
    _, ref, run = _checked(loop).run(lambda ts: triangle_reference(amplitude, period, cycles, ts))
    err = np.asarray(run.reference - run.torque)
    rate = np.asarray(ref.rate)
    settled = np.asarray(ref.t) > 0.25 * period  # past the first rise from rest
    inner = np.abs(np.asarray(ref.torque)) < 0.75 * amplitude
    up = np.median(err[settled & inner & (rate > 0)])
    down = np.median(err[settled & inner & (rate < 0)])
    half = 0.5 * float(up - down)
    return StaticResult(run, half, 100.0 * half / RATED_TORQUE_PAPER)


# ---------------------------------------------------------------------------------------------
# Fig. 16: step response
# ---------------------------------------------------------------------------------------------


class StepResponse(NamedTuple):
    run: ControlRun
    steady_state_error_pct: float
    """$(T_d - T_J)/T_d$ in %, $T_J$ averaged over the last 20 ms."""
    rise_time: float
    """10-90 % rise time [s] to the final value (linear interpolation between samples)."""
    overshoot_pct: float
    """Peak over the final value, in % of the final value."""


def _crossing(t, y, level):
    i = int(np.argmax(y >= level))
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (level - y[i - 1]) / (y[i] - y[i - 1]) * (t[i] - t[i - 1]))


def step_response(
    loop: TorqueLoop, *, amplitude: float = 5.0, duration: float = 0.2, t_step: float = 0.01
) -> StepResponse:
    """A torque step, Fig. 16 (the paper does not print the step size; 5 N·m as in Fig. 17).

    **Arguments:** `loop` (the [`TorqueLoop`][] driven), the step's `amplitude` [N·m], the
    run's `duration` [s] and the step's time `t_step` [s].
    """
    ctl, _, run = _checked(loop).run(lambda ts: step_reference(amplitude, duration, ts, t_step))
    t = np.asarray(run.t)
    y = np.asarray(run.torque)
    n_tail = max(1, int(round(0.02 / ctl.sample_period)))
    final = float(np.mean(y[-n_tail:]))
    err_pct = 100.0 * (amplitude - final) / amplitude
    if abs(final) > 1e-9:
        post = (t >= t_step) & (t <= t_step + 0.1)  # the first motion from rest
        rise = _crossing(t[post], y[post] / final, 0.9) - _crossing(t[post], y[post] / final, 0.1)
        over = 100.0 * (float(np.max(y)) - final) / abs(final)
    else:
        rise, over = math.nan, math.nan
    return StepResponse(run, err_pct, rise, over)


# ---------------------------------------------------------------------------------------------
# Fig. 17: sine tracking
# ---------------------------------------------------------------------------------------------


class SineResult(NamedTuple):
    run: ControlRun
    rms_error: float
    """RMS of $T_d - T_J$ after the first 50 ms [N·m]."""
    gain: float
    """Amplitude of $T_J$ at the drive frequency over the desired amplitude."""
    phase_deg: float
    """Phase of $T_J$ relative to $T_d$ at the drive frequency [deg] (negative: lag)."""


def fit_sine(t, y, frequency):
    """Amplitude and phase [rad] of the `frequency` component of `y`, by least squares."""
    w = 2 * math.pi * frequency
    cols = np.stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)], axis=1)
    (s, c, _), *_ = np.linalg.lstsq(cols, y, rcond=None)
    return math.hypot(s, c), math.atan2(c, s)


def sine_tracking(
    loop: TorqueLoop, *, amplitude: float = 5.0, frequency: float = 20.0, duration: float = 0.3
) -> SineResult:
    """Tracking of $A\\sin 2\\pi f t$, Fig. 17 (5 N·m, 20 Hz).

    **Arguments:** `loop` (the [`TorqueLoop`][] driven), the sine's `amplitude` [N·m] and
    `frequency` [Hz], the run's `duration` [s].
    """
    _, _, run = _checked(loop).run(lambda ts: sine_reference(amplitude, frequency, duration, ts))
    t = np.asarray(run.t)
    keep = t >= 0.05
    err = np.asarray(run.reference - run.torque)[keep]
    amp, ph = fit_sine(t[keep], np.asarray(run.torque)[keep], frequency)
    return SineResult(run, float(np.sqrt(np.mean(err**2))), amp / amplitude, math.degrees(ph))


def open_loop_error_friction(
    error_fraction: float, amplitude: float, ratio: float = 100.0
) -> float:
    r"""Motor Coulomb friction $\tau_F$ that leaves an open-loop step with a given error.

    In the undamped model of eqs. (15)-(18) with $\dot T_J$ starting from rest, the first
    half-oscillation of an open-loop step $T_d$ ends at $2(T_d - N\tau_F)$, where the motor
    sticks if $N\tau_F \le T_d \le 3N\tau_F$; the error is then $(2N\tau_F - T_d)/T_d$. An error
    fraction $e$ needs $N\tau_F = (1 + e)T_d/2$: $e$ = 0.7 at $T_d$ = 5 N·m needs
    $N\tau_F$ = 4.25 N·m, next to the 4 N·m of the ±4 N·m open-loop hysteresis of Fig. 15.

    **Returns:** $\tau_F$ [N·m at the motor].
    """
    if not 0 <= error_fraction < 1:
        raise ConfigError(f"error_fraction must be in [0, 1), got {error_fraction!r}")
    return 0.5 * (1.0 + error_fraction) * amplitude / ratio
