"""The residual loop's design matrix, assembled from one compiled program per term, equals the
compliance model's own design bit for bit (shared and per-segment base terms, effects of every
torque kind but the path), and a model with a torque-path term keeps the whole-model program;
its torque estimate, with the torque-free and linear effect groups evaluated per group, equals
the single-program inversion bit for bit."""

import numpy as np
import pytest

from hdjax.compliance import (
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
from hdjax.effects import Backlash, TwistHysteresis

from .discover_data import JOINT, synthetic_recording


@pytest.mark.parametrize("per_segment", [False, True])
def test_design_by_terms_equals_the_model_design(per_segment):
    rec = synthetic_recording(3, [("temperature", 0.02)], n=3000)
    model = ComplianceModel.paper(JOINT, per_segment=per_segment, current_scale=25.0)
    model = model.with_effects(
        Harmonics(signal="theta_m", orders=(2.0, 1.5)),
        Coulomb(signal="omega_l", omega_s=0.05),
        ColumnTimesTorque(name="temperature", center=20.0, scale=2.0, torque_scale=400.0),
        Backlash(width=20.0),
        TwistHysteresis(torque_scale=50.0, compliance=1.5e-5),
    )
    data = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity)
    sig, torque = data.pair(np.asarray(rec.torque) * 0.9)  # a driver no term here reads
    expected = np.asarray(design_columns(model, sig, torque))
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
        Harmonics(signal="theta_m", orders=(2.0,)),
        Coulomb(signal="omega_l", omega_s=0.05),
        ColumnTimesTorque(name="temperature", center=20.0, scale=2.0, torque_scale=400.0),
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
