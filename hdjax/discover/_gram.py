"""Candidate scores from per-block Gram matrices: one pass over the samples per step.

Every cross-validated score of a step is a least-squares refit on the training part of a fold
(Song et al. eqs. (15)-(17)) of the base design $A$ plus one candidate group $C_i$, judged by
its error on the held-out part. Folds are unions of whole contiguous blocks, so a fold's
training statistics are the total minus its held-out blocks'. [`block_statistics`][] makes one
pass over the samples and keeps, per block, only the parts of the Gram matrix of
$[A \\mid y \\mid C]$ that any refit reads: $A^\\top A$, $A^\\top y$, $y^\\top y$, $A^\\top C$,
$C^\\top y$ and each group's own $C_i^\\top C_i$ (never the cross products of two different
candidates). [`fold_gains`][] then scores every group for any assignment of blocks to folds
with small dense solves: the base by Cholesky of the Jacobi-scaled $A^\\top A$, and each group
by the Schur complement of its columns (the Frisch-Waugh-Lovell update), vectorised over the
groups. The standard folds and every resampled assignment (stability selection) share the
same statistics.

The result is the normal-equation solution of the per-fold least-squares problems; on the
loop's designs it agrees with the per-fold QR of [`hdjax.discover._select.cv_gains`][] to
within $\\epsilon\\kappa^2$ relative in each fold's SSE ratio ($\\kappa$ the condition number of
the column-scaled training design; normal equations square it): about $10^{-9}$ on typical
designs, $10^{-8}$ on the test's deliberately ill-conditioned ones, far below any decision
threshold.

Memory: the statistics take `n_blocks x (p + 1) x (p + 1 + c)` numbers; the pass reads the
samples in chunks of whole blocks of at most `chunk` rows, so no copy of the data is made, and
the candidates' columns may arrive batch by batch ([`block_statistics_streamed`][]), so the
library's columns need never be in memory all at once.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.linalg

CHUNK = 65536
"""Rows read at once by the statistics pass (whole blocks; a longer block is read alone)."""

DEGENERATE = 1e-12
"""A candidate direction whose scaled Schur complement falls below this is absorbed by the
base design: it explains nothing (its coefficient is set to zero)."""


@dataclasses.dataclass(frozen=True)
class BlockStatistics:
    """Per-block sums of the products of `[A | y]` with `[A | y | C]` and each group's own
    Gram block. Shapes: `ab` `(n_blocks, p + 1, p + 1 + c)`, `cc[w]` `(n_blocks, g_w, w, w)`
    for the groups of width `w` (their indices in `groups[w]`, their columns in `cols[w]`)."""

    ab: np.ndarray
    cc: dict
    groups: dict
    cols: dict
    p: int
    n_groups: int
    widths: tuple


def _block_bounds(blocks: np.ndarray) -> np.ndarray:
    """Start of each block and the end, for blocks that are contiguous and in order."""
    if blocks.size == 0:
        return np.zeros(1, int)
    step = np.diff(blocks)
    if np.any((step != 0) & (step != 1)) or blocks[0] != 0:
        raise ValueError("blocks must be contiguous and numbered in sample order")
    return np.r_[0, np.flatnonzero(step) + 1, blocks.size]


def block_statistics(a, groups, y, blocks, *, chunk: int = CHUNK) -> BlockStatistics:
    """Per-block statistics of the base design `a` `(n, p)`, the candidate `groups` (a list
    of `(n, w)` arrays) and the target `y` (see the module docstring), all in memory.

    `blocks` is the block index per sample (contiguous blocks in sample order, as
    [`hdjax.discover._folds.contiguous_blocks`][] makes them). The rows are read as
    [`block_statistics_streamed`][] reads a log: in passes of whole blocks, at most `chunk`
    rows at a time (at least one block).
    """
    passes = memory_passes(np.asarray(a, np.float64), list(groups), block_spans(blocks, chunk))
    return block_statistics_streamed([passes], y, blocks)


def block_spans(blocks, chunk: int = CHUNK) -> list[tuple[int, int]]:
    """`(lo, hi)` row spans of whole consecutive blocks, each at most `chunk` rows (a longer
    block alone)."""
    bounds = _block_bounds(np.asarray(blocks))
    spans, b = [], 0
    while b < bounds.size - 1:
        e = b + 1
        while e < bounds.size - 1 and bounds[e + 1] - bounds[b] <= chunk:
            e += 1
        spans.append((int(bounds[b]), int(bounds[e])))
        b = e
    return spans


def memory_passes(a: np.ndarray, groups: list, spans):
    """A `passes()` (see [`block_statistics_streamed`][]) over rows already in memory: the
    base design `a` and the candidate `groups`, read span by span (views, no copies)."""

    def passes():
        for lo, hi in spans:
            yield lo, hi, a[lo:hi], [g[lo:hi] for g in groups]

    return passes


def block_statistics_streamed(batch_passes, y, blocks, select=None) -> BlockStatistics:
    """[`block_statistics`][] from rows that arrive chunk by chunk, so neither the base design
    nor any candidate's columns need ever be held for the whole record.

    `batch_passes` yields, per batch of candidate groups, a `passes()` that starts a pass over
    the record: an iterator of `(lo, hi, a, groups)`, the base design's rows `lo:hi` and that
    batch's candidate groups' (a list of `(hi - lo, w)` arrays, the same groups in every
    chunk); chunk boundaries may fall anywhere (a block's sums are accumulated over the chunks
    it spans). `y` is the target over the whole record.

    Two passes per batch. The first sums $A^\\top C$, and on the first batch also
    $A^\\top A$ and $A^\\top y$. Then `select()` (when given) gives the indices, within the
    batch, of the groups to keep (what the first pass found usable), and the second pass sums
    the per-block statistics of `y` and of the kept groups made orthogonal to the base (a
    refit on `[A | C]` equals one on `[A | C - A W]`, so the scores are unchanged, but a
    candidate close to the base's span no longer loses its digits to the cancellation in
    $C^\\top C - C^\\top A (A^\\top A)^{-1} A^\\top C$), with the blocks' `[A | y]`
    products on the first batch. The groups are numbered in arrival order, the kept ones
    only.
    """
    y = np.asarray(y, np.float64)
    bounds = _block_bounds(np.asarray(blocks))
    base = project = wy = None
    parts, cc_parts, widths = [], {}, []
    for passes in batch_passes:
        aa = ay = ac = None
        batch_widths: list[int] = []
        for lo, hi, a, groups in passes():
            if ac is None:
                p = a.shape[1]
                batch_widths = [int(g.shape[1]) for g in groups]
                ac = np.zeros((p, sum(batch_widths)))
                if project is None:
                    aa, ay = np.zeros((p, p)), np.zeros(p)
            if project is None:
                aa += a.T @ a
                ay += a.T @ y[lo:hi]
            if groups:
                ac += a.T @ np.concatenate(groups, axis=1)
        if ac is None:
            raise ValueError("the passes hold no rows")
        if project is None:
            project = _projector(aa)
            wy = project(ay[:, None])[:, 0]
        keep = list(range(len(batch_widths))) if select is None else [int(i) for i in select()]
        offsets = np.cumsum([0, *batch_widths])
        keep_cols = [np.arange(offsets[i], offsets[i + 1]) for i in keep]
        wc = project(ac[:, np.concatenate([np.zeros(0, int), *keep_cols])])
        kept = tuple(batch_widths[i] for i in keep)
        part, cc_b, base_b = _block_sums(passes, y, bounds, wy, wc, keep, kept, base is None)
        base = base_b if base is None else base
        parts.append(part)
        widths.extend(kept)
        for w, v in cc_b.items():
            cc_parts.setdefault(w, []).append(v)
    widths = tuple(widths)
    by_width, cols = _by_width(widths)
    cc = {w: np.concatenate(cc_parts[w], axis=1) for w in by_width}
    ab = np.concatenate([base, *parts], axis=2)
    groups = {w: np.asarray(idx) for w, idx in by_width.items()}
    return BlockStatistics(ab, cc, groups, cols, wy.size, len(widths), widths)


def _projector(aa: np.ndarray):
    """`A^T R -> W`, the least-squares coefficients of columns `R` on the base (Jacobi-scaled
    normal equations, minimum norm where the base is rank-deficient)."""
    if not aa.size:
        return lambda ar: np.zeros((0, ar.shape[1]))
    d = np.sqrt(np.diag(aa)).copy()
    d[d == 0] = 1.0
    aa_scaled = aa / np.outer(d, d)
    return lambda ar: np.linalg.lstsq(aa_scaled, ar / d[:, None], rcond=1e-13)[0] / d[:, None]


def _block_sums(passes, y, bounds, wy, wc, keep, widths, with_base):
    """One pass of per-block sums: `[A | y]^T C` and each kept group's own `C_i^T C_i`, with
    `y - A wy` and `C - A wc` (orthogonal to the base), and `[A | y]^T [A | y]` where
    `with_base`. **Returns:** `(ab part (n_blocks, p + 1, c), {w: (n_blocks, g_w, w, w)},
    base (n_blocks, p + 1, p + 1) or None)`."""
    n_blocks = bounds.size - 1
    p = wy.size
    by_width, cols = _by_width(widths)
    ab = np.zeros((n_blocks, p + 1, wc.shape[1]))
    cc = {w: np.zeros((n_blocks, len(idx), w, w)) for w, idx in by_width.items()}
    base = np.zeros((n_blocks, p + 1, p + 1)) if with_base else None
    for lo, hi, a, groups in passes():
        yt = y[lo:hi] - a @ wy
        m = np.concatenate([groups[i] for i in keep], axis=1) if keep else np.zeros((hi - lo, 0))
        m = m - a @ wc
        j = int(np.searchsorted(bounds, lo, side="right")) - 1
        while j < n_blocks and bounds[j] < hi:
            r = slice(max(bounds[j], lo) - lo, min(bounds[j + 1], hi) - lo)
            ar, yr, cr = a[r], yt[r], m[r]
            if with_base:
                base[j, :p, :p] += ar.T @ ar
                base[j, :p, p] += ar.T @ yr
                base[j, p, :p] += ar.T @ yr
                base[j, p, p] += yr @ yr
            ab[j, :p] += ar.T @ cr
            ab[j, p] += yr @ cr
            for w, ci in cols.items():
                x = cr[:, ci]  # (rows, g_w, w)
                cc[w][j] += np.einsum("nga,ngb->gab", x, x)
            j += 1
    return ab, cc, base


def _by_width(widths) -> tuple[dict[int, list[int]], dict[int, np.ndarray]]:
    """Groups laid side by side with these column `widths`, bucketed by width.
    **Returns:** `(by_width, cols)`: per width, the groups' positions, and their column
    indices in the side-by-side layout, shape `(n_groups_of_width, width)`."""
    offsets = np.cumsum([0, *widths])
    by_width: dict[int, list[int]] = {}
    for i, w in enumerate(widths):
        by_width.setdefault(w, []).append(i)
    cols = {
        w: np.array([np.arange(offsets[i], offsets[i] + w) for i in idx])
        for w, idx in by_width.items()
    }
    return by_width, cols


def gram_solve(g: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The least-squares coefficients from normal equations `g x = rhs` (Cholesky; a
    minimum-norm least-squares solve where `g` is singular)."""
    try:
        c = np.linalg.cholesky(g)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(g, rhs, rcond=1e-12)[0]
    return scipy.linalg.cho_solve((c, True), rhs, check_finite=False)


def fold_gains(stats: BlockStatistics, fold_of_block: np.ndarray, n_folds: int):
    """Cross-validated gain of every group for one assignment of blocks to folds.

    **Returns:** `(total, per_fold)`: per group the overall gain
    $1 - \\sum_f SSE_f(C_i) / \\sum_f SSE_f(\\text{base})$, shape `(n_groups,)`, and the
    per-fold gains, shape `(n_groups, n_folds)`.
    """
    p = stats.p
    yi = p
    ab = stats.ab
    total = ab.sum(axis=0)
    cc_total = {w: v.sum(axis=0) for w, v in stats.cc.items()}
    # Jacobi scaling from the whole record's column norms (as the per-fold QR scales)
    diag = np.r_[np.diag(total[:, : p + 1]), np.zeros(total.shape[1] - p - 1)]
    for w, ci in stats.cols.items():
        diag[p + 1 + ci.ravel()] = np.einsum("gaa->ga", cc_total[w]).ravel()
    s = np.sqrt(diag)
    s[s == 0] = 1.0
    s_row = s[: p + 1]
    base_sse = np.zeros(n_folds)
    sse = np.zeros((stats.n_groups, n_folds))
    for f in range(n_folds):
        te = fold_of_block == f
        g_te = ab[te].sum(axis=0) / np.outer(s_row, s)
        g_tr = total / np.outer(s_row, s) - g_te
        cc_te = {w: v[te].sum(axis=0) for w, v in stats.cc.items()}
        base = np.flatnonzero(np.diag(g_tr[:p, :p]) > 1e-14)
        aa = g_tr[np.ix_(base, base)]
        ay = g_tr[base, yi]
        ac = g_tr[base, p + 1 :]
        sol = gram_solve(aa, np.column_stack([ay, ac]))
        theta0, w_all = sol[:, 0], sol[:, 1:]
        t_aa = g_te[np.ix_(base, base)]
        t_ay = g_te[base, yi]
        t_yy = g_te[yi, yi]
        base_sse[f] = t_yy - 2 * theta0 @ t_ay + theta0 @ t_aa @ theta0
        for w, gi in stats.groups.items():
            ci = stats.cols[w]  # (g_w, w) candidate column indices
            sc = s[p + 1 + ci]  # (g_w, w)
            r_cc = (cc_total[w] - cc_te[w]) / (sc[:, :, None] * sc[:, None, :])
            t_cc = cc_te[w] / (sc[:, :, None] * sc[:, None, :])
            r_ca = ac.T[ci]  # (g_w, w, k)
            wg = np.moveaxis(w_all[:, ci], 0, -1)  # (g_w, w, k)
            schur = r_cc - np.einsum("gak,gbk->gab", r_ca, wg)
            rhs = g_tr[yi, p + 1 + ci] - np.einsum("gak,k->ga", r_ca, theta0)
            gamma = _small_solves(schur, rhs, r_cc)
            theta_a = theta0[None, :] - np.einsum("gak,ga->gk", wg, gamma)  # (g_w, k)
            t_ca = g_te[base][:, p + 1 :].T[ci]  # (g_w, w, k)
            t_cy = g_te[yi, p + 1 + ci]  # (g_w, w)
            quad = (
                np.einsum("gk,kl,gl->g", theta_a, t_aa, theta_a)
                + 2 * np.einsum("gk,gak,ga->g", theta_a, t_ca, gamma)
                + np.einsum("ga,gab,gb->g", gamma, t_cc, gamma)
            )
            lin = theta_a @ t_ay + np.einsum("ga,ga->g", gamma, t_cy)
            sse[gi, f] = t_yy - 2 * lin + quad
    per_fold = 1.0 - sse / np.where(base_sse > 0, base_sse, 1e-300)[None, :]
    total_gain = 1.0 - sse.sum(axis=1) / max(base_sse.sum(), 1e-300)
    return total_gain, per_fold


def _small_solves(schur: np.ndarray, rhs: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Solve the `(g, w, w)` Schur systems; a direction the base absorbs gets no coefficient."""
    g, w = rhs.shape
    if w == 1:
        den = schur[:, 0, 0]
        ok = den > DEGENERATE * np.maximum(ref[:, 0, 0], 1e-300)
        return np.where(ok, rhs[:, 0] / np.where(ok, den, 1.0), 0.0)[:, None]
    out = np.zeros((g, w))
    for i in range(g):
        lam, vec = np.linalg.eigh(schur[i])
        keep = lam > DEGENERATE * max(np.trace(ref[i]), 1e-300)
        if keep.all():
            out[i] = np.linalg.solve(schur[i], rhs[i])
        else:
            v = vec[:, keep]
            out[i] = v @ ((v.T @ rhs[i]) / lam[keep])
    return out
