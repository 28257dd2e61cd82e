"""Torque estimation, Song et al. eqs. (26)-(27): forward model then inversion, segment rules."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st

import hdjax
from hdjax.compliance import (
    ComplianceModel,
    Signals,
    estimate_torque,
    estimate_torque_single,
    torque_estimator,
)
from tests.helpers import JOINT, make_signals, simulate

N_PROP = 64  # samples per hypothesis example (fixed shape: one compilation)


@pytest.fixture(scope="session")
def shared_model():
    return simulate("inv-shared", 10, per_segment=False, seed=31).model


@pytest.fixture(scope="session")
def segment_model():
    # per-segment blocks differ by 1 % of their size: neighbouring h differ by ~1e-6 rad
    return simulate("inv-seg", 10, per_segment=True, seed=32, spread=0.01).model


_predict = eqx.filter_jit(lambda m, s, t: m.predict_twist(s, t))


def _forward(model, torque, seed):
    sig, torque = make_signals(len(torque), seed=seed, torque=np.asarray(torque))
    twist = _predict(model, sig, jnp.asarray(torque))
    return eqx.tree_at(lambda s: s.twist, sig, twist), torque


torques = st.lists(
    st.floats(-1.2 * JOINT.rated_torque, 1.2 * JOINT.rated_torque), min_size=N_PROP, max_size=N_PROP
)
SETTINGS = settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


ON_KNOTS = [-60.0, -30.0, 30.0, 60.0] * (N_PROP // 4)  # found by hypothesis: ties at a knot


@SETTINGS
@given(torque=torques, seed=st.integers(0, 2**16))
@example(torque=ON_KNOTS, seed=8995)
def test_forward_then_inverse_shared(shared_model, torque, seed):
    sig, torque = _forward(shared_model, torque, seed)
    est = estimate_torque(shared_model, sig)
    # a shared (continuous, increasing) compliance has exactly one self-consistent segment;
    # the inversion is exact up to rounding: |dT| <~ |twist| u / k ~ 1e-12 N·m
    t = np.asarray(est.torque)
    np.testing.assert_allclose(t, torque, rtol=0, atol=1e-9)
    assert not np.asarray(est.unresolved).any()
    # a torque on a knot (to rounding) is self-consistent in both neighbours: the only
    # ambiguity allowed, and the only place the segment may differ from eq. (7)'s [l, u)
    at_knot = np.min(np.abs(t[:, None] - np.asarray(shared_model.knots)[None, :]), axis=1) < 1e-9
    assert not np.asarray(est.ambiguous)[~at_knot].any()
    seg = np.asarray(shared_model.segment_index(torque))
    np.testing.assert_array_equal(np.asarray(est.segment)[~at_knot], seg[~at_knot])


@SETTINGS
@given(torque=torques, seed=st.integers(0, 2**16))
@example(torque=ON_KNOTS, seed=8995)
@example(torque=ON_KNOTS, seed=35)
def test_forward_then_inverse_per_segment(segment_model, torque, seed):
    m = segment_model
    sig, torque = _forward(m, torque, seed)
    est = estimate_torque(m, sig)
    t = np.asarray(est.torque)
    amb = np.asarray(est.ambiguous)
    # the true segment's candidate is always self-consistent, so a sample is never unresolved
    assert not np.asarray(est.unresolved).any()
    # exactly one valid segment: the inversion is exact
    np.testing.assert_allclose(t[~amb], torque[~amb], rtol=0, atol=1e-9)
    # several valid: the pick may be a neighbour, off by at most the jump of h between
    # segments divided by the smallest compliance (here < 0.5 N·m), and only near a knot
    h = np.asarray(m.base_columns(sig) @ m.base_coef.T)
    bound = np.max(np.abs(np.diff(h, axis=1))) / float(np.min(np.asarray(m.k)))
    assert np.all(np.abs(t - torque) <= bound + 1e-9)
    if amb.any():
        near = np.min(np.abs(torque[amb, None] - np.asarray(m.knots)[None, :]), axis=1)
        assert np.all(near <= bound + 1e-9)


def _two_segment_model(h_left, h_right, k=(2e-5, 3e-5)):
    """Two segments split at +30 N·m, per-segment blocks holding only the constant $k_0$."""
    joint = hdjax.Joint(ratio=101.0, rated_torque=60.0)
    m = ComplianceModel.paper(joint, knots=(30.0,), poly_order=0, kinematic="none")
    coef = jnp.asarray([k[0], k[1], h_left, h_right])
    return eqx.tree_at(lambda mm: mm.coef, m, coef)


def _sig_of_twist(twist):
    z = jnp.zeros(len(twist), jnp.float64)
    return Signals(
        twist=jnp.asarray(twist, jnp.float64),
        current=z,
        theta_m=z,
        theta_l=z,
        omega_m=z,
        omega_l=z,
        extras={},
    )


def test_rule_several_valid_takes_the_deepest():
    # h jumps down by 1e-4 rad at the knot: twists just below 30 k0 are reachable from both
    # segments (overlap). Candidates: T0 = r/k0 and T1 = 30 + (r - h1 - 30 k0)/k1.
    m = _two_segment_model(0.0, -1e-4)
    r = 30.0 * 2e-5 - 0.5e-4  # T0 = 27.5 (depth 2.5/60 in segment 0), T1 = 31.67 (1.67/60)
    est = estimate_torque(m, _sig_of_twist([r]))
    assert bool(est.ambiguous[0]) and not bool(est.unresolved[0])
    assert int(est.segment[0]) == 0 and float(est.torque[0]) == pytest.approx(27.5)
    r = 30.0 * 2e-5 - 0.9e-4  # T0 = 25.5 (depth 4.5/60), T1 = 30.33 (0.33/60): segment 0 again
    r2 = 30.0 * 2e-5 - 0.1e-4  # T0 = 29.5 (0.5/60), T1 = 33.0 (3/60): segment 1 is deeper
    est = estimate_torque(m, _sig_of_twist([r, r2]))
    np.testing.assert_array_equal(np.asarray(est.segment), [0, 1])
    np.testing.assert_allclose(np.asarray(est.torque), [25.5, 33.0])


def test_rule_none_valid_takes_the_nearest_segment_edge():
    # h jumps up by 1e-4 rad at the knot: twists in (30 k0, 30 k0 + 1e-4) belong to no segment
    m = _two_segment_model(0.0, 1e-4)
    r = 30.0 * 2e-5 + 0.2e-4  # T0 = 31 (1 N·m outside), T1 = 30 - 2.67 (2.67 outside)
    r2 = 30.0 * 2e-5 + 0.9e-4  # T0 = 34.5 (4.5 outside), T1 = 29.67 (0.33 outside)
    est = estimate_torque(m, _sig_of_twist([r, r2]))
    np.testing.assert_array_equal(np.asarray(est.unresolved), [True, True])
    np.testing.assert_array_equal(np.asarray(est.segment), [0, 1])
    np.testing.assert_allclose(np.asarray(est.torque), [30.0, 30.0])  # clipped onto the knot


def test_out_of_range_is_flagged(shared_model):
    lo, hi = shared_model.torque_range
    assert (lo, hi) == (-90.0, 90.0)
    sig, torque = _forward(shared_model, [-120.0, -89.0, 0.0, 89.0, 95.0], seed=1)
    est = estimate_torque(shared_model, sig)
    np.testing.assert_allclose(np.asarray(est.torque), torque, atol=1e-9)  # still estimated
    np.testing.assert_array_equal(np.asarray(est.in_range), [False, True, True, True, False])


def test_single_sample_matches_batch(segment_model):
    sig, torque = _forward(segment_model, np.linspace(-80, 80, 9), seed=2)
    batch = estimate_torque(segment_model, sig)
    for i in range(9):
        x = [
            float(getattr(sig, k)[i])
            for k in Signals.__dataclass_fields__
            if k not in ("extras", "t")
        ]
        one = estimate_torque_single(segment_model, *x)
        assert one.torque == pytest.approx(float(batch.torque[i]), abs=1e-12)
        assert one.segment == int(batch.segment[i]) and one.in_range == bool(batch.in_range[i])
        assert one.ambiguous == bool(batch.ambiguous[i])


def test_estimate_from_recording_ignores_its_torque():
    from hdjax.compliance import calibrate_lstsq
    from tests.helpers import sim_recording

    rec = sim_recording(400)
    model = ComplianceModel.paper(JOINT, per_segment=False, poly_order=1, kinematic="none")
    model = calibrate_lstsq(model, rec).value
    est = estimate_torque(model, rec)
    est2 = estimate_torque(model, rec.with_torque(np.zeros(rec.n_samples)))
    np.testing.assert_array_equal(np.asarray(est.torque), np.asarray(est2.torque))
    # the simulated twist is exactly linear: torque recovered to the noise of the current fit
    np.testing.assert_allclose(np.asarray(est.torque), np.asarray(rec.torque), atol=1e-6)


def test_non_increasing_compliance_is_refused(shared_model):
    flipped = eqx.tree_at(lambda m: m.coef, shared_model, -shared_model.coef)
    sig, _ = make_signals(5, seed=0)
    with pytest.raises(hdjax.InversionError, match="twist_sign = -1"):
        estimate_torque(flipped, sig)
    with pytest.raises(hdjax.InversionError, match="not increasing"):
        torque_estimator(flipped)


def test_missing_extra_column_is_a_model_mismatch(shared_model):
    from hdjax.compliance import Column

    m = shared_model.with_effects(Column("temperature"))
    m = eqx.tree_at(lambda mm: mm.coef, m, jnp.concatenate([shared_model.coef, jnp.zeros(1)]))
    sig, _ = make_signals(5, seed=0)
    with pytest.raises(hdjax.ModelMismatchError, match="temperature"):
        estimate_torque(m, sig)


def test_estimator_does_not_recompile(shared_model):
    from hdjax.compliance._inversion import _estimate

    sig, _ = _forward(shared_model, np.zeros(N_PROP), seed=3)
    estimate_torque(shared_model, sig)
    size = _estimate._cached._cache_size()
    sig2 = jax.tree_util.tree_map(lambda x: x * 1.01, sig)
    estimate_torque(shared_model, sig2)
    assert _estimate._cached._cache_size() == size
