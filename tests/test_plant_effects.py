"""Effects registry: names, parameters, signs and shapes; each effect's closed-form behaviour."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax import plant


def test_unknown_effect_name_lists_known_names():
    with pytest.raises(hdjax.ConfigError) as err:
        plant.song_params(effects={"hysterisis": True})
    msg = str(err.value)
    assert "hysterisis" in msg and "did you mean 'hysteresis'" in msg
    for name in plant.EFFECT_NAMES:
        assert name in msg


def test_unknown_effect_parameter():
    with pytest.raises(hdjax.ConfigError, match="unknown parameter.*'levle'.*level"):
        plant.song_params(effects={"coulomb_l": {"levle": 3.0}})


@pytest.mark.parametrize(
    "effects, match",
    [
        ({"coulomb_m": {"level": -0.1}}, "'level' must be non-negative"),
        ({"coulomb_l": {"smoothing": 0.0}}, "'smoothing' must be positive"),
        ({"backlash": {"width": -1e-4}}, "'width' must be non-negative"),
        ({"hysteresis": {"a": -5.0}}, "'a' must be positive"),
        ({"hysteresis": {"beta": -1.0, "gamma": 0.5}}, "beta \\+ gamma > 0"),
        ({"wg_compliance": {"coefficients": [-0.01, 0.0]}}, "w_1 must be positive"),
        ({"stiffening": {"cubic": -1.0}}, "'cubic' must be non-negative"),
        ({"temperature": {"time_constant": -3.0}}, "'time_constant' must be positive"),
        ({"coulomb_m": {"level": "abc"}}, "'level' must be a number or a list of numbers"),
        ({"ripple_m": {"amplitudes": ["x"]}}, "'amplitudes' must be a number or a list"),
    ],
)
def test_wrong_sign_parameters(effects, match):
    with pytest.raises(hdjax.ConfigError, match=match):
        plant.song_params(effects=effects)


@pytest.mark.parametrize(
    "effects, match",
    [
        (
            {"harmonic_m": {"orders": [1.0, 2.0], "amplitudes": [1e-5], "phases": [0.0, 0.0]}},
            "'amplitudes' must have shape \\(2,\\)",
        ),
        (
            {"harmonic_l": {"orders": [[1.0]], "amplitudes": [1e-5], "phases": [0.0]}},
            "must be a 1-D list",
        ),
        ({"coulomb_l": {"level": [1.0, 2.0]}}, "'level' must have shape \\(\\)"),
    ],
)
def test_wrong_shape_parameters(effects, match):
    with pytest.raises(hdjax.ConfigError, match=match):
        plant.song_params(effects=effects)


def test_wrong_core_parameters():
    with pytest.raises(hdjax.ConfigError, match="compliance.*shape \\(5,\\)"):
        plant.song_params(compliance=[1e-5, 1e-5])
    with pytest.raises(hdjax.ConfigError, match="must be positive"):
        plant.song_params(compliance=[1e-5, -1e-5, 1e-5, 1e-5, 1e-5])
    with pytest.raises(hdjax.ConfigError, match="'inertia_l' must be positive"):
        plant.song_params(inertia_l=-1.0)
    with pytest.raises(hdjax.ConfigError, match="unknown plant parameter 'inertia'"):
        plant.song_params(inertia=1.0)
    with pytest.raises(hdjax.ConfigError, match="unknown model 'preisach'"):
        plant.song_params(effects={"hysteresis": {"model": "preisach"}})


def test_effects_switch_on_and_off():
    p = plant.song_params(defaults=False)
    assert p.effect_names == ()
    p = plant.with_effects(
        p,
        backlash=True,
        harmonic_m={"orders": [2.0 - 2.0 / 160.0], "amplitudes": [1e-5], "phases": [0.0]},
    )
    assert p.effect_names == ("harmonic_m", "backlash")
    p = plant.with_effects(p, backlash=None)
    assert p.effect_names == ("harmonic_m",)
    # non-integer order is used as given
    err = plant.kinematic_error(p, jnp.asarray(-1.0), jnp.asarray(0.0))
    assert float(err) == pytest.approx(1e-5 * np.sin(2.0 - 2.0 / 160.0), rel=1e-12)


@pytest.mark.parametrize("model", ["bouc_wen", "dahl", "lugre"])
def test_hysteresis_saturates_at_its_closed_form_level(model):
    eff = plant.make_effect("hysteresis", model=model)
    level = float(eff.saturation())
    rate = jax.jit(lambda z, v: eff.rate(z, v))
    z = jnp.asarray(0.0)
    # monotone loading at a moderate deflection rate: z -> +level; unloading: z -> -level
    for v in (1e-2, -1e-2):
        for _ in range(400):
            z = z + 1e-3 * rate(z, jnp.asarray(v))
        assert float(z) == pytest.approx(np.sign(v) * level, rel=2e-3)


def test_backlash_adds_half_width_at_large_torque():
    p0 = plant.song_params(defaults=False)
    p1 = plant.with_effects(p0, backlash={"width": 3e-4, "torque_scale": 5.0})
    t25 = jnp.asarray(25.0)
    for torque in (-300.0, 200.0):
        extra = plant.compliance_deflection(p1, torque, t25) - plant.compliance_deflection(
            p0, torque, t25
        )
        assert float(extra) == pytest.approx(np.sign(torque) * 1.5e-4, rel=1e-6)


def test_wave_generator_and_temperature_in_deflection():
    p0 = plant.song_params(defaults=False)
    p1 = plant.with_effects(
        p0,
        wg_compliance={"coefficients": [0.02, 0.0, 0.002]},
        temperature={"alpha": 0.01, "reference": 20.0},
    )
    torque, temp = 240.0, 30.0
    u = torque / 160.0
    want = 1.1 * float(plant.flexspline_deflection(p0, torque)) + (0.02 * u + 0.002 * u**3) / 160
    got = float(plant.compliance_deflection(p1, torque, jnp.asarray(temp)))
    assert got == pytest.approx(want, rel=1e-12)


def test_elastic_torque_inverts_the_series_compliance():
    p = plant.song_params(
        effects={"backlash": True, "temperature": {"alpha": 0.004}}, flexspline="smooth"
    )
    torques = jnp.linspace(-420.0, 420.0, 41)
    temp = jnp.full_like(torques, 31.0)
    d = plant.compliance_deflection(p, torques, temp)
    back = plant._dynamics.elastic_torque(p, d, temp)
    # 3 Newton steps from the piecewise guess: within 5e-6 of rated torque (2 mN·m), far
    # below the torque-sensor noise (0.8 N·m)
    np.testing.assert_allclose(np.asarray(back), np.asarray(torques), atol=2e-3)
    p2 = plant.song_params()  # default wave-generator polynomial: Newton steps
    d2 = plant.compliance_deflection(p2, torques, temp)
    back2 = plant._dynamics.elastic_torque(p2, d2, temp)
    np.testing.assert_allclose(np.asarray(back2), np.asarray(torques), atol=1e-6)
    # up to twice rated torque (the driver's current limit): within 0.1 N·m
    big = jnp.linspace(-800.0, 800.0, 81)
    back3 = plant._dynamics.elastic_torque(p2, plant.compliance_deflection(p2, big, 25.0), 25.0)
    np.testing.assert_allclose(np.asarray(back3), np.asarray(big), atol=0.1)
