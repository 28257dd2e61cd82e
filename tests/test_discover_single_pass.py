"""One pass over an angle does not confirm a spectrum peak of a few periods
(`_library.angle_passes`, `_library.repeats_in_span`).

On a one-way sweep every output angle is seen once, at one time and one load: a peak of a few
periods is then a smooth function of the sweep's time, and the loop cannot tell an error locked
to the angle from a drift along the sweep. The peak is still offered, and the loop says it is
unconfirmed. References: the pass counts of motions built to have them, and the rule's closed
form (a peak over one pass is confirmed iff the span holds at least ten of its periods).
"""

import math
import re

import numpy as np

from hdjax.compliance import ComplianceModel
from hdjax.discover import pipeline_signals
from hdjax.discover._library import angle_passes, build_library, spectrum_orders

from .helpers import JOINT, path_recording

SPAN = np.radians(298.0)
NAMED = [1.0, 2.0, 3.0, 4.0, 6.73, 10.87, 12.5]


def _sweep(n=2000, seed=0):
    """A one-way sweep that starts from rest, pauses half-way and ends at rest, read through
    1 arcsec of encoder noise."""
    half = n // 2
    s = np.r_[
        np.zeros(200), np.linspace(0, 0.5, half), np.full(300, 0.5), np.linspace(0.5, 1, half),
        np.ones(200),
    ]  # fmt: skip
    noise = np.radians(1 / 3600) * np.random.default_rng(seed).standard_normal(s.size)
    return -SPAN / 2 + SPAN * s + noise


def test_passes_count_the_legs_over_each_angle():
    one = _sweep()
    assert angle_passes(one) == 1.0
    assert angle_passes(np.r_[one, one[::-1]]) == 2.0  # there and back
    assert angle_passes(np.r_[one, one]) == 2.0  # two sweeps, a jump back between them
    assert angle_passes(np.tile(np.r_[one, one[::-1]], 3)) == 6.0
    assert angle_passes(np.full(100, 0.3)) == 1.0  # standing still
    assert angle_passes(np.zeros(0)) == 0.0


def _offered(theta, order, single_pass=None):
    """The orders offered for a residual that is one harmonic of `order` (peaks searched, and
    the named orders)."""
    residual = np.sin(order * theta + 0.3)
    orders, _ = spectrum_orders(
        theta,
        residual + 0.01 * np.random.default_rng(1).standard_normal(theta.size),
        signal="theta_l",
        order_range=(0.5, 14.0),
        named=NAMED,
        existing=[],
        n_peaks=1,
        single_pass=single_pass,
    )
    return sorted(round(k, 1) for k, _ in orders)


def test_one_pass_confirms_a_peak_only_where_its_span_repeats_it_ten_times():
    one = _sweep()
    span = float(np.ptp(one))
    assert 12.0 <= 20 * math.pi / span <= 12.2  # 298 degrees: peaks from order 12.08 up
    for order, confirmed in ((5.3, False), (8.4, False), (12.9, True)):
        unconfirmed = []
        got = _offered(one, order, unconfirmed)
        assert order in got, (order, got)  # offered either way
        assert [round(k, 1) for k in unconfirmed] == ([] if confirmed else [order])
        assert {round(k, 1) for k in NAMED} <= set(got)  # the named orders stay
        # the same sweep there and back passes every angle twice: nothing is unconfirmed
        there_and_back = []
        assert order in _offered(np.r_[one, one[::-1]], order, there_and_back)
        assert there_and_back == []


def _recording(theta_l, order):
    """A joint whose twist carries an output harmonic of `order`, on the motion `theta_l`."""
    torque = 40.0 * np.sin(theta_l)  # a gravity-like load along the path
    twist = torque * 1.5e-5 + np.radians(0.5 / 60) * np.sin(order * theta_l + 0.4)
    return path_recording(theta_l, torque, twist, dt=4e-3, source="one pass")


def _library(theta_l, order=5.3):
    rec = _recording(theta_l, order)
    model = ComplianceModel.paper(JOINT, per_segment=False)
    sig = pipeline_signals(rec, model.ratio, model.twist_sign, model.velocity).sig
    resid = np.radians(0.5 / 60) * np.sin(order * np.asarray(rec.theta_l) + 0.4)
    notes: list[str] = []
    cands, _ = build_library(sig, np.asarray(rec.torque), resid, model, unidentified=notes)
    return [c.key for c in cands], notes


def test_a_one_way_sweep_says_which_peaks_it_cannot_confirm_and_a_return_pass_confirms_them():
    one = _sweep()
    keys, notes = _library(one)
    assert [k for k in keys if k.startswith("harmonic:theta_l:5.")], keys
    assert "harmonic:theta_l:4" in keys  # a named order stays
    said = [n for n in notes if n.startswith("a harmonic:theta_l or ripple:theta_l peak below")]
    assert len(said) == 1, notes
    assert "passes over theta_l once" in said[0]
    limit = float(re.search(r"peak below order ([0-9.]+) is barely", said[0]).group(1))
    assert limit == float(f"{20 * math.pi / np.ptp(one):.3g}")  # ten periods of the span
    assert "record the range at least twice" in said[0] and "may not carry" in said[0]
    keys, notes = _library(np.r_[one, one[::-1]])
    assert [k for k in keys if k.startswith("harmonic:theta_l:5.")], keys
    assert not [n for n in notes if "passes over theta_l once" in n]
