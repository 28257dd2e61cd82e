"""A model holds at most one speed column (`_library.VELOCITY_KEYS`).

An encoder skew adds a twist `delay * omega_l`, viscous friction one in proportion to either
side's speed: to first order the same column. Beside one of them, another fits only their
second-order difference, with two large coefficients of opposite sign, and the skew's delay is
then no longer what the data say. Reference: which keys the library offers, with and without a
speed term in the model.
"""

import numpy as np

from hdjax.compliance import ComplianceModel
from hdjax.discover import pipeline_signals
from hdjax.discover._library import VELOCITY_KEYS, build_library
from hdjax.effects import EncoderSkew

from .helpers import JOINT, path_recording


def _to_and_fro(n=4000):
    t = np.arange(n) * 1e-3
    theta_l = 0.8 * np.sin(2 * np.pi * t / 2.0) + 0.2 * np.sin(2 * np.pi * t / 0.7)
    torque = 30.0 * np.sin(theta_l) + 5.0 * np.cos(2 * np.pi * t / 0.7)
    return path_recording(theta_l, torque, torque * 1.5e-5, dt=1e-3, source="to and fro")


def _offered(model):
    rec = _to_and_fro()
    sig = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity).sig
    resid = 1e-5 * np.asarray(sig.omega_l)  # a twist in proportion to the speed
    notes: list[str] = []
    cands, _ = build_library(sig, np.asarray(rec.torque), resid, model, unidentified=notes)
    return {c.key for c in cands}, notes


def test_beside_a_skew_no_viscous_friction_is_offered_and_the_note_says_why():
    start = ComplianceModel.paper(JOINT, per_segment=False)
    keys, notes = _offered(start)
    assert set(VELOCITY_KEYS) <= keys  # without a speed term, all three are candidates
    keys, notes = _offered(start.with_effects(EncoderSkew(delay=1e-3, ratio=JOINT.ratio)))
    assert not keys & set(VELOCITY_KEYS), keys
    said = [n for n in notes if n.startswith("viscous:omega_l and viscous:omega_m cannot")]
    assert len(said) == 1, notes
    assert "beside skew:encoders" in said[0] and "motor current" in said[0]
    assert "damping:twist_rate" in keys  # the twist rate keeps its own family
