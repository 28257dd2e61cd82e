"""Periodic angle features (beyond Song et al.): they carry a kinematic error a plain network
cannot represent over many motor turns (issue 4, item 2)."""

import jax
import numpy as np
import pytest

import hdjax
from hdjax import network as hn

JOINT = hdjax.Joint(ratio=160.0, rated_torque=400.0)
K = 2.0e4  # joint stiffness [N·m/rad] of the synthetic joint
A_KIN = 5e-4  # kinematic error amplitude [rad]: 10 N·m of torque, 2.5 % of rated


def _recording(seed: int, n: int = 4000, dt: float = 4e-3):
    """A joint with twist = tau / K + A sin(2 theta_m): the motor sweeps +-7.6 turns, so the
    kinematic error goes through about 30 periods; the current is a noisy torque (1 A = 16 N·m),
    so the twist is the better torque signal. Phases and noise come from `seed`."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    ph = rng.uniform(0.0, 2.0 * np.pi, 3)
    tau = 200 * np.sin(2 * np.pi * 0.7 * t + ph[0]) + 80 * np.sin(2 * np.pi * 1.9 * t + ph[1])
    theta_m = 160 * 0.3 * np.sin(2 * np.pi * 0.25 * t + ph[2])
    kin = A_KIN * np.sin(2 * theta_m)
    theta_l = theta_m / 160 + tau / K + kin
    current = tau / 16.0 + rng.normal(scale=1.0, size=n)
    return hdjax.make_recording(t, theta_m, theta_l, current, tau, source=f"kin{seed}"), K * kin


@pytest.fixture(scope="module")
def held_out_rms():
    train, _ = _recording(0)
    test, kin_torque = _recording(1)
    out = {}
    for periodic in (False, True):
        feats = hn.build_features(train, JOINT, periodic=periodic)
        net = hn.Network(feats.layout, (16,), key=jax.random.key(0))
        res = hn.train_optax(
            net, feats.x, train.torque, learning_rate=1e-2, steps=3000, key=jax.random.key(1)
        )
        err = np.asarray(hn.predict_torque(res.value, test, JOINT)) - np.asarray(test.torque)
        out[periodic] = float(np.sqrt(np.mean(err**2)))
        print(f"periodic={periodic}: held-out RMS {out[periodic]:.2f} N·m")
    return out, float(np.sqrt(np.mean(kin_torque**2)))


def test_periodic_features_carry_the_kinematic_error(held_out_rms):
    """Same architecture, seed and steps; held out on a recording with other phases and noise.

    Reference: the RMS of the kinematic error's torque, K * A sin(2 theta_m) (7.1 N·m here,
    from the known truth). The plain network cannot represent 30 periods of sin(2 theta_m) from
    the raw angle with 16 sigmoids, so it keeps at least 70 % of it (measured: ~100 %); with
    sin/cos of the angles it is a linear function of the inputs, and at most 50 % is left
    (measured: ~40 %), and at most 60 % of the plain network's error.
    """
    rms, kin_rms = held_out_rms
    assert rms[False] > 0.7 * kin_rms, (rms, kin_rms)
    assert rms[True] < 0.5 * kin_rms, (rms, kin_rms)
    assert rms[True] < 0.6 * rms[False], rms
