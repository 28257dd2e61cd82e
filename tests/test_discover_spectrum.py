"""Order spectrum: the least-squares periodogram against an angle."""

import math

import numpy as np
import pytest

from hdjax.discover import order_spectrum, spectrum_peaks
from hdjax.discover._library import spectrum_orders, torque_free
from hdjax.discover._spectrum import order_power, refine_peak


def _angle(n=6000, seed=0):
    # A back-and-forth motion (not monotone) covering many turns: theta(t) is unevenly
    # "sampled" in angle, which is why an FFT over time would not do.
    t = np.linspace(0.0, 60.0, n)
    return 300.0 * np.sin(2 * math.pi * t / 40.0) + 5.0 * np.sin(2 * math.pi * t / 3.0)


def test_power_equals_independent_least_squares():
    theta = _angle()
    rng = np.random.default_rng(1)
    r = 0.7 * np.cos(2.5 * theta + 0.3) + 0.5 * rng.standard_normal(theta.size)
    for k in (0.8, 2.5, 3.7):
        x = np.column_stack([np.cos(k * theta), np.sin(k * theta), np.ones_like(theta)])
        fit = x @ np.linalg.lstsq(x, r, rcond=None)[0]
        expect = 1.0 - np.sum((r - fit) ** 2) / np.sum((r - r.mean()) ** 2)
        # float64 normal equations of a 3-column design: agreement to ~1e-10 is rounding
        assert order_power(theta, r, [k])[0] == pytest.approx(expect, abs=1e-9)


def test_finds_non_integer_order_and_refines_it():
    theta = _angle()
    rng = np.random.default_rng(2)
    true = 2.0 - 2.0 / 160.0  # a combination order of a ratio-160 reducer
    r = np.sin(true * theta + 1.0) + 0.3 * rng.standard_normal(theta.size)
    spec = order_spectrum(theta, r, min_order=0.5, max_order=6.0)
    (k, p), *_ = spectrum_peaks(spec, n_peaks=1)
    assert abs(k - true) < spec.resolution  # located within one resolution on the grid
    refined = refine_peak(theta, r, k, spec.resolution)
    # the refined peak must beat the grid spacing by far (span ~610 rad -> resolution ~0.01)
    assert abs(refined - true) < 0.05 * spec.resolution
    assert p > 0.8


def test_two_peaks_are_both_reported():
    theta = _angle()
    r = np.sin(1.0 * theta) + 0.6 * np.cos(3.0 * theta)
    spec = order_spectrum(theta, r, min_order=0.5, max_order=5.0)
    orders = sorted(round(k, 1) for k, _ in spectrum_peaks(spec, n_peaks=2))
    assert orders == [1.0, 3.0]


def test_noise_gives_no_peak_above_threshold():
    theta = _angle()
    r = np.random.default_rng(3).standard_normal(theta.size)
    spec = order_spectrum(theta, r, min_order=0.5, max_order=6.0)
    # one sin/cos pair explains ~2/n of pure noise; 1 % is far above that
    assert spectrum_peaks(spec, min_power=0.01) == []


def _design(theta, orders):
    k = np.asarray(orders)[:, None, None]
    c, s = np.cos(k * theta[None, :, None]), np.sin(k * theta[None, :, None])
    return np.concatenate([c, s, np.ones_like(c)], axis=2)  # (orders, samples, 3)


def _old_power(theta, r, orders):
    # The former kernel, order by order: build the 3-column design, solve its ridged normal
    # equations and measure the residual (what the grid factorisation must reproduce).
    r = r - r.mean()
    x = _design(theta, orders)
    g = np.swapaxes(x, 1, 2) @ x + 1e-12 * np.eye(3) * theta.size
    beta = np.linalg.solve(g, np.swapaxes(x, 1, 2) @ r[:, None])
    return 1.0 - np.sum((r[:, None] - x @ beta) ** 2, axis=(1, 2)) / np.sum(r * r)


def _projection_power(theta, r, orders):
    # Independent: the explained share |Q^T r|^2 / |r|^2 of the orthogonal projection (no
    # normal equations, no cancellation at small power).
    r = r - r.mean()
    q = np.linalg.qr(_design(theta, orders))[0]
    return np.sum((np.swapaxes(q, 1, 2) @ r[:, None]) ** 2, axis=(1, 2)) / np.sum(r * r)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_grid_spectrum_equals_order_by_order_fit(seed):
    # random angle paths (amplitude, period, jitter), residuals with a random periodic part
    rng = np.random.default_rng(seed)
    print("seed", seed)
    t = np.sort(rng.uniform(0.0, 30.0, 1500))
    swing = rng.uniform(20, 60) * np.sin(2 * math.pi * t / rng.uniform(10, 40))
    theta = swing + rng.normal(0, 0.01, t.size)
    r = rng.uniform(0, 1) * np.cos(rng.uniform(0.5, 8) * theta) + rng.standard_normal(t.size)
    spec = order_spectrum(theta, r, min_order=0.5, max_order=8.0)
    assert spec.orders.size > 100  # the factorised grid path, not the direct one
    old = _old_power(theta, r, spec.orders)
    ref = _projection_power(theta, r, spec.orders)
    # The former kernel's own rounding is ~n eps on its residual sum, so the agreement with
    # it is stated relative to the spectrum's peak; the projection is accurate at small power
    # too, so against it element by element (float64 sums over 1500 samples: ~1e-13).
    assert np.max(np.abs(spec.power - old)) <= 1e-10 * np.max(old)
    np.testing.assert_allclose(spec.power, ref, rtol=1e-9, atol=1e-14)
    # the direct path (a few orders, as refine_peak and order_power use) agrees too
    pick = spec.orders[:: spec.orders.size // 7]
    np.testing.assert_allclose(
        order_power(theta, r, pick), _projection_power(theta, r, pick), rtol=1e-9
    )


def test_torque_free_removes_a_function_of_the_torque_and_keeps_the_rest():
    rng = np.random.default_rng(3)
    n = 5000
    torque = rng.uniform(-300.0, 300.0, n)
    bins = np.empty(n, int)
    bins[np.argsort(torque, kind="stable")] = np.arange(n) * 100 // n  # 100 bins of 50
    level = rng.standard_normal(100)
    # a function of the torque, constant on each bin: removed exactly
    np.testing.assert_allclose(torque_free(level[bins], torque), 0.0, atol=1e-12)
    # a part with zero mean in every bin: kept exactly
    rest = rng.standard_normal(n)
    rest -= (np.bincount(bins, rest) / np.bincount(bins))[bins]
    np.testing.assert_allclose(torque_free(rest + level[bins], torque), rest, atol=1e-12)


def _gravity_swing(n=15000):
    # the `slow` bench: the link swings pi/2 - 1.4 cos(2 pi t / 20) under weights whose arm
    # changes at 20 s, so the torque is a function of the output angle at each arm
    t = np.linspace(0.0, 30.0, n)
    theta_l = math.pi / 2 - 1.4 * np.cos(2 * math.pi * t / 20.0)
    arm = np.where(t < 20.0, 0.5, 0.75)
    return theta_l, -380.0 * arm * np.cos(theta_l)


def test_a_function_of_the_torque_is_no_output_order_under_a_gravity_load():
    theta, torque = _gravity_swing()
    rng = np.random.default_rng(4)
    # a compliance misfit that wiggles with the torque (the starting model's segments against
    # a smooth compliance curve), and sensor noise
    misfit = 5e-6 * np.sin(2 * math.pi * torque / 60.0) + 1e-6 * rng.standard_normal(theta.size)
    kw = dict(signal="theta_l", order_range=(0.5, 12.0), named=[], existing=[], n_peaks=3)
    found, _ = spectrum_orders(theta, misfit, **kw)
    assert found  # against the angle alone it shows as output orders
    assert spectrum_orders(theta, misfit, torque=torque, **kw)[0] == []
    # an output harmonic on top is still found, beside the misfit
    harmonic = 3e-6 * np.sin(4.6 * theta + 0.5)
    found, _ = spectrum_orders(theta, misfit + harmonic, torque=torque, **kw)
    assert [k for k, _ in found if abs(k - 4.6) < 0.1], found
