"""Step 7 of the residual loop ([`hdjax.discover._loop`][]): the path from a second starting
structure, the configured one without the paper's kinematic columns (Song et al. eq. (9))."""

from __future__ import annotations

import dataclasses

import numpy as np

from .._custom_types import Int
from .._errors import CalibrationError, InversionError
from ..effects import Candidate, PaperFourier
from ._aliases import _model_rows, _strided, first_canonical_r2
from ._decision import qualifies
from ._evaluate import test_errors
from ._path import LoopPath, LoopRun, add_effects, say_step
from ._pipeline import CrossValidation, cross_validate, estimate, within_one_se
from ._scores import training_data
from ._start import calibrate_baseline

MOTION_FAMILIES = frozenset(
    ("coulomb", "viscous", "skew", "stribeck", "hysteresis", "backlash", "damping")
)
"""Families whose columns depend on the speed or the direction of motion: on a slow sweep the
paper's kinematic columns (functions of angle times speed) compete with them."""

KINEMATIC_SHARE = 0.05
"""The second path runs only where the paper's kinematic columns span at least this share
(an $R^2$ on TRAIN) of some direction of the added motion effects' columns
([`kinematic_share`][])."""

KINEMATIC_FREE = (
    "the final model leaves out the starting model's kinematic columns (Song et al. eq. (9), "
    "functions of the product of angle and speed): from the same starting structure without "
    "them, the loop's path reaches a cross-validated torque RMS of {alt:.4g} N·m against "
    "{own:.4g} N·m with them ({why}). On "
    "a slow motion those columns are nearly proportional to the speed, so they take up what a "
    "speed-dependent effect (encoder skew, friction, hysteresis) explains physically; the "
    'model written holds the structure found ([model] kinematic = "none" for hdjax run)'
)


CARRIED = (
    "; that path starts by adding {keys}, the effects the path with the columns found that "
    "they compete with, whatever each one's own gain (only the path as a whole is judged), "
    "because from that start no single effect lowers the error: an effect such as a "
    "hysteresis can explain little without the columns until an encoder skew joins it"
)

BEYOND = "lower beyond one standard error, paired over the held-out blocks"
FEWER = (
    "within one standard error, paired over the held-out blocks, with {alt} coefficients "
    "against {own}: of structures the held-out blocks cannot tell apart, the one-standard-error "
    "rule keeps the simpler"
)


def _column_groups(model) -> tuple[list[int], list[list[int]]]:
    """The design columns (eq. (15)) of `model`'s kinematic term (eq. (9), every segment's copy)
    and of each effect term, in the order of `model.effect_terms`."""
    n_seg, nb = model.n_segments, model.n_base
    own, at = [], 0
    for t in model.base_terms:
        k = len(t.names())
        own += list(range(at, at + k)) if isinstance(t, PaperFourier) else []
        at += k
    copies = n_seg if model.per_segment else 1
    kinematic = [n_seg + s * nb + j for s in range(copies) for j in own]
    effects, at = [], model.n_coef - model.n_effect
    for t in model.effect_terms:
        effects.append(list(range(at, at + len(t.names()))))
        at += len(t.names())
    return kinematic, effects


def kinematic_share(model, data, est_train, last: list[bool]) -> float:
    """How much of the columns of `model`'s last effect terms flagged in `last` (one flag per
    term, for the terms the loop's steps added, in order) the paper's kinematic columns (Song
    et al. eq. (9)) span on TRAIN: the largest $R^2$ of a combination of those columns
    regressed on the kinematic ones ([`first_canonical_r2`][]; on at most `MAX_ROWS` evenly
    strided TRAIN rows, chunk by chunk with `data.chunk`).

    Near 0 the two are orthogonal on TRAIN: the effects' coefficients are then the same with
    the kinematic columns or without them (Frisch-Waugh-Lovell), so those columns cannot have
    taken up part of the effects, which is what the second starting structure corrects.
    """
    kinematic, effects = _column_groups(model)
    flagged = effects[len(effects) - len(last) :]
    cols = [c for flag, group in zip(last, flagged) if flag for c in group]
    if not kinematic or not cols:
        return 0.0
    sig, torque = training_data(model, data, est_train)
    take = _strided(int(np.asarray(torque).shape[0]), data.rows)
    rows = _model_rows(model, sig, torque, take, data.chunk)
    return first_canonical_r2(rows[:, kinematic], rows[:, cols])


def second_path_reason(
    found: CrossValidation,
    alt: CrossValidation,
    n_coef: tuple[int, int],
    blocks: Int[np.ndarray, " n"],
    options,
) -> str | None:
    """Why the path from the structure without the paper's kinematic columns (`alt`) is kept
    over the configured one (`found`), or `None` when it is not. `n_coef` holds the two final
    models' coefficient counts, `(found's, alt's)`.

    The one-standard-error rule (Hastie, Tibshirani & Friedman, *The Elements of Statistical
    Learning*, Section 7.10), as each step of the loop applies it: `alt` is kept when its
    cross-validated torque error is lower beyond one standard error (and by the loop's
    `min_torque_gain`), or when it lies within one standard error with fewer coefficients (of
    structures the held-out blocks cannot tell apart, the simpler). The error of a
    difference is taken pairwise over the held-out blocks ([`within_one_se`][]).
    """
    if qualifies(alt.torque_rms, found.torque_rms, options) and not within_one_se(
        found, alt, blocks
    ):
        return BEYOND
    if n_coef[1] < n_coef[0] and within_one_se(alt, found, blocks):
        return FEWER.format(alt=n_coef[1], own=n_coef[0])
    return None


def _path_without(quiet: LoopRun, start, base_cv, found: LoopPath, motion: list[bool]):
    """The path from `start` (the model without the kinematic columns, its TRAIN estimate and
    cross-validation), step by step; when it takes no step, the path again with `found`'s
    motion effects (flagged in `motion`) carried over first, their terms as found. Returns the
    path and the candidates carried (none when the first is returned)."""
    alt = add_effects(quiet, *start, reference=base_cv)
    if alt.steps:
        return alt, ()
    # effects that need each other there (a hysteresis beside the skew the columns took up)
    # cannot be added one at a time; a hysteresis keeps its width found with the columns:
    # on this start's residual, where that skew is back, the grid would choose another
    steps = [s for s, flag in zip(found.steps, motion) if flag]
    carried = tuple(Candidate(s.key, s.family, s.term, "carried") for s in steps)
    return add_effects(quiet, *start, reference=base_cv, carried=carried), carried


def without_kinematic(run: LoopRun, train, found: LoopPath, base_cv: CrossValidation) -> LoopPath:
    """The loop's path from the starting structure without the paper's kinematic columns
    (eq. (9)), on the same folds, kept instead of `found` by the one-standard-error rule
    ([`second_path_reason`][]: lower beyond one standard error, or within it with fewer
    coefficients; and its path beats the configured starting model's, `base_cv`, as every
    path must).

    The paper's columns are functions of $\\theta\\omega$: on a slow sweep nearly linear in
    the speed, they absorb an encoder skew or a speed-dependent friction or memory state in a
    form that does not carry over to other speeds and angles, and the effects the loop then
    adds compete with them. Which structure holds is a question of model choice between two
    whole paths (a greedy step cannot reach it: removing the columns before an effect is
    added raises the error), decided by the same cross-validation and the same
    one-standard-error rule as every step: a tie keeps the structure with fewer
    coefficients.

    From that structure the loop's own path is followed, one step at a time. Effects can need
    each other there: beside a hysteresis, the skew the columns took up is back in the
    residual, and neither alone lowers the error, so that path adds nothing (draw 4 of the
    two-speed skew cases of `benchmarks/real_log_cases.py`). When it adds nothing, the path is
    followed again adding first the motion effects `found` holds, their terms as found (a
    hysteresis keeps its width), whatever each one gains, then going on by the loop's rule.
    Effects are carried over only where no single one can start: where one can, carrying
    them as well gave, on a one-way sweep from rest, a lower cross-validated error through
    harmonics of the output angle that made up for a width chosen beside the columns, and a
    larger TEST error (one-sweep hysteresis draw 1 of `benchmarks/real_log_cases.py`).

    The other path is followed only when the configured one added an effect of a family the
    columns compete with (`MOTION_FAMILIES`), and the columns span a share of that effect's
    columns on TRAIN (at least `KINEMATIC_SHARE`, [`kinematic_share`][]): only then can they
    have taken up part of an effect the model holds. A joint on which the configured path finds
    no such effect is not given a second chance at one (on clean joints with white encoder
    noise, following it whenever such a family was merely screened named effects the joints
    do not have). On a to-and-fro motion over many cycles a friction's columns and the
    kinematic ones are nearly orthogonal, and the path, which takes as long as the first, is not
    run; over a few cycles, or with per-segment coefficients, they can overlap, and it runs.
    """
    options = run.options
    motion = [s.key.split(":")[0] in MOTION_FAMILIES for s in found.steps]
    if not any(motion):
        return found
    with run.phase("aliases"):
        share = kinematic_share(found.model, run.data, found.est_train, motion)
    if share < KINEMATIC_SHARE:
        return found
    alt_options = dataclasses.replace(options, fourier_order=0)
    notes: list[str] = []
    run.say(
        "second path: from the starting structure without the paper's kinematic columns "
        "(kept by the one-standard-error rule)"
    )
    try:
        with run.phase("baseline"):
            model = calibrate_baseline(train, run.joint, alt_options, notes)
            est_train = estimate(model, run.data)
        with run.phase("torque CV"):
            cv = cross_validate(
                model, run.data, run.plan.folds_rec, chunk=options.chunk, scored=run.plan.scored
            )
    except (CalibrationError, InversionError) as err:
        why = (
            "second path (from the starting structure without the kinematic columns) not "
            f"run: {err}"
        )
        run.say(why)
        return found._replace(notes=[*found.notes, why])
    quiet = run._replace(options=alt_options, say=lambda _: None)
    alt, carry = _path_without(quiet, (model, est_train, cv), base_cv, found, motion)
    n_coef = (found.model.n_coef, alt.model.n_coef)
    why = alt.steps and second_path_reason(found.cv, alt.cv, n_coef, run.plan.blocks_rec, options)
    if not why:
        return found
    change = KINEMATIC_FREE.format(alt=alt.cv.torque_rms, own=found.cv.torque_rms, why=why)
    change += CARRIED.format(keys=", ".join(c.key for c in carry)) if carry else ""
    run.say(change)
    with run.phase("test"):
        metrics = test_errors(model, run.test_data, run.joint.rated_torque)[0]
    start = dict(
        label="starting model without its kinematic columns",
        note=change,
        rms=metrics.rms,
        max=metrics.max,
        cv_torque_rms=cv.torque_rms,
        cv_twist_rms_arcsec=cv.twist_rms_arcsec,
    )
    run.say(
        f"{start['label']}: test torque RMS {metrics.rms:.4g} N·m, cross-validated torque RMS "
        f"{cv.torque_rms:.4g} N·m"
    )
    for k in range(1, len(alt.steps) + 1):
        say_step(alt.steps[:k], run.base_metrics, run.say, [])
    return alt._replace(notes=[change, *notes, *alt.notes], start_structure=start)
