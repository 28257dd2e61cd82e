"""The torque-domain choice among screened candidates, and the gate at the end of the loop's
path: the one-standard-error rule.

Candidates whose cross-validated torque errors the held-out blocks cannot tell apart are
chosen by parsimony (fewest columns); a path whose final model the held-out blocks cannot tell
from the starting model is taken back. The standard error of the difference is taken pairwise
over the held-out blocks; the cases below have it in closed form.
"""

from types import SimpleNamespace

import numpy as np

from hdjax.discover._decision import Trial, beats_start, choose, taken_back_note
from hdjax.discover._options import DiscoverOptions
from hdjax.discover._pipeline import CrossValidation, within_one_se

N_BLOCKS, PER_BLOCK = 10, 10
BLOCKS = np.repeat(np.arange(N_BLOCKS), PER_BLOCK)


def _cv(sq):
    sq = np.asarray(sq, float)
    ok = ~np.isnan(sq)
    return CrossValidation(float(np.sqrt(np.mean(sq[ok]))), 0.0, [], [], squared_errors=sq)


def _shifted(c, a):
    """Per-sample squared errors 1 + c + a(-1)^b in block b: the block differences to a
    constant 1 are 10 (c ± a), their sum 100 c and its standard error
    sqrt(10) * 10 a * sqrt(10/9) = 100 a / 3."""
    return 1.0 + c + a * (-1.0) ** BLOCKS


def test_within_one_standard_error_in_closed_form():
    best = _cv(np.ones(BLOCKS.size))
    assert within_one_se(_cv(_shifted(0.3, 1.0)), best, BLOCKS)  # 30 <= 33.3
    assert not within_one_se(_cv(_shifted(0.4, 1.0)), best, BLOCKS)  # 40 > 33.3
    assert not within_one_se(_cv(_shifted(0.01, 0.0)), best, BLOCKS)  # a constant excess
    assert within_one_se(_cv(_shifted(-0.01, 0.0)), best, BLOCKS)  # better everywhere


def test_unscored_samples_are_left_out_and_a_failed_estimate_is_never_within():
    sq_best = np.ones(BLOCKS.size)
    sq = _shifted(0.3, 1.0)
    # a sample that no fold scores (NaN in both) is left out; here it would carry +1000
    sq_best[5] = np.nan
    sq[5] = np.nan
    assert within_one_se(_cv(sq), _cv(sq_best), BLOCKS)
    sq[7] = np.inf  # a non-finite estimate on a scored sample
    assert not within_one_se(_cv(sq), _cv(sq_best), BLOCKS)


def _trial(key, n_columns, sq):
    term = SimpleNamespace(names=lambda: tuple(f"c{i}" for i in range(n_columns)))
    cv = _cv(sq)
    return Trial(SimpleNamespace(key=key, term=term), 0.0, np.zeros(0), 1.0, None, None, cv)


def test_the_simpler_of_two_indistinguishable_candidates_is_chosen():
    current = _cv(np.full(BLOCKS.size, 4.0))
    rich = _trial("harmonic", 2, np.ones(BLOCKS.size))
    near = _trial("coulomb", 1, _shifted(0.3, 1.0))  # within one standard error of `rich`
    far = _trial("viscous", 1, _shifted(0.4, 1.0))  # not within
    opts, notes = DiscoverOptions(), []
    assert choose([rich, near, far], current, BLOCKS, opts, notes).key == "coulomb"
    assert "within one standard error" in notes[0]
    assert choose([rich, far], current, BLOCKS, opts, []).key == "harmonic"
    # a simpler candidate that does not lower the current error by `min_torque_gain` is not
    # chosen, however close to the lowest
    current = _cv(np.full(BLOCKS.size, 1.3))
    assert choose([rich, near], current, BLOCKS, opts, []).key == "harmonic"
    # and when not even the lowest does, none is chosen: the loop stops
    assert choose([rich, near], _cv(np.full(BLOCKS.size, 1.0)), BLOCKS, opts, []) is None


def test_a_path_the_held_out_blocks_cannot_tell_from_the_start_is_taken_back():
    ones = _cv(np.ones(BLOCKS.size))
    near, far = _cv(_shifted(0.3, 1.0)), _cv(_shifted(0.4, 1.0))  # 30 <= 33.3 < 40
    assert not beats_start([near, ones], BLOCKS)  # one step within noise: taken back
    assert beats_start([far, ones], BLOCKS)
    # two steps: the whole path is tested, not its last step; block differences to the final
    # model 10 (0.6 ± 2): a sum of 60 within 66.7, so both steps go back
    assert not beats_start([_cv(1.6 + 2.0 * (-1.0) ** BLOCKS), near, ones], BLOCKS)
    # a confirmed path keeps a weak last step (near -> ones alone would be within)
    assert beats_start([_cv(np.full(BLOCKS.size, 4.0)), near, ones], BLOCKS)
    assert beats_start([ones], BLOCKS)  # no step, nothing to take back


def test_the_taken_back_note_names_the_steps_and_their_errors():
    steps = [SimpleNamespace(key=k) for k in ("harmonic:theta_l:2", "stiffness:torque")]
    path = [_cv(np.full(BLOCKS.size, 4.0)), _cv(_shifted(0.3, 1.0)), _cv(np.ones(BLOCKS.size))]
    note = taken_back_note(steps, path)
    assert note.startswith("taken back: harmonic:theta_l:2, stiffness:torque. ")
    assert "(after each step: 2 -> 1.14 -> 1 N·m)" in note
