r"""The residual loop's least-squares fits, chunk by chunk ([`hdjax.discover._chunked`][]).

- [`twist_residual`][]: $y - A\beta$ (an $n$-vector) without the $n \times p$ design.
- [`ChunkedFoldSolver`][]: the per-fold fits of cross-validation (Song et al. eqs. (15)-(17) on
  each fold's training rows) from per-fold Gram matrices summed over chunks: a row adds to the
  sums of its fold, and a fold's training Gram matrix is the total minus its own. The same
  corrected semi-normal equations as [`hdjax.discover._pipeline.FoldSolver`][] (Cholesky of
  the Jacobi-scaled Gram matrix and one refinement step with the true residual, a second pass
  that also gives the held-out twist errors), or a streamed QR ([`hdjax.compliance.StreamingQR`][])
  where the scaled condition number exceeds `CSNE_MAX_COND`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .._custom_types import Float
from ..compliance import ComplianceModel, StreamingQR
from ..compliance._lstsq import CSNE_MAX_COND
from ..compliance._shape import ShapeConstraint, ShapeData, solve_on
from ..compliance._stream import scaled_cho_factor
from ._chunked import Chunks


def twist_residual(model: ComplianceModel, chunks: Chunks, coef=None) -> Float[np.ndarray, " n"]:
    """The twist residual $y - A\\beta$ over the record, the design formed chunk by chunk."""
    coef = np.asarray(model.coef if coef is None else coef)
    out = np.empty(chunks.n)
    y = np.asarray(chunks.sig.twist)
    for lo, hi, a in chunks.designs(model):
        out[lo:hi] = y[lo:hi] - a @ coef
    return out


class ChunkedFoldSolver:
    """Per-fold least squares of the twist on the `active` columns of `model`'s design over
    each fold's training rows, the design read chunk by chunk (see the module docstring).

    **Arguments:** `model` (canonical), `chunks` (the record, with the driver of this design),
    `fold_id` (the fold of each row), `scored` (per fold, a mask of the held-out rows whose
    twist error is summed), `folds` (the folds to fit; default all).
    """

    def __init__(self, model, chunks: Chunks, fold_id, scored, folds=None):
        self.model, self.chunks = model, chunks
        self.fold_id = np.asarray(fold_id)
        self.scored = scored
        self.y = np.asarray(chunks.sig.twist)
        self.active = np.flatnonzero(np.asarray(model.active))
        self.p = int(model.n_coef)
        n_folds = len(scored)
        self.folds = list(range(n_folds)) if folds is None else list(folds)
        q = self.active.size
        self.g = np.zeros((n_folds, q, q))
        self.aty = np.zeros((n_folds, q))
        self.nz = np.zeros((n_folds, q), np.int64)
        g_tot, aty_tot, nz_tot = np.zeros((q, q)), np.zeros(q), np.zeros(q, np.int64)
        shape = ShapeData(model, layout="full")
        torque = np.asarray(chunks.torque)
        for lo, hi, a_full in chunks.designs(model):
            a = np.compress(np.isin(np.arange(self.p), self.active), a_full, axis=1)
            y, fid = self.y[lo:hi], self.fold_id[lo:hi]
            shape.add(a_full, y, torque[lo:hi])
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
        self.shape = ShapeConstraint.of(model, shape, np.asarray(model.active))
        """The shape constraint of the structure on the whole record (every fold's fit is
        held to it, as the full calibration is)."""
        self._solved = None

    def _designs(self):
        for lo, hi, a in self.chunks.designs(self.model):
            yield lo, hi, np.compress(np.isin(np.arange(self.p), self.active), a, axis=1)

    def _first_solves(self):
        """Per fold `(keep, coef on the kept columns, cho factor and scale or None)`."""
        out = {}
        qr_folds = []
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
            fast = chol[0]
            beta = scipy.linalg.cho_solve(fast, aty / d, check_finite=False) / d
            out[f] = [keep, beta, fast, d]
        if qr_folds:
            self._qr_solves(out, qr_folds)
        return out

    def _qr_solves(self, out, folds):
        """Streamed QR of each fold's training rows (the fallback of `FoldSolver`)."""
        qrs = {}
        for f in folds:
            keep = out[f][0]
            norms = np.sqrt(np.diag(self.g_tot - self.g[f])[keep])
            qrs[f] = StreamingQR(norms)
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
            keep, beta = first[f][0], first[f][1]
            coef0[np.flatnonzero(keep), f] = beta
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
            keep, beta, fast, d = first[f]
            c = coef0[:, f].copy()
            dx = np.zeros(q)
            if fast is not None:
                atr = (atr_tot[:, f] - atr_te[:, f])[keep]
                dx[np.flatnonzero(keep)] = (
                    scipy.linalg.cho_solve(fast, atr / d, check_finite=False) / d
                )
                c += dx
            full = np.zeros(self.p)
            full[self.active] = c
            if self.shape is not None and self.shape.violation(full) > 0.0:
                kept = self.active[keep]
                g = (self.g_tot - self.g[f])[np.ix_(keep, keep)]
                full = solve_on(self.shape, full, g, kept)
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
