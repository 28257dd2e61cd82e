"""The setting of a chosen effect refined by the cross-validated torque error.

A family offers some effects on a grid of one continuous setting (a hysteresis width at
fractions of the rated torque, a factor 2-2.5 apart), and the shortlist tries, per key, the
first grid member that calibrates, in the order of the twist screen's gains. The screen fits
one linear column per member; the torque error it is chosen to lower comes from the whole
pipeline (the driver rounds, the inversion), and on a one-way sweep from rest the two can
rank the widths differently: a width a step up the grid can halve the cross-validated torque
error of the member tried.

So once the loop has chosen a step, [`refined_trial`][] walks its setting along the family's
`neighbours` (a pattern search in the logarithm of the setting): it moves to a neighbour that
lowers the cross-validated torque RMS by at least `min_torque_gain`, the least gain the loop
counts (closer errors are tied, and a tie does not move), and halves the logarithmic step when
neither neighbour does, from a factor 2 down to `MIN_STEP`, with at most `MAX_TRIES` trials.
The effect stays the one chosen; only its setting moves, and the note says from what to what.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from .. import effects
from .._errors import CalibrationError, InversionError
from ..effects import Candidate
from ._decision import Trial
from ._options import DiscoverOptions

FIRST_STEP = 2.0
"""The first factor between a setting and its neighbours (about the grid's spacing)."""

MIN_STEP = 2.0**0.25
"""The finest factor tried (three halvings of the logarithmic step)."""

MAX_TRIES = 8
"""The most trials one refinement calibrates."""


def refined_trial(
    best: Trial,
    try_one: Callable[..., Trial],
    options: DiscoverOptions,
    notes: list[str],
    n: int,
) -> Trial:
    """`best` with its continuous setting moved, neighbour by neighbour, while a move lowers
    the cross-validated torque RMS by `min_torque_gain` (a pattern search, see the module
    docstring: the first neighbour that does is taken, the step up tried first); `best`
    itself when its family has no such setting or no neighbour lowers the error so."""
    current, step, tries = best, FIRST_STEP, 0
    while step >= MIN_STEP * (1 - 1e-9) and tries < MAX_TRIES:
        moved = False
        for term in effects.neighbours(current.candidate.term, step):
            if tries >= MAX_TRIES:
                break
            tries += 1
            cand = Candidate(current.candidate.key, current.candidate.family, term, "refined")
            try:
                trial = try_one(cand, current.gain, current.fold_gains, current.stability)
            except (CalibrationError, InversionError):
                continue  # a setting too sharp for its amplitude: not a move
            if trial.cv_rms <= (1.0 - options.min_torque_gain) * current.cv_rms:
                current, moved = trial, True
                break
        if not moved:
            step = math.sqrt(step)
    if current is not best:
        notes.append(
            f"step {n}: {best.key}'s setting refined by the cross-validated torque error: "
            f"{effects.setting_text(best.candidate.term)} -> "
            f"{effects.setting_text(current.candidate.term)} "
            f"({best.cv_rms:.4g} -> {current.cv_rms:.4g} N·m, {tries} trials)"
        )
    return current
