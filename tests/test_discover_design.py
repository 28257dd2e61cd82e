"""The residual loop's design matrix, assembled from one compiled program per term, equals the
compliance model's own design bit for bit (shared and per-segment base terms, effects of every
torque kind but the path; each family whose float hyperparameters reach the term's program as
values, not constants, at non-dyadic values, where a constant would round otherwise), and a
model with a torque-path term keeps the whole-model program;
its torque estimate, with the torque-free and linear effect groups evaluated per group, equals
the single-program inversion bit for bit."""

import equinox as eqx
import numpy as np
import pytest

from hdjax.compliance import (
    Column,
    ColumnTimesTorque,
    ComplianceModel,
    Coulomb,
    Harmonics,
    Hysteresis,
    calibrate_lstsq,
)
from hdjax.compliance._inversion import _estimate
from hdjax.compliance._lstsq import design_columns
from hdjax.discover._pipeline import (
    canonical,
    design,
    design_by_terms,
    estimate,
    pipeline_signals,
)
from hdjax.effects import (
    Backlash,
    EncoderSkew,
    Ripple,
    Stiffening,
    Stribeck,
    TwistHysteresis,
    TwistRate,
    Viscous,
)

from .discover_data import JOINT, synthetic_recording


@pytest.mark.parametrize("per_segment", [False, True])
def test_design_by_terms_equals_the_model_design(per_segment):
    rec = synthetic_recording(3, [("temperature", 0.02)], n=3000)
    model = ComplianceModel.paper(JOINT, per_segment=per_segment, current_scale=25.0)
    model = model.with_effects(
        Harmonics(signal="theta_m", orders=(2.0, 1.5, 1.98)),
        Coulomb(signal="omega_l", omega_s=0.05),
        ColumnTimesTorque(name="temperature", center=20.0, scale=2.0, torque_scale=400.0),
        Backlash(width=20.0),
        TwistHysteresis(torque_scale=50.0, compliance=1.5e-5),
        TwistHysteresis(torque_scale=37.0, compliance=1.3e-5, initial=-1.0),
        EncoderSkew(delay=-4.9e-4, ratio=JOINT.ratio, sign=1.0),
        EncoderSkew(delay=1.7e-3, ratio=JOINT.ratio, sign=-1.0),
        Stribeck(signal="omega_m", omega_s=0.3, omega_st=1.7),
        Viscous(signal="omega_l", scale=0.07),
        TwistRate(ratio=JOINT.ratio, sign=1.0, scale=0.013),
        Ripple(signal="theta_l", order=2.7, torque_scale=400.0),
        Stiffening(torque_scale=310.0),
    )
    data = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity)
    sig, torque = data.pair(np.asarray(rec.torque) * 0.9)  # a driver no term here reads
    # the model's own single program, its hyperparameters constants of the program
    expected = np.asarray(eqx.filter_jit(type(model).design)(model, sig, torque))
    np.testing.assert_array_equal(np.asarray(design_columns(model, sig, torque)), expected)
    got = design_by_terms(model, sig, torque)
    assert got.shape == expected.shape == (rec.t.size, model.n_coef)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(design(model, sig, torque), expected)


def test_a_path_term_keeps_the_whole_model_program():
    rec = synthetic_recording(4, n=2000)
    model = ComplianceModel.paper(JOINT, current_scale=25.0).with_effects(
        Hysteresis(torque_scale=40.0)
    )
    data = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity)
    sig, torque = data.pair(np.asarray(rec.torque) * 0.5)
    assert design_by_terms(model, sig, torque) is None
    np.testing.assert_array_equal(
        design(model, sig, torque), np.asarray(design_columns(model, sig, torque))
    )


@pytest.mark.parametrize("per_segment", [False, True])
def test_estimate_by_parts_equals_the_single_program(per_segment):
    rec = synthetic_recording(5, [("temperature", 0.02)], n=12000)
    model = ComplianceModel.paper(JOINT, per_segment=per_segment, current_scale=25.0)
    model = model.with_effects(
        Harmonics(signal="theta_m", orders=(1.98,)),
        Coulomb(signal="omega_l", omega_s=0.05),
        ColumnTimesTorque(name="temperature", center=20.0, scale=2.0, torque_scale=400.0),
        Ripple(signal="theta_l", order=2.7, torque_scale=400.0),
        EncoderSkew(delay=-4.9e-4, ratio=JOINT.ratio, sign=1.0),
        Viscous(signal="omega_m", scale=0.07),
        Column(name="temperature", center=20.3, scale=2.7),
        Backlash(width=20.0),
    )
    data = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity)
    model = canonical(calibrate_lstsq(model, data.pair()).value)
    expected = np.asarray(_estimate(model, data.sig).torque)
    assert np.isfinite(expected).all()
    np.testing.assert_array_equal(estimate(model, data), expected)
    # a model without torque-free or linear effect groups takes the same program
    base = canonical(calibrate_lstsq(model.restructured(effect_terms=()), data.pair()).value)
    np.testing.assert_array_equal(
        estimate(base, data), np.asarray(_estimate(base, data.sig).torque)
    )


def test_estimate_by_parts_with_a_path_term():
    rec = synthetic_recording(6, [("hysteresis", 5e-6, 40.0)], n=6000)
    model = ComplianceModel.paper(JOINT, per_segment=False, current_scale=25.0).with_effects(
        Harmonics(signal="theta_m", orders=(2.0,)),
        Coulomb(signal="omega_l", omega_s=0.05),
        Hysteresis(torque_scale=40.0),
    )
    data = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity)
    model = canonical(calibrate_lstsq(model, data.pair(data.torque)).value)
    expected = np.asarray(_estimate(model, data.sig).torque)
    assert np.isfinite(expected).all()
    np.testing.assert_array_equal(estimate(model, data), expected)


def _compilations(fn) -> list[str]:
    """The names of the programs XLA compiles while `fn` runs."""
    import jax.monitoring as mon

    names = []

    def on_duration(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            names.append(kw.get("fun_name", "?"))

    mon.register_event_duration_secs_listener(on_duration)
    try:
        fn()
    finally:
        mon.unregister_event_duration_listener(on_duration)
    return names


def test_new_hyperparameter_values_compile_nothing():
    # the residual loop builds terms whose orders, delays, widths and scales come from the
    # data: with them as constants of the column and inversion programs, every new joint (and
    # every refinement) compiled each program again; handed in as values, a family already
    # compiled compiles nothing for new values (with the same signs)
    rec = synthetic_recording(7, [("temperature", 0.02)], n=6000)

    def model(k):
        return ComplianceModel.paper(JOINT, per_segment=False, current_scale=25.0).with_effects(
            Harmonics(signal="theta_m", orders=(1.9 + 0.01 * k, 3.0 - 0.02 * k)),
            EncoderSkew(delay=(4.9 + k) * 1e-4, ratio=JOINT.ratio),
            Coulomb(signal="omega_l", omega_s=0.05 + 0.01 * k),
            TwistHysteresis(torque_scale=50.0 + 3 * k, compliance=1.5e-5),
            Ripple(signal="theta_l", order=2.7 - 0.1 * k, torque_scale=400.0),
            Backlash(width=20.0 + k),
        )

    data = pipeline_signals(rec, JOINT.ratio, 1.0, "difference")
    fitted = [canonical(calibrate_lstsq(model(k), data.pair()).value) for k in range(2)]

    def run(m):
        design(m, *data.pair())
        design_columns(m, *data.pair())
        estimate(m, data)

    run(fitted[0])
    again = _compilations(lambda: run(fitted[1]))
    assert not again, again


class _ConstantScale(Viscous):
    """A family written elsewhere whose columns need their scale as a Python float."""

    def transform(self, x, xp):
        return x / float(self.scale)


def test_a_term_that_needs_its_hyperparameters_as_constants_still_works():
    # its columns cannot trace with the scale as a value: the programs run it with the constant
    # (as before), and the residual loop's design still equals the model's own program
    rec = synthetic_recording(8, n=3000)
    model = ComplianceModel.paper(JOINT, per_segment=False, current_scale=25.0).with_effects(
        _ConstantScale(signal="omega_l", scale=0.07), Coulomb(signal="omega_l", omega_s=0.05)
    )
    data = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity)
    sig, torque = data.pair()
    expected = np.asarray(eqx.filter_jit(type(model).design)(model, sig, torque))
    np.testing.assert_array_equal(design_by_terms(model, sig, torque), expected)
    np.testing.assert_array_equal(np.asarray(design_columns(model, sig, torque)), expected)
    fitted = canonical(calibrate_lstsq(model, data.pair()).value)
    np.testing.assert_array_equal(
        estimate(fitted, data), np.asarray(_estimate(fitted, data.sig).torque)
    )
