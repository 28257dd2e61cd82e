"""Aliases: candidates that TRAIN cannot tell apart from the one the loop added.

Two candidates are aliases on a record when their columns span the same directions there:
Coulomb friction at the motor, $\\tanh(\\omega_m/\\omega_s)$, and at the output,
$\\tanh(\\omega_l/\\omega_s')$, are one column on a stiff joint, since $\\omega_l \\approx
\\omega_m/N$ (Song et al. eq. (5)); a Stribeck excess and a Coulomb term are one column on a
sweep that never slows down. The loop's cross-validated scores then differ by noise, and which
key it names is arbitrary: the report lists the aliases of every step, so the user reads "motor
or output side, this record cannot say" rather than a confident side.

The measure is the smallest cosine of the principal angles between the two column spans
(Björck & Golub 1973) after centring (the model's constant absorbs a shift), on at most
`MAX_ROWS` evenly strided TRAIN samples: 1 for the same span, 0 for orthogonal ones. Candidates
with a different number of columns are not compared (one does not stand in for the other).
"""

from __future__ import annotations

import numpy as np

from ._library import candidate_columns

ALIAS_COSINE = 0.99
"""Smallest principal-angle cosine at which two candidates count as aliases."""

MAX_ROWS = 200_000
"""At most this many TRAIN samples (evenly strided) enter the comparison."""


def _basis(cols: np.ndarray) -> np.ndarray | None:
    """An orthonormal basis of the centred columns, or None for a column that is constant."""
    c = cols - cols.mean(axis=0, keepdims=True)
    norms = np.sqrt((c * c).sum(axis=0))
    if not np.all(norms > 0.0) or not np.all(np.isfinite(c)):
        return None
    q, r = np.linalg.qr(c / norms)
    if np.min(np.abs(np.diag(r))) < 1e-8:
        return None  # the group's own columns are (nearly) dependent
    return q


def span_cosine(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest cosine of the principal angles between the centred column spans of `a` and
    `b` (same number of columns); 0 where either has a constant or dependent column."""
    qa, qb = _basis(np.asarray(a, float)), _basis(np.asarray(b, float))
    if qa is None or qb is None or qa.shape[1] != qb.shape[1]:
        return 0.0
    s = np.linalg.svd(qa.T @ qb, compute_uv=False)
    return float(np.clip(s.min(), 0.0, 1.0))


def find_aliases(
    term, others, sig, torque, *, threshold: float = ALIAS_COSINE, take=None
) -> list[dict]:
    """The candidates among `others` (`(key, term)` pairs) whose columns on TRAIN span what
    `term`'s span, to `threshold`: `[{"key", "cosine"}]`, the closest first.

    `sig` and `torque` are the training signals the candidates were scored on; `take`
    (optional) takes TRAIN's rows from columns computed on a whole log it is part of.
    """
    take = take or (lambda x: x)
    own = take(np.asarray(candidate_columns(term, sig, torque)))
    n = own.shape[0]
    rows = slice(None, None, max(1, -(-n // MAX_ROWS)))
    own = own[rows]
    out = []
    for key, other in others:
        cols = take(np.asarray(candidate_columns(other, sig, torque)))[rows]
        if cols.shape[1] != own.shape[1]:
            continue
        cos = span_cosine(own, cols)
        if cos >= threshold:
            out.append({"key": key, "cosine": cos})
    return sorted(out, key=lambda d: -d["cosine"])
