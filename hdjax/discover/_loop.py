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
   updates of per-block Gram statistics), on the standard folds and on every resampled deal.
4. **Screening.** A candidate is eligible when pysindy's STLSQ selects it, it removes at least
   `min_gain` of the cross-validated twist error, and it does so in at least
   `min_stability` of the resampled fold assignments (stability selection).
5. **Acceptance in the torque domain.** For the `n_shortlist` best eligible candidates (an
   alias of one already shortlisted, whose columns span the same directions on TRAIN, takes
   no place; a speed term is tried as the reading the motor current supports, an encoder
   skew or viscous friction), the whole pipeline runs per fold: calibration on the fold's
   training part, then inversion (eqs. (26)-(27)), with memory states computed causally from
   the estimate exactly as on TEST. A candidate is added only if it lowers that error by at
   least `min_torque_gain`. Of those within one standard error of the lowest (paired over the
   held-out blocks: the one-standard-error rule), the one with the fewest columns, then the
   lowest is added; of errors closer than `min_torque_gain` (a tie), one seriously collinear
   with the model's columns gives way to one TRAIN determines more than twice as well (the
   share of a column's variance the model's columns do not span,
   [`hdjax.discover._aliases.determination`][]). An accepted step never raises it. When no
   trial qualifies, the next `n_shortlist` eligible candidates are tried, up to
   `n_shortlist_rounds` rounds; stop when none does, or after `max_effects` effects.
6. **The gate.** If the final model's cross-validated torque error lies within one standard
   error of the starting model's (paired over the held-out blocks), every step is taken back:
   the run claims no effect the starting model lacks. The whole path is tested first, the
   single steps after it (a protected procedure), so a joint without an undeclared effect
   rarely gets one, and a weak step after a confirmed one keeps its chance.
7. **A second starting structure.** When the starting model holds the paper's kinematic
   columns (eq. (9), functions of angle times speed) and the path added an effect whose
   columns depend on the speed or direction of motion and which those columns partly span on
   TRAIN, steps 3-6 run again from the structure without them, on the same folds (when no
   single effect lowers the error there, once more adding first the first path's motion
   effects as found: effects that need each other, a hysteresis beside a skew, cannot be
   added one at a time). That path is kept by the one-standard-error rule: when its final
   cross-validated torque error lies beyond one standard error below the first's, or within
   one standard error with fewer coefficients
   ([`hdjax.discover._second_start.second_path_reason`][]).
8. Refit on all of TRAIN, estimate torque on TEST and record the errors. TEST is never used
   to choose. At the end every added effect's amplitude gets a 95 % moving-block bootstrap
   interval over TRAIN ([`hdjax.discover._uncertainty`][]), and structure the final model
   leaves above the noise is listed as `unexplained`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from .._errors import ConfigError, DataError, HdjaxError
from .._joint import Joint
from .._recording import Recording
from .._solution import RESULTS, Solution
from ..effects import SEGMENT_START, one_way_from_rest
from ._closing import (
    closing_notes,
    effect_amplitudes,
    left_unexplained,
    reference_findings,
    skew_estimate,
)
from ._evaluate import residual, test_errors, twist_rms
from ._folds import MEMORY_GAP, fold_plan
from ._options import DiscoverOptions as DiscoverOptions, stopping_rule
from ._path import LoopRun, add_effects
from ._pipeline import (
    context_parts,
    coverage_arguments,
    cross_validate,
    estimate,
    scored_rows,
)
from ._record import DiscoveryRecord as DiscoveryRecord, DiscoveryStep as DiscoveryStep
from ._scores import _as_data, score_candidates as score_candidates
from ._second_start import without_kinematic
from ._start import calibrate_baseline as calibrate_baseline, start_table, toml_settings
from ._timing import Phases


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
        base_metrics, base_est = test_errors(model, test_data, joint.rated_torque)
        base_twist = twist_rms(model, test_data, chunk=options.chunk)
    say(f"baseline: test torque RMS {base_metrics.rms:.4g} N·m, max {base_metrics.max:.4g} N·m")
    with phase("baseline"):
        est_train = estimate(model, data)
        resid0 = data.part(residual(model, data, None, options.chunk))
    return model, data, test_data, base_metrics, base_est, base_twist, est_train, resid0


def _discover(train, test, joint, options, progress, context=None) -> Solution:
    say = progress or (lambda _: None)
    t_start = time.perf_counter()
    no_initial = bool(options.chunk and getattr(options.library, "dahl_initial", False))
    if no_initial:
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
    if no_initial and "hysteresis:torque" in getattr(options.library, "families", ()):
        _say_no_initial_state(data, notes)
    plan, options = _fold_plan(model, data, test_data, resid0, options, notes)
    with phase("torque CV"):
        cv = cross_validate(model, data, plan.folds_rec, chunk=options.chunk, scored=plan.scored)
    base_cv = cv
    say(f"baseline: cross-validated torque RMS {cv.torque_rms:.4g} N·m on TRAIN")
    if not np.isfinite(cv.torque_rms):
        notes.append(
            "cross-validation scores no held-out sample: every fold holds out torques outside "
            "the range its training part calibrates, so no effect can be judged and none is added"
        )
    unidentified: list[str] = []
    run = LoopRun(
        data, test_data, plan, options, extra_columns, joint, base_metrics, phase, say, notes,
        unidentified,
    )  # fmt: skip
    chosen = add_effects(run, model, est_train, cv)
    if options.fourier_order:
        chosen = without_kinematic(run, train, chosen, base_cv)
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


def _fold_plan(model, data, test_data, resid0, options, notes):
    """The folds ([`hdjax.discover._folds.fold_plan`][]) and the held-out rows each scores,
    fixed from the starting `model`'s coverage, so every structure is scored on the same rows;
    a note when a fold scores less than half of its held-out rows."""
    plan, options = fold_plan(data, test_data, resid0, options, notes)
    plan = plan._replace(scored=scored_rows(data, plan.folds_rec, coverage_arguments(model, data)))
    notes += coverage_notes(plan)
    return plan, options


MIN_SCORED_SHARE = 0.5
"""A fold that scores less than this share of its held-out samples is named in the notes."""


def coverage_notes(plan) -> list[str]:
    """A note naming the folds that score less than `MIN_SCORED_SHARE` of their held-out
    samples ([`hdjax.discover._pipeline.scored_rows`][]), with what the user can do."""
    low = [
        (f + 1, s.size / te.size)
        for f, (te, s) in enumerate(zip(plan.folds_rec, plan.scored))
        if te.size and s.size < MIN_SCORED_SHARE * te.size
    ]
    if not low:
        return []
    shares = ", ".join(f"fold {f}: {share:.0%}" for f, share in low)
    return [
        f"cross-validation scores only part of some folds' held-out samples ({shares}): the "
        "rest lie outside what the fold's training part covers (the torque in their motion "
        "regime, the current, or the output's angle times speed of the paper's kinematic "
        "columns), where TEST does not ask the model to go; TRAIN that repeats each motion "
        "(more sweeps, at each speed) leaves fewer such samples"
    ]


def _say_no_initial_state(data, notes: list[str]) -> None:
    """With `chunk`, memory states start at 0: on a one-way sweep from rest, where hysteresis
    is the transition from the state the last motion left, that can hide it, so say so."""
    sig = getattr(data, "sig", None)
    if sig is None or not one_way_from_rest(np.asarray(sig.twist), np.asarray(sig.omega_l)):
        return
    notes.append(
        "hysteresis:torque is offered only with its state starting at 0: TRAIN is a one-way "
        "sweep from rest, whose hysteresis is the transition from the state its last motion "
        "left, and with --chunk the state at the start is not fitted; run without --chunk (or "
        "on a part of the log that fits in memory) to let the loop fit it"
    )


__all__ = [
    "DiscoverOptions",
    "DiscoveryRecord",
    "DiscoveryStep",
    "discover",
    "HdjaxError",
]
