"""One estimator interface (compliance model, network, hybrid) and one fit result.

Each estimator must return exactly what its underlying function returns (the reference: the
same call made directly), and the abstract interface cannot be instantiated.
"""

import jax
import numpy as np
import pytest

import hdjax
from hdjax import compliance as hc, fit, network as hn, pipelines, plant

JOINT = hdjax.Joint(ratio=160, rated_torque=400)


@pytest.fixture(scope="module")
def rec():
    # the recording of test_signals.py (one compiled simulation serves both)
    r = plant.simulate_scenario("fast", key=jax.random.PRNGKey(3), duration=4.0)
    return r.select(np.asarray(r.t) >= 0.2)


def test_estimators_return_what_their_functions_return(rec):
    structure = hc.ComplianceModel.paper(JOINT, n_segments=1, per_segment=False, kinematic="none")
    model = hc.calibrate_lstsq(structure, rec).value
    feats = hn.build_features(rec, JOINT)
    net = hn.Network(feats.layout, (4,), key=jax.random.key(0))
    inputs = fit.hybrid_inputs(rec, JOINT, compliance=model, twist_rate=True)
    hyb = fit.make_hybrid(inputs, compliance=model, hidden=(4,), key=jax.random.key(1))
    cases = [
        (fit.ComplianceEstimator(model), hc.estimate_torque(model, rec).torque),
        (fit.NetworkEstimator(net, JOINT), hn.predict_torque(net, rec, JOINT)),
        (
            fit.HybridEstimator(hyb, model, JOINT, (("twist_rate", True),)),
            fit.predict_hybrid(hyb, inputs),
        ),
    ]
    for estimator, reference in cases:
        assert isinstance(estimator, fit.AbstractEstimator)
        got = np.asarray(estimator.estimate(rec))
        assert got.shape == (rec.n_samples,)
        np.testing.assert_array_equal(got, np.asarray(reference))
    with pytest.raises(TypeError):
        fit.AbstractEstimator()


def test_solution_results_say_what_to_do():
    ok = hdjax.Solution(1.0, hdjax.RESULTS.successful, {"steps": 3})
    assert ok.ok and ok.message == "" and ok.raise_if_failed() is ok
    bad = hdjax.Solution(1.0, hdjax.RESULTS.rank_deficient, {})
    assert not bad.ok and "add load variation" in bad.message
    with pytest.raises(hdjax.CalibrationError, match="excitation too poor"):
        bad.raise_if_failed()


def test_comparison_methods_are_a_loop_over_fitters():
    assert tuple(pipelines.FITTERS) == pipelines.METHOD_NAMES
