"""Benchmark: the sampled torque loop of eq. (19) on the Table I joint (hdjax.strain).

Times `simulate_torque_control` (lax.scan over 0.5 ms samples, RK4 substeps inside) for a 1 s
closed-loop sine run with the strain-gauge sensor in the loop, compile apart from steady state
(min of timeit.repeat, block_until_ready), against a NumPy reference of the same loop (the
paper's idealised joint of eqs. (15)-(17), same substeps, same sensor and control law) in the
same process. Target: the JAX loop at least 10x faster than the NumPy loop in steady state.

Run: /work/venv/bin/python benchmarks/bench_strain.py
"""

import json
import math
import platform
import time
import timeit

import jax
import numpy as np

import hdjax  # noqa: F401  (float64)
from hdjax.strain import (
    IdealJoint,
    StrainGaugeSensor,
    hashimoto_controller,
    simulate_torque_control,
    sine_reference,
)

DURATION = 1.0
SUBSTEPS = 43  # Coulomb smooth sign 1e-2 rad/s: |lambda| dt <= 0.5


def numpy_reference(ctl, joint, sensor, ref):
    """The same loop, one sample and one RK4 substep at a time in NumPy."""
    n, jm, k = joint.ratio, joint.motor_inertia, joint.stiffness
    fc, ws = joint.coulomb, joint.smoothing
    k_s = float(sensor.sensitivity())
    psi0, da = sensor.psi0, float(sensor.dalpha)
    kgf, e, g = sensor.gauge_factor, sensor.supply, sensor.amplifier_gain
    c_t = float(hdjax.strain.strain_per_torque(sensor.geometry))

    def read(torque, q_m):
        b = q_m
        eps = torque * c_t
        # eq. (10): e1 + e3 - e2 - e4 with the antisymmetric split of gauge_strains
        s = 4 * eps + psi0 * (np.sin(2 * b) + np.sin(2 * (b - 0.5 * np.pi - da)))
        return 0.25 * kgf * s * e * g / k_s

    def rhs(x, u):
        torque = k * x[0] / n
        return np.array([x[1], (u - fc * np.tanh(x[1] / ws) - torque / n) / jm])

    a, c, ts = ctl.torque_inertia, ctl.static_gain, ctl.sample_period
    dt = ts / SUBSTEPS
    x = np.zeros(2)
    meas_prev = read(0.0, 0.0)
    out = np.empty(len(ref.torque))
    td_all, dtd_all, ddtd_all = (np.asarray(v) for v in (ref.torque, ref.rate, ref.accel))
    for i in range(len(td_all)):
        torque = k * x[0] / n
        meas = read(torque, x[0])
        rate = (meas - meas_prev) / ts
        inner = ddtd_all[i] + ctl.kd * (dtd_all[i] - rate) + ctl.kp * (td_all[i] - meas)
        u = (a * inner + c * td_all[i]) / n
        meas_prev = meas
        out[i] = torque
        for _ in range(SUBSTEPS):
            k1 = rhs(x, u)
            k2 = rhs(x + 0.5 * dt * k1, u)
            k3 = rhs(x + 0.5 * dt * k2, u)
            k4 = rhs(x + dt * k3, u)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


def main():
    ctl = hashimoto_controller()
    joint = IdealJoint(coulomb=0.04, smoothing=1e-2)
    sensor = StrainGaugeSensor(dalpha=math.radians(2.0), mounting="casing")
    ref = sine_reference(5.0, 20.0, DURATION)

    def run():
        out = simulate_torque_control(ctl, joint, sensor, ref, substeps=SUBSTEPS)
        return jax.block_until_ready(out.torque)

    t0 = time.perf_counter()
    jax_out = np.asarray(run())
    first = time.perf_counter() - t0
    steady = min(timeit.repeat(run, number=1, repeat=5))
    t0 = time.perf_counter()
    np_out = numpy_reference(ctl, joint, sensor, ref)
    t_np = time.perf_counter() - t0
    ratio = t_np / steady
    print(
        json.dumps(
            {
                "benchmark": "strain torque loop, 1 s at 0.5 ms, 43 RK4 substeps/sample",
                "machine": platform.processor() or platform.machine(),
                "backend": jax.default_backend(),
                "precision": "float64",
                "compile_and_first_run_s": first,
                "steady_state_s": steady,
                "numpy_reference_s": t_np,
                "speedup": ratio,
                "max_abs_diff_Nm": float(np.max(np.abs(jax_out - np_out))),
                "target": "speedup >= 10",
                "target_met": ratio >= 10,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
