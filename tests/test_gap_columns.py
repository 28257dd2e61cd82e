"""The columns that look back in time (the encoder skew's interpolation, the twist rate one
sample late) never read across a long gap.

A record with a long gap (two recordings joined, the blocks of a split log) holds segments in
which the joint may have moved anywhere between them. The skew's column interpolates the
encoder read earlier back by the delay; across such a gap that interpolation reads the jump
between the segments as a speed the joint never had, a spike of up to the whole jump over the
delay. One spike per join is enough to bias the fitted delay wherever the starting model's
columns take most of the speed (measured on a two-speed TRAIN: 1.24 ms fitted for 1.79 ms).

Reference: the column of each segment computed on that segment alone (a recording of its own),
which is what the joined record must give, the same rule as the velocities (which never cross
a gap) and the memory states (which restart after a long one).
"""

import numpy as np
import pytest

import hdjax
from hdjax.discover import pipeline_signals
from hdjax.effects import EncoderSkew, TwistRate

RATIO = 160.0


def _segment(t0, theta0, n=400, speed=0.3, seed=0):
    rng = np.random.default_rng(seed)
    t = t0 + 1e-3 * np.arange(n) + rng.uniform(-2e-4, 2e-4, n)  # jittered sample instants
    theta_l = theta0 + speed * (t - t0) + 0.02 * np.sin(7.0 * (t - t0))
    twist = 2e-5 * np.sin(3.0 * (t - t0))
    return t, RATIO * (theta_l + twist), theta_l


def _recording(*segments):
    t, tm, tl = (np.concatenate(x) for x in zip(*segments))
    return hdjax.make_recording(t, tm, tl, np.zeros_like(t), np.zeros_like(t))


def _columns(term, rec):
    sig = pipeline_signals(rec, RATIO, 1.0, "difference").sig
    return np.asarray(term.numpy_columns(sig))[:, 0], np.asarray(term.columns(sig))[:, 0]


@pytest.mark.parametrize("delay", [1.8e-3, -2.4e-3])
def test_the_skew_column_of_a_joined_record_is_each_segments_own(delay):
    # the second segment starts 1 s later, 2.3 rad away: the join of two sweeps
    a, b = _segment(0.0, -1.2), _segment(1.4, 1.2, seed=1)
    term = EncoderSkew(delay=delay, ratio=RATIO)
    joined_np, joined_jnp = _columns(term, _recording(a, b))
    own = [_columns(term, _recording(s)) for s in (a, b)]
    n = a[0].size
    for got in (joined_np, joined_jnp):
        np.testing.assert_allclose(got[:n], own[0][0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(got[n:], own[1][0], rtol=0, atol=1e-9)
    # the reference itself: away from the segment's start, the column is the link speed
    # (the motor angle over the ratio for a negative delay, both within the twist's rate)
    np.testing.assert_allclose(own[1][0][10:], own[1][1][10:], atol=1e-9)
    assert np.abs(own[1][0][10:] - 0.3).max() < 0.2


def test_the_twist_rate_of_a_joined_record_is_each_segments_own():
    # one sample late, the damping column read the first segment's last rate at the second
    # segment's first sample (measured: off by 0.38 of the column's scale at the join here)
    a, b = _segment(0.0, -1.2), _segment(1.4, 1.2, seed=1)
    term = TwistRate(ratio=RATIO, sign=1.0, scale=1e-4)
    joined = _columns(term, _recording(a, b))
    own = [_columns(term, _recording(s)) for s in (a, b)]
    n = a[0].size
    for got in joined:
        np.testing.assert_allclose(got[:n], own[0][0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(got[n:], own[1][0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(own[1][0], own[1][1], rtol=0, atol=1e-9)


def test_a_dropped_sample_is_interpolated_across():
    # a gap of two sample periods (a dropped sample) is no segment start: the column reads
    # across it as on the record without the gap, to the interpolation's accuracy
    t, tm, tl = _segment(0.0, 0.0)
    keep = np.ones(t.size, bool)
    keep[200] = False
    term = EncoderSkew(delay=1.5e-3, ratio=RATIO)
    full, _ = _columns(term, _recording((t, tm, tl)))
    dropped, _ = _columns(term, _recording((t[keep], tm[keep], tl[keep])))
    np.testing.assert_allclose(dropped, full[keep], atol=2e-3)
