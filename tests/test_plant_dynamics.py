"""Plant core: compliance (Song eqs. (7), (27)), Hashimoto eqs. (15)-(17), RK4 order, statics."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

import hdjax  # noqa: F401  (x64)
from hdjax import plant


def _song_eq7(T, k, tau0):
    """Song et al. eq. (7) written case by case, as printed (independent of the plant code)."""
    k1, k2, k3, k4, k5 = k
    c, b = tau0 / 3, 2 * tau0 / 3
    if T < -b:
        return -k1 * c - k2 * c + k3 * (T + b)
    if T < -c:
        return -k1 * c + k2 * (T + c)
    if T < c:
        return k1 * T
    if T < b:
        return k1 * c + k4 * (T - c)
    return k1 * c + k4 * c + k5 * (T - b)


def test_flexspline_matches_song_eq7_and_inverse_eq27():
    p = plant.song_params(defaults=False)
    k = np.asarray(p.compliance)
    torques = np.linspace(-420.0, 420.0, 57)
    got = np.asarray(plant.flexspline_deflection(p, jnp.asarray(torques)))
    want = np.array([_song_eq7(T, k, 400.0) for T in torques])
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-18)
    back = np.asarray(plant.flexspline_inverse(p, jnp.asarray(want)))
    np.testing.assert_allclose(back, torques, rtol=1e-11, atol=1e-9)


def test_hashimoto_preset_table1_and_linear_joint_torque():
    p = plant.hashimoto_params()
    assert float(p.ratio) == 100.0 and float(p.inertia_l) == 0.88 and float(p.inertia_m) == 9.4e-5
    assert float(p.torque_constant) == 0.1
    np.testing.assert_allclose(1.0 / np.asarray(p.compliance), 8800.0)
    s = plant.zero_state()
    s = eqx.tree_at(lambda s: (s.theta_m, s.theta_l), s, (jnp.asarray(0.3), jnp.asarray(0.0021)))
    # eq. (17): T_J = K (q_M / N - q_L)
    assert float(plant.flexspline_torque(p, s)) == pytest.approx(8800.0 * (0.003 - 0.0021), 1e-12)


def test_song_preset_defaults():
    p = plant.song_params()
    assert float(p.ratio) == 160.0 and float(p.rated_torque) == 400.0
    assert set(p.effect_names) == set(plant.SONG_DEFAULT_EFFECTS)
    # k1 = 1/K1 of the catalogue (6.7e4 N·m/rad), the other segments in the paper's ratios
    np.testing.assert_allclose(1.0 / float(p.compliance[0]), 6.7e4, rtol=1e-12)
    np.testing.assert_allclose(
        np.asarray(p.compliance) / float(p.compliance[0]),
        np.array([0.26305, 0.19913, 0.04946, 0.29008, 0.08434]) / 0.26305,
        rtol=1e-12,
    )


_equilibrium = eqx.filter_jit(plant.equilibrium_state)
_derivatives = eqx.filter_jit(plant.derivatives)


@pytest.mark.parametrize("load", [-350.0, 0.0, 300.0])
def test_equilibrium_is_at_rest(load):
    p = plant.song_params(effects={"stiffening": True, "backlash": True})
    s = _equilibrium(p, theta_l=0.4, load_torque=load)
    d = _derivatives(p, s, s.current * p.torque_constant, load)
    # accelerations vanish to round-off relative to the load torque / inertia scale
    assert abs(float(d.omega_l)) < 1e-8 * max(abs(load), 1.0)
    assert abs(float(d.omega_m)) < 1e-6 * max(abs(load), 1.0)
    assert float(plant.flexspline_torque(p, s)) == pytest.approx(-load, abs=1e-8)


def _linear_matrix(p):
    """x = (theta_m, omega_m, theta_l, omega_l) for the linear Hashimoto joint, current held 0."""
    n, k = float(p.ratio), 1.0 / float(p.compliance[0])
    jm, jl = float(p.inertia_m), float(p.inertia_l)
    return np.array(
        [
            [0, 1, 0, 0],
            [-k / (n * n * jm), 0, k / (n * jm), 0],
            [0, 0, 0, 1],
            [k / (n * jl), 0, -k / jl, 0],
        ]
    )


def test_rk4_converges_at_fourth_order_against_matrix_exponential():
    p = plant.hashimoto_params(effects={"coulomb_m": None})
    s0 = eqx.tree_at(lambda s: s.theta_m, plant.zero_state(), jnp.asarray(0.5))
    x0 = np.array([0.5, 0.0, 0.0, 0.0])
    horizon = 0.1
    exact = scipy.linalg.expm(_linear_matrix(p) * horizon) @ x0
    step = jax.jit(plant.rk4_step)
    errs = []
    for dt in (2e-3, 1e-3):
        s = s0
        for _ in range(int(round(horizon / dt))):
            s = step(p, s, 0.0, 0.0, dt)
        errs.append(abs(float(s.theta_l) - exact[2]))
    # classical RK4: halving dt divides the error by 2^4 = 16 (slope within 10 %)
    assert np.log2(errs[0] / errs[1]) == pytest.approx(4.0, abs=0.4)


def test_current_loop_is_integrated_exactly():
    p = plant.song_params(defaults=False)
    s = plant.zero_state()
    cmd = 1.7  # N·m -> i_ref = 6.8 A
    for _ in range(3):
        s = plant.rk4_step(p, s, cmd, 0.0, 5e-4)
    i_ref = cmd / float(p.torque_constant)
    want = i_ref * (1.0 - np.exp(-1.5e-3 / float(p.current_time_constant)))
    assert float(s.current) == pytest.approx(want, rel=1e-12)


def test_rk4_agrees_with_solve_ivp_on_full_song_plant():
    """Independent integrator (scipy DOP853, tight tolerances) on the same right-hand side."""
    p = plant.song_params(effects={"stribeck_l": True, "stribeck_m": True})
    s0 = plant.equilibrium_state(p, theta_l=0.2, load_torque=-150.0)
    cmd, load = 1.4, -100.0  # a torque step: excites the joint mode and the hysteresis
    leaves, tree = jax.tree.flatten(s0)
    # the plant holds the current reference over the step; give scipy the same (smooth) input
    f = jax.jit(
        lambda x: jax.tree.leaves(
            plant.derivatives(p, jax.tree.unflatten(tree, list(x)), cmd, load)
        )
    )
    rhs = lambda t, x: np.array([float(v) for v in f(jnp.asarray(x))])
    ref = scipy.integrate.solve_ivp(
        rhs,
        (0, 0.01),
        np.array([float(v) for v in leaves]),
        method="DOP853",
        rtol=1e-11,
        atol=1e-13,
    )
    step = jax.jit(plant.rk4_step)
    want = ref.y[:, -1]
    n = float(p.ratio)
    errors = []
    for dt in (5e-4, 2.5e-4):
        s = s0
        for _ in range(int(round(0.01 / dt))):
            s = step(p, s, cmd, load, dt)
        got = np.array([float(v) for v in jax.tree.leaves(s)])
        # the deflection (what torque estimation uses) to 1e-4 at the default 0.5 ms step
        assert got[0] / n - got[2] == pytest.approx(want[0] / n - want[2], rel=1e-4)
        assert got[4] == pytest.approx(want[4], rel=1e-6)  # current: exact exponential
        errors.append(abs(got[3] - want[3]))
    # link speed: the error shrinks at least 8x when the step halves (order >= 3 in practice,
    # 4 in theory; the tanh-smoothed friction and the eq. (7) knots cost some order)
    assert errors[1] < errors[0] / 8


def test_positive_motor_torque_drives_link_forward_with_positive_joint_torque():
    p = plant.hashimoto_params(effects={"coulomb_m": None})
    s = plant.zero_state()
    for _ in range(40):
        s = plant.rk4_step(p, s, 0.05, 0.0, 5e-4)
    assert float(s.omega_l) > 0 and float(plant.flexspline_torque(p, s)) > 0
