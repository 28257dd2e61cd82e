"""The residual loop: find what the model gets wrong, name the effect, add it, refit, repeat.

1. Calibrate the starting model (the paper's, Song et al. Section II) by least squares on the
   training recording. A recording with gaps (time steps over 3 sample periods, or the joins
   of a block split) is a list of segments: derivatives never cross a gap; memory states
   carry across short gaps (dropped samples) and restart at long ones
   ([`hdjax.discover.pipeline_signals`][]).
2. Cut TRAIN into whole contiguous blocks, no shorter than the residual's correlation length
   and never across a gap; deal them to `n_folds` folds (interleaved), and again in
   `n_resamples` random balanced deals for stability selection.
3. Compute the twist residual on TRAIN and its order spectra against both angles; build the
   candidate library ([`hdjax.discover.build_library`][]) and score every candidate by the
   share of the cross-validated twist error it removes (exactly, by Frisch-Waugh-Lovell
   updates of per-fold QR factors), on the standard folds and on every resampled deal.
4. **Screening.** A candidate is eligible when pysindy's STLSQ selects it, it removes at least
   `min_gain` of the cross-validated twist error, and it does so in at least
   `min_stability` of the resampled fold assignments (stability selection).
5. **Acceptance in the torque domain.** For the `n_shortlist` best eligible candidates (an
   alias of one already shortlisted, whose columns span the same directions on TRAIN, takes
   no place), the whole pipeline runs per fold: calibration on the fold's training part, then
   inversion (eqs. (26)-(27)), with memory states computed causally from the estimate exactly
   as on TEST. A candidate is added only if it lowers that error by at least
   `min_torque_gain`. Of those within one standard error of the lowest (paired over the
   held-out blocks: the one-standard-error rule), the one with the fewest columns, then the
   lowest is added; of errors closer than `min_torque_gain` (a tie), one seriously collinear
   with the model's columns gives way to one TRAIN determines more than twice as well (the
   share of a column's variance the model's columns do not span,
   [`hdjax.discover._aliases.determination`][]). An accepted step never raises it. Stop
   when none does, or after `max_effects` effects.
6. **The gate.** If the final model's cross-validated torque error lies within one standard
   error of the starting model's (paired over the held-out blocks), every step is taken back:
   the run claims no effect the starting model lacks. The whole path is tested first, the
   single steps after it (a protected procedure), so a joint without an undeclared effect
   rarely gets one, and a weak step after a confirmed one keeps its chance.
7. **A second starting structure.** When the starting model holds the paper's kinematic
   columns (eq. (9), functions of angle times speed) and the path added an effect whose
   columns depend on the speed or direction of motion, steps 3-6 run again from the structure
   without those columns, on the same folds; that path is kept when its final cross-validated
   torque error lies beyond one standard error below the first's (`_without_kinematic`).
8. Refit on all of TRAIN, estimate torque on TEST and record the errors. TEST is never used
   to choose. At the end every added effect's amplitude gets a 95 % moving-block bootstrap
   interval over TRAIN ([`hdjax.discover._uncertainty`][]), and structure the final model
   leaves above the noise is listed as `unexplained`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from threadpoolctl import threadpool_limits

from .._errors import CalibrationError, ConfigError, DataError, HdjaxError, InversionError
from .._joint import Joint
from .._metrics import ErrorMetrics, error_metrics
from .._recording import Recording
from .._solution import RESULTS, Solution
from ..effects import SEGMENT_START
from ._aliases import alias_test, determination, find_aliases
from ._chunked import twist_residual
from ._closing import (
    closing_notes,
    effect_amplitudes,
    left_unexplained,
    reference_findings,
    skew_estimate,
)
from ._decision import (
    Trial,
    beats_start,
    choose,
    eligible,
    no_step_note,
    qualifies,
    rank,
    ranking_rows,
    speed_reading,
    taken_back_note,
)
from ._folds import MEMORY_GAP, FoldPlan, fold_plan
from ._options import DiscoverOptions as DiscoverOptions, stopping_rule
from ._pipeline import (
    CrossValidation,
    PipelineData,
    calibrate,
    canonical,
    chunks_of,
    context_parts,
    cross_validate,
    design,
    estimate,
    has_path,
    within_one_se,
)
from ._record import DiscoveryRecord as DiscoveryRecord, DiscoveryStep as DiscoveryStep
from ._scores import _as_data, score_candidates as score_candidates, training_data
from ._start import calibrate_baseline as calibrate_baseline, start_table, toml_settings
from ._timing import Phases, null_phases

ARCSEC = 180.0 * 3600.0 / np.pi


def _test_errors(model, test, rated):
    """TEST torque errors of `model` (the pipeline's signals: gaps honoured; with a context,
    estimated through the whole log and scored on TEST's rows). **Returns:** the metrics and
    the estimate on TEST's rows."""
    data = _as_data(model, test)
    torque = data.part(estimate(model, data))
    return error_metrics(torque, data.part(data.torque), rated), torque


def _twist_rms(model, data, driver=None, chunk=0) -> float:
    data = _as_data(model, data)
    if driver is None and has_path(model):
        driver = estimate(model, data)
    r = data.part(_residual(model, data, driver, chunk))
    return float(np.sqrt(np.mean(r**2)) * ARCSEC)


def _residual(model, data: PipelineData, driver, chunk: int) -> np.ndarray:
    """The twist residual of `model` on `data` (hysteresis driven by `driver`), the design
    formed whole or, with `chunk`, chunk by chunk."""
    sig, torque = data.pair(driver)
    if chunk:
        return twist_residual(canonical(model), chunks_of(sig, torque, chunk))
    return np.asarray(sig.twist) - design(model, sig, torque) @ np.asarray(model.coef)


def _usable_columns(train: Recording) -> tuple[str, ...]:
    return tuple(name for name, x in train.extras.items() if float(np.ptp(np.asarray(x))) > 0.0)


def discover(
    train: Recording,
    test: Recording,
    joint: Joint,
    options: DiscoverOptions = DiscoverOptions(),
    *,
    progress: Callable[[str], None] | None = None,
    context: Recording | None = None,
) -> Solution:
    """Run the residual loop (see the module docstring).

    **Arguments:** `train` (calibration and selection), `test` (reporting only; needs a
    reference torque), `joint`, `options`, `progress` (called with one line per stage),
    `context` (optional: the whole log `train` and `test` were cut from, as blocks of one
    sweep: derivatives and memory states then run through it, as the estimator runs on the
    robot, while TRAIN's rows alone are fitted and TEST's alone scored; the reference torque of
    the other part is never read).

    **Returns:** an [`hdjax.Solution`][]: `value` the final
    [`hdjax.compliance.ComplianceModel`][]; `stats` `n_effects`, `baseline_test_rms` and
    `final_test_rms` [N·m], `baseline_cv_torque_rms` and `final_cv_torque_rms` [N·m] (on
    TRAIN), `cv_block_samples` and `fit_time_s`; `aux` the loop's
    [`hdjax.discover.DiscoveryRecord`][] (baseline, steps, spectra, ranking, notes).

    The loop's linear algebra is many small dense solves between JAX programs; it runs with
    one BLAS thread (`threadpoolctl`), which on a small shared machine is several times faster
    than BLAS threads contending with XLA's and with each other (the results are the same).
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _discover(train, test, joint, options, progress, context)


def _parts(train, test, joint, options, context, notes):
    """TRAIN's and TEST's pipeline signals: each its own recording, or (with `context`) parts
    of the one log they were cut from."""
    if context is None:
        return train, test
    if options.chunk:
        raise ConfigError(
            "a context log (TRAIN and TEST cut from one log) runs in memory; set chunk = 0, or "
            "give TRAIN and TEST as separate logs to run chunk by chunk"
        )
    tr, te = context_parts(context, [train, test], joint.ratio, joint.twist_sign, "difference")
    notes.append(
        f"TRAIN and TEST are blocks of one log ({context.n_samples} samples): derivatives and "
        "memory states run through the whole log, as the estimator runs on the robot; TRAIN's "
        "rows alone are fitted and TEST's alone scored"
    )
    return tr, te


class _Run(NamedTuple):
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


def _trial(run: _Run, model, cand, gain, folds_, stab, est_train, cv, phase) -> Trial:
    """Calibrate `cand` into `model` and cross-validate the whole pipeline per fold; raises
    `CalibrationError` or `InversionError` when it cannot."""
    data, chunk = run.data, run.options.chunk
    with phase("calibrate"):
        new_model, new_est = calibrate(
            model.with_effects(cand.term), data, run.notes, est_train, chunk
        )
    with phase("torque CV"):
        new_cv = cross_validate(new_model, data, run.plan.folds_rec, cv, chunk)
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


def _start(train, test, joint, options, phase, notes, say):
    """The starting model calibrated on TRAIN, its errors on TEST, its TRAIN estimate and
    twist residual (on TRAIN's rows)."""
    notes.append(
        f"starting model: [model] {toml_settings(start_table(options))}, calibrated by the "
        "function hdjax run calibrates with (the same logs and [model] settings give the same "
        "starting model there); on purpose, run's default is per_segment = true (the paper's "
        'Table I), and run with [fit] method = "rls" or a chunked fit calibrates its '
        "structure without merging segments"
    )
    with phase("baseline"):
        model = calibrate_baseline(train, joint, options, notes)
        # with a chunk, estimates run chunk by chunk too (see PipelineData.chunk)
        data = dataclasses.replace(_as_data(model, train), chunk=options.chunk)
        test_data = dataclasses.replace(_as_data(model, test), chunk=options.chunk)
    n_gaps = int(data.starts.sum()) - 1
    if n_gaps:
        n_mem = int(np.asarray(data.sig.extras[SEGMENT_START]).sum()) - 1
        notes.append(
            f"TRAIN has {n_gaps} gap(s) (time steps over 3 sample periods): {n_gaps + 1} "
            f"segments; derivatives stop at each gap, memory states restart at the {n_mem} "
            f"longer than {MEMORY_GAP:g} s and carry across the others"
        )
    with phase("test"):
        base_metrics, base_est = _test_errors(model, test_data, joint.rated_torque)
        base_twist = _twist_rms(model, test_data, chunk=options.chunk)
    say(f"baseline: test torque RMS {base_metrics.rms:.4g} N·m, max {base_metrics.max:.4g} N·m")
    with phase("baseline"):
        est_train = estimate(model, data)
        resid0 = data.part(_residual(model, data, None, options.chunk))
    return model, data, test_data, base_metrics, base_est, base_twist, est_train, resid0


def _discover(train, test, joint, options, progress, context=None) -> Solution:
    say = progress or (lambda _: None)
    t_start = time.perf_counter()
    if options.chunk and getattr(options.library, "dahl_initial", False):
        # a state carried chunk by chunk starts at 0: over a long log its start hardly counts
        options = dataclasses.replace(
            options, library=dataclasses.replace(options.library, dahl_initial=False)
        )
    for rec, name in ((train, "TRAIN"), (test, "TEST")):
        if rec.torque is None:
            raise DataError(f"{name} ({rec.source}) has no 'torque' column; the loop needs it")
    notes: list[str] = []
    phase = Phases()
    extra_columns = _usable_columns(train)
    test_recording = test  # the record keeps TEST as given (figures, reports)
    train, test = _parts(train, test, joint, options, context, notes)
    model, data, test_data, base_metrics, base_est, base_twist, est_train, resid0 = _start(
        train, test, joint, options, phase, notes, say
    )
    baseline_model, baseline_est_train = model, est_train
    plan, options = fold_plan(data, test_data, resid0, options, notes)
    with phase("torque CV"):
        cv = cross_validate(model, data, plan.folds_rec, chunk=options.chunk)
    base_cv = cv
    say(f"baseline: cross-validated torque RMS {cv.torque_rms:.4g} N·m on TRAIN")
    if not np.isfinite(cv.torque_rms):
        notes.append(
            "cross-validation scores no held-out sample: every fold holds out torques outside "
            "the range its training part calibrates, so no effect can be judged and none is added"
        )
    unidentified: list[str] = []
    run = _Run(
        data, test_data, plan, options, extra_columns, joint, base_metrics, phase, say, notes,
        unidentified,
    )  # fmt: skip
    chosen = _add_effects(run, model, est_train, cv)
    if options.fourier_order:
        chosen = _without_kinematic(run, train, chosen, base_cv)
    steps, model, est_train, cv, spectra, resid, ranking = chosen[:7]
    notes += chosen.notes
    with phase("intervals"):
        amplitudes = effect_amplitudes(model, data, est_train, options) if steps else []
        for s_, iv in zip(steps, amplitudes):
            s_.amplitude = iv
        readings = [("starting model", baseline_model, baseline_est_train)]
        readings += [("final model", model, est_train)] if steps else []
        # the skew note's advice reads the structure the steps start from
        start_options = (
            dataclasses.replace(options, fourier_order=0) if chosen.start_structure else options
        )
        skew = skew_estimate(readings, data, start_options, joint)
    with phase("unexplained"):
        left = left_unexplained(resid, spectra, data, options)
    notes += list(dict.fromkeys(chosen.unidentified)) + ([skew] if skew else [])
    final = steps[-1].test if steps else base_metrics
    with phase("reference"):
        checks = reference_findings(
            model, data, est_train, test_data, steps[-1].torque_estimate if steps else base_est
        )
        for part, found in checks.items():
            for f in found:
                if f["flagged"]:
                    say(f"reference ({part}): {f['message']}")
    say(phase.line())
    ratio = cv.torque_rms / final.rms if final.rms > 0 else float("nan")
    notes += closing_notes(ratio, cv, base_cv, final, base_metrics)
    record = DiscoveryRecord(
        baseline_model=baseline_model,
        baseline=base_metrics,
        baseline_estimate=base_est,
        baseline_twist_rms_arcsec=float(base_twist),
        baseline_cv_torque_rms=base_cv.torque_rms,
        baseline_cv_twist_rms_arcsec=base_cv.twist_rms_arcsec,
        steps=steps,
        final=final,
        final_spectra=spectra,
        final_ranking=ranking,
        train_residual_final=resid,
        notes=list(dict.fromkeys(notes)),
        test=test_recording,
        unexplained=left,
        cv_block_samples=plan.block,
        reference_checks=checks,
        cv_test_ratio=float(ratio),
        stopping_rule=stopping_rule(options),
        start_structure=chosen.start_structure,
    )
    stats = dict(
        n_effects=len(steps),
        baseline_test_rms=base_metrics.rms,
        final_test_rms=final.rms,
        baseline_cv_torque_rms=base_cv.torque_rms,
        final_cv_torque_rms=cv.torque_rms,
        cv_block_samples=plan.block,
        fit_time_s=time.perf_counter() - t_start,
    )
    return Solution(model, RESULTS.successful, stats, aux=record)


class _Path(NamedTuple):
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


def _add_effects(run: _Run, model, est_train, cv, reference: CrossValidation | None = None):
    """The loop proper: score the library, shortlist, try, choose and add one effect per
    step until the stopping rule ([`hdjax.discover._decision.choose`][]) or `max_effects`
    stops it; then every step is taken back unless the path as a whole beats the starting
    model beyond one standard error ([`hdjax.discover._decision.beats_start`][]), or
    `reference`, when given (the configured starting model's cross-validation, for a path
    from another starting structure).

    **Returns:** a `_Path`: the steps, and the model, TRAIN estimate, cross-validation,
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

        def try_key(key, ranked=ranked, try_one=try_one, cv=cv):
            # the reading's own candidate, when the shortlist did not try it: its best member,
            # which must pass the test the chosen trial passed
            for r in (r for r in ranked if r.candidate.key == key):
                try:
                    gain, cand, folds_ = r.members[0]
                    trial = try_one(cand, gain, folds_, r.stability, null_phases())
                except (CalibrationError, InversionError):
                    return None
                return trial if qualifies(trial.cv_rms, cv.torque_rms, options) else None
            return None

        aliased = alias_test(*training_data(model, data, est_train), take=data.part)
        shortlist = eligible(ranked, options, aliased)
        trials = _shortlist_trials(shortlist, ranking, try_one, notes, options)

        determined = determination(model, data, est_train)
        best = choose(
            trials, cv, plan.blocks_rec, options, notes, lambda t: determined(t.candidate.term)
        )
        if best is None:
            notes.append(no_step_note(trials, shortlist, cv, options))
            break
        best = speed_reading(best, trials, data, notes, try_key)
        step = _step(run, best, model, est_train, ranked, ranking, spectra)
        model, est_train, cv = best.model, best.estimate, best.cv
        steps.append(step)
        path.append(cv)
        _say_step(steps, run.base_metrics, run.say, notes)
    gate = path if reference is None else [reference, *path[1:]]
    if not beats_start(gate, plan.blocks_rec):
        notes.append(taken_back_note(steps, gate))
        run.say(notes[-1])
        return _Path([], *start, notes, run.unidentified)
    return _Path(steps, model, est_train, cv, spectra, resid, ranking, notes, run.unidentified)


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


def _without_kinematic(run: _Run, train, found: _Path, base_cv: CrossValidation) -> _Path:
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
    alt = _add_effects(quiet, model, est_train, cv, reference=base_cv)
    if not alt.steps or not qualifies(alt.cv.torque_rms, found.cv.torque_rms, options):
        return found
    if within_one_se(found.cv, alt.cv, run.plan.blocks_rec):
        return found
    change = KINEMATIC_FREE.format(alt=alt.cv.torque_rms, own=found.cv.torque_rms)
    run.say(change)
    with run.phase("test"):
        metrics = _test_errors(model, run.test_data, run.joint.rated_torque)[0]
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
        _say_step(alt.steps[:k], run.base_metrics, run.say, [])
    return alt._replace(notes=[change, *notes, *alt.notes], start_structure=start)


def _step(run: _Run, best, model, est_train, ranked, ranking, spectra) -> DiscoveryStep:
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
        metrics, est = _test_errors(best.model, run.test_data, run.joint.rated_torque)
        twist_rms = _twist_rms(best.model, run.test_data, chunk=run.options.chunk)
    return DiscoveryStep(
        key=cand.key,
        family=cand.family,
        term=cand.term,
        model=best.model,
        torque_estimate=est,
        fold_gains=[float(x) for x in best.fold_gains],
        test=metrics,
        twist_rms_arcsec=twist_rms,
        cv_gain=best.gain,
        cv_torque_rms=best.cv.torque_rms,
        cv_twist_rms_arcsec=best.cv.twist_rms_arcsec,
        stability=best.stability,
        ranking=ranking,
        spectra=spectra,
        aliases=aliases,
    )


def _say_step(steps, base_metrics, say, notes) -> None:
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


__all__ = [
    "DiscoverOptions",
    "DiscoveryRecord",
    "DiscoveryStep",
    "discover",
    "HdjaxError",
]
