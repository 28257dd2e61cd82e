"""Scoring candidate effects: cross-validated explained variance, and pysindy sparse selection.

Adding a group of columns $C$ to a least-squares model with design $A$ and refitting is, by the
Frisch-Waugh-Lovell theorem, the same as regressing the model's residual on the part of $C$
orthogonal to $A$. With one QR factorisation of $A$ per fold every candidate's refit costs only
a few columns, so all candidates are scored exactly (not approximately) in one pass.

Cross-validation uses only the training data: `n_folds` interleaved blocks of `block` samples
(block $b$ goes to fold $b \\bmod K$), so every fold spans the whole record and every torque
segment, while samples inside a block stay together against short-range correlation.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import scipy.linalg

from .._custom_types import ArrayLike, Bool, Float, Int
from .._lazy import pysindy

MAX_SINDY_ROWS = 20000


@dataclasses.dataclass(frozen=True)
class FoldBasis:
    """Per-fold QR factors of the base design and base residuals, reused for every candidate."""

    train: list[np.ndarray]
    test: list[np.ndarray]
    q: list[np.ndarray]
    r: list[tuple[np.ndarray, np.ndarray]]
    resid_train: list[np.ndarray]
    resid_test: list[np.ndarray]
    a_test: list[np.ndarray]
    base_sse: np.ndarray


def fold_indices(n: int, n_folds: int = 5, block: int = 200) -> list[np.ndarray]:
    """Held-out index sets of interleaved contiguous blocks."""
    blocks = np.arange(n) // block
    return [np.flatnonzero(blocks % n_folds == f) for f in range(n_folds)]


def _scaled(a: np.ndarray):
    s = np.sqrt((a * a).sum(axis=0))
    s[s == 0] = 1.0
    return a / s


def fold_basis(
    a: Float[np.ndarray, "n n_terms"],
    y: Float[np.ndarray, " n"],
    n_folds: int = 5,
    block: int = 200,
    *,
    tests: Sequence[Int[np.ndarray, " _n_test"]] | None = None,
) -> FoldBasis:
    """QR of the base design on each fold's training part, and the base held-out error.

    `tests` (optional) gives the held-out index sets directly (whole contiguous blocks, see
    `hdjax.discover._folds`); otherwise interleaved blocks of `block` samples.
    """
    a = _scaled(a)
    n = a.shape[0]
    if tests is None:
        tests = fold_indices(n, n_folds, block)
    out = {k: [] for k in ("train", "q", "r", "rtr", "rte", "ate")}
    sse = []
    for te in tests:
        tr = np.setdiff1d(np.arange(n), te, assume_unique=True)
        keep = np.abs(a[tr]).max(axis=0) > 0  # a segment block the fold misses stays out
        q, r = np.linalg.qr(a[tr][:, keep])
        beta = np.zeros(a.shape[1])
        beta[keep] = scipy.linalg.lstsq(r, q.T @ y[tr])[0]
        out["train"].append(tr)
        out["q"].append(q)
        out["r"].append((r, keep))
        out["rtr"].append(y[tr] - a[tr] @ beta)
        e0 = y[te] - a[te] @ beta
        out["rte"].append(e0)
        out["ate"].append(a[te][:, keep])
        sse.append(np.sum(e0**2))
    return FoldBasis(
        out["train"],
        tests,
        out["q"],
        out["r"],
        out["rtr"],
        out["rte"],
        out["ate"],
        np.asarray(sse),
    )


def cv_gains(basis: FoldBasis, groups: list[np.ndarray]) -> list[tuple[float, np.ndarray]]:
    """Cross-validated fraction of the base model's held-out error removed by each group.

    Each group (an `(n, c)` array of candidate columns) is added to the base model alone and
    refitted on every fold's training part (exactly, through the fold's QR factors).

    **Returns:** per group, the overall gain $1 - \\sum_f SSE_f(C) / \\sum_f SSE_f(\\text{base})$
    and the per-fold gains.
    """
    widths = [g.shape[1] for g in groups]
    cols = _scaled(np.concatenate(groups, axis=1))
    bounds = np.cumsum([0] + widths)
    sse = np.zeros((len(groups), len(basis.test)))
    for f, (tr, te) in enumerate(zip(basis.train, basis.test)):
        q = basis.q[f]
        r, _ = basis.r[f]
        ct = cols[tr]
        qtc = q.T @ ct
        c_perp = ct - q @ qtc
        c_te = cols[te] - basis.a_test[f] @ scipy.linalg.solve_triangular(r, qtc)
        # Each group has a column or two: solve its small least-squares problem from the
        # Gram blocks of the (already orthogonalised, unit-scaled) columns.
        gram = c_perp.T @ c_perp
        rhs = c_perp.T @ basis.resid_train[f]
        for i in range(len(groups)):
            sl = slice(bounds[i], bounds[i + 1])
            gamma = np.linalg.lstsq(gram[sl, sl], rhs[sl], rcond=1e-12)[0]
            e = basis.resid_test[f] - c_te[:, sl] @ gamma
            sse[i, f] = np.sum(e**2)
    per_fold = 1.0 - sse / basis.base_sse[None, :]
    total = 1.0 - sse.sum(axis=1) / basis.base_sse.sum()
    return [(float(t), p) for t, p in zip(total, per_fold)]


def cv_gain(
    basis: FoldBasis, cols: Float[ArrayLike, "n ..."]
) -> tuple[float, Float[np.ndarray, " n_folds"]]:
    """`cv_gains` for a single group."""
    return cv_gains(basis, [np.atleast_2d(np.asarray(cols).T).T])[0]


def sindy_select(
    a: Float[np.ndarray, "n n_terms"],
    residual: Float[np.ndarray, " n"],
    columns: Sequence[Float[np.ndarray, " n"]],
    names: Sequence[str],
    *,
    threshold: float = 0.02,
    alpha: float = 1e-6,
) -> Bool[np.ndarray, " n_columns"]:
    """Sparse regression of the residual on the candidate library with pysindy's STLSQ.

    The library columns are first made orthogonal to the base design (what the base model can
    already absorb is not credited to a candidate), then scaled to unit RMS, as is the target;
    STLSQ keeps the terms whose coefficient exceeds `threshold` (a fraction of the residual's
    RMS per unit-RMS column). **Returns:** a boolean per column.
    """
    ps = pysindy()
    # The selection needs no more than a few ten thousand rows: take evenly spaced samples.
    step = max(1, a.shape[0] // MAX_SINDY_ROWS)
    a, residual = a[::step], residual[::step]
    q, _ = np.linalg.qr(_scaled(a))
    lib = np.column_stack([c[::step] for c in columns])
    lib = lib - q @ (q.T @ lib)
    rms = np.sqrt(np.mean(lib**2, axis=0))
    ok = rms > 1e-12 * max(rms.max(), 1e-300)
    lib = lib[:, ok] / rms[ok]
    target = residual - q @ (q.T @ residual)
    target = target / max(np.sqrt(np.mean(target**2)), 1e-300)
    identity = ps.IdentityLibrary()
    theta = identity.fit_transform(lib)
    opt = ps.STLSQ(threshold=threshold, alpha=alpha, max_iter=50)
    opt.fit(np.asarray(theta), target[:, None])
    coef = np.zeros(len(names))
    coef[np.flatnonzero(ok)] = np.asarray(opt.coef_).ravel()
    return coef != 0.0
