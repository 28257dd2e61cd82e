"""Shared pieces of the long-log benchmarks: the machine record and a closed-form joint log.

`joint_log(start, n)` gives samples `start .. start+n` of one endless simulated log, so a file
of any length is written chunk by chunk (the twist follows the paper's model: a five-segment
flexspline, a cubic current term and a first-order kinematic error, with 1 arcsec noise).
"""

from __future__ import annotations

import datetime
import math
import os
import platform
import subprocess

import numpy as np

RATIO, RATED, DT = 160.0, 400.0, 1e-3
ARCSEC = math.pi / 648000.0
K = np.array([0.9, 1.0, 1.2, 1.0, 0.9]) / 6.7e4
KNOTS = np.array([-2, -1, 1, 2]) * RATED / 3
CURRENT_PEAK = 400.0 / (RATIO * 0.1) * 1.25  # the `current_scale` of the model


def machine() -> dict:
    """Where and how a benchmark ran, with the load at the start."""
    import jax

    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except OSError:
        commit = ""
    return {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "load_average_1_5_15": [round(x, 2) for x in os.getloadavg()],
        "precision": "float64",
        "jax": jax.__version__,
        "commit": commit,
    }


def joint_log(start: int, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Samples `start .. start + n` of the endless log (columns t, theta_m, theta_l, current,
    torque), the same for any chunking."""
    i = np.arange(start, start + n, dtype=np.float64)
    t = i * DT
    rng = np.random.default_rng([seed, start])
    torque = (
        300 * np.sin(2 * np.pi * 0.13 * t)
        + 60 * np.sin(2 * np.pi * 0.37 * t + 0.5)
        + 20 * np.sin(2 * np.pi * 1.1 * t)
    )
    theta_l = 1.2 * np.sin(2 * np.pi * t / 20.0) + 0.3 * np.sin(2 * np.pi * 0.21 * t + 1)
    omega_l = 1.2 * 2 * np.pi / 20.0 * np.cos(2 * np.pi * t / 20.0) + 0.3 * 2 * np.pi * 0.21 * (
        np.cos(2 * np.pi * 0.21 * t + 1)
    )
    current = torque / (RATIO * 0.1) + 2.0 * np.tanh(omega_l / 0.05) + 0.05 * rng.standard_normal(n)
    edges = np.r_[-np.inf, KNOTS, np.inf]
    twist = np.zeros(n)
    for j in range(5):
        lo, hi = edges[j], edges[j + 1]
        twist += K[j] * (np.clip(torque, lo, hi) - min(max(0.0, lo), hi))
    x = current / CURRENT_PEAK
    twist += 2e-4 * x + 3e-5 * x**3 + 1e-5 * np.cos(theta_l * omega_l)
    twist += ARCSEC * rng.standard_normal(n)
    theta_m = RATIO * (theta_l - twist)
    return {"t": t, "theta_m": theta_m, "theta_l": theta_l, "current": current, "torque": torque}


def model():
    """The structure calibrated in the benchmarks (the paper's, one shared block)."""
    import hdjax
    from hdjax.compliance import ComplianceModel

    joint = hdjax.Joint(ratio=RATIO, rated_torque=RATED)
    return ComplianceModel.paper(
        joint, poly_order=3, fourier_order=1, per_segment=False, current_scale=CURRENT_PEAK
    )
