r"""Nested least squares: every member of a polynomial- or Fourier-order sweep from one pass.

A model of polynomial order $p$ is the order-$p_{max}$ model with the higher powers left out: its
columns are a subset $S$ of the largest model's. So the Gram matrix $G = A^\top A$ and
$A^\top b$ of the largest design are accumulated once (segment by segment from the compact
columns, never forming the $n \times p$ design), and each member solves its own small system
$G_{SS} x = (A^\top b)_S$ — column-scaled, by Cholesky, with one refinement step against the
true residual (corrected semi-normal equations, as [`hdjax.compliance.calibrate_lstsq`][] does),
the refinement of all members in one batched pass over the data. A member whose scaled
condition number exceeds `CSNE_MAX_COND` ($10^6$) is solved from one Householder QR of the
largest design instead. The helpers (the compact column layout, the scaled QR, the active-term
selection, `CSNE_MAX_COND`) are those of [`hdjax.compliance.calibrate_lstsq`][].

Held-out estimates are batched too: a member is the largest model with zero coefficients for
the columns it lacks, so all members with the same calibrated segments are inverted in one
`vmap` over their coefficient vectors.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg

from .._custom_types import Array, Bool, Float
from .._features import Signals
from .._solution import RESULTS, Solution
from ._inversion import calibrated_segments, estimate_torque_arrays
from ._lstsq import (
    CSNE_MAX_COND,
    _compact_index,
    _scaled_qr,
    _select_active,
    check_invertible,
    invertibility,
)
from ._model import ComplianceModel


@eqx.filter_jit
def _compact(model, sig, torque):
    parts = [model.hinge_basis(torque), model.base_columns(sig), model.effect_columns(sig, torque)]
    return jnp.concatenate(parts, axis=1), model.segment_index(torque)


@eqx.filter_jit
def _gram(model, sig, torque):
    c, seg = _compact(model, sig, torque)
    b = sig.twist
    p = model.n_coef
    g = jnp.zeros((p, p), c.dtype)
    atb = jnp.zeros((p,), c.dtype)
    for s, idx in enumerate(_compact_index(model)):
        cm = c if not model.per_segment else c * (seg == s).astype(c.dtype)[:, None]
        g = g.at[np.ix_(idx, idx)].add(cm.T @ c)
        atb = atb.at[idx].add(cm.T @ b)
    return g, atb, b @ b


@eqx.filter_jit
def _residual_atr(model, sig, torque, coefs):
    r"""$A^\top (b - A x_m)$ for a batch of coefficient vectors `coefs` (M, p)."""
    c, seg = _compact(model, sig, torque)
    b = sig.twist
    blocks = _compact_index(model)
    fits = jnp.stack([c @ coefs[:, i].T for i in blocks], axis=1)  # (n, n_blocks, M)
    if len(blocks) == 1:
        fit = fits[:, 0, :]
    else:
        fit = jnp.take_along_axis(fits, seg[:, None, None], axis=1)[:, 0, :]
    r = b[:, None] - fit  # (n, M)
    atr = jnp.zeros(coefs.shape, c.dtype)
    for s, i in enumerate(blocks):
        cm = c if not model.per_segment else c * (seg == s).astype(c.dtype)[:, None]
        atr = atr.at[:, i].add((cm.T @ r).T)
    return atr


class NestedCoef(NamedTuple):
    """A member's coefficients placed in the largest structure's columns (its `aux`)."""

    coef_big: Float[np.ndarray, " n_big"]
    active_big: Bool[np.ndarray, " n_big"]


def member_message(member: Solution) -> str:
    """What a user reads about one member's fit: the minimum-norm note of a rank-deficient
    design and why a non-invertible compliance cannot be inverted; `""` when it succeeded."""
    st = member.stats
    note = ""
    if st["rank"] < st["n_terms"]:
        note = f"rank-deficient design (rank {st['rank']} < {st['n_terms']} terms), minimum-norm"
    return " ".join((note + " " + check_invertible(member.value)).split())


def estimable(member: Solution) -> bool:
    """Whether a member's compliance can be inverted for torque (a rank-deficient member is, by
    its minimum-norm coefficients)."""
    return member.result in (RESULTS.successful, RESULTS.rank_deficient)


def nested_fit(
    big: ComplianceModel,
    members: Sequence[ComplianceModel],
    sig: Signals,
    torque: Float[Array, " n"],
) -> tuple[list[Solution], float]:
    r"""Calibrate every member model (each a column subset of `big`) from shared passes.

    One pass accumulates the Gram matrix of the largest model; members whose scaled condition
    number is at most `CSNE_MAX_COND` are solved from it (Cholesky plus one batched refinement
    against the true residual); if any member is worse conditioned, one Householder QR of the
    largest (column-scaled, twist-augmented) design serves all of those: a subset $S$ of the
    columns solves $\min \|R_{:,S} y - (Q^\top b)\|$, a small problem, by SVD (minimum-norm
    when rank-deficient, as `calibrate_lstsq(throw=False)`).

    **Arguments:**

    - `big`: the largest model structure (its term names contain every member's).
    - `members`: member model structures (uncalibrated).
    - `sig`, `torque`: training signals and reference torque.

    **Returns:** `(results, shared_s)`: one [`hdjax.Solution`][] per member and the time of the
    shared passes [s]. A member's `value` is its calibrated model, its `result`
    `RESULTS.not_invertible` or `RESULTS.twist_reversed` when the compliance cannot be
    inverted, else `RESULTS.rank_deficient` when its design is (the coefficients are then the
    minimum-norm solution, still estimable), else `RESULTS.successful`; `stats` holds `n_terms`,
    `rank`, `condition`, `residual_rms` [rad] and `fit_time_s`; `aux` a [`NestedCoef`][]. See
    [`member_message`][] for the text a user reads.
    """
    t0 = time.perf_counter()
    g, atb, btb = jax.block_until_ready(_gram(big, sig, torque))
    g, atb, btb = np.asarray(g), np.asarray(atb), float(btb)
    shared_s = time.perf_counter() - t0
    t_np = np.asarray(torque)
    n = t_np.size
    big_names = {name: i for i, name in enumerate(big.term_names)}
    nonzero_big = np.diag(g) > 0
    prepared = []
    for model in members:
        t1 = time.perf_counter()
        try:
            idx = np.asarray([big_names[name] for name in model.term_names])
        except KeyError as err:
            raise ValueError(f"member term {err} is not a column of the largest model") from None
        active, _, _ = _select_active(model, nonzero_big[idx], t_np)
        cols = idx[active]
        d = np.sqrt(np.diag(g)[cols])
        gs = g[np.ix_(cols, cols)] / np.outer(d, d)
        ev = np.linalg.eigvalsh(gs)
        cond = float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else float("inf")
        entry = {"model": model, "active": active, "cols": cols, "d": d, "cond": cond}
        if cond <= CSNE_MAX_COND:
            entry["factor"] = scipy.linalg.cho_factor(gs, lower=False)
            entry["x"] = scipy.linalg.cho_solve(entry["factor"], atb[cols] / d) / d
        entry["own_s"] = time.perf_counter() - t1
        prepared.append(entry)
    # -- ill-conditioned members: one QR of the largest design serves them all -------------
    hard = [e for e in prepared if "x" not in e]
    if hard:
        t2 = time.perf_counter()
        # R of the column-scaled design augmented by the twist (Householder QR, R only)
        everything = jnp.ones(big.n_coef, bool)
        qtb, r, scale = jax.block_until_ready(
            _scaled_qr(big.design(sig, torque), sig.twist, everything)
        )
        qtb, r, scale = np.asarray(qtb), np.asarray(r), np.asarray(scale)
        shared_s += time.perf_counter() - t2
        for e in hard:
            t3 = time.perf_counter()
            cols = e["cols"]
            rs = r[:, cols]
            sv = np.linalg.svd(rs, compute_uv=False)
            e["cond"] = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
            e["rank"] = int((sv > 1e-10 * sv[0]).sum())
            y = np.linalg.lstsq(rs, qtb, rcond=None)[0]
            e["x"] = y / scale[cols]
            e["own_s"] += time.perf_counter() - t3
    # -- one batched refinement pass for the Cholesky members: x <- x + G^-1 A^T (b - A x) --
    easy = [e for e in prepared if "factor" in e]
    if easy:
        t2 = time.perf_counter()
        coefs = np.zeros((len(easy), big.n_coef))
        for row, e in enumerate(easy):
            coefs[row, e["cols"]] = e["x"]
        atr = np.asarray(_residual_atr(big, sig, torque, jnp.asarray(coefs)))
        share = (time.perf_counter() - t2) / len(easy)
        for row, e in enumerate(easy):
            cols, d = e["cols"], e["d"]
            e["x"] = e["x"] + scipy.linalg.cho_solve(e["factor"], atr[row, cols] / d) / d
            e["own_s"] += share
    results = []
    for e in prepared:
        model, active, cols, x = e["model"], e["active"], e["cols"], e["x"]
        rss = btb - 2.0 * x @ atb[cols] + x @ g[np.ix_(cols, cols)] @ x
        coef = np.zeros(model.n_coef)
        coef[active] = x
        calibrated = [s for s in range(model.n_segments) if active[s]]
        seg_of = np.searchsorted(np.asarray(model.knots), t_np, side="right")
        t_in = t_np[np.isin(seg_of, calibrated)]
        rng = (float(t_in.min()), float(t_in.max())) if t_in.size else model.torque_range
        fitted = dataclasses.replace(
            model, coef=jnp.asarray(coef), active=tuple(bool(a) for a in active), torque_range=rng
        )
        coef_big = np.zeros(big.n_coef)
        coef_big[cols] = x
        active_big = np.zeros(big.n_coef, bool)
        active_big[cols] = True
        n_terms = int(active.sum())
        rank = int(e.get("rank", len(cols)))
        result = invertibility(fitted)
        if result == RESULTS.successful and rank < len(cols):
            result = RESULTS.rank_deficient
        stats = dict(
            n_terms=n_terms,
            rank=rank,
            condition=e["cond"],
            residual_rms=float(np.sqrt(max(rss, 0.0) / n)),
            fit_time_s=e["own_s"],
        )
        results.append(Solution(fitted, result, stats, NestedCoef(coef_big, active_big)))
    return results, shared_s


def batched_estimates(
    big: ComplianceModel, fits: Sequence[Solution], sig: Signals
) -> list[Float[np.ndarray, " n"] | None]:
    """Held-out torque of every nested member, members with the same calibrated segments in one
    `vmap` over coefficient vectors of the largest structure; `None` for a member whose
    compliance cannot be inverted."""
    out: list = [None] * len(fits)
    groups: dict = {}
    for i, f in enumerate(fits):
        if not estimable(f):
            continue
        groups.setdefault(tuple(calibrated_segments(big, f.aux.active_big)), []).append(i)
    for members in groups.values():
        union = np.zeros(big.n_coef, bool)
        for i in members:
            union |= fits[i].aux.active_big
        model = dataclasses.replace(big, active=tuple(bool(a) for a in union))
        coefs = jnp.asarray(np.stack([fits[i].aux.coef_big for i in members]))
        one = lambda c: estimate_torque_arrays(eqx.tree_at(lambda m: m.coef, model, c), sig)
        torques = np.asarray(jax.vmap(one)(coefs))
        for row, i in enumerate(members):
            out[i] = torques[row]
    return out
