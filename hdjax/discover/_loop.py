"""The residual loop: find what the model gets wrong, name the effect, add it, refit, repeat.

1. Calibrate the starting model (the paper's, Song et al. Section II) by least squares on the
   training recording. A recording with gaps (time steps over 3 sample periods, or the joins
   of a block split) is a list of segments: derivatives never cross a gap and memory states
   restart at one ([`hdjax.discover.pipeline_signals`][]).
2. Cut TRAIN into whole contiguous blocks, no shorter than the residual's correlation length
   and never across a gap; deal them to `n_folds` folds (interleaved), and again in
   `n_resamples` random balanced deals for stability selection.
3. Compute the twist residual on TRAIN and its order spectra against both angles; build the
   candidate library ([`hdjax.discover.build_library`][]) and score every candidate by the
   share of the cross-validated twist error it removes (exactly, by Frisch-Waugh-Lovell
   updates of per-fold QR factors), on the standard folds and on every resampled deal.
4. **Screening.** A candidate is eligible when pysindy's STLSQ selects it, it removes at least
   `min_gain` (default 5 %) of the cross-validated twist error, and it does so in at least
   `min_stability` (70 %) of the resampled fold assignments (stability selection).
5. **Acceptance in the torque domain.** For the `n_shortlist` best eligible candidates, the
   whole pipeline runs per fold: calibration on the fold's training part, then inversion
   (eqs. (26)-(27)), with memory states computed causally from the estimate exactly as on
   TEST. A candidate is added only if it lowers that error by at least `min_torque_gain`; of
   those, the lowest, or one with fewer columns within one standard error of it (paired over
   the held-out blocks: the one-standard-error rule). An accepted step never raises it. Stop
   when none does, or after `max_effects` effects.
6. Refit on all of TRAIN, estimate torque on TEST and record the errors. TEST is never used
   to choose. At the end every added effect's amplitude gets a 95 % moving-block bootstrap
   interval over TRAIN ([`hdjax.discover._uncertainty`][]), and structure the final model
   leaves above the noise is listed as `unexplained`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from .._custom_types import Float
from .._errors import CalibrationError, ConfigError, DataError, HdjaxError, InversionError
from .._joint import Joint
from .._metrics import ErrorMetrics, error_metrics
from .._recording import Recording
from .._solution import RESULTS, Solution
from ..compliance import ComplianceModel, merge_sparse_segments
from ..compliance._lstsq import CalibrationData, failure_message, prepare
from ..effects import AbstractTerm, current_viscous_slope, velocity_reading
from ..reference import reference_checks
from ._aliases import find_aliases
from ._chunked import Chunks, DahlCarry, check_chunk, own_rows, sequential
from ._chunked_fits import twist_residual
from ._folds import (
    contiguous_blocks,
    correlation_length,
    cv_block_length,
    fold_assignment,
    resampled_assignments,
    run_length,
)
from ._gram import block_statistics_batched, block_statistics_streamed, fold_gains
from ._library import LibraryOptions, build_library, candidate_columns
from ._pipeline import (
    PipelineData,
    calibrate,
    canonical,
    chunks_of,
    context_parts,
    cross_validate,
    design,
    estimate,
    fit_merging,
    has_path,
    pipeline_signals,
    within_one_se,
)
from ._select import (
    MAX_SINDY_ROWS,
    block_grams,
    cv_gains,
    cv_gains_by_blocks,
    fold_basis,
    sindy_select,
)
from ._spectrum import OrderSpectrum, order_spectrum
from ._timing import Phases, null_phases
from ._uncertainty import bootstrap_length, effect_intervals, instrument_torque
from ._unexplained import all_spectra, unexplained_structure

ARCSEC = 180.0 * 3600.0 / np.pi


@dataclasses.dataclass(frozen=True)
class DiscoverOptions:
    """Settings of the residual loop (see the module docstring for the stopping rule)."""

    max_effects: int = 5
    min_gain: float = 0.05
    min_torque_gain: float = 0.02
    min_stability: float = 0.7
    n_resamples: int = 20
    n_shortlist: int = 3
    n_grid_tries: int = 3
    seed: int = 0
    n_folds: int = 5
    block: int = 200
    sindy_threshold: float = 0.02
    library: LibraryOptions = dataclasses.field(default_factory=LibraryOptions)
    n_segments: int = 5
    poly_order: int = 6
    fourier_order: int = 3
    per_segment: bool = False
    current_scale: float | None = None
    chunk: int = 0
    """Samples per chunk of the loop's least-squares fits (calibration, cross-validation,
    candidate scores, intervals), so that no design of the whole record is formed; 0: the
    whole record at once. Same coefficients to 1e-9 relative; memory bounded by the chunk."""

    def __post_init__(self):
        check_chunk(self.chunk)


@dataclasses.dataclass
class DiscoveryStep:
    """One effect the residual loop added, with its scores and the errors after adding it."""

    key: str
    family: str
    term: AbstractTerm
    cv_gain: float
    fold_gains: list[float]
    test: ErrorMetrics
    twist_rms_arcsec: float
    ranking: list[dict]
    spectra: dict[str, OrderSpectrum]
    model: ComplianceModel
    torque_estimate: Float[np.ndarray, " n_test"]
    stability: float = 1.0
    cv_torque_rms: float = float("nan")
    cv_twist_rms_arcsec: float = float("nan")
    amplitude: dict | None = None
    aliases: list[dict] = dataclasses.field(default_factory=list)
    """Candidates TRAIN cannot tell apart from this one: `{"key", "cosine"}`, the smallest
    principal-angle cosine between the centred column spans (at least 0.99)."""


@dataclasses.dataclass
class DiscoveryRecord:
    """What the residual loop did, step by step: the `aux` of the [`hdjax.Solution`][] that
    [`hdjax.discover.discover`][] returns (its `value` is the final model)."""

    baseline_model: ComplianceModel
    baseline: ErrorMetrics
    baseline_twist_rms_arcsec: float
    baseline_estimate: Float[np.ndarray, " n_test"]
    steps: list[DiscoveryStep]
    final: ErrorMetrics
    final_spectra: dict[str, OrderSpectrum]
    final_ranking: list[dict]
    notes: list[str]
    test: Recording
    train_residual_final: Float[np.ndarray, " n_train"]
    baseline_cv_torque_rms: float = float("nan")
    baseline_cv_twist_rms_arcsec: float = float("nan")
    unexplained: list = dataclasses.field(default_factory=list)
    cv_block_samples: int = 0
    reference_checks: dict = dataclasses.field(default_factory=dict)
    """Per part (`"TRAIN"`, `"TEST"`), the findings of
    [`hdjax.reference.reference_checks`][] on the final model's estimate."""
    cv_test_ratio: float = float("nan")
    """The final cross-validated torque RMS over the TEST RMS: far from 1 (above 2 or below
    1/2), cross-validation does not represent TEST."""

    @property
    def effects(self) -> list[str]:
        return [s.key for s in self.steps]


def _calibrate_monotone(model, data: PipelineData, notes, chunk=0):
    """Calibrate the starting model (shape-constrained, merging segments the data does not
    determine: [`hdjax.discover._pipeline.fit_merging`][]); a failure raises."""
    res = fit_merging(model, data.pair(), notes, chunk=chunk, rows=data.rows, throw=False)
    if not res.ok:
        raise CalibrationError(failure_message(res))
    return res


def calibrate_baseline(
    train: Recording | PipelineData, joint: Joint, options: DiscoverOptions, notes: list[str]
) -> ComplianceModel:
    """The starting model (paper structure) calibrated on `train`, with documented fallbacks.

    Segments the torque hardly covers, or whose compliance comes out non-positive, are merged
    into their inner neighbour. If the model is rank-deficient on the data (e.g. a current that
    is the reference torque itself), fall back in order to shared coefficients, then without
    the current polynomial, then without the kinematic-error term, and say so in `notes`.
    `train` is a recording, or its pipeline signals (a part of a log with `rows`).
    """
    data = _as_data(None, train, joint)
    current = data.part(data.sig.current)
    scale = options.current_scale or float(np.max(np.abs(current))) or 1.0
    attempts = []
    for kw in (
        dict(
            per_segment=options.per_segment,
            poly_order=options.poly_order,
            fourier_order=options.fourier_order,
        ),
        dict(per_segment=False, poly_order=options.poly_order, fourier_order=options.fourier_order),
        dict(per_segment=False, poly_order=0, fourier_order=options.fourier_order),
        dict(per_segment=False, poly_order=0, fourier_order=0),
    ):
        if kw not in attempts:
            attempts.append(kw)
    last = None
    for i, kw in enumerate(attempts):
        model = ComplianceModel.paper(
            joint,
            n_segments=options.n_segments,
            current_scale=scale,
            kinematic="paper" if kw["fourier_order"] else "none",
            **kw,
        )
        model, merged = merge_sparse_segments(model, data.part(data.torque))
        trial_notes = list(merged)
        try:
            res = _calibrate_monotone(model, data, trial_notes, options.chunk)
        except (CalibrationError, InversionError) as err:
            last = err
            notes.append(f"starting model {kw} not calibrated: {err}")
            continue
        notes.extend(trial_notes)
        if i:
            notes.append(f"starting model fell back to {kw}")
        return res.value
    raise CalibrationError(f"no starting model could be calibrated on the training data: {last}")


def _as_data(model, data, joint: Joint | None = None) -> PipelineData:
    """`data` as pipeline signals (a recording's derived with `model`'s or `joint`'s ratio and
    sign)."""
    if isinstance(data, PipelineData):
        return data
    if model is None:
        return pipeline_signals(data, joint.ratio, joint.twist_sign, "difference")
    return pipeline_signals(data, model.ratio, model.twist_sign, model.velocity)


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


def training_data(model: ComplianceModel, train, estimate_=None):
    """Training signals and reference torque, with the present model's torque *estimate* as the
    driver of path-dependent candidates (hysteresis is computed from the torque being
    estimated, causally, never from the reference sensor)."""
    data = _as_data(model, train)
    driver = estimate(model, data) if estimate_ is None else estimate_
    return data.pair(driver)


def _fold_of_block(blocks: np.ndarray, folds) -> np.ndarray:
    """The fold of each block, for held-out sets made of whole blocks."""
    out = np.zeros(int(blocks.max()) + 1, int)
    for f, te in enumerate(folds):
        out[blocks[te]] = f
    return out


BATCH_COLUMNS = 16
"""Candidate columns computed and summed into the block statistics at once (memory: this
many columns of the record, not the whole library's)."""


def _usable(c: np.ndarray) -> bool:
    """A candidate whose columns are finite and not constant can be scored.

    Column by column (a reduction along the first axis of an `(n, 2)` array is several times
    slower); a column is finite exactly when its minimum and maximum are."""
    varies = False
    for j in range(c.shape[1]):
        lo, hi = c[:, j].min(), c[:, j].max()
        if not (np.isfinite(lo) and np.isfinite(hi)):
            return False
        varies = varies or bool(hi > lo)
    return varies


def _streamed_scores(cands, sig, torque, a, y, resid, blocks, options, phase, take=None):
    """Block statistics of the candidates' columns, computed `BATCH_COLUMNS` columns at a
    time, and the sparse regression on every `step`-th sample of them (the rows
    [`sindy_select`][hdjax.discover._select.sindy_select] reads).

    `take` (optional) takes a part's rows from columns computed on the whole record.

    **Returns:** `(sindy-selected per column, owner candidate per column, usable candidate
    indices, BlockStatistics of the usable candidates)`.
    """
    take = take or (lambda x: x)
    n = a.shape[0]
    step = max(1, n // MAX_SINDY_ROWS)
    thin: list[np.ndarray] = []
    owner: list[int] = []
    usable: list[int] = []

    def batches():
        batch, width = [], 0
        for i, cand in enumerate(cands):
            c = take(candidate_columns(cand.term, sig, torque))
            for j in range(c.shape[1]):
                thin.append(np.ascontiguousarray(c[::step, j]))
                owner.append(i)
            if _usable(c):
                usable.append(i)
                batch.append(c)
                width += c.shape[1]
            if width >= BATCH_COLUMNS:
                yield batch
                batch, width = [], 0
        if batch:
            yield batch

    with phase("twist CV"):  # the candidates' columns included
        stats = block_statistics_batched(a, batches(), y, blocks)
    with phase("sindy"):
        # every `step`-th row, as `sindy_select` takes them (it keeps these rows whole)
        selected = sindy_select(
            a[::step],
            resid[::step],
            thin,
            [str(o) for o in owner],
            threshold=options.sindy_threshold,
        )
    return selected, np.asarray(owner), usable, stats


def _chunked_scores(cands, model, chunks: Chunks, resid, blocks, options, phase):
    """[`_streamed_scores`][] with the base design and every candidate's columns formed chunk
    by chunk ([`hdjax.discover._gram.block_statistics_streamed`][]); the Dahl states of
    hysteresis candidates carry across chunks. The sparse regression reads the same rows
    (every `step`-th sample), gathered during the first pass."""
    model = canonical(model)
    n = chunks.n
    step = max(1, n // MAX_SINDY_ROWS)
    active = np.asarray(model.active)
    widths = []
    lo_hi = []  # per candidate column: running minimum and maximum
    thin_a, thin_c = [], []
    first = [True]

    def passes():
        carry = DahlCarry()
        for lo, hi, sc, tc, a_full, h in chunks.rows(model):
            a = a_full if active.all() else np.compress(active, a_full, axis=1)
            rows = hi - lo
            groups = []
            for i, cand in enumerate(cands):
                if sequential(cand.term):
                    c = carry.column(
                        i,
                        cand.term,
                        own_rows(sc, h),
                        own_rows(tc, h),
                        rows,
                        cand.term.score_in_numpy,
                    )
                    c = c[:, None]
                else:
                    c = candidate_columns(cand.term, sc, tc)[h : h + rows]
                groups.append(np.asarray(c, np.float64))
            if first[0]:
                # copies, not views: a view of every `step`-th row keeps the whole chunk's
                # arrays alive, and memory would grow with the record instead of the chunk
                start = (-lo) % step
                thin_a.append(np.array(a[start::step]))
                thin_c.append([np.array(g[start::step]) for g in groups])
                lo_hi.append([(g.min(axis=0), g.max(axis=0)) for g in groups])
            yield lo, hi, a, groups
        first[0] = False

    def usable_groups():
        for i in range(len(cands)):
            lo_ = np.min([m[i][0] for m in lo_hi], axis=0)
            hi_ = np.max([m[i][1] for m in lo_hi], axis=0)
            finite = np.all(np.isfinite(lo_)) and np.all(np.isfinite(hi_))
            if finite and np.any(hi_ > lo_):
                widths.append(i)
        return widths

    with phase("twist CV"):  # the candidates' columns included
        stats = block_statistics_streamed(passes, chunks.sig.twist, blocks, usable_groups)
    with phase("sindy"):
        thin, owner = [], []
        for i in range(len(cands)):
            cat = np.concatenate([t[i] for t in thin_c])
            for j in range(cat.shape[1]):
                thin.append(np.ascontiguousarray(cat[:, j]))
                owner.append(i)
        selected = sindy_select(
            np.concatenate(thin_a),
            resid[::step],
            thin,
            [str(o) for o in owner],
            threshold=options.sindy_threshold,
        )
    return selected, np.asarray(owner), widths, stats


def score_candidates(
    model,
    train,
    options: DiscoverOptions,
    extra_columns,
    *,
    folds=None,
    blocks=None,
    resamples=(),
    est=None,
    phases=None,
    unidentified=None,
):
    """Library, spectra and per-candidate scores for one step (the families' reasons for
    offering nothing appended to `unidentified`, when given).

    With `blocks` (the folds' whole contiguous blocks), every cross-validated score comes from
    one pass of per-block Gram statistics ([`hdjax.discover._gram`][]); without, from per-fold
    QR factors ([`hdjax.discover._select.cv_gains`][]).

    **Returns:** `(scored, spectra, resid)`, `scored` a list of `(candidate, gain, fold gains,
    sindy-selected, gains over the resampled fold assignments)`.
    """
    phase = phases or null_phases()
    data = _as_data(model, train)
    chunk = options.chunk
    take = data.part  # columns are computed on the whole record, scored on the part's rows
    with phase("design"):
        sig, torque = training_data(model, data, est)
        y = take(sig.twist)
        if chunk:
            a = None
            resid = twist_residual(canonical(model), chunks_of(sig, torque, chunk))
        else:
            a_full = take(design(model, sig, torque))
            active = np.asarray(model.active)
            # np.compress copies the active columns several times faster than a[:, active]
            a = a_full if active.all() else np.compress(active, a_full, axis=1)
            resid = y - a_full @ np.asarray(model.coef)
            del a_full
    with phase("library"):
        cands, spectra = build_library(
            data.part_signals(sig),
            take(torque),
            resid,
            model,
            options=options.library,
            extra_columns=extra_columns,
            unidentified=unidentified,
        )
        if not cands:
            return [], spectra, resid
    if blocks is not None and folds is not None:
        if chunk:
            selected, owner, usable, stats = _chunked_scores(
                cands, model, chunks_of(sig, torque, chunk), resid, blocks, options, phase
            )
        else:
            selected, owner, usable, stats = _streamed_scores(
                cands, sig, torque, a, y, resid, blocks, options, phase, take
            )
        with phase("twist CV"):
            total, per_fold = fold_gains(stats, _fold_of_block(blocks, folds), options.n_folds)
            gains = list(zip(total.tolist(), per_fold))
            resampled = [fold_gains(stats, fb, options.n_folds)[0] for fb in resamples]
    else:
        with phase("library"):
            cols = [take(candidate_columns(c.term, sig, torque)) for c in cands]
        with phase("sindy"):
            flat_cols, owner = [], []
            for i, c in enumerate(cols):
                for j in range(c.shape[1]):
                    flat_cols.append(c[:, j])
                    owner.append(i)
            selected = sindy_select(
                a, resid, flat_cols, [str(o) for o in owner], threshold=options.sindy_threshold
            )
            owner = np.asarray(owner)
        with phase("twist CV"):
            usable = [i for i, c in enumerate(cols) if _usable(c)]
            groups = [cols[i] for i in usable]
            basis = fold_basis(a, y, options.n_folds, options.block, tests=folds)
            gains = cv_gains(basis, groups)
            if len(resamples):
                stats = block_grams(a, groups, y, blocks)
                resampled = [cv_gains_by_blocks(stats, fb, options.n_folds) for fb in resamples]
            else:
                resampled = []
    scored = [
        (
            cands[i],
            gain,
            folds_,
            bool(selected[owner == i].any()),
            np.asarray([r[j] for r in resampled]),
        )
        for j, (i, (gain, folds_)) in enumerate(zip(usable, gains))
    ]
    return scored, spectra, resid


def _best_per_key(scored, min_gain):
    """The best grid member of each key, with the key's stability: the share of resampled
    fold assignments in which some member of the key removes at least `min_gain`."""
    best, stable, members = {}, {}, {}
    for cand, gain, folds, sel, res in scored:
        hit = res >= min_gain if res.size else np.ones(1, bool) * (gain >= min_gain)
        stable[cand.key] = stable.get(cand.key, np.zeros_like(hit)) | hit
        members.setdefault(cand.key, []).append((gain, cand, folds))
        if cand.key not in best or gain > best[cand.key][1]:
            best[cand.key] = (cand, gain, folds, sel)
    out = [
        (*v, float(np.mean(stable[k])), sorted(members[k], key=lambda m: -m[0]))
        for k, v in best.items()
    ]
    return sorted(out, key=lambda s: -s[1])


def _parsimonious(trials, cv, blocks, options, notes):
    """The trial to add: of those that lower the cross-validated torque error by
    `min_torque_gain` and lie within one standard error of the lowest
    ([`hdjax.discover._pipeline.within_one_se`][]), the one with the fewest columns (then the
    lowest error). Cross-validated errors that the held-out blocks cannot tell apart do not
    choose; the simpler effect is named, and a richer one must earn its columns."""
    lowest = trials[0]
    level = (1.0 - options.min_torque_gain) * cv.torque_rms
    near = [
        t
        for t in trials
        if t[0] <= level and (t is lowest or within_one_se(t[7], lowest[7], blocks))
    ]
    best = min(near, key=lambda t: (len(t[1].term.names()), t[0]))
    if best is not lowest:
        notes.append(
            f"{best[1].key} ({best[0]:.4g} N·m) chosen over {lowest[1].key} ({lowest[0]:.4g} "
            "N·m): within one standard error over the held-out blocks, with fewer columns"
        )
    return best


VELOCITY_KEYS = ("skew:encoders", "viscous:omega_l", "viscous:omega_m")
"""Keys whose columns are, to first order, the same speed: an encoder time skew and viscous
friction (the twist cannot tell them apart; the current may)."""


def _twist_per_speed(model: ComplianceModel, key: str) -> float:
    """The twist [rad] per rad/s of link speed that the fitted term `key` adds."""
    coef = np.asarray(model.coef)
    i = model.n_coef - model.n_effect
    for term in model.effect_terms:
        m = len(term.names())
        if term.key == key:
            c = float(coef[i])
            if key == "skew:encoders":
                return c  # the coefficient is the delay: twist = delay * speed
            per = c / term.scale
            return per * model.ratio if term.signal == "omega_m" else per
        i += m
    return float("nan")


def _velocity_reading(best, trials, data: PipelineData, notes: list[str], try_key=None):
    """When the chosen trial is a speed term ([`VELOCITY_KEYS`][]), which reading the data
    supports ([`hdjax.effects.velocity_reading`][]): its twist per speed, over the data's
    compliance, against the current's own viscous slope. The chosen trial is swapped for the
    other reading's (tried now through `try_key(key)` when it was not among the trials), and
    the sentence is noted either way."""
    key = best[1].key
    if key not in VELOCITY_KEYS:
        return best
    model = best[5]
    view = data.view()
    # the model's own compliance where the speed is (weighted by the speed's square)
    w = np.asarray(view.sig.omega_l) ** 2
    seg = np.searchsorted(np.asarray(model.knots), view.torque, side="right")
    k_local = np.asarray(model.k)[seg]
    k = float(np.sum(w * k_local) / np.sum(w)) if np.sum(w) > 0 else float("nan")
    per_speed = _twist_per_speed(model, key) / k if k else float("nan")
    slope = current_viscous_slope(
        np.asarray(view.sig.current), view.torque, np.asarray(view.sig.omega_l)
    )
    sentence = velocity_reading(per_speed, slope)
    want = "skew:encoders" if sentence.startswith("skew") else "viscous:omega_l"
    if slope is not None and key != want:
        other = [t for t in trials if t[1].key == want]
        if not other and try_key is not None:
            other = [t for t in [try_key(want)] if t is not None]
        if other:
            notes.append(f"{want} chosen over {key}, which fits the same speed column: {sentence}")
            return other[0]
    notes.append(f"{key}: {sentence}")
    return best


def _eligible(ranked, options: DiscoverOptions):
    """The shortlist of `_best_per_key`'s ranking: selected by the sparse regression,
    removing at least `min_gain` of the cross-validated twist error on the standard folds, and
    stable (doing so in at least `min_stability` of the resampled fold assignments)."""
    return [
        r for r in ranked if r[3] and r[1] >= options.min_gain and r[4] >= options.min_stability
    ][: options.n_shortlist]


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
    with phase("baseline"):
        model = baseline_model = calibrate_baseline(train, joint, options, notes)
        # with a chunk, estimates run chunk by chunk too (see PipelineData.chunk)
        data = dataclasses.replace(_as_data(model, train), chunk=options.chunk)
        test_data = dataclasses.replace(_as_data(model, test), chunk=options.chunk)
    n_gaps = int(data.starts.sum()) - 1
    if n_gaps:
        notes.append(
            f"TRAIN has {n_gaps} gap(s) (time steps over 3 sample periods): {n_gaps + 1} "
            "segments; memory states restart and derivatives stop at each gap"
        )
    with phase("test"):
        base_metrics, base_est = _test_errors(model, test_data, joint.rated_torque)
        base_twist = _twist_rms(model, test_data, chunk=options.chunk)
    say(f"baseline: test torque RMS {base_metrics.rms:.4g} N·m, max {base_metrics.max:.4g} N·m")
    # folds: whole contiguous blocks, no shorter than the residual's correlation length
    with phase("baseline"):
        est_train = estimate(model, data)
        resid0 = data.part(_residual(model, data, None, options.chunk))
    minimum, per_fold = options.block, 2
    if test_data.rows is not None:
        # TEST is blocks of the same log: hold out blocks like TEST's, one per fold at least,
        # so the folds ask TRAIN for what TEST will (as far from the training rows)
        minimum, per_fold = max(1, run_length(test_data.rows)), 1
    block, note = cv_block_length(resid0, data.part_starts, options.n_folds, minimum, per_fold)
    if note:
        notes.append(note)
    # blocks and folds over TRAIN's rows ("local"); the record's rows for the torque CV
    blocks = contiguous_blocks(data.part_starts, block)
    n_folds = min(options.n_folds, int(blocks.max()) + 1)
    if n_folds != options.n_folds:
        notes.append(
            f"TRAIN holds {n_folds} blocks as long as TEST's: cross-validation uses {n_folds} folds"
        )
        options = dataclasses.replace(options, n_folds=n_folds)
    folds = fold_assignment(blocks, options.n_folds)
    folds_rec = folds if data.rows is None else [data.rows[f] for f in folds]
    blocks_rec = blocks
    if data.rows is not None:
        blocks_rec = np.full(data.n, -1)
        blocks_rec[data.rows] = blocks
    # each resample deals the blocks to the folds in a random balanced order
    resamples = resampled_assignments(
        int(blocks.max()) + 1, options.n_folds, options.n_resamples, options.seed
    )
    with phase("torque CV"):
        cv = cross_validate(model, data, folds_rec, chunk=options.chunk)
    base_cv = cv
    say(f"baseline: cross-validated torque RMS {cv.torque_rms:.4g} N·m on TRAIN")
    if not np.isfinite(cv.torque_rms):
        notes.append(
            "cross-validation scores no held-out sample: every fold holds out torques outside "
            "the range its training part calibrates, so no effect can be judged and none is added"
        )
    steps: list[DiscoveryStep] = []
    unidentified: list[str] = []
    excluded: set[str] = set()
    ranking: list[dict] = []
    spectra: dict = {}
    resid = None
    while True:
        scored, spectra, resid = score_candidates(
            model,
            data,
            options,
            extra_columns,
            folds=folds,
            blocks=blocks,
            resamples=resamples,
            est=est_train,
            phases=phase,
            unidentified=unidentified,
        )
        ranked = _best_per_key([s for s in scored if s[0].key not in excluded], options.min_gain)
        ranking = [
            dict(
                key=c.key,
                cv_gain=g,
                min_fold_gain=float(np.min(f)),
                sindy=s,
                stability=st,
                origin=c.origin,
            )
            for c, g, f, s, st, _ in ranked[:10]
        ]
        if len(steps) >= options.max_effects:
            notes.append(f"stopped: reached max_effects = {options.max_effects}")
            break
        eligible = _eligible(ranked, options)
        trials = []
        for _, _, _, _, stab, members in eligible:
            # the best grid member that calibrates to an invertible model (a hysteresis scale
            # too sharp for its amplitude is not)
            for gain, cand, folds_ in members[: options.n_grid_tries]:
                if gain < options.min_gain:
                    break
                try:
                    with phase("calibrate"):
                        new_model, new_est = calibrate(
                            model.with_effects(cand.term), data, notes, est_train, options.chunk
                        )
                    with phase("torque CV"):
                        new_cv = cross_validate(new_model, data, folds_rec, cv, options.chunk)
                except (CalibrationError, InversionError) as err:
                    notes.append(f"candidate {cand.key} could not be added: {err}")
                    continue
                for r in ranking:
                    if r["key"] == cand.key:
                        r["cv_torque_rms"] = new_cv.torque_rms
                trials.append(
                    (new_cv.torque_rms, cand, gain, folds_, stab, new_model, new_est, new_cv)
                )
                break
        if not trials and eligible:
            notes.append(
                "stopped: the eligible candidates ("
                + ", ".join(r[0].key for r in eligible)
                + ") could not be calibrated to an invertible model"
            )
            break
        if not trials:
            notes.append(
                "stopped: no candidate selected by the sparse regression removes at least "
                f"{options.min_gain:.0%} of the cross-validated twist error in at least "
                f"{options.min_stability:.0%} of {options.n_resamples} resampled fold assignments"
            )
            break
        trials.sort(key=lambda x: x[0])
        if not trials[0][0] <= (1.0 - options.min_torque_gain) * cv.torque_rms:
            tried = ", ".join(f"{t[1].key} {t[0]:.4g} N·m" for t in trials)
            notes.append(
                f"stopped: no candidate lowers the cross-validated torque error "
                f"({cv.torque_rms:.4g} N·m) by {options.min_torque_gain:.0%} (tried: {tried})"
            )
            break
        best = _parsimonious(trials, cv, blocks_rec, options, notes)

        def _try_key(key, ranked=ranked):
            # the reading's own candidate, when the shortlist did not try it
            for *_, stab, members in (r for r in ranked if r[0].key == key):
                gain, cand, folds_ = members[0]
                try:
                    new_model, new_est = calibrate(
                        model.with_effects(cand.term), data, notes, est_train, options.chunk
                    )
                    new_cv = cross_validate(new_model, data, folds_rec, cv, options.chunk)
                except (CalibrationError, InversionError):
                    return None
                if not new_cv.torque_rms <= (1.0 - options.min_torque_gain) * cv.torque_rms:
                    return None  # it must pass the test the chosen trial passed
                return (new_cv.torque_rms, cand, gain, folds_, stab, new_model, new_est, new_cv)
            return None

        best = _velocity_reading(best, trials, data, notes, _try_key)
        _, cand, gain, folds_, stab, new_model, new_est, new_cv = best
        with phase("aliases"):
            # on the signals the candidates were scored on (the model before this step)
            others = [(r[0].key, r[0].term) for r in ranked[:10] if r[0].key != cand.key]
            aliases = find_aliases(
                cand.term, others, *training_data(model, data, est_train), take=data.part
            )
        with phase("test"):
            metrics, est = _test_errors(new_model, test_data, joint.rated_torque)
            twist_rms = _twist_rms(new_model, test_data, chunk=options.chunk)
        model, est_train, cv = new_model, new_est, new_cv
        steps.append(
            DiscoveryStep(
                key=cand.key,
                family=cand.family,
                term=cand.term,
                model=model,
                torque_estimate=est,
                fold_gains=[float(x) for x in folds_],
                test=metrics,
                twist_rms_arcsec=twist_rms,
                cv_gain=gain,
                cv_torque_rms=new_cv.torque_rms,
                cv_twist_rms_arcsec=new_cv.twist_rms_arcsec,
                stability=stab,
                ranking=ranking,
                spectra=spectra,
                aliases=aliases,
            )
        )
        say(
            f"step {len(steps)}: added {cand.key} (CV twist gain {gain:.1%}, stability "
            f"{stab:.0%}, CV torque {new_cv.torque_rms:.4g} N·m); test torque RMS "
            f"{metrics.rms:.4g} N·m, max {metrics.max:.4g} N·m"
            + (
                "; TRAIN cannot tell it apart from " + ", ".join(a["key"] for a in aliases)
                if aliases
                else ""
            )
        )
        before = steps[-2].test.rms if len(steps) > 1 else base_metrics.rms
        if metrics.rms > before:
            # TEST never chooses, so a step it disagrees with stays: say so, loudly
            rise = (
                f"warning: step {len(steps)} ({cand.key}) raised the TEST torque RMS from "
                f"{before:.4g} to {metrics.rms:.4g} N·m (+{metrics.rms / before - 1:.1%}), "
                "although cross-validation on TRAIN lowered the torque error: TRAIN and TEST differ"
            )
            notes.append(rise)
            say(rise)
    # amplitudes with intervals, and what is left
    intervals = []
    with phase("intervals"):
        if steps:
            sig_d, torque = data.pair(est_train)
            if options.chunk:
                chunks = chunks_of(sig_d, torque, options.chunk)
                res_final = twist_residual(canonical(model), chunks)
                length = bootstrap_length(res_final, data.starts)
                inst = chunks_of(sig_d, instrument_torque(torque, data.starts), options.chunk)
                intervals = effect_intervals(
                    model, None, data, est_train, length=length, chunks=chunks, instruments=inst
                )
            else:
                # designs on the whole record (memory states), statistics on TRAIN's rows
                view = data.view()
                a_final = data.part(design(model, sig_d, torque))
                res_final = view.twist - a_final @ np.asarray(model.coef)
                length = bootstrap_length(res_final, view.starts)
                inst = np.full(data.n, np.nan)
                inst[data.rows if data.rows is not None else slice(None)] = instrument_torque(
                    view.torque, view.starts
                )
                z = data.part(design(model, sig_d, inst))
                intervals = effect_intervals(
                    model, a_final, view, data.part(est_train), length=length, instruments=z
                )
                del a_final, z
            for s_, iv in zip(steps, intervals):
                s_.amplitude = iv
    with phase("unexplained"):
        view = data.view()
        corr = correlation_length(resid, view.starts) if resid is not None else 1
        angles = {s: np.asarray(view.sig.get(s)) for s in ("theta_m", "theta_l")}
        left = unexplained_structure(
            resid if resid is not None else view.twist * 0.0,
            spectra
            if resid is None
            else all_spectra(
                resid,
                angles,
                {"theta_m": options.library.orders_m, "theta_l": options.library.orders_l},
                spectra,
            ),
            {
                "torque": view.torque,
                "omega_m": np.asarray(view.sig.omega_m),
                "omega_l": np.asarray(view.sig.omega_l),
            },
            correlation_length=corr,
            starts=view.starts,
            angles=angles,
        )
    notes += list(dict.fromkeys(unidentified))
    final = steps[-1].test if steps else base_metrics
    with phase("reference"):
        checks = _reference_findings(
            model, data, est_train, test_data, steps[-1].torque_estimate if steps else base_est
        )
        for part, found in checks.items():
            for f in found:
                if f["flagged"]:
                    say(f"reference ({part}): {f['message']}")
    say(phase.line())
    ratio = cv.torque_rms / final.rms if final.rms > 0 else float("nan")
    if np.isfinite(ratio) and not 0.5 <= ratio <= 2.0:
        notes.append(
            f"cross-validation does not represent TEST: the final cross-validated torque RMS "
            f"({cv.torque_rms:.4g} N·m) is {ratio:.2g} times the TEST RMS ({final.rms:.4g} N·m), "
            "so the held-out blocks of TRAIN ask for "
            + ("more extrapolation than TEST does" if ratio > 1 else "less than TEST does")
            + "; the loop's choices rest on TRAIN's folds, and the TEST figure is what to trust"
        )
    if final.rms > base_metrics.rms:
        # TEST never chooses, so it can disagree with cross-validation: say so, loudly
        notes.append(
            f"warning: on TEST the final model's torque RMS ({final.rms:.4g} N·m) is "
            f"{final.rms / base_metrics.rms - 1:.1%} above the starting model's "
            f"({base_metrics.rms:.4g} N·m), although cross-validation on TRAIN lowered it from "
            f"{base_cv.torque_rms:.4g} to {cv.torque_rms:.4g} N·m: TRAIN and TEST differ"
        )
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
        cv_block_samples=int(block),
        reference_checks=checks,
        cv_test_ratio=float(ratio),
    )
    stats = dict(
        n_effects=len(steps),
        baseline_test_rms=base_metrics.rms,
        final_test_rms=final.rms,
        baseline_cv_torque_rms=base_cv.torque_rms,
        final_cv_torque_rms=cv.torque_rms,
        cv_block_samples=block,
        fit_time_s=time.perf_counter() - t_start,
    )
    return Solution(model, RESULTS.successful, stats, aux=record)


def _reference_findings(model, data, est_train, test_data, est_test) -> dict:
    """[`hdjax.reference.reference_checks`][] of TRAIN (the final model's estimate on its rows)
    and TEST (its estimate there, and the calibrated range)."""
    out = {}
    lo, hi = model.torque_range
    for part, d, est in (("TRAIN", data, data.part(est_train)), ("TEST", test_data, est_test)):
        v = d.view()
        est = np.asarray(est, np.float64)
        out[part] = reference_checks(
            np.asarray(v.sig.t),
            v.torque,
            est,
            current=np.asarray(v.sig.current),
            omega=np.asarray(v.sig.omega_l),
            in_range=(est >= lo) & (est <= hi),
        )
    return out


def refit_structure(
    train: Recording,
    test: Recording,
    joint: Joint,
    terms: Sequence[AbstractTerm],
    options: DiscoverOptions = DiscoverOptions(),
) -> ErrorMetrics:
    """TEST errors of the starting model plus `terms` (e.g. the true structure), calibrated by
    the same pipeline as the loop's (hysteresis driven by the model's own estimate).

    **Returns:** an [`hdjax.ErrorMetrics`][].
    """
    notes: list[str] = []
    base = calibrate_baseline(train, joint, options, notes)
    data = _as_data(base, train)
    model, _ = calibrate(base.with_effects(*terms), data, notes, estimate(base, data))
    return _test_errors(model, test, joint.rated_torque)[0]


def residual_spectra(
    model: ComplianceModel, data: CalibrationData, *, orders: tuple[float, float] = (0.5, 8.0)
) -> dict[str, OrderSpectrum]:
    """Order spectra of a model's twist residual against both angles (for reports)."""
    sig, torque = prepare(model, data)
    r = np.asarray(sig.twist) - np.asarray(model.predict_twist(sig, torque))
    out = {}
    for signal in ("theta_m", "theta_l"):
        theta = np.asarray(sig.get(signal))
        lo = max(orders[0], 2 * np.pi / max(np.ptp(theta), 1e-12))
        if lo < orders[1]:
            out[signal] = order_spectrum(theta, r, signal=signal, min_order=lo, max_order=orders[1])
    return out


__all__ = [
    "DiscoverOptions",
    "DiscoveryRecord",
    "DiscoveryStep",
    "discover",
    "refit_structure",
    "HdjaxError",
]
