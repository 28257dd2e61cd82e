"""Aliases: candidates that TRAIN cannot tell apart from the one the loop added, or from one
already shortlisted; and how well TRAIN determines a candidate beside the model's own columns
([`determination`][]).

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
from ._pipeline import chunks_of, design
from ._scores import training_data

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


def _strided(n: int, rows) -> np.ndarray:
    """At most `MAX_ROWS` of the part's rows, evenly strided (indices into the record)."""
    own = np.arange(n) if rows is None else np.asarray(rows)
    return own[:: max(1, -(-own.size // MAX_ROWS))]


def _model_rows(model, sig, torque, take: np.ndarray, chunk: int) -> np.ndarray:
    """The rows `take` of `model`'s design on the record, chunk by chunk with a chunk."""
    if not chunk:
        return np.asarray(design(model, sig, torque))[take]
    out = []
    for lo, hi, _, _, a, _ in chunks_of(sig, torque, chunk).rows(model):
        sel = take[(take >= lo) & (take < hi)]
        out.append(np.asarray(a)[sel - lo])
    return np.concatenate(out)


def determination(model, data, estimate_):
    """`determined(term)`: how well TRAIN determines `term`'s coefficients beside `model`'s,
    the share of its centred columns' variance (unit-normalised, the worst direction of a
    group) that the model's own columns do not span: 1 / the variance inflation factor
    (Belsley, Kuh & Welsch 1980, *Regression Diagnostics*, Section 3.1). Near 0, TRAIN fixes the
    coefficient only through a small residue, and the fit leans on a cancellation between the
    term and the model's columns that another regime (a TEST at another speed or over another
    range) breaks.

    On at most `MAX_ROWS` evenly strided TRAIN rows (`data.rows` where TRAIN is part of a
    log); with `data.chunk` the model's design is formed chunk by chunk. The model's rows are
    formed once, at the first call.
    """
    sig, torque = training_data(model, data, estimate_)
    take = _strided(int(np.asarray(torque).shape[0]), data.rows)
    rows: list[np.ndarray] = []

    def determined(term) -> float:
        if not rows:
            rows.append(_model_rows(model, sig, torque, take, data.chunk))
        cols = np.asarray(candidate_columns(term, sig, torque), np.float64)[take]
        return unspanned_share(rows[0], cols)

    return determined


def unspanned_share(a: np.ndarray, cols: np.ndarray) -> float:
    """The share of the centred, unit-normalised `cols`' variance that the centred columns of
    `a` do not span, in the worst direction of `cols` (the smallest eigenvalue of the
    residual Gram matrix): $1 - R^2$ of one column regressed on `a` with an intercept; 0 for
    a constant or non-finite column."""
    a = np.asarray(a, np.float64)
    cols = np.asarray(cols, np.float64)
    centred = a - a.mean(axis=0, keepdims=True)
    keep = np.sqrt((centred * centred).sum(axis=0)) > 0.0
    c = cols - cols.mean(axis=0, keepdims=True)
    norms = np.sqrt((c * c).sum(axis=0))
    if not np.all(norms > 0.0) or not np.all(np.isfinite(c)):
        return 0.0
    c = c / norms
    u = _orthonormal(centred[:, keep])
    r = c - u @ (u.T @ c)
    return float(np.clip(np.linalg.eigvalsh(r.T @ r).min(), 0.0, 1.0))


def _orthonormal(a: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the span of `a`'s columns (directions with a singular value
    under 1e-10 of the largest dropped)."""
    u, sv, _ = np.linalg.svd(a, full_matrices=False)
    return u[:, sv > sv[0] * 1e-10] if sv.size and sv[0] > 0.0 else u[:, :0]


def _centred(a) -> np.ndarray:
    a = np.asarray(a, np.float64)
    return a - a.mean(axis=0, keepdims=True)


def first_canonical_r2(a: np.ndarray, b: np.ndarray) -> float:
    """The largest share of the variance of a combination of `b`'s columns that `a`'s columns
    explain (with an intercept): the first squared canonical correlation between the two
    (Hotelling 1936, *Biometrika* 28), the square of the largest cosine of the principal angles
    between the centred spans (where [`span_cosine`][] takes the smallest); 0 where either set
    is constant."""
    qa, qb = _orthonormal(_centred(a)), _orthonormal(_centred(b))
    if not qa.shape[1] or not qb.shape[1]:
        return 0.0
    top = np.linalg.svd(qa.T @ qb, compute_uv=False)[0]
    return float(np.clip(top * top, 0.0, 1.0))


def alias_test(sig, torque, take=None, threshold: float = ALIAS_COSINE):
    """`aliased(a, b)` for two candidates (anything with a `.candidate.term`): whether their
    columns on TRAIN span the same directions to `threshold` ([`span_cosine`][]); each
    candidate's columns are computed once, on at most `MAX_ROWS` strided rows."""
    take = take or (lambda x: x)
    cache: dict = {}

    def cols(r):
        key = r.candidate.key
        if key not in cache:
            c = take(np.asarray(candidate_columns(r.candidate.term, sig, torque)))
            cache[key] = c[:: max(1, -(-c.shape[0] // MAX_ROWS))]
        return cache[key]

    def aliased(a, b) -> bool:
        ca, cb = cols(a), cols(b)
        return ca.shape[1] == cb.shape[1] and span_cosine(ca, cb) >= threshold

    return aliased
