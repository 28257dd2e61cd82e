r"""Streaming least squares: normal equations and QR factors accumulated chunk by chunk.

A linear least-squares problem $\min_x \|Ax - b\|$ over $n$ rows needs, for its solution and
diagnostics, only $p \times p$ summaries of the rows: the Gram matrix $G = A^\top A$,
$A^\top b$ and $b^\top b$ (Song et al. eq. (17)), or the triangular factor $R$ of
$[A D^{-1} \mid b]$. Both are sums (or stacked factorisations) over row blocks, so a log of
any length is reduced one chunk at a time with memory bounded by the chunk:

- [`NormalEquations`][] adds $A_c^\top A_c$, $A_c^\top b_c$, $b_c^\top b_c$ of each chunk
  (optionally per cross-validation fold, so the Gram matrix of "all folds but $k$" is a
  subtraction, not another pass), solves by column-scaled Cholesky, and refines a solution
  with a second pass that accumulates $A^\top (b - Ax)$ (corrected semi-normal equations,
  Bjorck 1987; see [`hdjax.compliance.calibrate_lstsq`][]).
- [`StreamingQR`][] keeps $R$ of the column-scaled design augmented by $b$ and folds each chunk
  in by one QR of $[R; A_c D^{-1} \mid b_c]$ (TSQR), for designs too ill-conditioned for the
  normal equations; $Q^\top b$ is $R$'s last column and $|R_{p,p}|^2$ the residual sum of
  squares.

The accumulators know nothing about compliance models; [`hdjax.compliance.calibrate_stream`][]
and the residual loop feed them design blocks.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from .._custom_types import ArrayLike, Float, Int


class NormalEquations:
    r"""Running $A^\top A$, $A^\top b$, $b^\top b$ and row count over row blocks.

    **Arguments:**

    - `n_coef`: the number of columns $p$ of the full design.
    - `n_folds`: keep the sums per fold (for cross-validation), default one.

    `add(a, b, columns=None, fold=0)` adds a block: `a` of shape `(q, rows)` (columns as rows,
    contiguous for BLAS) and `b` of shape `(rows,)`; `columns` (length `q`) says where the
    block's columns sit among the `p` (a sparse row structure such as one torque segment's
    block), default all of them in order.
    """

    def __init__(self, n_coef: int, n_folds: int = 1) -> None:
        self.p = int(n_coef)
        self.g = np.zeros((n_folds, self.p, self.p))
        self.atb = np.zeros((n_folds, self.p))
        self.btb = np.zeros(n_folds)
        self.n = np.zeros(n_folds, dtype=np.int64)

    def add(
        self,
        a: Float[ArrayLike, "q rows"],
        b: Float[ArrayLike, " rows"],
        columns: Int[ArrayLike, " q"] | Sequence[int] | None = None,
        fold: int = 0,
    ) -> None:
        a = np.asarray(a, np.float64)
        b = np.asarray(b, np.float64)
        if columns is None:
            self.g[fold] += a @ a.T
            self.atb[fold] += a @ b
        else:
            idx = np.asarray(columns)
            self.g[fold][np.ix_(idx, idx)] += a @ a.T
            self.atb[fold][idx] += a @ b

    def add_rhs(self, b: Float[ArrayLike, " rows"], fold: int = 0) -> None:
        """Count the rows of a block and add $b^\\top b$ (once per row, whatever the blocks)."""
        b = np.asarray(b, np.float64)
        self.btb[fold] += b @ b
        self.n[fold] += b.shape[0]

    def total(
        self, leave_out: int | None = None
    ) -> tuple[Float[np.ndarray, "p p"], Float[np.ndarray, " p"], float, int]:
        """`(G, A^T b, b^T b, n)` over every fold, or every fold but `leave_out`."""
        keep = np.ones(self.g.shape[0], bool)
        if leave_out is not None:
            keep[leave_out] = False
        return (
            self.g[keep].sum(axis=0),
            self.atb[keep].sum(axis=0),
            float(self.btb[keep].sum()),
            int(self.n[keep].sum()),
        )


def scaled_cho_factor(gs: np.ndarray, max_cond: float):
    """The Cholesky factor of a Jacobi-scaled Gram matrix `gs` (unit diagonal), when the
    semi-normal equations may use it.

    **Returns:** `(factor, cond)`, with `factor` scipy's `cho_factor` pair (upper) and `cond`
    the scaled condition number $\\sqrt{\\lambda_{max} / \\lambda_{min}}$; or `None` when `gs`
    is not positive definite, `cond` exceeds `max_cond`, or Cholesky fails (then QR decides
    rank and solution).
    """
    ev = np.linalg.eigvalsh(gs)
    if not ev[0] > 0:
        return None
    cond = float(np.sqrt(ev[-1] / ev[0]))
    if not cond <= max_cond:
        return None
    try:
        return scipy.linalg.cho_factor(gs, lower=False, check_finite=False), cond
    except np.linalg.LinAlgError:
        return None


def scaled_cholesky(g: np.ndarray, atb: np.ndarray, active: np.ndarray, max_cond: float):
    r"""Solve $G x = A^\top b$ on the active columns, scaled by $D = \sqrt{\mathrm{diag}\,G}$.

    **Returns:** `(coef, cond, solve)` with `coef` of length `p` (zeros where inactive), the
    scaled condition number and `solve(rhs)` applying $G^{-1}$ (scaled, active columns) to a
    right-hand side such as $A^\top r$ for refinement; or `None` when the scaled condition
    number exceeds `max_cond` or Cholesky fails (then use [`StreamingQR`][]).
    """
    active = np.asarray(active, bool)
    d = np.sqrt(np.diag(g)[active])
    gs = g[np.ix_(active, active)] / np.outer(d, d)
    chol = scaled_cho_factor(gs, max_cond)
    if chol is None:
        return None
    factor, cond = chol

    def solve(rhs: np.ndarray) -> np.ndarray:
        out = np.zeros(g.shape[0])
        out[active] = scipy.linalg.cho_solve(factor, np.asarray(rhs)[active] / d) / d
        return out

    return solve(atb), cond, solve


class StreamingQR:
    r"""The triangular factor $R$ of $[A D^{-1} \mid b]$, folded in chunk by chunk (TSQR).

    **Arguments:**

    - `scale`: the column scale $D$ (length $p$; e.g. the column norms from a first pass over
      the data, `sqrt(diag(G))`); columns with a zero scale are left out.
    """

    def __init__(self, scale: Float[ArrayLike, " p"]) -> None:
        self.scale = np.asarray(scale, np.float64)
        self.p = self.scale.shape[0]
        self.r = np.zeros((0, self.p + 1))

    def add(self, a: Float[ArrayLike, "rows p"], b: Float[ArrayLike, " rows"]) -> None:
        """Fold in a block: `a` of shape `(rows, p)` (unscaled) and `b` of shape `(rows,)`."""
        s = np.where(self.scale > 0, self.scale, 1.0)
        block = np.column_stack([np.asarray(a) / s[None, :], np.asarray(b)])
        self.r = np.linalg.qr(np.vstack([self.r, block]), mode="r")

    def factor(self) -> tuple[Float[np.ndarray, "p p"], Float[np.ndarray, " p"], float]:
        r"""`(R, Q^T b, rss)`: the $p \times p$ factor of the scaled design, $Q^\top b$ and the
        residual sum of squares of the least-squares solution (full rank)."""
        p = self.p
        r = np.zeros((p + 1, p + 1))
        r[: self.r.shape[0]] = self.r[: p + 1]
        return r[:p, :p], r[:p, p], float(r[p, p] ** 2)
