"""Recordings for the residual-loop tests.

`synthetic_recording` builds a joint whose twist is exactly the paper's model (five segments,
current polynomial) plus chosen effects, quantised by 21-bit encoders, with sensor noise: fast,
and the truth is known in closed form. The plant-based cases live in `test_discover_plant.py`.
"""

import math

import numpy as np

import hdjax
from hdjax.compliance import dahl_state

RATIO, RATED = 160.0, 400.0
JOINT = hdjax.Joint(ratio=RATIO, rated_torque=RATED)
ARCSEC = math.pi / (180 * 3600)


def _hinge(torque):
    k = np.array([0.9, 1.0, 1.2, 1.0, 0.9]) / 6.7e4
    edges = np.r_[-np.inf, np.array([-2, -1, 1, 2]) * RATED / 3, np.inf]
    out = np.zeros_like(torque)
    for j in range(5):
        lo, hi = edges[j], edges[j + 1]
        out += k[j] * (np.clip(torque, lo, hi) - min(max(0.0, lo), hi))
    return out


def synthetic_recording(seed: int, effects=(), n: int = 20000, dt: float = 2e-3):
    """A recording of `n` samples with the named effects in its twist.

    Effects: `("harmonic_m", order, amplitude_rad)`, `("coulomb_l", level_rad, speed)`,
    `("hysteresis", amplitude_rad, torque_scale)`, `("temperature", relative_change)`,
    `("backlash", amplitude_rad, width)`.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    theta_l = 1.2 * np.sin(2 * math.pi * t / 20.0) + 0.3 * np.sin(2 * math.pi * 0.21 * t + 1)
    torque = (
        300 * np.sin(2 * math.pi * 0.13 * t + seed)
        + 60 * np.sin(2 * math.pi * 0.37 * t)
        + 20 * np.sin(2 * math.pi * 1.1 * t)
    )
    current = torque / (RATIO * 0.1)
    base = _hinge(torque) + 2e-4 * (current / 25) + 3e-5 * (current / 25) ** 3
    extras = {}
    omega_l = np.gradient(theta_l, t)
    twist = base.copy()
    for _ in range(4):  # harmonics of the *recorded* motor angle: iterate to consistency
        theta_m = RATIO * (theta_l - twist)
        twist = base.copy()
        for eff in effects:
            name = eff[0]
            if name == "harmonic_m":
                twist += eff[2] * np.sin(eff[1] * theta_m + 0.4)
            elif name == "coulomb_l":
                twist += eff[1] * np.tanh(omega_l / eff[2])
            elif name == "hysteresis":
                twist += eff[1] * np.asarray(dahl_state(torque, eff[2]))
            elif name == "backlash":
                twist += eff[1] * np.tanh(torque / eff[2])
            elif name == "temperature":
                temp = 25 + 10 * t / t[-1] + 0.05 * rng.standard_normal(n)
                twist += (twist - twist.mean()) * 0 + _hinge(torque) * eff[1] * (temp - 25) / 10
                extras["temperature"] = temp
    twist += 1.5e-6 * rng.standard_normal(n)
    theta_m = RATIO * (theta_l - twist)
    q = 2 * math.pi / 2**21
    return hdjax.make_recording(
        t,
        np.round(theta_m / q) * q,
        np.round(theta_l / q) * q,
        current + 0.05 * rng.standard_normal(n),
        torque + 0.5 * rng.standard_normal(n),
        extras,
        source=f"synthetic:{seed}",
    )
