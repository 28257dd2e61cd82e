"""hdjax.compliance.merge_sparse_segments: which knots go, worked out by hand from the rule.

Rated torque 300 N·m, five segments: knots -200, -100, 100, 200 (the paper's +-tau0/3,
+-2 tau0/3), so the segments are (-inf, -200), [-200, -100), [-100, 100) (central, never
merged), [100, 200), [200, inf). Inner segments are 100 N·m wide, and the outer ones are
measured against that width. A segment is kept when it holds at least 30 samples spanning at
least 25 % of its width; otherwise the knot on its side facing 0 N·m goes, and the rule is
applied again to the new layout. An empty segment is left to the calibration.
"""

import numpy as np
import pytest

import hdjax
from hdjax.compliance import ComplianceModel, merge_sparse_segments

JOINT = hdjax.Joint(ratio=160.0, rated_torque=300.0)
KNOTS = (-200.0, -100.0, 100.0, 200.0)


def _model():
    model = ComplianceModel.paper(JOINT, per_segment=False)
    assert model.knots == KNOTS  # the layout the expectations below are worked out on
    return model


def _spread(lo, hi, n):
    """`n` torques spread evenly over [lo, hi] (span hi - lo exactly)."""
    return np.linspace(lo, hi, n)


# every segment but the one under test well covered: 200 samples over most of its width
FULL = {
    "below": _spread(-290.0, -210.0, 200),  # outer: span 80 of 100
    "neg": _spread(-195.0, -105.0, 200),
    "centre": _spread(-95.0, 95.0, 400),
    "pos": _spread(105.0, 195.0, 200),
    "above": _spread(210.0, 290.0, 200),
}


def _torque(**replace):
    return np.concatenate([replace.get(k, v) for k, v in FULL.items()])


def test_well_covered_segments_are_kept():
    model = _model()
    same, notes = merge_sparse_segments(model, _torque())
    assert same is model and notes == []
    # thresholds are inclusive: exactly 30 samples spanning exactly 25 N·m (25 % of 100) stay
    edge = _spread(120.0, 145.0, 30)
    same, notes = merge_sparse_segments(model, _torque(pos=edge))
    assert same.knots == KNOTS and notes == []


@pytest.mark.parametrize(
    "segment, torques, knots, words",
    [
        # 29 samples in [100, 200): one too few; its knot facing 0 N·m is 100
        ("pos", _spread(105.0, 195.0, 29), (-200.0, -100.0, 200.0), "[100, 200) N·m holds 29"),
        # 100 samples spanning 20 N·m of [-200, -100): 20 % cover; the knot facing 0 is -100
        ("neg", _spread(-180.0, -160.0, 100), (-200.0, 100.0, 200.0), "covering 20%"),
        # outer [200, inf): 100 samples over 24 N·m, 24 % of the inner width; knot 200 goes
        ("above", _spread(230.0, 254.0, 100), (-200.0, -100.0, 100.0), "[200, inf)"),
        # outer (-inf, -200) with 10 samples: knot -200 goes
        ("below", _spread(-260.0, -220.0, 10), (-100.0, 100.0, 200.0), "[-inf, -200)"),
    ],
)
def test_a_sparse_segment_loses_its_inner_knot(segment, torques, knots, words):
    model = _model()
    merged, notes = merge_sparse_segments(model, _torque(**{segment: torques}))
    assert merged.knots == knots
    assert len(notes) == 1 and words in notes[0] and "merged into its neighbour" in notes[0]
    removed = (set(KNOTS) - set(knots)).pop()
    assert f"knot {removed:g} removed" in notes[0]
    # the coefficients are reset for the new layout: one compliance per remaining segment
    assert merged.n_segments == len(knots) + 1 and not np.any(np.asarray(merged.coef))


def test_merges_cascade_and_empty_segments_stay():
    model = _model()
    # [100, 200) holds 5 samples: knot 100 goes, and [-100, 200) is now central. [200, inf)
    # holds 100 samples over 210..260: 50 % of the paper's 100 N·m segment width, kept (the
    # merged segment, 300 N·m wide, is not the measure: against it the cover would be 17 %).
    # Nothing below -200 N·m: that segment is empty and left for the calibration to drop.
    t = _torque(pos=_spread(120.0, 180.0, 5), above=_spread(210.0, 260.0, 100), below=np.array([]))
    merged, notes = merge_sparse_segments(model, t)
    assert merged.knots == (-200.0, -100.0, 200.0) and len(notes) == 1
    # both positive segments sparse: [100, 200) first (knot 100), then [200, inf), now beside
    # the central [-100, 200), loses knot 200; the negative side is untouched
    t = _torque(pos=_spread(120.0, 180.0, 5), above=_spread(210.0, 215.0, 100))
    merged, notes = merge_sparse_segments(model, t)
    assert merged.knots == (-200.0, -100.0) and len(notes) == 2
    assert "knot 100 removed" in notes[0] and "knot 200 removed" in notes[1]
    # the thresholds are arguments: with min_samples = 5 the 5-sample segment stays
    merged, notes = merge_sparse_segments(model, _torque(pos=_spread(120.0, 180.0, 5)),
                                          min_samples=5)  # fmt: skip
    assert merged.knots == KNOTS and notes == []
