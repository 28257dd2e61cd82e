"""One step's candidate scores: the library's columns, their cross-validated twist gains
on the standard folds and on every resampled fold assignment, and pysindy's selection (in
memory, or chunk by chunk with `options.chunk`)."""

from __future__ import annotations

import numpy as np

from .._joint import Joint
from ..compliance import ComplianceModel
from ._chunked import Chunks, DahlCarry, own_rows, sequential, twist_residual
from ._decision import Scored
from ._gram import block_statistics_batched, block_statistics_streamed, fold_gains
from ._library import build_library, candidate_columns
from ._options import DiscoverOptions
from ._pipeline import PipelineData, canonical, chunks_of, design, estimate, pipeline_signals
from ._select import (
    MAX_SINDY_ROWS,
    block_grams,
    cv_gains,
    cv_gains_by_blocks,
    fold_basis,
    sindy_select,
)
from ._timing import null_phases


def _as_data(model, data, joint: Joint | None = None) -> PipelineData:
    """`data` as pipeline signals (a recording's derived with `model`'s or `joint`'s ratio and
    sign)."""
    if isinstance(data, PipelineData):
        return data
    if model is None:
        return pipeline_signals(data, joint.ratio, joint.twist_sign, "difference")
    return pipeline_signals(data, model.ratio, model.twist_sign, model.velocity)


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
        Scored(
            cands[i],
            gain,
            folds_,
            bool(selected[owner == i].any()),
            np.asarray([r[j] for r in resampled]),
        )
        for j, (i, (gain, folds_)) in enumerate(zip(usable, gains))
    ]
    return scored, spectra, resid
