"""One step's candidate scores: the library's columns, their cross-validated twist gains
on the standard folds and on every resampled fold assignment, and pysindy's selection.

The scores are computed once, against a row source ([`_block_scores`][]): the record in
memory ([`_memory_batches`][]: the candidates' columns computed on the whole record, a batch
at a time) or a log chunk by chunk with `options.chunk` ([`_chunk_batches`][]: every column
formed chunk by chunk, memory states carried)."""

from __future__ import annotations

import numpy as np

from .._joint import Joint
from ..compliance import ComplianceModel
from ._chunked import Chunks, DahlCarry, own_rows, sequential, twist_residual
from ._decision import Scored
from ._gram import block_spans, block_statistics_streamed, fold_gains, memory_passes
from ._library import build_library, candidate_columns
from ._options import DiscoverOptions
from ._pipeline import PipelineData, canonical, chunks_of, design, estimate, pipeline_signals
from ._select import (
    MAX_SINDY_ROWS,
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


def _column_range(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each column's minimum and maximum (column by column: a reduction along the first axis
    of an `(n, 2)` array is several times slower)."""
    lo = np.array([c[:, j].min() for j in range(c.shape[1])])
    hi = np.array([c[:, j].max() for j in range(c.shape[1])])
    return lo, hi


def _scorable(lo: np.ndarray, hi: np.ndarray) -> bool:
    """From its columns' ranges: a candidate whose columns are finite and not all constant can
    be scored (a column is finite exactly when its minimum and maximum are)."""
    return bool(np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.any(hi > lo))


def _memory_batches(cands, sig, torque, a, take, blocks):
    """The in-memory row source: per batch of candidates (at least `BATCH_COLUMNS` columns),
    `(candidate indices, passes)`, the columns computed on the whole record (memory states
    run through every row), taken to the part's rows, and read in spans of whole blocks.
    A batch's columns are computed when the batch is asked for, so only one batch is held."""
    spans = block_spans(blocks)
    batch, cols, width = [], [], 0
    for i, cand in enumerate(cands):
        c = take(candidate_columns(cand.term, sig, torque))
        batch.append(i)
        cols.append(c)
        width += c.shape[1]
        if width >= BATCH_COLUMNS or i == len(cands) - 1:
            yield batch, memory_passes(a, cols, spans)
            batch, cols, width = [], [], 0


def _chunk_batches(cands, model, chunks: Chunks):
    """The chunked row source: one batch of every candidate, its `passes()` forming the base
    design and each candidate's columns chunk by chunk, the Dahl states of hysteresis
    candidates carried across chunks."""
    active = np.asarray(model.active)

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
                    )[:, None]
                else:
                    c = candidate_columns(cand.term, sc, tc)[h : h + rows]
                groups.append(np.asarray(c, np.float64))
            yield lo, hi, a, groups

    yield list(range(len(cands))), passes


def _block_scores(batches, y, resid, blocks, options, phase):
    """Block statistics of the candidates' columns and the sparse regression on every
    `step`-th sample of them (the rows [`sindy_select`][hdjax.discover._select.sindy_select]
    reads), from a row source: `batches` yields `(candidate indices, passes)` (see
    [`hdjax.discover._gram.block_statistics_streamed`][]); `y` is the target, row by row.

    The first pass of each batch also gathers the thinned rows (copies: a view of every
    `step`-th row would keep each chunk's arrays alive) and each candidate's running range; a
    candidate whose columns are not all finite, or all constant, is not scored.

    **Returns:** `(sindy-selected per column, owner candidate per column, usable candidate
    indices, BlockStatistics of the usable candidates)`.
    """
    step = max(1, y.size // MAX_SINDY_ROWS)
    thin_a: list[np.ndarray] = []
    thin: dict[int, list[np.ndarray]] = {}
    ranges: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    usable: list[int] = []
    current: list[int] = []

    def tracked(idx, passes, with_base):
        first = True

        def run():
            nonlocal first
            for lo, hi, a, groups in passes():
                if first:
                    start = (-lo) % step
                    if with_base:
                        thin_a.append(np.array(a[start::step]))
                    for i, g in zip(idx, groups):
                        thin.setdefault(i, []).append(np.array(g[start::step]))
                        ranges.setdefault(i, []).append(_column_range(g))
                yield lo, hi, a, groups
            first = False

        return run

    def batch_passes():
        for b, (idx, passes) in enumerate(batches):
            current[:] = idx
            yield tracked(idx, passes, b == 0)

    def select():
        keep = []
        for k, i in enumerate(current):
            lo = np.min([r[0] for r in ranges[i]], axis=0)
            hi = np.max([r[1] for r in ranges[i]], axis=0)
            if _scorable(lo, hi):
                keep.append(k)
                usable.append(i)
        return keep

    with phase("twist CV"):  # the candidates' columns included
        stats = block_statistics_streamed(batch_passes(), y, blocks, select)
    with phase("sindy"):
        cols, owner = [], []
        for i in sorted(thin):
            cat = np.concatenate(thin[i])
            for j in range(cat.shape[1]):
                cols.append(np.ascontiguousarray(cat[:, j]))
                owner.append(i)
        selected = sindy_select(
            np.concatenate(thin_a),
            resid[::step],
            cols,
            [str(o) for o in owner],
            threshold=options.sindy_threshold,
        )
    return selected, np.asarray(owner), usable, stats


def score_candidates(
    model,
    train,
    options: DiscoverOptions,
    extra_columns,
    *,
    folds,
    blocks,
    resamples=(),
    est=None,
    phases=None,
    unidentified=None,
):
    """Library, spectra and per-candidate scores for one step (the families' reasons for
    offering nothing appended to `unidentified`, when given).

    `folds` are unions of the whole contiguous `blocks` (the block index per sample), so every
    cross-validated score, on the standard folds and on each resampled assignment, comes from
    one pass of per-block Gram statistics ([`hdjax.discover._gram`][]).

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
            a, chunks = None, chunks_of(sig, torque, chunk)
            resid = twist_residual(canonical(model), chunks)
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
    if chunk:
        batches = _chunk_batches(cands, canonical(model), chunks)
        target = np.asarray(chunks.sig.twist)
    else:
        batches, target = _memory_batches(cands, sig, torque, a, take, blocks), y
    selected, owner, usable, stats = _block_scores(batches, target, resid, blocks, options, phase)
    with phase("twist CV"):
        total, per_fold = fold_gains(stats, _fold_of_block(blocks, folds), options.n_folds)
        gains = list(zip(total.tolist(), per_fold))
        resampled = [fold_gains(stats, fb, options.n_folds)[0] for fb in resamples]
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
