"""Recursive least squares by the Sherman-Morrison-Woodbury update, Song et al. eqs. (18)-(25).

With $P_k = G_k^{-1} = (A_{0:k}^\\top A_{0:k})^{-1}$, a block of new rows $A_{k+1}, b_{k+1}$
updates (eqs. (22)-(23))

$$P_{k+1} = \\frac{1}{\\lambda}\\Big(P_k - P_k A_{k+1}^\\top (\\lambda I + A_{k+1} P_k
A_{k+1}^\\top)^{-1} A_{k+1} P_k\\Big), \\qquad x_{k+1} = x_k + P_{k+1} A_{k+1}^\\top (b_{k+1} -
A_{k+1} x_k),$$

with forgetting factor $\\lambda \\in (0, 1]$ ($\\lambda = 1$ is the paper's recursion); a
single row gives the rank-one form of eqs. (24)-(25). Each update is one step of a `lax.scan`;
$P$ is re-symmetrised after every step so rounding cannot make it indefinite. Columns are
scaled by fixed factors (from the initial block) so $P$ stays well scaled.
"""

from __future__ import annotations

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float
from .._errors import CalibrationError, ConfigError, InversionError
from .._solution import RESULTS, Solution
from ._lstsq import (
    CalibrationData,
    _SegmentedDesign,
    _select_active,
    _with_static,
    check_invertible,
    invertibility,
    prepare,
)
from ._model import ComplianceModel


class RLSState(eqx.Module):
    """Recursive least-squares state: estimate `x` and inverse information `p` ($P_k$)."""

    x: Float[Array, " p"]
    p: Float[Array, "p p"]


@jax.jit
def rls_init(a0: Float[ArrayLike, "m p"], b0: Float[ArrayLike, " m"]) -> RLSState:
    """Initial solution from a first batch, eq. (18): $x_0 = G_0^{-1} A_0^\\top b_0$.

    $G_0^{-1}$ is formed from the QR factor of $A_0$ ($P_0 = R^{-1} R^{-\\top}$).
    """
    q, r = jnp.linalg.qr(a0, mode="reduced")
    rinv = jax.scipy.linalg.solve_triangular(r, jnp.eye(r.shape[0], dtype=r.dtype), lower=False)
    x0 = rinv @ (q.T @ b0)
    return RLSState(x=x0, p=rinv @ rinv.T)


def rls_step(
    state: RLSState,
    a: Float[ArrayLike, "m p"],
    b: Float[ArrayLike, " m"],
    forgetting: Float[ArrayLike, ""] = 1.0,
) -> RLSState:
    """One block update, eqs. (20)-(23) (eqs. (24)-(25) when `a` has one row).

    With $S = \\lambda I + A P A^\\top = L L^\\top$ (Cholesky) and $W = L^{-1} A P$, the SMW
    update of eq. (22) is $P_{k+1} = (P_k - W^\\top W)/\\lambda$ - a symmetric downdate by
    construction - and eq. (23) is $x_{k+1} = x_k + W^\\top L^{-1} (b - A x_k)$ (the gain
    $P_k A^\\top S^{-1}$ written through the same factor). One Cholesky of the small $m \\times m$
    matrix and one triangular solve per block.
    """
    # innovation covariance S = lambda I + A P A^T and its Cholesky factor
    ap = a @ state.p
    s = forgetting * jnp.eye(a.shape[0], dtype=a.dtype) + ap @ a.T
    chol = jnp.linalg.cholesky(0.5 * (s + s.T))
    # W = L^-1 A P and z = L^-1 (b - A x), by one triangular solve with p + 1 right-hand sides
    rhs = jnp.concatenate([ap, (b - a @ state.x)[:, None]], axis=1)
    wz = jax.scipy.linalg.solve_triangular(chol, rhs, lower=True)
    w, z = wz[:, :-1], wz[:, -1]
    # covariance downdate (eq. (22)), then forgetting; estimate update (eq. (23))
    p = (state.p - w.T @ w) / forgetting
    p = 0.5 * (p + p.T)
    x = state.x + w.T @ z
    return RLSState(x=x, p=p)


@eqx.filter_jit
def rls_scan(
    state: RLSState,
    a_blocks: Float[ArrayLike, "n_blocks m p"],
    b_blocks: Float[ArrayLike, "n_blocks m"],
    forgetting: float = 1.0,
) -> tuple[RLSState, Float[Array, "n_blocks p"]]:
    """Apply `rls_step` over blocks (`a_blocks`: `(n_blocks, m, p)`) in a `lax.scan`."""

    def _step(carry, ab):
        a, b = ab
        carry = rls_step(carry, a, b, forgetting)
        return carry, carry.x

    return jax.lax.scan(_step, state, (a_blocks, b_blocks))


_rls_step_jit = jax.jit(rls_step)


@jax.jit
def _r_factor(a):
    return jnp.linalg.qr(a, mode="r")


def rls_solve(
    a: Float[ArrayLike, "n p"],
    b: Float[ArrayLike, " n"],
    *,
    block_size: int = 1,
    forgetting: float = 1.0,
    init_samples: int | None = None,
) -> tuple[RLSState, Float[Array, "n_steps p"]]:
    """Recursive least squares over all rows of `a` (in order).

    The first `init_samples` rows initialise by eq. (18) (default: the shortest prefix of
    `2 * p`, `4 * p`, ... rows that determines all `p` coefficients); the rest are
    processed in blocks of `block_size` rows (a last, shorter block included).

    **Returns:** the final [`RLSState`][] and the estimate after each block.
    """
    # slice on the host: eager JAX slicing would compile one small program per shape
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    n, p = a.shape
    if not isinstance(block_size, int) or block_size < 1:
        raise ConfigError(f"block_size must be a positive integer, got {block_size!r}")
    if not 0.0 < forgetting <= 1.0:
        raise ConfigError(f"forgetting factor must lie in (0, 1], got {forgetting}")
    full_rank = lambda m: (lambda d: d.min() > 1e-10 * d.max())(np.abs(np.diag(_r_factor(a[:m]))))
    if init_samples is None:
        # the shortest prefix (2p rows, doubling) that determines every coefficient: a slow
        # recording's first 2p samples often cover one torque segment only
        n0 = min(2 * p, n)
        while n0 < n and not full_rank(n0):
            n0 = min(2 * n0, n)
    else:
        n0 = int(init_samples)
    if n0 < p or n0 > n:
        raise ConfigError(f"init_samples must lie in [{p}, {n}], got {n0}")
    if not full_rank(n0):
        raise CalibrationError(
            f"the first {n0} rows do not determine all {p} coefficients (rank-deficient initial "
            "block, eq. (18)); raise init_samples so the first block covers every torque "
            "segment and excites every term"
        )
    state = rls_init(a[:n0], b[:n0])
    n_rest = n - n0
    n_full = n_rest // block_size
    history = []
    if n_full:
        stop = n0 + n_full * block_size
        state, h = rls_scan(
            state,
            a[n0:stop].reshape(n_full, block_size, p),
            b[n0:stop].reshape(n_full, block_size),
            forgetting,
        )
        history.append(h)
    tail = n_rest - n_full * block_size
    if tail:
        state = _rls_step_jit(state, a[n - tail :], b[n - tail :], forgetting)
        history.append(np.asarray(state.x)[None])
    if not history:
        return state, state.x[None]
    return state, jnp.asarray(np.concatenate([np.asarray(h) for h in history]))


def calibrate_rls(
    model: ComplianceModel,
    data: CalibrationData,
    *,
    block_size: int = 32,
    forgetting: float = 1.0,
    init_samples: int | None = None,
    throw: bool = True,
) -> Solution:
    """Calibrate by recursive least squares (eqs. (18)-(25)), a block at a time.

    Same design, column selection and checks as [`hdjax.compliance.calibrate_lstsq`][]; with
    `forgetting=1` and well-conditioned data the result equals the batch solution to rounding.
    Samples are taken in time order.

    **Returns:** an [`hdjax.Solution`][] with the calibrated model in `value` and the stats of
    [`hdjax.compliance.calibrate_lstsq`][] (the rank is not decided here: `rank` is the number of
    active terms, `condition` is NaN).
    """
    t0 = time.perf_counter()
    sig, torque = prepare(model, data)
    A = _SegmentedDesign(model, sig, torque).dense()
    active, counts, dropped = _select_active(model, np.abs(A).max(axis=0) > 0, np.asarray(torque))
    idx = np.flatnonzero(active)
    a = A[:, idx]
    scale = np.sqrt(np.mean(a * a, axis=0))
    state, _ = rls_solve(
        a / scale,
        sig.twist,
        block_size=block_size,
        forgetting=forgetting,
        init_samples=init_samples,
    )
    coef = np.zeros(model.n_coef)
    coef[idx] = np.asarray(state.x) / scale
    resid = A @ coef - np.asarray(sig.twist)
    fitted = eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef))
    fitted = _with_static(fitted, active=tuple(bool(x) for x in active))
    invertible = invertibility(fitted)
    if invertible != RESULTS.successful and throw:
        raise InversionError(check_invertible(fitted))
    stats = dict(
        rank=len(idx),
        n_terms=len(idx),
        condition=float("nan"),
        residual_rms=float(np.sqrt(np.mean(resid**2))),
        n_samples=sig.n_samples,
        segment_counts=counts,
        dropped=dropped,
        collinear=(),
        fit_time_s=time.perf_counter() - t0,
    )
    return Solution(fitted, invertible, stats)
