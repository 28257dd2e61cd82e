r"""Closed-loop poles of the sampled torque loop, and the checks made before a simulation.

Without friction, eq. (18) is a second-order system in the joint torque alone,
$a\ddot T_J + c\,T_J = N\tau_M$ with $a = N^2J_M/K$ and $c = 1 + N^2J_M/J_L$ (the rigid-body
mode of a free link does not show in $T_J$). Held over each period $T_s$ (zero-order hold) and
closed through the sampled law of eq. (19) with a backward-difference rate, the loop is linear
in the state $z_k = (T_k, \dot T_k, T_{k-1}[, u_{k-1}])$; its poles decide stability.

**References:** Hashimoto, Kiyosawa & Paul (1993), eqs. (18)-(19).
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import numpy as np
import scipy.linalg

from .._custom_types import Scalar
from .._errors import ConfigError
from ._control import TorqueController

MIN_SAMPLES_PER_PERIOD = 10
"""Below this many samples per period of the fastest mode, a warning is given."""


class SamplingWarning(UserWarning):
    """The sampling period is long for the fastest mode (fewer than 10 samples a period)."""


class LoopPoles(NamedTuple):
    """Poles of the linear sampled torque loop and of its continuous-time ideal."""

    discrete: np.ndarray
    """Closed-loop poles $z$ of the sampled loop (complex)."""
    continuous_ideal: np.ndarray
    """Roots of $s^2 + K_d s + K_p + c/a$, the continuous loop of eq. (19) (complex) [1/s]."""
    spectral_radius: float
    """$\\max|z|$: the loop is stable when below 1."""
    plant_mode: float
    """Natural frequency of the open-loop torque mode $\\sqrt{c/a}$ [rad/s]."""

    @property
    def stable(self) -> bool:
        return self.spectral_radius < 1.0

    def describe(self) -> str:
        zs = ", ".join(f"{z.real:.4f}{z.imag:+.4f}j (|z|={abs(z):.4f})" for z in self.discrete)
        return f"discrete closed-loop poles: {zs}"


def _zoh(a: Scalar, c: Scalar, ts: Scalar):
    # x = (T, Tdot); a Tddot + c T = u  ->  xdot = A x + B u
    amat = np.array([[0.0, 1.0], [-c / a, 0.0]])
    bmat = np.array([[0.0], [1.0 / a]])
    m = np.zeros((3, 3))
    m[:2, :2] = amat
    m[:2, 2:] = bmat
    e = scipy.linalg.expm(m * ts)
    return e[:2, :2], e[:2, 2:]


def loop_poles(controller: TorqueController) -> LoopPoles:
    r"""Closed-loop poles of the sampled linear torque loop (eqs. (18)-(19), no friction).

    The loop matrix is built from the zero-order-hold discretisation of
    $a\ddot T + cT = N\tau_M$ and the feedback part of eq. (19),
    $N\tau_{M,k} = -a[K_p T_k + K_d (T_k - T_{k-1})/T_s]$ (the reference does not move poles).
    With `delay_samples=1` the command is applied one period late and the state grows by one.

    **Returns:** a [`hdjax.strain.LoopPoles`][].
    """
    ctl = controller
    a, c, ts = ctl.torque_inertia, ctl.static_gain, ctl.sample_period
    ad, bd = _zoh(a, c, ts)
    # u_k = k_T T_k + k_prev T_{k-1}   (u = N tau_M)
    k_t = -a * (ctl.kp + ctl.kd / ts)
    k_prev = a * ctl.kd / ts
    if ctl.delay_samples == 0:
        # z = (T, Tdot, T_prev)
        m = np.zeros((3, 3))
        m[:2, :2] = ad
        m[:2, 0] += bd[:, 0] * k_t
        m[:2, 2] += bd[:, 0] * k_prev
        m[2, 0] = 1.0
    else:
        # z = (T, Tdot, T_prev, u_prev); u_prev is applied during this period
        m = np.zeros((4, 4))
        m[:2, :2] = ad
        m[:2, 3] = bd[:, 0]
        m[2, 0] = 1.0
        m[3, 0] = k_t
        m[3, 2] = k_prev
    z = np.linalg.eigvals(m)
    z = z[np.argsort(-np.abs(z))]
    s = np.roots([1.0, ctl.kd, ctl.kp + c / a]).astype(complex)
    return LoopPoles(
        discrete=z,
        continuous_ideal=s,
        spectral_radius=float(np.max(np.abs(z))),
        plant_mode=math.sqrt(c / a),
    )


def check_loop(controller: TorqueController, *, on_unstable: str = "raise") -> LoopPoles:
    r"""Refuse a sampling period too long for the fastest mode, and unstable gains.

    - If $T_s \ge \pi/\omega_p$, with $\omega_p = \sqrt{c/a}$ the torsional mode of the drive
      (eq. (18); 96.8 rad/s constrained, 139 rad/s free), that mode lies above the Nyquist
      frequency and aliases: raise [`hdjax.ConfigError`][].
    - If fewer than 10 samples fall in one period of that mode, warn
      ([`hdjax.strain.SamplingWarning`][]).
    - If the sampled loop has a pole on or outside the unit circle (outside only, for the open
      loop $K_p = K_d = 0$, whose undamped poles lie on it), raise
      [`hdjax.ConfigError`][] listing the poles (`on_unstable="raise"`), or warn with the same
      message (`"warn"`), or say nothing (`"ignore"`).

    **Returns:** the [`hdjax.strain.LoopPoles`][].
    """
    if on_unstable not in ("raise", "warn", "ignore"):
        raise ConfigError(f"on_unstable must be 'raise', 'warn' or 'ignore', got {on_unstable!r}")
    poles = loop_poles(controller)
    ts = controller.sample_period
    mode = poles.plant_mode
    nyquist = math.pi / mode
    if ts >= nyquist:
        raise ConfigError(
            f"sampling period {ts:g} s is too long: the drive's torsional mode is "
            f"{mode:.1f} rad/s ({mode / (2 * math.pi):.1f} Hz), which needs a period below "
            f"pi/omega = {nyquist:.3g} s (Nyquist) and in practice below "
            f"{2 * math.pi / (MIN_SAMPLES_PER_PERIOD * mode):.3g} s (10 samples a period); "
            "the paper samples at 0.5e-3 s"
        )
    per_period = 2 * math.pi / (mode * ts)
    if per_period < MIN_SAMPLES_PER_PERIOD:
        warnings.warn(
            f"only {per_period:.1f} samples per period of the drive's torsional mode "
            f"({mode:.1f} rad/s) at a sampling period of {ts:g} s; the sampled loop "
            "will differ markedly from the continuous design",
            SamplingWarning,
            stacklevel=2,
        )
    # The open loop of the undamped model (eq. (18)) is marginal, |z| = 1: not the gains' fault.
    marginal_open = controller.is_open_loop and poles.spectral_radius <= 1.0 + 1e-9
    if not poles.stable and not marginal_open and on_unstable != "ignore":
        msg = (
            f"the sampled torque loop is unstable with kp={controller.kp:g}, kd={controller.kd:g},"
            f" sample_period={ts:g} s: {poles.describe()}; spectral radius "
            f"{poles.spectral_radius:.4f} >= 1. Lower kd (the backward-difference rate gain "
            f"a*kd/Ts is the usual culprit) or shorten the sampling period"
        )
        if on_unstable == "raise":
            raise ConfigError(msg)
        warnings.warn(msg, SamplingWarning, stacklevel=2)
    return poles
