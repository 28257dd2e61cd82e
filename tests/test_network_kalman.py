"""The Kalman-filtered current, Song et al. eqs. (29)-(35) and Fig. 5."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax import network as hn


def _numpy_kalman(z, q, r, p0):
    """Independent reference: the textbook scalar random-walk filter as a Python loop."""
    mu, p = z[0], p0
    out = []
    for zk in z:
        p = p + q
        k = p / (p + r)
        mu = mu + k * (zk - mu)
        p = (1 - k) * p
        out.append((mu, p))
    return np.array(out).T


def test_matches_independent_loop():
    z = np.random.default_rng(0).normal(size=500)
    mean, cov = hn.kalman_filter(z)
    ref_mean, ref_cov = _numpy_kalman(z, 0.05, 0.25, 0.01)
    # Same arithmetic in a different order: agreement to float64 round-off.
    np.testing.assert_allclose(mean, ref_mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(cov, ref_cov, rtol=1e-12)


def test_steady_state_gain_closed_form():
    # Closed form: P^2 - qP - qr = 0 for the predicted covariance, K = P/(P + r).
    q, r = 0.05, 0.25
    p_pred = (q + math.sqrt(q * q + 4 * q * r)) / 2
    assert hn.steady_state_gain() == pytest.approx(p_pred / (p_pred + r), rel=1e-14)
    _, cov = hn.kalman_filter(np.zeros(400))
    # Posterior covariance converges geometrically to (1 - K) * P_pred.
    assert float(cov[-1]) == pytest.approx((1 - hn.steady_state_gain()) * p_pred, rel=1e-12)


def test_fig5_fluctuation_halved_on_synthetic_current():
    # Fig. 5: "reduce the fluctuation amplitude of the signal by half". A slow current (0.5 Hz,
    # as a joint under a slowly changing load) sampled every 0.5 ms with white driver noise.
    t = np.arange(0, 4.0, hn.PAPER_RAW_PERIOD)
    true = 2.0 * np.sin(2 * np.pi * 0.5 * t)
    raw = true + np.random.default_rng(1).normal(scale=0.1, size=t.size)
    mean, _ = hn.kalman_filter(raw)
    ratio = np.std(np.asarray(mean) - true) / np.std(raw - true)
    # Theory for white noise: sqrt(K/(2-K)) = 0.467; the slow signal adds a little lag error.
    assert hn.white_noise_std_ratio() == pytest.approx(0.467, abs=1e-3)
    assert 0.40 < ratio < 0.55, ratio
    # The literal reading of eqs. (31)-(35) (variances swapped) would not halve the noise.
    assert hn.white_noise_std_ratio(q=0.25, r=0.05) > 0.8


def test_filter_current_holds_every_20ms():
    t = np.arange(0, 0.1, 0.5e-3)
    rec = hdjax.make_recording(t, t * 160, t, np.random.default_rng(2).normal(size=t.size))
    out = hn.filter_current(rec)
    cur = np.asarray(out.current)
    # 20 ms / 0.5 ms = 40 samples per held value; 0.1 s -> 5 distinct values.
    assert len(np.unique(cur)) == 5
    assert np.all(cur[:40] == cur[0])
    mean, _ = hn.kalman_filter(rec.current)
    np.testing.assert_array_equal(cur[40:80], np.asarray(mean)[40])
    np.testing.assert_array_equal(out.extras["current_raw"], rec.current)
    every = hn.filter_current(rec, output_period=None)
    np.testing.assert_array_equal(every.current, mean)


def test_bad_input():
    with pytest.raises(hdjax.ConfigError, match="q must be a positive"):
        hn.kalman_filter(np.zeros(3), q=-1.0)
    with pytest.raises(hdjax.DataError, match="NaN/inf, first at sample 1"):
        hn.kalman_filter(jnp.asarray([0.0, jnp.nan, 1.0]))


def _fluctuation(x, window=41):
    """Std of the signal around its centred 20 ms moving average (41 samples of 0.5 ms)."""
    ma = np.convolve(x, np.ones(window) / window, mode="same")
    return float(np.std((x - ma)[window:-window]))


def test_fig5_fluctuation_halved_on_plant_static_loading():
    """Fig. 5 on plant data: the static loading experiment (motor nearly at rest under load,
    the situation the paper describes: "the speed of the motor is slow when subjected to
    external loads"). Raw current every 0.5 ms from hdjax.plant, key 0."""
    import jax

    from hdjax import plant

    rec = plant.simulate_scenario("static", key=jax.random.key(0), duration=4.0)
    raw = np.asarray(rec.current)
    mean, _ = hn.kalman_filter(raw)
    ratio = _fluctuation(np.asarray(mean)) / _fluctuation(raw)
    # "reduce the fluctuation amplitude of the signal by half": measured 0.48.
    assert 0.35 < ratio < 0.65, ratio
