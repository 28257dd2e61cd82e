"""The residual loop's fast kernels against the exact computations they replace.

Candidate scores from per-block Gram statistics (`hdjax.discover._gram`) against the per-fold
QR of `cv_gains` (standard folds) and explicit refits (a resampled assignment); the per-fold
torque-CV solve (corrected semi-normal equations), in memory and chunk by chunk, against
`scipy.linalg.lstsq` on the copied rows. The designs are ill-conditioned on purpose
(monomials up to order 6 and blocks of different scales), as the loop's are.
"""

import numpy as np
import pytest
import scipy.linalg

from hdjax.discover._fold_solver import FoldSolver, one_block
from hdjax.discover._folds import contiguous_blocks, fold_assignment
from hdjax.discover._gram import (
    block_spans,
    block_statistics,
    block_statistics_streamed,
    fold_gains,
    memory_passes,
)
from hdjax.discover._select import cv_gains, fold_basis


def _problem(seed, n=4000):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.standard_normal(n)) / np.sqrt(n)
    x = x / np.abs(x).max()
    t = np.linspace(0.0, 40.0, n)
    a = np.column_stack(
        [x**k for k in range(7)] + [1e3 * np.sin(t), 1e-3 * np.cos(3 * t), np.clip(x, 0, None)]
    )
    groups = [
        np.column_stack([np.sin(2 * t), np.cos(2 * t)]),
        np.tanh(x / 0.05)[:, None],
        rng.standard_normal((n, 1)),
        (x**3 + 1e-3 * rng.standard_normal(n))[:, None],  # nearly in the base's span
        np.column_stack([np.sin(5 * t) * x, np.cos(5 * t) * x, x**7]),
    ]
    y = a @ rng.standard_normal(a.shape[1]) + 0.3 * groups[0][:, 0] + 0.05 * groups[1][:, 0]
    y += 0.02 * rng.standard_normal(n)
    starts = np.zeros(n, bool)
    starts[[0, n // 3]] = True  # two segments
    blocks = contiguous_blocks(starts, 150)
    return a, groups, y, blocks


@pytest.mark.parametrize("seed", range(6))
def test_gram_scores_equal_the_per_fold_qr_scores(seed):
    a, groups, y, blocks = _problem(seed)
    folds = fold_assignment(blocks, 5)
    exact = cv_gains(fold_basis(a, y, tests=folds), groups)
    n_blocks = int(blocks.max()) + 1
    total, per_fold = fold_gains(
        block_statistics(a, groups, y, blocks, chunk=700), np.arange(n_blocks) % 5, 5
    )
    # normal equations square the condition number: each fold's SSE ratio 1 - gain agrees to
    # eps * kappa^2 relative, kappa that of the column-scaled training design [A | C_i] (up to
    # 5e4 here: x^7 beside x^0..x^6), independent of the magnitude of the gain
    ratio_exact = 1.0 - np.array([f for _, f in exact])
    total_exact = 1.0 - np.array([t for t, _ in exact])
    for i, g in enumerate(groups):
        bounds = []
        for f, te in enumerate(folds):
            tr = np.ones(len(y), bool)
            tr[te] = False
            x = np.column_stack([a, g])[tr]
            kappa = np.linalg.cond(x / np.linalg.norm(x, axis=0))
            bound = np.finfo(float).eps * kappa**2
            err = abs((1.0 - per_fold[i, f]) - ratio_exact[i, f]) / abs(ratio_exact[i, f])
            assert err <= bound, (i, f, err, bound)
            bounds.append(bound)
        # the overall ratio is a weighted mean of the folds' ratios: no worse than the worst
        err = abs((1.0 - total[i]) - total_exact[i]) / abs(total_exact[i])
        assert err <= max(bounds), (i, err, max(bounds))


def test_gram_scores_of_a_resampled_assignment_equal_explicit_refits():
    a, groups, y, blocks = _problem(11)
    n_blocks = int(blocks.max()) + 1
    fob = np.random.default_rng(3).permutation(np.arange(n_blocks) % 5)
    total, per_fold = fold_gains(block_statistics(a, groups, y, blocks), fob, 5)
    fold = fob[blocks]
    for i, g in enumerate(groups):
        sse0 = sse1 = 0.0
        for f in range(5):
            tr, te = fold != f, fold == f
            full = np.column_stack([a, g])
            b0 = scipy.linalg.lstsq(a[tr], y[tr])[0]
            b1 = scipy.linalg.lstsq(full[tr], y[tr])[0]
            e0, e1 = np.sum((y[te] - a[te] @ b0) ** 2), np.sum((y[te] - full[te] @ b1) ** 2)
            assert per_fold[i, f] == pytest.approx(1 - e1 / e0, abs=1e-7)
            sse0, sse1 = sse0 + e0, sse1 + e1
        assert total[i] == pytest.approx(1 - sse1 / sse0, abs=1e-7)


def test_scores_do_not_depend_on_the_chunk():
    a, groups, y, blocks = _problem(2)
    fob = np.arange(int(blocks.max()) + 1) % 5
    one = fold_gains(block_statistics(a, groups, y, blocks, chunk=1), fob, 5)
    whole = fold_gains(block_statistics(a, groups, y, blocks, chunk=10**9), fob, 5)
    np.testing.assert_allclose(one[0], whole[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(one[1], whole[1], rtol=0, atol=1e-9)


def test_scores_do_not_depend_on_the_batches():
    # the candidates' columns streamed in batches (a generator, as the loop computes them)
    # score as when all are held at once: each group's statistics are its own, so only the
    # rounding of the base-projection solves differs (per batch of right-hand sides), which
    # the ill-conditioned design (monomials to x^7) amplifies to a few 1e-12
    a, groups, y, blocks = _problem(5)
    fob = np.random.default_rng(1).permutation(np.arange(int(blocks.max()) + 1) % 5)
    whole = fold_gains(block_statistics(a, groups, y, blocks, chunk=900), fob, 5)
    for sizes in ([1, 1, 1, 1, 1], [2, 0, 3], [4, 1]):
        edges = np.cumsum([0] + sizes)
        spans = block_spans(blocks, 900)
        batches = (memory_passes(a, groups[lo:hi], spans) for lo, hi in zip(edges[:-1], edges[1:]))
        stats = block_statistics_streamed(batches, y, blocks)
        assert stats.widths == tuple(g.shape[1] for g in groups)
        got = fold_gains(stats, fob, 5)
        np.testing.assert_allclose(got[0], whole[0], rtol=0, atol=1e-10)
        np.testing.assert_allclose(got[1], whole[1], rtol=0, atol=1e-10)


def _lstsq(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    # the reference: QR least squares on the copied rows, zero columns left out
    s = np.sqrt((a * a).sum(axis=0))
    keep = s > 0
    beta = np.zeros(a.shape[1])
    beta[keep] = scipy.linalg.lstsq(a[:, keep] / s[keep], y)[0] / s[keep]
    return beta


def _chunked(a: np.ndarray, size: int):
    n = len(a)
    return lambda: ((lo, min(lo + size, n), a[lo : lo + size]) for lo in range(0, n, size))


@pytest.mark.parametrize("seed", range(4))
def test_fold_solver_equals_lstsq_on_the_training_rows(seed):
    a, _, y, blocks = _problem(seed)
    n = len(y)
    active = np.ones(a.shape[1], bool)
    active[2] = False
    a[: n // 2, -1] = 0.0  # a column a fold may see only zeros of
    rng = np.random.default_rng(seed)
    for folds in (fold_assignment(blocks, 5), [np.arange(n // 2, n)]):
        fold_id = np.full(n, -1)  # the half split: the first half trains and is never held out
        for f, te in enumerate(folds):
            fold_id[te] = f
        scored = [np.isin(np.arange(n), te) & (rng.random(n) < 0.7) for te in folds]
        for rows in (one_block(a), _chunked(a, 999)):
            solver = FoldSolver(rows, y, fold_id, scored, active)
            for f, te in enumerate(folds):
                tr = np.ones(n, bool)
                tr[te] = False
                ref = np.zeros(a.shape[1])
                ref[active] = _lstsq(a[tr][:, active], y[tr])
                got = solver.solve(f)
                assert got[~active].tolist() == [0.0] * int((~active).sum())
                np.testing.assert_allclose(a @ got, a @ ref, rtol=0, atol=1e-7 * np.abs(y).max())
                w = a[scored[f]] @ got - y[scored[f]]
                np.testing.assert_allclose(solver.twist_sse(f), w @ w, rtol=1e-9)


def test_usable_check_equals_the_whole_array_check():
    from hdjax.discover._scores import _column_range, _scorable

    _usable = lambda c: _scorable(*_column_range(c))

    rng = np.random.default_rng(0)
    x = rng.standard_normal((500, 2))
    cases = [x, x[:, :1], np.ones((500, 2)), np.column_stack([np.ones(500), x[:, 0]])]
    for bad in (np.nan, np.inf, -np.inf):
        y = x.copy()
        y[123, 1] = bad
        cases.append(y)
    for c in cases:
        # the former check: all finite, and some column not constant
        assert _usable(c) == bool(np.isfinite(c).all() and np.ptp(c, axis=0).max() > 0)
