"""Hashimoto et al. (1993) sensor model, eqs. (1)-(14): paper numbers and independent sums."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax.strain import (
    FlexsplineGeometry,
    GaugeStrains,
    StrainGaugeSensor,
    bridge_output,
    gauge_strains,
    misalignment_error_index,
    residual_ripple,
    resolved_torque_gain,
    strain_per_torque,
    strain_per_torque_appendix,
)

PAPER = FlexsplineGeometry(thickness=0.39e-3, r1=15.8e-3, r2=24.85e-3, shear_modulus=8.3e10)


def test_resolved_torque_gain_eq8_matches_eq14():
    # Paper eq. (14): K_R = 50 uV/(N m); the formula gives 50.74 (the paper rounds).
    k_r = float(resolved_torque_gain(PAPER, gauge_factor=2.1, supply=3.0))
    by_hand = (
        2.1 * 3.0 * (15.8e-3 + 24.85e-3) / (8 * math.pi * 0.39e-3 * 8.3e10 * 15.8e-3**2 * 24.85e-3)
    )
    assert k_r == pytest.approx(by_hand, rel=1e-12)
    assert k_r == pytest.approx(50e-6, rel=0.02)  # "50 uV/N m": 1.5% rounding
    # x500 amplifier: 25 mV/(N m) (Sec. III-B), the measured 24 mV/(N m) within 6%.
    sens = float(StrainGaugeSensor(geometry=PAPER).sensitivity())
    assert sens == pytest.approx(25e-3, rel=0.02)
    assert sens == pytest.approx(24e-3, rel=0.06)


def test_appendix_a6_is_minus_eq7():
    # Eq. (A6) as printed carries r2/(r1 - r2) from (A5), negative for r1 < r2: it is -eq. (7),
    # same magnitude, so it also gives K_R ~ 50 uV/(N m).
    for geom in (PAPER, FlexsplineGeometry(thickness=1e-3, r1=5e-3, r2=40e-3)):
        a6 = float(strain_per_torque_appendix(geom))
        e7 = float(strain_per_torque(geom))
        assert a6 == pytest.approx(-e7, rel=1e-12)
    assert abs(float(strain_per_torque_appendix(PAPER))) * 6.3 == pytest.approx(50e-6, rel=0.02)


def test_eq7_against_numerical_integral_of_a3():
    # Independent: integrate d theta = T dr / (2 pi r^3 t G) (A3) numerically, then (A5)-(A6)
    # with |r2 - r1|.
    r = np.linspace(PAPER.r1, PAPER.r2, 20001)
    f = 1.0 / (2 * np.pi * r**3 * PAPER.thickness * PAPER.shear_modulus)
    theta_d = np.trapezoid(f, r)
    eps = 0.5 * PAPER.r2 / (PAPER.r2 - PAPER.r1) * theta_d
    assert float(strain_per_torque(PAPER)) == pytest.approx(eps, rel=1e-7)


def test_bridge_cancels_modulation_and_common_strain():
    beta = jnp.linspace(0.0, 2 * jnp.pi, 97)
    eps_t = 1.5e-4
    s = gauge_strains(eps_t, beta, psi0=100e-6, dalpha=0.0, common=3e-4)
    # eq. (3) and eq. (4): each pair carries the modulation with opposite sign
    np.testing.assert_allclose(s.e1 - s.e2, 2 * eps_t + 100e-6 * np.sin(2 * beta), atol=1e-18)
    np.testing.assert_allclose(
        s.e3 - s.e4, 2 * eps_t + 100e-6 * np.sin(2 * beta - np.pi), atol=1e-18
    )
    # eq. (5): E_out = K_gf eps_t E, independent of beta and of the common strain
    np.testing.assert_allclose(bridge_output(s, 2.1, 3.0), 2.1 * eps_t * 3.0, rtol=1e-12)
    # the exact bridge departs from eq. (5) by O(K_gf eps) only
    exact = bridge_output(s, 2.1, 3.0, linear=False)
    np.testing.assert_allclose(exact, 2.1 * eps_t * 3.0, rtol=2 * 2.1 * 4.5e-4)


@pytest.mark.parametrize("dalpha_deg", [-30.0, -2.0, -0.5, 0.5, 2.0, 10.0, 60.0, 120.0])
def test_ripple_eqs_10_12_against_numeric_sum(dalpha_deg):
    dalpha = math.radians(dalpha_deg)
    beta = np.linspace(0.0, np.pi, 181)
    psi0, eps_t = 100e-6, 7e-5
    s = gauge_strains(eps_t, beta, psi0=psi0, dalpha=dalpha)
    direct = np.asarray(s.e1 + s.e3 - s.e2 - s.e4) - 4 * eps_t  # direct sum of four strains
    rip = residual_ripple(dalpha, psi0)
    assert float(rip.amplitude) == pytest.approx(2 * psi0 * abs(math.sin(dalpha)), rel=1e-12)
    np.testing.assert_allclose(
        direct, float(rip.amplitude) * np.sin(2 * beta + float(rip.phase)), atol=1e-17
    )
    # Independent: amplitude and phase fitted by least squares on sin/cos columns.
    cols = np.stack([np.sin(2 * beta), np.cos(2 * beta)], axis=1)
    (cs, cc), *_ = np.linalg.lstsq(cols, direct, rcond=None)
    assert math.hypot(cs, cc) == pytest.approx(float(rip.amplitude), rel=1e-9)
    phase = math.atan2(cc, cs)
    assert math.remainder(phase - float(rip.phase), 2 * math.pi) == pytest.approx(0, abs=1e-9)


def test_ripple_zero_misalignment():
    rip = residual_ripple(0.0)
    assert float(rip.amplitude) == 0.0 and float(rip.phase) == 0.0


def test_error_index_eq13_paper_values():
    # E_R = 0.25 |sin dalpha| with Psi0 = 100 ustrain and eps_t^R = 200 ustrain
    da = np.radians(np.linspace(-5, 5, 41))
    np.testing.assert_allclose(
        misalignment_error_index(da, 100e-6, 200e-6), 0.25 * np.abs(np.sin(da)), rtol=1e-12
    )
    # "within +-1% of the rated torque" for |dalpha| <= 2 deg: 0.87% at 2 deg
    worst = float(misalignment_error_index(math.radians(2.0)))
    assert worst == pytest.approx(0.008725, rel=1e-3)
    assert worst < 0.01


def test_sensor_ripple_in_torque_units():
    # Independent: the reading's peak-to-peak over one motor revolution over 2 equals
    # Psi / (4 eps_t/T) (eq. 13 in N m).
    sensor = StrainGaugeSensor(dalpha=math.radians(2.0))
    q_m = jnp.linspace(0.0, 2 * jnp.pi, 4001)
    reading = np.asarray(sensor.read(10.0, q_m, 0.0))  # output held: beta = q_m
    half_p2p = 0.5 * (reading.max() - reading.min())
    assert half_p2p == pytest.approx(float(sensor.ripple_amplitude()), rel=1e-4)
    assert np.mean(reading) == pytest.approx(10.0, abs=1e-3)
    # two lobes: two ripple periods per motor revolution
    spec = np.abs(np.fft.rfft(reading[:-1] - reading[:-1].mean()))
    assert int(np.argmax(spec)) == 2
    aligned = StrainGaugeSensor()
    np.testing.assert_allclose(aligned.read(10.0, q_m, 0.0), 10.0, rtol=1e-12)


def test_sensor_adc_quantisation():
    sensor = StrainGaugeSensor(adc_bits=12)
    lsb_torque = 20.0 / 4096 / float(sensor.sensitivity())
    t = jnp.linspace(-5.0, 5.0, 1001)
    err = np.asarray(sensor.read(t, 0.0, 0.0)) - np.asarray(t)
    assert np.max(np.abs(err)) <= 0.5 * lsb_torque * (1 + 1e-9)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(r1=30e-3, r2=24.85e-3), "r1=0.03 m must be smaller"),
        (dict(r1=24.85e-3, r2=24.85e-3), "must be smaller than the diaphragm radius"),
        (dict(thickness=0.0), "thickness must be a positive"),
        (dict(thickness=-1e-3), "thickness must be a positive"),
        (dict(shear_modulus=0.0), "shear_modulus must be a positive"),
        (dict(r1=-1e-3), "r1 must be a positive"),
    ],
)
def test_nonphysical_geometry_raises(kwargs, match):
    with pytest.raises(hdjax.ConfigError, match=match):
        FlexsplineGeometry(**kwargs)


def test_bad_sensor_options_raise():
    with pytest.raises(hdjax.ConfigError, match="mounting must be one of"):
        StrainGaugeSensor(mounting="flange")
    with pytest.raises(hdjax.ConfigError, match="adc_bits"):
        StrainGaugeSensor(adc_bits=1)
    with pytest.raises(hdjax.ConfigError, match="gauge_factor must be positive"):
        StrainGaugeSensor(gauge_factor=0.0)


def test_gauge_strains_type():
    assert isinstance(gauge_strains(0.0, 0.0), GaugeStrains)
