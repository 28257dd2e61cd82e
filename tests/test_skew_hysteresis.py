"""A hysteresis of the measured twist beside an encoder time skew follows the deflection, the
twist of the two encoders read at one instant.

With the load encoder read `delay` after the motor encoder, the recorded twist carries about
`delay * omega_l` besides the deflection: a step each time the joint starts or stops, of tens of
N·m of torque path on a real joint (2 ms at 0.4 rad/s is half the width of a typical loop),
which a Dahl state of the recorded twist follows although the flexspline never did. In a model
that holds both terms, the state's driver is the twist less the skew's column.

Reference: the deflection itself, computed here from the motion the recording was sampled
from (closed form), at the instant the later encoder's sample is interpolated back to.
"""

import jax
import numpy as np
import pytest

import hdjax
from hdjax import ConfigError
from hdjax.compliance import ComplianceModel
from hdjax.discover import pipeline_signals
from hdjax.effects import EncoderSkew, TwistHysteresis
from hdjax.effects.internal import DahlCarry

RATIO, K = 160.0, 1.0 / 6.7e4
JOINT = hdjax.Joint(ratio=RATIO, rated_torque=400.0)


def _link(t):
    # starts at rest, speeds up to 0.8 rad/s and stops again every 2 s
    return 0.4 * (t - np.sin(np.pi * t) / np.pi)


def _deflection(t):
    return 3e-4 * np.sin(3.0 * t) + 1e-4 * np.tanh(5.0 * np.sin(np.pi * t / 2))


def _signals(delay, n=4000, seed=0):
    rng = np.random.default_rng(seed)
    t = 1e-3 * np.arange(n) + rng.uniform(-2e-4, 2e-4, n)  # jittered sample instants
    theta_m = RATIO * (_link(t) - _deflection(t))  # twist = theta_l - theta_m / N
    theta_l = _link(t + delay)  # the load encoder read `delay` after the motor encoder
    rec = hdjax.make_recording(t, theta_m, theta_l, np.zeros(n), np.zeros(n))
    return t, pipeline_signals(rec, RATIO, 1.0, "difference").sig


def _model(delay):
    hyst = TwistHysteresis(torque_scale=40.0, compliance=K)
    base = ComplianceModel.paper(JOINT, poly_order=0, kinematic="none", per_segment=False)
    return base.with_effects(EncoderSkew(delay=delay, ratio=RATIO), hyst)


@pytest.mark.parametrize("delay", [2e-3, -1.3e-3])
def test_the_state_of_a_model_with_a_skew_follows_the_deflection(delay):
    t, sig = _signals(delay)
    model = _model(delay)
    term = model.effect_terms[1]
    assert (term.skew, term.ratio, term.sign) == (delay, RATIO, 1.0)
    # the instant both encoders are read at once after the interpolation: the earlier one's
    at = t + min(delay, 0.0)
    truth = _deflection(at)
    driver = np.asarray(term.dahl_driver(sig)) * K
    recorded = np.asarray(sig.twist)
    skip = 20  # the interpolation has no samples before the record's start
    step = abs(delay) * np.abs(np.gradient(_link(t), t)).max()  # what the skew adds at most
    assert np.abs(driver - truth)[skip:].max() < 0.01 * step
    assert np.abs(recorded - truth)[skip:].max() > 0.5 * step
    # without the skew the same term reads the recorded twist
    plain = ComplianceModel.paper(JOINT, poly_order=0, kinematic="none", per_segment=False)
    alone = plain.with_effects(TwistHysteresis(torque_scale=40.0, compliance=K)).effect_terms[0]
    assert alone.skew == 0.0
    np.testing.assert_allclose(np.asarray(alone.dahl_driver(sig)), recorded / K, rtol=1e-15)
    # the saved model keeps the alignment
    again = ComplianceModel.from_dict(model.to_dict())
    assert again.effect_terms == model.effect_terms


def test_the_aligned_state_is_the_same_whole_in_numpy_in_jax_and_chunk_by_chunk():
    _, sig = _signals(2e-3, n=1000)
    term = _model(2e-3).effect_terms[1]
    whole = np.asarray(term.numpy_columns(sig))[:, 0]
    np.testing.assert_allclose(np.asarray(term.columns(sig))[:, 0], whole, rtol=0, atol=1e-12)
    assert np.ptp(whole) > 0.3  # the state moves
    carry, parts = DahlCarry(), []
    for lo in range(0, 1000, 97):  # the driver reads 17 samples back, across each join
        hi = min(lo + 97, 1000)
        part = jax.tree_util.tree_map(lambda x: x[lo:hi], sig)
        parts.append(carry.column(0, term, part, None, hi - lo, numpy=True))
    np.testing.assert_allclose(np.concatenate(parts), whole, rtol=0, atol=1e-12)


@pytest.mark.parametrize("field", ["skew", "sign"])
def test_a_non_finite_alignment_is_refused_with_what_it_is(field):
    # a NaN delay would make every state NaN without a word: refused at construction
    with pytest.raises(ConfigError, match=f"TwistHysteresis: {field} .* must be finite, got nan"):
        TwistHysteresis(torque_scale=40.0, compliance=K, **{field: float("nan")})
