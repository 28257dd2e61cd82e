r"""Cross-validation's per-fold fits over a row source: a record in memory or chunk by chunk.

Each fold refits the structure (Song et al. eqs. (15)-(17)) on its training rows: least
squares of the twist on the `active` columns of the design. A row source is a callable that
starts a pass over the rows, `(lo, hi, A)` blocks of the full design; a record in memory is
one block, a long one arrives chunk by chunk ([`hdjax.discover._chunked.Chunks`][]). Both run
the same arithmetic, so the in-memory and the chunked loop fit alike:

- one pass sums, per fold, the Gram matrix and $A^\top y$ of the rows it holds out; a fold's
  training Gram matrix is the total minus its own (a row that no fold holds out trains every
  fold);
- each fold is solved by the corrected semi-normal equations on the Jacobi-scaled Gram matrix
  (Cholesky, then one refinement step with the true residual of its training rows, as
  [`hdjax.compliance.calibrate_lstsq`][] does), which gives the least-squares solution to the
  accuracy of QR while the scaled condition number stays below `CSNE_MAX_COND`; above it, or
  when the factorisation fails, by a streamed QR of its training rows
  ([`hdjax.compliance.StreamingQR`][]);
- the second pass (the refinement's residual) also sums each fold's twist errors over its
  scored held-out rows, so the held-out twist error needs no third pass;
- every fold's fit is held to the shape constraint of the full calibration (the twist rises
  with the torque), with the fold's training Gram matrix as the metric.

A column that is zero over a fold's training rows gets no coefficient in that fold.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
import scipy.linalg

from .._custom_types import Bool, Float, Int
from ..compliance import ComplianceModel, ShapeConstraint, ShapeData, StreamingQR
from ..compliance.internal import CSNE_MAX_COND, scaled_cho_factor, solve_on

Rows = Callable[[], Iterable[tuple[int, int, np.ndarray]]]
"""A row source: each call starts a pass, `(lo, hi, A)` with `A` the full design's rows
`lo:hi`, `(hi - lo, p)`, in order."""


def one_block(a: Float[np.ndarray, "n p"]) -> Rows:
    """A design held in memory as a row source of one block."""
    return lambda: iter([(0, a.shape[0], a)])


class FoldSolver:
    """Per-fold least squares of the twist over a row source (see the module docstring).

    **Arguments:**

    - `rows`: the row source (a callable that starts a pass; [`one_block`][] for a design in
      memory).
    - `y`: the twist on the source's rows.
    - `fold_id`: per row, the fold that holds it out (-1: none, it trains every fold).
    - `scored`: per fold, a mask of the held-out rows whose twist error is summed.
    - `active`: the design's columns to fit (a mask).
    - `folds`: the folds to fit (default all).
    - `shape`: the shape constraint to hold every fold to; with `model` (and the reference
      `torque` on the rows) and no `shape`, the constraint of `model`'s structure on these
      rows, found in the first pass.
    """

    def __init__(
        self,
        rows: Rows,
        y: Float[np.ndarray, " n"],
        fold_id: Int[np.ndarray, " n"],
        scored: list[Bool[np.ndarray, " n"]],
        active: Bool[np.ndarray, " p"],
        *,
        folds=None,
        shape: ShapeConstraint | None = None,
        model: ComplianceModel | None = None,
        torque: Float[np.ndarray, " n"] | None = None,
    ):
        self.rows, self.y = rows, np.asarray(y, np.float64)
        self.fold_id = np.asarray(fold_id)
        self.scored = scored
        active = np.asarray(active, bool)
        self.mask = active
        self.active = np.flatnonzero(active)
        self.p = int(active.size)
        n_folds = len(scored)
        self.folds = list(range(n_folds)) if folds is None else list(folds)
        q = self.active.size
        self.g = np.zeros((n_folds, q, q))
        self.aty = np.zeros((n_folds, q))
        self.nz = np.zeros((n_folds, q), np.int64)
        g_tot, aty_tot, nz_tot = np.zeros((q, q)), np.zeros(q), np.zeros(q, np.int64)
        found = ShapeData(model, layout="full") if (shape is None and model is not None) else None
        for lo, hi, a_full in rows():
            # np.compress copies the active columns several times faster than a[:, active]
            a = a_full if q == self.p else np.compress(active, a_full, axis=1)
            y, fid = self.y[lo:hi], self.fold_id[lo:hi]
            if found is not None:
                found.add(a_full, y, np.asarray(torque)[lo:hi])
            g_tot += a.T @ a
            aty_tot += y @ a
            nz_tot += np.count_nonzero(a, axis=0)
            for f in self.folds:
                m = fid == f
                if m.any():
                    am = a[m]
                    self.g[f] += am.T @ am
                    self.aty[f] += y[m] @ am
                    self.nz[f] += np.count_nonzero(am, axis=0)
        self.g_tot, self.aty_tot, self.nz_tot = g_tot, aty_tot, nz_tot
        self.shape = shape if found is None else ShapeConstraint.of(model, found, active)
        """The shape constraint every fold's fit is held to (as the full calibration is)."""
        self._solved = None

    def _designs(self):
        for lo, hi, a in self.rows():
            yield lo, hi, a if self.active.size == self.p else np.compress(self.mask, a, axis=1)

    def _first_solves(self):
        """Per fold `[keep, coef on the kept columns, cho factor or None, scale]`."""
        out, qr_folds = {}, []
        for f in self.folds:
            keep = (self.nz_tot - self.nz[f]) > 0
            g = (self.g_tot - self.g[f])[np.ix_(keep, keep)]
            aty = (self.aty_tot - self.aty[f])[keep]
            d = np.sqrt(np.maximum(np.diag(g), 0.0))
            chol = None
            if d.size and np.all(d > 0):
                chol = scaled_cho_factor(g / np.outer(d, d), CSNE_MAX_COND)
            if chol is None:
                qr_folds.append(f)
                out[f] = [keep, None, None, d]
                continue
            beta = scipy.linalg.cho_solve(chol[0], aty / d, check_finite=False) / d
            out[f] = [keep, beta, chol[0], d]
        if qr_folds:
            self._qr_solves(out, qr_folds)
        return out

    def _qr_solves(self, out, folds):
        """A streamed QR of each fold's training rows (where its normal equations are too
        ill-conditioned)."""
        qrs = {}
        for f in folds:
            keep = out[f][0]
            qrs[f] = StreamingQR(np.sqrt(np.diag(self.g_tot - self.g[f])[keep]))
        for lo, hi, a in self._designs():
            y, fid = self.y[lo:hi], self.fold_id[lo:hi]
            for f in folds:
                m = fid != f
                if m.any():
                    qrs[f].add(a[m][:, out[f][0]], y[m])
        for f in folds:
            r, qtb, _ = qrs[f].factor()
            s = np.where(qrs[f].scale > 0, qrs[f].scale, 1.0)
            out[f][1] = scipy.linalg.lstsq(r, qtb)[0] / s

    def _solve_all(self):
        first = self._first_solves()
        q = self.active.size
        n_folds = len(self.scored)
        coef0 = np.zeros((q, n_folds))
        for f in self.folds:
            coef0[np.flatnonzero(first[f][0]), f] = first[f][1]
        # second pass: A^T r over each fold's training rows (refinement), and over its scored
        # held-out rows the residual's sum of squares, A^T w and A^T A (the refined error)
        atr_tot = np.zeros((q, n_folds))
        atr_te = np.zeros((q, n_folds))
        sw = np.zeros(n_folds)
        aw = np.zeros((q, n_folds))
        gs = np.zeros((n_folds, q, q))
        for lo, hi, a in self._designs():
            y, fid = self.y[lo:hi], self.fold_id[lo:hi]
            r = y[:, None] - a @ coef0  # (rows, folds)
            atr_tot += a.T @ r
            for f in self.folds:
                m = fid == f
                if m.any():
                    atr_te[:, f] += a[m].T @ r[m, f]
                s = self.scored[f][lo:hi]
                if s.any():
                    w = -r[s, f]
                    sw[f] += w @ w
                    aw[:, f] += a[s].T @ w
                    gs[f] += a[s].T @ a[s]
        coefs, sse = {}, {}
        for f in self.folds:
            keep, _, fast, d = first[f]
            dx = np.zeros(q)
            if fast is not None:
                atr = (atr_tot[:, f] - atr_te[:, f])[keep]
                dx[np.flatnonzero(keep)] = (
                    scipy.linalg.cho_solve(fast, atr / d, check_finite=False) / d
                )
            full = np.zeros(self.p)
            full[self.active] = coef0[:, f] + dx
            if self.shape is not None and self.shape.violation(full) > 0.0:
                g = (self.g_tot - self.g[f])[np.ix_(keep, keep)]
                full = solve_on(self.shape, full, g, self.active[keep])
                dx = full[self.active] - coef0[:, f]
            coefs[f] = full
            sse[f] = float(sw[f] + 2.0 * dx @ aw[:, f] + dx @ gs[f] @ dx)
        return coefs, sse

    def solve(self, f: int) -> np.ndarray:
        """Coefficients of fold `f` (all of the design's columns; zero where not active)."""
        if self._solved is None:
            self._solved = self._solve_all()
        return self._solved[0][f].copy()

    def twist_sse(self, f: int) -> float:
        """Sum of squared twist errors of fold `f`'s fit over its scored held-out rows."""
        if self._solved is None:
            self._solved = self._solve_all()
        return self._solved[1][f]
