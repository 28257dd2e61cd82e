r"""Torque feedback from the flexspline bridge against feedback from the encoder twist.

Same controller (eq. (19), Table I gains), same simulated free-link joint, three feedback
sources: the true torque (reference), the strain-gauge bridge of eqs. (5)-(13) with a gauge
misalignment $\Delta\alpha$, and the deformation estimate $K(\hat q_M/N - \hat q_L)$ from two
quantised encoders ([`hdjax.strain.DeformationSensor`][], the linear-stiffness form of the Song
et al. estimate). The link turns during the test, so the wave generator sweeps the gauges and a
misaligned bridge injects its ripple $\Psi\sin(2\beta+\gamma)$ into the loop.

Reported per case: RMS tracking error of the true torque, RMS sensor error (reading minus true
torque), and the amplitude of the $2\beta$ component of the true torque error (the ripple the
loop lets through), each after a 50 ms start-up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..plant import zero_state
from ..strain import (
    AbstractTorqueSensor,
    ControlRun,
    DeformationSensor,
    IdealTorqueSensor,
    StrainGaugeSensor,
    hashimoto_controller,
    simulate_torque_control,
    sine_reference,
)
from ._strain_experiments import SMOOTHING_STICK, paper_joint

DALPHA_DEG = (0.0, 0.5, 1.0, 2.0, 5.0)


class CaseResult(NamedTuple):
    name: str
    run: ControlRun
    rms_tracking: float
    """RMS of $T_d - T_J$ [N·m]."""
    rms_sensor: float
    """RMS of reading minus true torque [N·m]."""
    ripple: float
    """Amplitude of the $\\sin 2\\beta$, $\\cos 2\\beta$ part of $T_d - T_J$ [N·m]."""
    bias: float
    """Mean of $T_d - T_J$ [N·m] (the friction error of eq. (20) while the motor slides)."""


def _metrics(name: str, run: ControlRun, t_skip: float) -> CaseResult:
    keep = np.asarray(run.t) >= t_skip
    err = np.asarray(run.reference - run.torque)[keep]
    sens = np.asarray(run.measured - run.torque)[keep]
    beta = (np.asarray(run.q_m) - np.asarray(run.q_l))[keep]
    t = np.asarray(run.t)[keep]
    cols = np.stack([np.sin(2 * beta), np.cos(2 * beta), np.ones_like(t), t], axis=1)
    coef, *_ = np.linalg.lstsq(cols, err, rcond=None)
    return CaseResult(
        name,
        run,
        float(np.sqrt(np.mean(err**2))),
        float(np.sqrt(np.mean(sens**2))),
        float(math.hypot(coef[0], coef[1])),
        float(np.mean(err)),
    )


class Comparison(NamedTuple):
    cases: tuple[CaseResult, ...]
    dalpha_deg: tuple[float, ...]
    """Misalignments of the strain-gauge cases, in the order they appear in `cases`."""

    def table(self) -> str:
        """A Markdown table of the cases."""
        lines = [
            "| feedback | RMS tracking error [N·m] | mean error [N·m] | RMS sensor error [N·m] "
            "| 2β ripple in T_J [N·m] |",
            "|---|---|---|---|---|",
        ]
        for c in self.cases:
            lines.append(
                f"| {c.name} | {c.rms_tracking:.3f} | {c.bias:.3f} | {c.rms_sensor:.3f} "
                f"| {c.ripple:.3f} |"
            )
        return "\n".join(lines)

    def as_dict(self) -> dict:
        return {
            c.name: {
                "rms_tracking": c.rms_tracking,
                "bias": c.bias,
                "rms_sensor": c.rms_sensor,
                "ripple": c.ripple,
            }
            for c in self.cases
        }


def compare_feedback(
    *,
    dalpha_deg: Sequence[float] = DALPHA_DEG,
    link_speed: float = 1.0,
    amplitude: float = 5.0,
    frequency: float = 20.0,
    duration: float = 0.3,
    deformation: DeformationSensor | None = None,
    hysteresis: bool = False,
    t_skip: float = 0.05,
    smoothing: float = SMOOTHING_STICK,
) -> Comparison:
    r"""Run the comparison of strain-gauge and deformation-based torque feedback.

    **Arguments:**

    - `dalpha_deg`: gauge misalignments $\Delta\alpha$ to try [deg].
    - `link_speed`: initial link speed [rad/s] (the motor turns $N$ times faster, so the
      ripple of a misaligned bridge sits at $2N\omega_L/2\pi$ Hz: 32 Hz at 1 rad/s).
    - `amplitude`, `frequency`, `duration`: the desired torque $A\sin 2\pi f t$ (Fig. 17's
      5 N·m, 20 Hz by default) and the run length [s].
    - `deformation`: the encoder-twist sensor (default: 14-bit motor, 19-bit output encoder,
      $K$ = 8800 N·m/rad).
    - `hysteresis`: switch on the plant's Bouc-Wen hysteresis torque in the flexspline (about
      ±1 N·m at 40 N·m rated), which the bridge feels and the linear twist estimate does not.
    - `t_skip`: start-up left out of the metrics [s].
    - `smoothing`: smooth-sign width of the motor's Coulomb friction [rad/s].

    **Returns:** a [`hdjax.pipelines.Comparison`][].
    """
    joint = paper_joint(
        constrained=False,
        smoothing=smoothing,
        effects={"hysteresis": True} if hysteresis else None,
    )
    ctl = hashimoto_controller(feedback=True, constrained=False)
    ref = sine_reference(amplitude, frequency, duration, ctl.sample_period)
    n = float(ctl.ratio)
    z = zero_state()
    state0 = type(z)(
        z.theta_m,
        z.omega_m + n * link_speed,
        z.theta_l,
        z.omega_l + link_speed,
        z.current,
        z.z,
        z.temperature,
    )
    deformation = DeformationSensor() if deformation is None else deformation

    sensors: list[tuple[str, AbstractTorqueSensor]] = [("ideal (true torque)", IdealTorqueSensor())]
    for d in dalpha_deg:
        sensor = StrainGaugeSensor(dalpha=jnp.asarray(math.radians(d), jnp.float64))
        sensors.append((f"strain gauges, dalpha={d:g} deg", sensor))
    bits = f"{deformation.motor_bits}/{deformation.load_bits}-bit encoders"
    sensors.append((f"deformation K*twist, {bits}", deformation))
    cases = []
    for name, sensor in sensors:
        run = simulate_torque_control(ctl, joint, sensor, ref, state0=state0)
        cases.append(_metrics(name, run, t_skip))
    return Comparison(tuple(cases), tuple(float(d) for d in dalpha_deg))
