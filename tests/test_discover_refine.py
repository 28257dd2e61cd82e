"""The chosen effect's setting refined by the cross-validated torque error.

Each check runs `refined_trial` against a cross-validated error given in closed form as a
function of the hysteresis width (a stand-in for the pipeline: the refinement reads nothing
else), so the width it must reach is known: the minimum of that function, to within the finest
step the search takes.
"""

import math

import numpy as np
import pytest

from hdjax._errors import CalibrationError
from hdjax.discover import DiscoverOptions
from hdjax.discover._decision import Trial
from hdjax.discover._pipeline import CrossValidation
from hdjax.discover._refine import MAX_TRIES, MIN_STEP, refined_trial
from hdjax.effects import Candidate, Coulomb, TwistHysteresis, neighbours, setting_text

OPTIONS = DiscoverOptions()


def _trial(term, cv_rms: float) -> Trial:
    cv = CrossValidation(cv_rms, 1.0, [], [])
    return Trial(Candidate.of(term), 0.5, np.array([0.5, 0.5]), 1.0, None, None, cv)


def _trier(cv_of_width, calls: list, fails=lambda w: False):
    def try_one(cand, gain, folds_, stab):
        w = cand.term.torque_scale
        calls.append(w)
        if fails(w):
            raise CalibrationError(f"width {w} too sharp")
        return _trial(cand.term, cv_of_width(w))

    return try_one


def _hysteresis(width: float) -> TwistHysteresis:
    return TwistHysteresis(torque_scale=width, compliance=2e-5, initial=-1.0, play=0.5)


def test_the_hysteresis_family_offers_the_width_a_step_up_and_down_and_keeps_the_rest():
    term = _hysteresis(20.0)
    up, down = neighbours(term, 2.0)
    assert (up.torque_scale, down.torque_scale) == (40.0, 10.0)
    for t in (up, down):
        assert (t.compliance, t.initial, t.play) == (2e-5, -1.0, 0.5)
    assert neighbours(Coulomb("omega_m", 0.01), 2.0) == []  # no continuous setting
    assert setting_text(term) == "width 20 N·m" and setting_text(Coulomb("omega_m", 0.01)) == ""


def test_the_width_moves_to_the_minimum_of_the_cross_validated_error():
    best_width = 13.0  # between the grid's 10 and 20: a factor 3.25 above the member tried
    cv = lambda w: 1.0 + math.log(w / best_width) ** 2  # noqa: E731
    calls, notes = [], []
    out = refined_trial(_trial(_hysteresis(4.0), cv(4.0)), _trier(cv, calls), OPTIONS, notes, 2)
    assert abs(math.log(out.candidate.term.torque_scale / best_width)) <= math.log(MIN_STEP)
    assert out.cv_rms < cv(4.0) and out.candidate.term.initial == -1.0
    assert len(calls) <= MAX_TRIES
    assert len(notes) == 1 and notes[0].startswith("step 2: hysteresis:torque's setting refined")
    assert "width 4 N·m -> width" in notes[0]


def test_a_gain_below_the_least_the_loop_counts_does_not_move_the_setting():
    # each neighbour lowers the error by 1 %, below min_torque_gain (2 %): a tie
    cv = lambda w: 1.0 - 0.01 * (w != 20.0)  # noqa: E731
    calls, notes = [], []
    start = _trial(_hysteresis(20.0), 1.0)
    assert refined_trial(start, _trier(cv, calls), OPTIONS, notes, 1) is start
    assert notes == [] and calls  # tried, not moved


def test_a_neighbour_that_cannot_be_calibrated_is_not_a_move_and_the_search_goes_on():
    cv = lambda w: 1.0 + math.log(w / 40.0) ** 2  # noqa: E731
    calls = []
    out = refined_trial(
        _trial(_hysteresis(10.0), cv(10.0)),
        _trier(cv, calls, fails=lambda w: w < 10.0),
        OPTIONS,
        [],
        1,
    )
    assert out.candidate.term.torque_scale == pytest.approx(40.0)


def test_an_effect_without_a_continuous_setting_is_returned_untried():
    calls = []
    start = _trial(Coulomb("omega_m", 0.01), 1.0)
    assert refined_trial(start, _trier(lambda w: 0.0, calls), OPTIONS, [], 1) is start
    assert calls == []
