r"""Shape-constrained calibration: the twist must increase with torque everywhere (see
[`hdjax.compliance.ShapeConstraint`][])."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.optimize

from .._custom_types import Bool, Float
from ._model import ComplianceModel

SLOPE_FLOOR = 0.01
"""The least slope $\\partial\\Delta\\theta/\\partial T$ a calibration allows anywhere, as a
fraction of the data's overall compliance: a segment at most a hundred times stiffer than the
joint on average (harmonic drives stiffen two- to six-fold over their rated range), so the
floor only keeps the model invertible and never shapes a compliance the data determines."""

GRID_POINTS = 201
"""Torque grid points on which the slope of memoryless torque terms is constrained."""

_DIRECTIONS = 24
"""Random directions (besides the axes) along which extreme slope points are kept."""

_LINEAR_MIN_TORQUE = 0.05
"""Rows whose |torque| is below this fraction of the rated torque give no slope point (the
slope of a linear term is its column divided by the torque)."""


def _term_layout(model: ComplianceModel) -> tuple[list, list]:
    """`(memoryless, linear)`: `(term, coefficient indices, compact indices)` of the effect
    groups whose twist depends on the torque memorylessly or linearly."""
    n_seg, nb = model.n_segments, model.n_base
    memoryless, linear = [], []
    i, c = model.n_coef - model.n_effect, n_seg + nb
    for term in model.effect_terms:
        m = len(term.names())
        entry = (term, np.arange(i, i + m), np.arange(c, c + m))
        if term.torque_kind == "memoryless":
            memoryless.append(entry)
        elif term.torque_kind == "linear":
            linear.append(entry)
        i, c = i + m, c + m
    return memoryless, linear


class ShapeData:
    """What the shape constraint needs from the calibration rows, accumulated block by block
    (`add`, as a streamed Gram matrix is): the sums of the twist-torque regression (the data's
    overall compliance) and the extreme slopes $u(x)$ of the terms linear in torque.

    **Arguments:** `model`, the structure being calibrated; `layout`, how the blocks given to
    `add` order their columns: `"compact"` (hinges, one segment's base terms, effects; the
    calibration's blocks, `q x rows`) or `"full"` (the model's coefficient order, `rows x p`).
    """

    def __init__(self, model: ComplianceModel, layout: str = "compact"):
        self.rated = float(model.rated_torque)
        self.layout = layout
        _, linear = _term_layout(model)
        col = 2 if layout == "compact" else 1
        self.lin_compact = np.concatenate([e[col] for e in linear]) if linear else np.zeros(0, int)
        self.sums = np.zeros(5)  # n, sum T, sum T^2, sum b, sum T b
        self.points = np.zeros((0, self.lin_compact.size))
        q = self.lin_compact.size
        if q:
            rng = np.random.default_rng(0)
            d = rng.standard_normal((_DIRECTIONS, q))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            self.directions = np.vstack([np.eye(q), -np.eye(q), d])

    def add(
        self,
        x: Float[np.ndarray, "_ _"],
        b: Float[np.ndarray, " n"],
        torque: Float[np.ndarray, " n"],
    ) -> None:
        """Add a block: `x` its columns (in the `layout`: coefficients by rows when compact,
        rows by coefficients when full), `b` the twist, `torque` the
        reference torque of the rows."""
        t = np.asarray(torque, np.float64)
        b = np.asarray(b, np.float64)
        self.sums += (t.size, t.sum(), t @ t, b.sum(), t @ b)
        if self.lin_compact.size:
            keep = np.abs(t) >= _LINEAR_MIN_TORQUE * self.rated
            if keep.any():
                x = np.asarray(x) if self.layout == "compact" else np.asarray(x).T
                u = (x[self.lin_compact][:, keep] / t[keep]).T
                self.points = self._extremes(np.vstack([self.points, u]))

    def _extremes(self, u: np.ndarray) -> np.ndarray:
        # a linear constraint holds on the convex hull of the points once it holds at its
        # vertices; the extremes along many directions approximate them (the solver then
        # checks every kept point)
        # (directions x points): the reductions run along contiguous rows, some thirty times
        # faster than along the columns of the points' layout
        proj = self.directions @ u.T
        idx = np.unique(np.r_[np.argmax(proj, axis=1), np.argmin(proj, axis=1)])
        return u[idx]

    def compliance(self) -> float:
        """The least-squares slope of the twist on the torque over the rows [rad/(N·m)] (NaN
        with fewer than two distinct torques)."""
        n, st, stt, sb, stb = self.sums
        var = stt - st * st / max(n, 1)
        return float((stb - st * sb / max(n, 1)) / var) if var > 0 else float("nan")


def torque_grid(model: ComplianceModel, n: int = GRID_POINTS) -> np.ndarray:
    """The torques at which a memoryless torque term's slope is constrained and checked: the
    rated range and the calibrated range."""
    lo = min(model.torque_range[0], -model.rated_torque)
    hi = max(model.torque_range[1], model.rated_torque)
    return np.linspace(lo, hi, n)


def slope_rows(model: ComplianceModel, points: np.ndarray, active: np.ndarray) -> np.ndarray:
    """The constraint matrix $C$: each row, dotted with the coefficients, is the twist's slope
    in torque at one torque (its segment's $k_j$ and the memoryless terms' slopes) and one
    extreme slope point of the linear terms; only segments with `active` compliances."""
    n_seg = model.n_segments
    memoryless, linear = _term_layout(model)
    act_seg = np.flatnonzero(np.asarray(active)[:n_seg])
    p = model.n_coef
    if memoryless:
        grid = torque_grid(model)
        seg = np.searchsorted(np.asarray(model.knots), grid, side="right")
        keep = np.isin(seg, act_seg)
        grid, seg = grid[keep], seg[keep]
        base = np.zeros((grid.size, p))
        base[np.arange(grid.size), seg] = 1.0
        for term, idx, _ in memoryless:
            base[:, idx[0]] = np.asarray(term.value_and_slope(grid)[1], np.float64)
    else:
        base = np.zeros((act_seg.size, p))
        base[np.arange(act_seg.size), act_seg] = 1.0
    if not linear or points.shape[0] == 0:
        return base
    lin_idx = np.concatenate([e[1] for e in linear])
    rows = np.repeat(base, points.shape[0], axis=0)
    rows[:, lin_idx] += np.tile(points, (base.shape[0], 1))
    return rows


@dataclasses.dataclass(frozen=True)
class ShapeConstraint:
    r"""The shape constraint of one structure on one data set: $C x \ge s_{min}$.

    Shape-constrained calibration: the twist must increase with torque everywhere.

    The inversion of Song et al. eq. (27) needs a compliance $\partial\Delta\theta/\partial T$ that
    is positive in every calibrated segment, effects that depend on the torque included. Plain
    least squares (eq. (17)) does not know that: on a one-way sweep, or where an angle harmonic
    moves with a gravity load, an outer segment's $k_j$ can come out small or negative and the
    model cannot be inverted. The calibration therefore solves

    $$\min_x \lVert A x - b\rVert^2 \quad \text{s.t.} \quad s(T, u;\ x) \ge s_{min}$$

    with $s = k_{j(T)} + \sum_g c_g f_g'(T) + \sum_h u_h^\top c_h$ the slope of the twist in torque:
    the segment compliance, the slopes of the memoryless torque terms (stiffening, lost motion) on
    a torque grid over the rated and calibrated range, and the slopes $u(x)$ of the terms linear in
    torque (compliance ripple, drift with an extra column) at the extreme values the calibration
    rows take. $s_{min}$ is `SLOPE_FLOOR` times the data's overall compliance (the least-squares
    slope of the twist on the torque), so a segment may be at most $1/$`SLOPE_FLOOR` times stiffer
    than the joint on average.

    **Solver.** The objective is $\lVert R(x - x^*)\rVert^2$ + const, with $x^*$ the unconstrained
    (refined) least-squares solution and $R$ the Cholesky factor of the Jacobi-scaled Gram matrix
    $A^\top A$: the constrained problem is a least distance programme, solved exactly by
    non-negative least squares on its dual (Lawson and Hanson 1974, ch. 23; `scipy.optimize.nnls`).
    Only the Gram matrix is needed, so the same code serves the in-memory, the streamed and the
    cross-validation fits. When $x^*$ already satisfies every constraint it is returned unchanged,
    bit for bit.

    **Intervals at the bounds.** A coefficient held at its bound has no sampling distribution of its
    own; the residual loop's bootstrap intervals hold the compliances of segments whose constraint
    is active at their fitted values and resample the rest (intervals conditional on the active
    set, which is asymptotically exact when the active set is stable).

    References: C. L. Lawson, R. J. Hanson, *Solving Least Squares Problems*, Prentice-Hall 1974,
    ch. 23 (LSI, LDP, NNLS); Song et al. 2019, eqs. (7), (17), (27).

    **Fields:** `rows` ($C$, over all coefficients), `floor` ($s_{min}$ [rad/(N·m)]),
    `compliance` (the data's overall compliance it is a fraction of).
    """

    rows: Float[np.ndarray, "m p"]
    floor: float
    compliance: float

    @classmethod
    def of(
        cls,
        model: ComplianceModel,
        data: ShapeData,
        active: Bool[np.ndarray, " p"],
        fraction: float = SLOPE_FLOOR,
    ) -> ShapeConstraint | None:
        """The constraint of `model` on the rows accumulated in `data`; `None` when the twist
        does not rise with torque over them (no floor can be set; the sign is then wrong)."""
        k = data.compliance()
        if not k > 0:
            return None
        return cls(slope_rows(model, data.points, active), fraction * k, k)

    def violation(self, coef: Float[np.ndarray, " p"]) -> float:
        """How far the slope falls below the floor at worst [rad/(N·m)] (0 when it holds)."""
        if self.rows.shape[0] == 0:
            return 0.0
        return float(max(0.0, np.max(self.floor - self.rows @ coef)))

    def active_segments(self, coef: Float[np.ndarray, " p"], n_seg: int) -> Bool[np.ndarray, " s"]:
        """The segments at least one of whose constraints holds with equality."""
        if self.rows.shape[0] == 0:
            return np.zeros(n_seg, bool)
        tight = self.rows @ coef <= self.floor * (1.0 + 1e-7)
        return np.any(self.rows[tight][:, :n_seg] != 0.0, axis=0)

    def solve(
        self,
        coef: Float[np.ndarray, " p"],
        g: Float[np.ndarray, "p p"],
        active: Bool[np.ndarray, " p"],
        residual_pass: Callable[[Float[np.ndarray, " p"]], Float[np.ndarray, " p"]] | None = None,
    ) -> Float[np.ndarray, " p"]:
        """The coefficients closest to the least-squares solution `coef` in the metric of the
        Gram matrix `g` that satisfy the constraint (see the module docstring); `coef`
        itself, unchanged, when it already does.

        `residual_pass(x)` (optional) returns $A^\\top (b - Ax)$ from the rows: the solution
        on the active constraints is then refined once with the true residual (the corrected
        semi-normal equations of [`hdjax.compliance.calibrate_lstsq`][], restricted to the
        constraints' null space), which removes the squared condition number from its error.
        """
        if self.violation(coef) <= 0.0:
            return coef
        act = np.flatnonzero(np.asarray(active, bool))
        d = np.sqrt(np.diag(g)[act])
        d[d == 0] = 1.0
        gs = g[np.ix_(act, act)] / np.outer(d, d)
        r = _factor(gs)
        c = self.rows[:, act] / d  # constraints in scaled coordinates
        # LDP: min ||z|| s.t. E z >= h, z = R (xs - xs*)
        e = scipy.linalg.solve_triangular(r, c.T, trans="T", lower=False).T
        h = self.floor - self.rows @ coef
        norm = np.linalg.norm(e, axis=1)
        norm[norm == 0] = 1.0
        e, h = e / norm[:, None], h / norm
        m = e.shape[1]
        dual = np.vstack([e.T, h[None, :]])
        rhs = np.zeros(m + 1)
        rhs[-1] = 1.0
        u, _ = scipy.optimize.nnls(dual, rhs, maxiter=50 * dual.shape[1])
        res = dual @ u - rhs
        if not abs(res[-1]) > 1e-12:
            return coef  # infeasible constraints: nothing better to offer (flagged later)
        z = -res[:-1] / res[-1]
        tight = u > 0
        if tight.any():
            # the least-norm z on the constraints NNLS found active, solved exactly (NNLS
            # stops at its own tolerance; the equality-constrained step does not)
            zp = np.linalg.lstsq(e[tight], h[tight], rcond=None)[0]
            if np.all(e @ zp >= h - 1e-12 * np.maximum(1.0, np.abs(h))):
                z = zp
        out = np.array(coef, dtype=np.float64, copy=True)
        out[act] += scipy.linalg.solve_triangular(r, z, lower=False) / d
        if residual_pass is not None and tight.any():
            # one corrected step inside the null space of the active constraints
            basis = scipy.linalg.null_space(c[tight])
            if basis.size:
                atr = np.asarray(residual_pass(out))[act] / d
                reduced = basis.T @ gs @ basis
                step = basis @ np.linalg.solve(reduced, basis.T @ atr)
                out[act] += step / d
        return out


def solve_on(shape, coef: np.ndarray, g: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """`coef` under the shape constraint `shape` (a [`ShapeConstraint`][], or `None`: returned
    unchanged), with the Gram matrix `g` of the coefficients `idx` (a subset, such as the
    columns a cross-validation fold's training rows reach) as the metric."""
    if shape is None or shape.violation(coef) <= 0.0:
        return coef
    full = np.zeros((coef.size, coef.size))
    full[np.ix_(idx, idx)] = g
    active = np.zeros(coef.size, bool)
    active[idx] = True
    return shape.solve(coef, full, active)


def _factor(gs: np.ndarray) -> np.ndarray:
    """An upper-triangular $R$ with $R^\\top R \\approx$ `gs` (Cholesky, or from the QR of an
    eigen-decomposition's square root when `gs` is not numerically positive definite)."""
    try:
        return scipy.linalg.cholesky(gs, lower=False, check_finite=False)
    except np.linalg.LinAlgError:
        w, v = np.linalg.eigh(gs)
        w = np.maximum(w, w.max() * 1e-14)
        return np.linalg.qr(np.sqrt(w)[:, None] * v.T, mode="r")
