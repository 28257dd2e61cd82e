"""Order spectrum: the least-squares periodogram against an angle."""

import math

import numpy as np
import pytest

from hdjax.discover import order_spectrum, spectrum_peaks
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
