"""Partialling out by the Gram matrix (the bootstrap intervals' projections) against lstsq.

[`partial_out`][hdjax.discover._uncertainty.partial_out] makes an effect's columns and the
twist orthogonal to the other columns by corrected semi-normal equations on one Gram matrix;
the reference is the residual of `numpy.linalg.lstsq` (SVD) on the other columns, and the
projection must leave nothing in their span. The design is read as one block (in memory) and
in chunks of rows (a long log), which must agree.
"""

import numpy as np
import pytest

from hdjax.discover._uncertainty import partial_out, row_gram


class _Rows:
    """A design as a row source of `size`-row chunks (`size=None`: one block)."""

    def __init__(self, a: np.ndarray, size: int | None = None):
        self.a, self.size = a, size or a.shape[0]

    def designs(self, model):
        for lo in range(0, self.a.shape[0], self.size):
            yield lo, min(lo + self.size, self.a.shape[0]), self.a[lo : lo + self.size]


def _partial_out(a, y, others, cols, size=None):
    rows = _Rows(a, size)
    return partial_out(None, rows, y, others, cols, row_gram(None, rows, y))


def _design(seed: int, n: int, poly_order: int, collinear: bool = False):
    """Columns shaped like the loop's: torque segments, a current polynomial, harmonics of an
    angle, a constant, and an effect pair; the twist a noisy combination of all of them."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 20.0, n)
    torque = 300 * np.sin(2 * np.pi * 0.13 * t) + 40 * np.sin(2 * np.pi * 0.9 * t)
    current = torque / 16 + rng.normal(0, 0.05, n)
    x = current / np.abs(current).max()
    theta = 3.0 * t + 0.4 * np.sin(t)
    knots = (-150.0, 150.0)
    cols = [np.clip(torque, -np.inf, knots[0]) - knots[0], np.clip(torque, *knots)]
    cols += [np.clip(torque, knots[1], np.inf) - knots[1]]
    cols += [x**j for j in range(1, poly_order + 1)]
    cols += [np.cos(theta), np.sin(theta), np.ones(n)]
    if collinear:  # a near copy of a column: scaled condition number ~1e7, solved by QR
        cols += [x + 1e-7 * rng.normal(size=n)]
    cols += [np.cos(2 * theta), np.sin(2 * theta)]  # the effect
    a = np.column_stack(cols) * rng.uniform(1e-6, 1e-3, len(cols))
    y = a @ rng.normal(size=len(cols)) + rng.normal(0, 1e-6, n)
    return a, y


@pytest.mark.parametrize("size", [None, 1999])
@pytest.mark.parametrize("seed, poly_order, collinear", [(0, 3, 0), (1, 6, 0), (2, 6, 1)])
def test_partial_out_equals_lstsq_residuals(seed, poly_order, collinear, size):
    a, y = _design(seed, 20_000, poly_order, collinear)
    p = a.shape[1]
    cols = np.array([p - 2, p - 1])
    others = np.arange(p - 2)
    xp, yp = _partial_out(a, y, others, cols, size)
    target = np.column_stack([a[:, cols], y])
    o = a[:, others]
    s = np.sqrt((o * o).sum(axis=0))
    ref = target - o @ (np.linalg.lstsq(o / s, target, rcond=None)[0] / s[:, None])
    # both are least-squares residuals; the semi-normal equations with one refinement step
    # (or QR, for the design with a near copy, whose scaled condition number exceeds 1e6)
    # agree with the SVD to ~cond * eps of the columns' norm, far inside 1e-9
    got = np.column_stack([xp, yp])
    norm = np.sqrt((target * target).sum(axis=0))
    assert np.all(np.sqrt(((got - ref) ** 2).sum(axis=0)) <= 1e-9 * norm)
    # nothing of the other columns' span is left
    assert np.all(np.abs((o / s).T @ got) <= 1e-9 * norm)


def test_partial_out_with_no_other_columns():
    a, y = _design(3, 500, 2)
    xp, yp = _partial_out(a, y, np.array([], int), np.array([1]), 97)
    np.testing.assert_array_equal(xp[:, 0], a[:, 1])
    np.testing.assert_array_equal(yp, y)
