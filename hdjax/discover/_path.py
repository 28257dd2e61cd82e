"""One path of the residual loop (steps 3-6 of [`hdjax.discover._loop`][]): from a starting
model, score the library, shortlist, try, choose and add one effect per step, then the gate
that takes every step back unless the path beats the starting model."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .. import effects
from .._errors import CalibrationError, InversionError
from .._joint import Joint
from .._metrics import ErrorMetrics
from ._aliases import alias_test, determination, find_aliases
from ._decision import (
    Trial,
    beats_start,
    choose,
    eligible,
    no_step_note,
    qualifies,
    rank,
    ranking_rows,
    read_speed_trials,
    shortlist_rounds,
    speed_reading,
    taken_back_note,
)
from ._evaluate import test_errors, twist_rms
from ._folds import FoldPlan
from ._options import DiscoverOptions, _percent
from ._pipeline import CrossValidation, PipelineData, calibrate, cross_validate
from ._record import DiscoveryStep
from ._refine import refined_trial
from ._scores import score_candidates, training_data
from ._timing import Phases, null_phases


class LoopRun(NamedTuple):
    """What stays fixed while the loop adds effects: TRAIN's and TEST's signals, the fold
    plan, the settings, the starting model's TEST errors, and where to time, say and note."""

    data: PipelineData
    test_data: PipelineData
    plan: FoldPlan
    options: DiscoverOptions
    extra_columns: tuple[str, ...]
    joint: Joint
    base_metrics: ErrorMetrics
    phase: Phases
    say: Callable[[str], None]
    notes: list[str]
    unidentified: list[str]


def _trial(run: LoopRun, model, cand, gain, folds_, stab, est_train, cv, phase) -> Trial:
    """Calibrate `cand` into `model` and cross-validate the whole pipeline per fold; raises
    `CalibrationError` or `InversionError` when it cannot."""
    data, chunk = run.data, run.options.chunk
    with phase("calibrate"):
        new_model, new_est = calibrate(
            model.with_effects(cand.term), data, run.notes, est_train, chunk
        )
    with phase("torque CV"):
        new_cv = cross_validate(new_model, data, run.plan.folds_rec, cv, chunk, run.plan.scored)
    return Trial(cand, gain, folds_, stab, new_model, new_est, new_cv)


def _shortlist_trials(shortlist, ranking, try_one, notes, options) -> list[Trial]:
    """Per shortlisted key, the best grid member (of the first `n_grid_tries`) that
    calibrates to an invertible model (a hysteresis scale too sharp for its amplitude does
    not); its cross-validated torque RMS goes into the `ranking` rows."""
    trials = []
    for r in shortlist:
        for gain, cand, folds_ in r.members[: options.n_grid_tries]:
            if gain < options.min_gain:
                break
            try:
                trial = try_one(cand, gain, folds_, r.stability)
            except (CalibrationError, InversionError) as err:
                notes.append(f"candidate {cand.key} could not be added: {err}")
                continue
            for row in ranking:
                if row["key"] == cand.key:
                    row["cv_torque_rms"] = trial.cv_rms
            trials.append(trial)
            break
    return trials


def _key_trier(ranked, ranking, try_one, cv, options, tried: dict):
    """`try_key(key)`: the trial of `key`'s best member (the reading's own candidate, when the
    shortlist did not try it), calibrated once per step (kept in `tried`, None when it cannot
    be calibrated) and returned only when it qualifies against `cv`, the test the chosen
    trial passed; its cross-validated torque RMS goes into the `ranking` rows."""

    def try_key(key):
        if key not in tried:
            tried[key] = None
            for r in (r for r in ranked if r.candidate.key == key):
                try:
                    gain, cand, folds_ = r.members[0]
                    tried[key] = try_one(cand, gain, folds_, r.stability, null_phases())
                except (CalibrationError, InversionError):
                    break
                for row in (row for row in ranking if row["key"] == key):
                    row["cv_torque_rms"] = tried[key].cv_rms
                break
        trial = tried[key]
        return trial if trial and qualifies(trial.cv_rms, cv.torque_rms, options) else None

    return try_key


class LoopPath(NamedTuple):
    """One path of the loop from a starting model: its steps and the state after the last,
    the notes it wrote, and (when it starts from another structure than the configured one)
    that start: `DiscoveryRecord.start_structure`."""

    steps: list[DiscoveryStep]
    model: object
    est_train: np.ndarray
    cv: CrossValidation
    spectra: dict
    resid: np.ndarray
    ranking: list[dict]
    notes: list[str]
    unidentified: list[str]
    start_structure: dict = {}


def _carried_trial(carry, ranked, try_one, notes, cv, n: int) -> Trial | None:
    """The trial of step `n`, the candidate `carry`, as it is (its term with its own
    settings), whatever its gain: an effect carried into a path, not chosen by the stopping
    rule (the path is judged whole); scored with its key's gain and stability on this path's
    library, against `cv`, the cross-validation before it. `None` (with a note) when the
    library offers no such key or the term does not calibrate."""
    r = next((r for r in ranked if r.candidate.key == carry.key), None)
    if r is None:
        notes.append(f"carried effect {carry.key} not added: this path's library does not offer it")
        return None
    try:
        best = try_one(carry, r.gain, r.fold_gains, r.stability)
    except (CalibrationError, InversionError) as err:
        notes.append(f"carried effect {carry.key} could not be added: {err}")
        return None
    setting = effects.setting_text(carry.term)
    notes.append(
        f"step {n}: {best.key} carried over from the path with the configured structure, "
        f"its term as found there{f' ({setting})' if setting else ''}, "
        "whatever its own gain (cross-validated torque RMS "
        f"{cv.torque_rms:.4g} -> {best.cv_rms:.4g} N·m; the path is judged whole; the "
        "twist gain and stability shown are its key's best candidate's on this path)"
    )
    return best


def _chosen_trial(run: LoopRun, model, est_train, cv, ranked, ranking, try_one, n: int):
    """Step `n` by the loop's rule: shortlist, try and choose
    ([`hdjax.discover._decision.choose`][]), with the speed reading, and the chosen effect's
    setting refined ([`hdjax.discover._refine.refined_trial`][]); `None` (with a note) when no
    candidate qualifies."""
    data, options, notes = run.data, run.options, run.notes
    by_key: dict = {}  # this step's trials by key (None: could not be calibrated)

    try_key = _key_trier(ranked, ranking, try_one, cv, options, by_key)
    aliased = alias_test(*training_data(model, data, est_train), take=data.part)

    def try_round(part, trials):
        # a key try_key has already calibrated is not calibrated again
        part = [r for r in part if by_key.get(r.candidate.key) is None]
        if trials:
            notes.append(
                f"step {n}: none of "
                + ", ".join(f"{t.key} ({t.cv_rms:.4g} N·m)" for t in trials)
                + f" lowers the cross-validated torque error ({cv.torque_rms:.4g} N·m) by "
                f"{_percent(options.min_torque_gain)}; the next eligible tried: "
                + ", ".join(r.candidate.key for r in part)
            )
        tried = _shortlist_trials(part, ranking, try_one, notes, options)
        by_key.update({t.key: t for t in tried})
        taken = frozenset(t.key for t in trials) | {r.candidate.key for r in part}
        return trials + read_speed_trials(tried, data, try_key, taken)

    shortlist, trials = shortlist_rounds(
        eligible(ranked, options, aliased), options, cv.torque_rms, try_round
    )

    determined = determination(model, data, est_train)
    best = choose(
        trials, cv, run.plan.blocks_rec, options, notes, lambda t: determined(t.candidate.term)
    )
    if best is None:
        notes.append(no_step_note(trials, shortlist, cv, options))
        return None
    # the reading's trial must pass the test the chosen trial passed
    passing = [t for t in trials if qualifies(t.cv_rms, cv.torque_rms, options)]
    best = speed_reading(best, passing, data, notes, try_key)
    return refined_trial(best, try_one, options, notes, n)


def add_effects(
    run: LoopRun,
    model,
    est_train,
    cv,
    reference: CrossValidation | None = None,
    carried: tuple = (),
):
    """The loop proper: score the library, shortlist, try, choose and add one effect per
    step until the stopping rule ([`hdjax.discover._decision.choose`][]) or `max_effects`
    stops it; then every step is taken back unless the path as a whole beats the starting
    model beyond one standard error ([`hdjax.discover._decision.beats_start`][]), or
    `reference`, when given (the configured starting model's cross-validation, for a path
    from another starting structure).

    The candidates in `carried` are added first, in order, with their terms as they are and
    whatever their gain (scored as any step is, and marked `carried`): the effects a path
    from another structure takes over from the configured one. They are not chosen by the
    stopping rule, so only the path as a whole is judged, by the gate above and by the rule
    that compares it with the configured path. A carried effect that cannot be added ends the
    carrying (with a note); the loop then goes on by its rule.

    **Returns:** a `LoopPath`: the steps, and the model, TRAIN estimate, cross-validation,
    spectra, residual and ranking after the last step; its notes are its own (`run.notes`
    and `run.unidentified` are not written).
    """
    run = run._replace(notes=[], unidentified=[])
    data, plan, options, notes = run.data, run.plan, run.options, run.notes
    steps: list[DiscoveryStep] = []
    start: tuple = ()  # the starting model's state, kept after its scoring
    path = [cv]  # the cross-validation after each step, the starting model's first
    while True:
        scored, spectra, resid = score_candidates(
            model,
            data,
            options,
            run.extra_columns,
            folds=plan.folds,
            blocks=plan.blocks,
            resamples=plan.resamples,
            est=est_train,
            phases=run.phase,
            unidentified=run.unidentified,
        )
        ranked = rank(scored, options.min_gain)
        ranking = ranking_rows(ranked)
        if not steps:
            start = (model, est_train, cv, spectra, resid, ranking)
        if len(steps) >= options.max_effects:
            notes.append(f"stopped: reached max_effects = {options.max_effects}")
            break

        def try_one(cand, gain, folds_, stab, phase=run.phase, model=model, est=est_train, cv=cv):
            return _trial(run, model, cand, gain, folds_, stab, est, cv, phase)

        n, best = len(steps) + 1, None
        if len(steps) < len(carried):
            best = _carried_trial(carried[len(steps)], ranked, try_one, notes, cv, n)
            carried = carried if best else ()  # one that cannot be added ends the carrying
        best = best or _chosen_trial(run, model, est_train, cv, ranked, ranking, try_one, n)
        if best is None:
            break
        step = _step(run, best, model, est_train, ranked, ranking, spectra)
        steps.append(dataclasses.replace(step, carried=best.candidate.origin == "carried"))
        model, est_train, cv = best.model, best.estimate, best.cv
        path.append(cv)
        say_step(steps, run.base_metrics, run.say, notes)
    gate = path if reference is None else [reference, *path[1:]]
    if not beats_start(gate, plan.blocks_rec):
        notes.append(taken_back_note(steps, gate))
        run.say(notes[-1])
        return LoopPath([], *start, notes, run.unidentified)
    return LoopPath(steps, model, est_train, cv, spectra, resid, ranking, notes, run.unidentified)


def _step(run: LoopRun, best, model, est_train, ranked, ranking, spectra) -> DiscoveryStep:
    """The step that adds `best` to `model`: its aliases (on the signals the candidates were
    scored on, the model before this step) and its TEST errors."""
    cand, data, phase = best.candidate, run.data, run.phase
    with phase("aliases"):
        others = [
            (r.candidate.key, r.candidate.term) for r in ranked[:10] if r.candidate.key != cand.key
        ]
        aliases = find_aliases(
            cand.term, others, *training_data(model, data, est_train), take=data.part
        )
    with phase("test"):
        metrics, est = test_errors(best.model, run.test_data, run.joint.rated_torque)
        test_twist = twist_rms(best.model, run.test_data, chunk=run.options.chunk)
    return DiscoveryStep(
        key=cand.key,
        family=cand.family,
        term=cand.term,
        model=best.model,
        torque_estimate=est,
        fold_gains=[float(x) for x in best.fold_gains],
        test=metrics,
        twist_rms_arcsec=test_twist,
        cv_gain=best.gain,
        cv_torque_rms=best.cv.torque_rms,
        cv_twist_rms_arcsec=best.cv.twist_rms_arcsec,
        stability=best.stability,
        ranking=ranking,
        spectra=spectra,
        aliases=aliases,
    )


def say_step(steps, base_metrics, say, notes) -> None:
    """The progress line of the last step; a loud warning when TEST disagrees with it."""
    s = steps[-1]
    say(
        f"step {len(steps)}: added {s.key} (CV twist gain {s.cv_gain:.1%}, stability "
        f"{s.stability:.0%}, CV torque {s.cv_torque_rms:.4g} N·m); test torque RMS "
        f"{s.test.rms:.4g} N·m, max {s.test.max:.4g} N·m"
        + (
            "; TRAIN cannot tell it apart from " + ", ".join(a["key"] for a in s.aliases)
            if s.aliases
            else ""
        )
    )
    before = steps[-2].test.rms if len(steps) > 1 else base_metrics.rms
    if s.test.rms > before:
        # TEST never chooses, so a step it disagrees with stays: say so, loudly
        rise = (
            f"warning: step {len(steps)} ({s.key}) raised the TEST torque RMS from "
            f"{before:.4g} to {s.test.rms:.4g} N·m (+{s.test.rms / before - 1:.1%}), "
            "although cross-validation on TRAIN lowered the torque error: TRAIN and TEST differ"
        )
        notes.append(rise)
        say(rise)
