"""Twist (eq. (5)) and velocities (eqs. (13)-(14), smoothed) against closed forms."""

import numpy as np
import pytest

import hdjax
from hdjax.compliance import signals_from_recording


def test_twist_resolves_arcseconds_under_big_motor_angles():
    # 84 motor turns (the LARA8 log) and a twist of 1 arcsec
    arcsec = np.pi / 180 / 3600
    theta_l = np.array([5.2, 5.2])
    theta_m = 101 * (theta_l - np.array([0.0, arcsec]))
    tw = np.asarray(hdjax.twist(theta_m, theta_l, 101.0))
    assert tw.dtype == np.float64
    np.testing.assert_allclose(tw, [0.0, arcsec], rtol=0, atol=1e-6 * arcsec)
    np.testing.assert_allclose(np.asarray(hdjax.twist(theta_m, theta_l, 101.0, -1.0)), -tw)
    with pytest.raises(hdjax.DataError, match="ratio must be positive"):
        hdjax.twist(theta_m, theta_l, 0.0)


def test_backward_difference_with_jitter_is_eq13():
    rng = np.random.default_rng(0)
    t = np.cumsum(0.004 + 0.001 * rng.uniform(-1, 1, 50))
    theta = 3.0 * t + 0.5  # linear: every backward difference is exactly the slope
    v = np.asarray(hdjax.finite_difference_velocity(t, theta))
    np.testing.assert_allclose(v, 3.0, rtol=1e-10)
    theta = np.sin(t)
    v = np.asarray(hdjax.finite_difference_velocity(t, theta))
    ref = np.diff(theta) / np.diff(t)
    np.testing.assert_array_equal(v[1:], ref)
    assert v[0] == v[1]


def test_smoothed_velocity_is_exact_on_lines_and_less_noisy():
    rng = np.random.default_rng(1)
    t = np.cumsum(0.004 + 0.001 * rng.uniform(-1, 1, 400))
    v = np.asarray(hdjax.smoothed_velocity(t, 2.0 * t - 1.0, half_window=4))
    np.testing.assert_allclose(v, 2.0, rtol=1e-9)  # a local LS line reproduces a line exactly
    noisy = 2.0 * t + 1e-4 * rng.standard_normal(400)
    e_fd = np.std(np.asarray(hdjax.finite_difference_velocity(t, noisy)) - 2.0)
    e_sm = np.std(np.asarray(hdjax.smoothed_velocity(t, noisy, half_window=5)) - 2.0)
    assert e_sm < e_fd / 5  # noise falls ~h^{-3/2}: 11 points vs 2
    with pytest.raises(hdjax.DataError, match="half_window must be a positive integer"):
        hdjax.smoothed_velocity(t, noisy, half_window=0)


def test_bad_shapes_and_gaps():
    with pytest.raises(hdjax.DataError, match="1-D of one length"):
        hdjax.finite_difference_velocity(np.arange(3.0), np.arange(4.0))
    t = np.r_[np.arange(10) * 0.004, 1.0, 1.004]
    np.testing.assert_array_equal(hdjax.find_gaps(t), [9])


def test_signals_from_recording():
    from tests.helpers import sim_recording

    rec = sim_recording(100)
    sig = signals_from_recording(rec, 101.0, 1.0)
    np.testing.assert_allclose(
        np.asarray(sig.twist), np.asarray(rec.theta_l) - np.asarray(rec.theta_m) / 101, atol=1e-15
    )
    assert sig.get("temperature").shape == (100,)
    with pytest.raises(hdjax.DataError, match="no signal 'pressure'"):
        sig.get("pressure")
    with pytest.raises(hdjax.DataError, match="velocity must be one of"):
        signals_from_recording(rec, 101.0, velocity="spline")
    smooth = signals_from_recording(rec, 101.0, velocity="smoothed", half_window=3)
    assert smooth.omega_l.shape == (100,)
