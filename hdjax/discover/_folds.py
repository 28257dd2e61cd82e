"""Segments of a recording with gaps, and cross-validation folds of whole contiguous blocks.

A recording with gaps is a list of contiguous segments. A gap is a time step longer than
`GAP_FACTOR` (3) median sample periods, which is also what the joins of a block split (TRAIN
made of every other block, say) look like. Derivatives never cross a gap; memory states carry
across one up to `MEMORY_GAP` long and restart at a longer one ([`memory_starts`][], used by
[`hdjax.discover.pipeline_signals`][]).

Cross-validation holds out whole contiguous blocks that never straddle a gap and are no
shorter than the residual's correlation time (so a held-out block is not predicted from its
own correlated neighbours). The standard assignment interleaves the blocks (block $b$ goes to
fold $b \\bmod K$, so every fold spans the whole record); the resampled ones, for stability
selection, deal the blocks to the folds in a random balanced order.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .._features import find_gaps

GAP_FACTOR = 3.0
MAX_BLOCKS = 250


def segment_starts(t) -> np.ndarray:
    """A boolean per sample, true at the first sample of each contiguous segment."""
    t = np.asarray(t, np.float64)
    start = np.zeros(t.shape, bool)
    if t.size:
        start[0] = True
        start[find_gaps(t, GAP_FACTOR) + 1] = True
    return start


MEMORY_GAP = 0.1
"""The longest gap [s] a memory state (hysteresis, backlash) carries across.

A rate-independent memory (the Dahl law, Song et al. Fig. 2) changes with the torque path, not
with time, so across a gap its update takes the torque step over the gap: exact while the
torque does not reverse inside the gap. The gaps of a real log's dropped samples last
milliseconds, far shorter than any reversal of a joint's load; restarting the state at each of
them would throw a one-way sweep's state back to its initial value in mid-motion. Longer gaps,
where a block split joins its blocks or recordings meet, can hide reversals: there the state
restarts."""


def memory_starts(t) -> np.ndarray:
    """A boolean per sample, true where memory states restart: the first sample, and after
    each gap ([`segment_starts`][]) longer than `MEMORY_GAP` or where time does not advance."""
    t = np.asarray(t, np.float64)
    start = segment_starts(t)
    k = np.flatnonzero(start)[1:]
    step = t[k] - t[k - 1]
    start[k] = (step > MEMORY_GAP) | (step <= 0)
    return start


def correlation_length(residual, starts=None, *, max_lag: int = 2000) -> int:
    """Lag [samples] at which the residual's autocorrelation first falls below $1/e$.

    Computed within segments only (products across a gap are left out). At least 1.
    """
    r = np.asarray(residual, np.float64)
    r = r - r.mean()
    n = r.size
    var = float(np.dot(r, r))
    if n < 3 or var == 0.0:
        return 1
    seg = np.zeros(n, int) if starts is None else np.cumsum(starts) - 1
    max_lag = min(max_lag, n // 2)
    if seg[-1] == seg[0]:
        # one segment: every pair counts, so no masks (the same sums, several times faster)
        for lag in range(1, max_lag):
            if float(np.dot(r[lag:], r[:-lag])) / (n - lag) <= var / n / np.e:
                return lag
        return max_lag
    for lag in range(1, max_lag):
        same = seg[lag:] == seg[:-lag]
        if not same.any():
            return lag
        num = float(np.dot(r[lag:][same], r[:-lag][same])) / same.sum()
        if num <= var / n / np.e:
            return lag
    return max_lag


def contiguous_blocks(starts, length: int) -> np.ndarray:
    """Block index per sample: blocks of about `length` samples that never cross a gap.

    Each segment is cut into `max(1, round(len / length))` nearly equal blocks, so every block
    is at least 3/4 of `length` long unless its whole segment is shorter (cutting into
    `len // length` blocks instead halves the blocks of segments just under two lengths, and the
    fewer held-out blocks make the cross-validation noisier: 8 of 20 clean plant joints then get
    an effect). `cv_block_length` asks for 4/3 of the
    correlation length, so no block is shorter than it.
    """
    starts = np.asarray(starts, bool)
    n = starts.size
    bounds = np.r_[np.flatnonzero(starts), n]
    out = np.empty(n, int)
    b = 0
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        m = max(1, int(round((hi - lo) / max(1, length))))
        edges = np.linspace(lo, hi, m + 1).round().astype(int)
        for j in range(m):
            out[edges[j] : edges[j + 1]] = b
            b += 1
    return out


def fold_assignment(blocks: np.ndarray, n_folds: int, *, rng=None) -> list[np.ndarray]:
    """Held-out index sets: block $b$ to fold $b \\bmod K$, or a random balanced deal (`rng`)."""
    n_blocks = int(blocks.max()) + 1
    order = np.arange(n_blocks) if rng is None else rng.permutation(n_blocks)
    fold_of_block = np.empty(n_blocks, int)
    fold_of_block[order] = np.arange(n_blocks) % n_folds
    fold = fold_of_block[blocks]
    return [np.flatnonzero(fold == f) for f in range(n_folds)]


def resampled_assignments(n_blocks: int, n_folds: int, n_resamples: int, seed: int):
    """`n_resamples` random balanced deals of the blocks to the folds (fold of each block),
    for stability selection; reproducible from `seed`."""
    rng = np.random.default_rng(seed)
    return [rng.permutation(np.arange(n_blocks) % n_folds) for _ in range(n_resamples)]


def run_length(rows: np.ndarray) -> int:
    """The median length of the contiguous runs of `rows` (sorted row indices of a record):
    how long the stretches a part cut in blocks from one log are."""
    rows = np.asarray(rows)
    if rows.size == 0:
        return 0
    cuts = np.flatnonzero(np.diff(rows) != 1) + 1
    lengths = np.diff(np.r_[0, cuts, rows.size])
    return int(np.median(lengths))


def cv_block_length(
    residual, starts, n_folds: int, minimum: int, per_fold: int = 2
) -> tuple[int, str | None]:
    """Block length for the folds: the correlation length, at least `minimum` samples and
    `n / MAX_BLOCKS`, at most what leaves `per_fold` blocks per fold; a note when the cap
    binds.

    The note is a warning when the capped blocks are shorter than the correlation length (the
    record is too short for the residual's memory: held-out blocks are partly predicted from
    their correlated neighbours, and the cross-validated errors are optimistic)."""
    n = np.asarray(residual).size
    corr = correlation_length(residual, starts)
    cap = max(1, n // (per_fold * n_folds))
    # long records: at most MAX_BLOCKS blocks (the stability scores keep a Gram matrix each)
    # 4/3: contiguous_blocks keeps every block at least 3/4 of the length it is given
    length = max(minimum, -(-4 * corr // 3), -(-n // MAX_BLOCKS))
    note = None
    if length > cap:
        if corr > cap:
            note = (
                f"warning: the residual stays correlated over {corr} samples, longer than the "
                f"{cap}-sample blocks that leave {per_fold} per cross-validation fold; folds use "
                f"{cap}-"
                "sample blocks, shorter than the correlation time, so the cross-validated errors "
                "are optimistic (a longer TRAIN recording avoids this)"
            )
        else:
            note = (
                f"cross-validation blocks of {cap} samples ({per_fold} per fold), fewer than the "
                f"{length} asked for, but no shorter than the residual's correlation length "
                f"({corr} samples)"
            )
        length = cap
    return length, note


class FoldPlan(NamedTuple):
    """The cross-validation plan over TRAIN: its blocks and folds, as TRAIN's rows ("local")
    and as the record's rows (for the torque CV), and the resampled deals."""

    block: int
    blocks: np.ndarray
    folds: list
    folds_rec: list
    blocks_rec: np.ndarray
    resamples: list
    scored: list | None = None
    """Per fold, the held-out rows it scores (`hdjax.discover._pipeline.scored_rows`), fixed
    from the starting model; None: each cross-validation finds them from its own model."""


def fold_plan(data, test_data, resid0, options, notes):
    """Whole contiguous blocks of TRAIN, no shorter than the residual's correlation length
    (as long as TEST's runs when TEST is blocks of the same log), dealt to the folds; returns
    `(plan, options)` with `n_folds` lowered when TRAIN holds fewer blocks."""
    minimum, per_fold = options.block, 2
    if test_data.rows is not None:
        # TEST is blocks of the same log: hold out blocks like TEST's, one per fold at least,
        # so the folds ask TRAIN for what TEST will (as far from the training rows)
        minimum, per_fold = max(1, run_length(test_data.rows)), 1
    block, note = cv_block_length(resid0, data.part_starts, options.n_folds, minimum, per_fold)
    if note:
        notes.append(note)
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
    return FoldPlan(int(block), blocks, folds, folds_rec, blocks_rec, resamples), options
