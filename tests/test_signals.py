"""One function derives the signals (`hdjax.signals`): a joint whose twist falls as torque rises.

A joint whose encoders count the other way (both angles negated) has a recorded twist
$\\theta_l - \\theta_m/N$ that *falls* as the torque rises; `hdjax.Joint(twist_sign=-1)` says so.
Every consumer (the compliance model's calibration and inversion, the network's features, the
hybrid fits' inputs) must then see the same twist as on the original recording with
`twist_sign=+1`. References: the original recording (an independent path through the same
physics), and the closed form of eq. (5).
"""

import equinox as eqx
import jax
import numpy as np
import pytest

import hdjax
from hdjax import compliance as hc, plant
from hdjax.fit import hybrid_inputs
from hdjax.network import build_features

POS = hdjax.Joint(ratio=160, rated_torque=400, twist_sign=1)
NEG = hdjax.Joint(ratio=160, rated_torque=400, twist_sign=-1)


@pytest.fixture(scope="module")
def recordings():
    rec = plant.simulate_scenario("fast", key=jax.random.PRNGKey(3), duration=4.0)
    rec = rec.select(np.asarray(rec.t) >= 0.2)
    flipped = eqx.tree_at(lambda r: (r.theta_m, r.theta_l), rec, (-rec.theta_m, -rec.theta_l))
    return rec, flipped


def test_twist_with_the_joint_sign(recordings):
    rec, flipped = recordings
    s_pos, s_neg = hdjax.signals(rec, POS), hdjax.signals(flipped, NEG)
    closed = np.asarray(rec.theta_l) - np.asarray(rec.theta_m) / 160.0  # eq. (5)
    np.testing.assert_allclose(np.asarray(s_pos.twist), closed, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(s_neg.twist), np.asarray(s_pos.twist))
    np.testing.assert_array_equal(np.asarray(s_neg.omega_m), -np.asarray(s_pos.omega_m))
    # the twist grows with the torque on the original and with the sign on the flipped one
    c = np.corrcoef(np.asarray(s_neg.twist), np.asarray(rec.torque))[0, 1]
    c_raw = np.corrcoef(np.asarray(hdjax.signals(flipped, POS).twist), np.asarray(rec.torque))
    assert c > 0.9 and c_raw[0, 1] < -0.9
    assert s_pos.gaps().size == 0
    assert hc.Signals.concatenate([s_pos, s_pos]).gaps().tolist() == [s_pos.n_samples - 1]


def test_calibration_and_inversion_follow_the_sign(recordings):
    rec, flipped = recordings
    est = {}
    for name, joint, data in (("pos", POS, rec), ("neg", NEG, flipped)):
        structure = hc.ComplianceModel.paper(
            joint,
            n_segments=1,
            per_segment=False,
            kinematic="harmonic",
            harmonic_orders_l=(),
            current_scale=10.0,
        )
        model = hc.calibrate_lstsq(structure, data).value
        assert model.joint == joint
        est[name] = np.asarray(hc.estimate_torque(model, data).torque)
    # the same column space (cos even, sin odd in the angle, current unchanged): the same fit
    scale = float(np.max(np.abs(est["pos"])))
    np.testing.assert_allclose(est["neg"], est["pos"], rtol=0, atol=1e-8 * scale)
    err = np.sqrt(np.mean((est["neg"] - np.asarray(rec.torque)) ** 2))
    assert err < 0.05 * POS.rated_torque


def test_network_and_hybrid_inputs_follow_the_sign(recordings):
    rec, flipped = recordings
    f_pos, f_neg = build_features(rec, POS), build_features(flipped, NEG)
    i = f_pos.layout.names.index("twist")
    np.testing.assert_array_equal(np.asarray(f_neg.x[:, i]), np.asarray(f_pos.x[:, i]))
    model = hc.ComplianceModel.paper(NEG, per_segment=False, kinematic="none")
    h = hybrid_inputs(flipped, NEG, compliance=model, twist_rate=True, hysteresis=(1e-4,))
    h_pos = hybrid_inputs(rec, POS, compliance=hc.ComplianceModel.paper(POS, kinematic="none"))
    np.testing.assert_array_equal(np.asarray(h.sig.twist), np.asarray(h_pos.sig.twist))
    names = h.layout.names
    rate = np.asarray(h.x[:, names.index("twist_rate")])
    assert np.corrcoef(rate, np.gradient(np.asarray(rec.torque)))[0, 1] > 0.5


def test_signals_from_recording_takes_the_joint(recordings):
    rec, flipped = recordings
    a = hc.signals_from_recording(flipped, NEG)
    np.testing.assert_array_equal(np.asarray(a.twist), np.asarray(hdjax.signals(rec, POS).twist))
    with pytest.raises(hdjax.HdjaxError, match="contradicts"):
        hc.signals_from_recording(flipped, NEG, 1.0)
    with pytest.raises(hdjax.HdjaxError, match="needs an hdjax.Joint"):
        hdjax.signals(rec, 160.0)
