"""Step 7 of the residual loop ([`hdjax.discover._loop`][]): the path from a second starting
structure, the configured one without the paper's kinematic columns (Song et al. eq. (9))."""

from __future__ import annotations

import dataclasses

from .._errors import CalibrationError, InversionError
from ._decision import qualifies
from ._evaluate import test_errors
from ._path import LoopPath, LoopRun, add_effects, say_step
from ._pipeline import CrossValidation, cross_validate, estimate, within_one_se
from ._start import calibrate_baseline

MOTION_FAMILIES = frozenset(
    ("coulomb", "viscous", "skew", "stribeck", "hysteresis", "backlash", "damping")
)
"""Families whose columns depend on the speed or the direction of motion: on a slow sweep the
paper's kinematic columns (functions of angle times speed) compete with them."""

KINEMATIC_FREE = (
    "the final model leaves out the starting model's kinematic columns (Song et al. eq. (9), "
    "functions of the product of angle and speed): from the same starting structure without "
    "them, the loop's path reaches a cross-validated torque RMS of {alt:.4g} N·m against "
    "{own:.4g} N·m with them (beyond one standard error, paired over the held-out blocks). On "
    "a slow motion those columns are nearly proportional to the speed, so they take up what a "
    "speed-dependent effect (encoder skew, friction, hysteresis) explains physically; the "
    'model written holds the structure found ([model] kinematic = "none" for hdjax run)'
)


def without_kinematic(run: LoopRun, train, found: LoopPath, base_cv: CrossValidation) -> LoopPath:
    """The loop's path from the starting structure without the paper's kinematic columns
    (eq. (9)), on the same folds, kept instead of `found` when its final model's
    cross-validated torque error lies beyond one standard error below `found`'s (and its path
    beats the configured starting model's, `base_cv`, as every path must).

    The paper's columns are functions of $\\theta\\omega$: on a slow sweep nearly linear in
    the speed, they absorb an encoder skew or a speed-dependent friction or memory state in a
    form that does not carry over to other speeds and angles, and the effects the loop then
    adds compete with them. Which structure holds is a question of model choice between two
    whole paths (a greedy step cannot reach it: removing the columns before an effect is
    added raises the error), decided by the same cross-validation as every step, and a tie
    keeps the configured structure.

    The other path is followed only when the configured one added an effect of a family the
    columns compete with (`MOTION_FAMILIES`): only then can they have taken up part of an
    effect the model holds. A joint on which the configured path finds no such effect is not
    given a second chance at one (on clean joints with white encoder noise, following it
    whenever such a family was merely screened named effects the joints do not have).
    """
    options = run.options
    if not {s.key.split(":")[0] for s in found.steps} & MOTION_FAMILIES:
        return found
    alt_options = dataclasses.replace(options, fourier_order=0)
    notes: list[str] = []
    run.say(
        "second path: from the starting structure without the paper's kinematic columns "
        "(kept only if its cross-validated torque error is lower beyond one standard error)"
    )
    try:
        with run.phase("baseline"):
            model = calibrate_baseline(train, run.joint, alt_options, notes)
            est_train = estimate(model, run.data)
        with run.phase("torque CV"):
            cv = cross_validate(model, run.data, run.plan.folds_rec, chunk=options.chunk)
    except (CalibrationError, InversionError) as err:
        why = (
            "second path (from the starting structure without the kinematic columns) not "
            f"run: {err}"
        )
        run.say(why)
        return found._replace(notes=[*found.notes, why])
    quiet = run._replace(options=alt_options, say=lambda _: None)
    alt = add_effects(quiet, model, est_train, cv, reference=base_cv)
    if not alt.steps or not qualifies(alt.cv.torque_rms, found.cv.torque_rms, options):
        return found
    if within_one_se(found.cv, alt.cv, run.plan.blocks_rec):
        return found
    change = KINEMATIC_FREE.format(alt=alt.cv.torque_rms, own=found.cv.torque_rms)
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
