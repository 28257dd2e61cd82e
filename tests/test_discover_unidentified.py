"""A log that cannot identify a family is told so in one line that names the family and the
data that would identify it (not refused, not silently skipped)."""

import numpy as np

import hdjax
from hdjax.compliance import ComplianceModel
from hdjax.discover import pipeline_signals
from hdjax.discover._library import build_library

from .helpers import JOINT


def _standstill(n=2000):
    # the joint held still under a small, slowly varying load: the link never moves and the
    # twist swings through far less torque path than any hysteresis loop searched
    t = np.arange(n) * 1e-3
    torque = 0.2 * np.sin(2 * np.pi * t / 2.0)
    # the output encoder reads a constant; the motor side carries the twist
    theta_m = JOINT.ratio * (0.3 - torque * 1.5e-5)
    return hdjax.make_recording(
        t=t,
        theta_m=theta_m,
        theta_l=np.full(n, 0.3),
        current=torque / 10.0,
        torque=torque,
        extras={},
        source="standstill",
    )


def test_a_log_that_cannot_identify_a_family_says_so_in_one_line_each():
    rec = _standstill()
    model = ComplianceModel.paper(JOINT, per_segment=False)
    sig = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity).sig
    notes = []
    build_library(sig, np.asarray(rec.torque), np.zeros(rec.n_samples), model, unidentified=notes)
    by_family = {n.split(" cannot be identified")[0]: n for n in notes}
    assert "skew:encoders" in by_family, notes
    assert "record the joint moving" in by_family["skew:encoders"]
    assert "hysteresis:torque" in by_family, notes
    assert "wider torque range" in by_family["hysteresis:torque"]
    assert all("\n" not in n for n in notes)
