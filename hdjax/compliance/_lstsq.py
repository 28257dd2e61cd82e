"""Closed-form least-squares calibration, Song et al. eqs. (15)-(17).

The paper writes the solution through the normal equations, $x^* = (A^\\top A)^{-1} A^\\top b$
(eq. (17)). Two solvers compute that minimiser soundly, both on the column-scaled design
$A D^{-1}$ ($D$ the column norms):

- **Corrected semi-normal equations** (the fast path; Bjorck 1987): the scaled Gram matrix is
  accumulated segment by segment without ever forming the $n \\times p$ design (a row of the
  per-segment model touches one segment's block only), factored by Cholesky, and the solution is
  refined once with the true residual, $x \\leftarrow x + G^{-1} A^\\top (b - Ax)$. That one step
  removes the squared condition number from the error, so the result is as accurate as QR
  while $\\kappa^2 u \\ll 1$; the path is taken only when the scaled condition number is at
  most `CSNE_MAX_COND` ($10^6$, so $\\kappa^2 u \\le 10^{-4}$).
- **Householder QR** of the scaled design augmented by $b$ (`R` only, $Q^\\top b$ read from the
  last column), for worse-conditioned or rank-deficient designs: the rank is decided from the
  singular values of the small triangular factor and a rank-deficient design is refused with
  the names of the collinear terms.

The condition number reported is that of the scaled design in both cases. Every calibration
returns an [`hdjax.Solution`][]: the fitted model in `value`, a [`hdjax.RESULTS`][] member in
`result` and the diagnostics in `stats`:

- `rank`, `n_terms` (active coefficients), `condition` (2-norm condition number of the
  column-scaled design), `residual_rms` (twist residual [rad]), `n_samples`, `segment_counts`
  (samples per torque segment), `dropped` (terms left out, each with the reason), `collinear`
  (groups of term names spanning the null space of a rank-deficient design) and `fit_time_s`.

[`calibration_messages`][] spells the diagnostics out for a user (terms left out, the
collinear terms, the segments whose compliance is not positive).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import ArrayLike, Float, Int
from .._errors import CalibrationError, DataError, InversionError
from .._features import signals
from .._recording import Recording
from .._solution import RESULTS, Solution
from ..effects import TORQUE_PATH
from ..effects.internal import join_hypers, run_split, split_hypers, with_fields
from ._model import ComplianceModel, base_term_columns
from ._shape import ShapeConstraint, ShapeData, torque_grid
from ._signals import Signals
from ._stream import scaled_cholesky

CalibrationData = Recording | tuple[Signals, Float[ArrayLike, " n"]]
"""What a calibration reads: a recording with a reference torque, or `(signals, torque)`."""

RANK_RTOL = 1e-10
"""Singular values of the scaled design below `RANK_RTOL * max` count as zero."""

CSNE_MAX_COND = 1e6
"""Largest scaled condition number solved by the semi-normal equations (else QR)."""

MIN_SEGMENT_SAMPLES_PER_TERM = 3
"""A segment's own block is calibrated only with at least this many samples per coefficient."""


def prepare(model: ComplianceModel, data) -> tuple[Signals, jax.Array]:
    """Signals and reference torque from a recording (or a `(Signals, torque)` pair)."""
    if isinstance(data, Recording):
        if data.torque is None:
            raise DataError(
                f"{data.source}: calibration needs a reference 'torque' column (a torque sensor "
                "or another reference); the recording has none"
            )
        sig = signals(data, model.joint, velocity=model.velocity)
        return sig, data.torque
    if isinstance(data, tuple) and len(data) == 2 and isinstance(data[0], Signals):
        return data[0], jnp.asarray(data[1], jnp.float64)
    raise DataError(f"expected a Recording or a (Signals, torque) pair, got {type(data).__name__}")


def design_columns(model: ComplianceModel, sig: Signals, torque):
    """The design matrix of eq. (15) in one compiled program per model structure: neither the
    active flags (the design does not read them) nor the effect terms' float hyperparameters
    (handed in as values, `split_hypers`) are part of its key."""
    return run_split(_design_columns, split_model_hypers, model, sig, torque)


@eqx.filter_jit
def _design_columns(skeleton, values, sig: Signals, torque):
    return join_model_hypers(skeleton, values).design(sig, torque)


def split_model_hypers(model: ComplianceModel, *, keep_active: bool = False):
    """`model` with its effect terms split as [`split_hypers`][] splits one (and, unless
    `keep_active`, every coefficient marked active), and the terms' values, one dict per term."""
    parts = [split_hypers(term) for term in model.effect_terms]
    fields = {"effect_terms": tuple(p[0] for p in parts)}
    if not keep_active:
        fields["active"] = (True,) * model.n_coef
    return with_fields(model, fields), tuple(p[1] for p in parts)


def join_model_hypers(skeleton: ComplianceModel, values: tuple) -> ComplianceModel:
    """The model [`split_model_hypers`][] split, with its terms' values put back."""
    if not any(values):
        return skeleton
    terms = tuple(join_hypers(t, v) for t, v in zip(skeleton.effect_terms, values))
    return with_fields(skeleton, {"effect_terms": terms})


@jax.jit
def _scaled_qr(A, b, active):
    # QR of [A D^-1 | b]: R's last column holds Q^T b, so Q is never formed. The active columns
    # go first: a zeroed (inactive) column ahead of active ones would leave part of their
    # factor in its row of R (its Householder reflector is the identity), which
    # R[active][:, active] would then lose. With the active columns first, the leading block
    # of R is the factor of the active design alone; it is scattered back to the original
    # column order (the inactive rows and columns are never read).
    act = active.astype(A.dtype)
    norms = jnp.sqrt(jnp.sum(A * A, axis=0))
    scale = jnp.where((norms > 0) & active, norms, 1.0)
    perm = jnp.argsort(~active, stable=True)
    As = (A * (act / scale)[None, :])[:, perm]
    r = jnp.linalg.qr(jnp.concatenate([As, b[:, None]], axis=1), mode="r")
    p = A.shape[1]
    r_orig = jnp.zeros((p, p), A.dtype).at[perm[:, None], perm[None, :]].set(r[:p, :p])
    qtb = jnp.zeros(p, A.dtype).at[perm].set(r[:p, p])
    return qtb, r_orig, scale


@eqx.filter_jit
def _base_column_list(terms: tuple, sig: Signals) -> list:
    """The base terms' columns as separate 1-D arrays (one program per set of base terms).

    Separate outputs, not one stacked matrix: XLA on CPU concatenates columns slowly (measured
    10x slower than computing them), so the stacking is left to NumPy.
    """
    return base_term_columns(terms, sig)


def term_columns(term, sig: Signals, torque) -> Float[jax.Array, "n k"]:
    """One effect group's columns: one compiled program per group structure, whatever its
    float hyperparameters' values (orders, widths, delays, scales: handed in as values,
    `split_hypers`)."""
    return run_split(_term_columns, split_hypers, term, sig, torque)


@eqx.filter_jit
def _term_columns(skeleton, values, sig: Signals, torque) -> Float[jax.Array, "n k"]:
    return join_hypers(skeleton, values).columns(sig, torque)


def term_signals(sig: Signals) -> Signals:
    """`sig` without the torque path (`TORQUE_PATH`), for the terms that do not read it: the
    same signals then give the same compiled program whichever driver the caller attached."""
    if TORQUE_PATH not in sig.extras:
        return sig
    extras = {k: v for k, v in sig.extras.items() if k != TORQUE_PATH}
    return eqx.tree_at(lambda s: s.extras, sig, extras)


def compact_column_list(model: ComplianceModel, sig: Signals, torque):
    """Hinge, base and effect columns as separate 1-D arrays, and each row's segment.

    The hinges and segments in NumPy (exact), the base terms in one compiled program and each
    effect group in its own ([`term_columns`][]): a structure made of groups already seen
    (the residual loop tries dozens) traces, lowers and loads nothing new, where a program per
    structure would. The numbers equal those of a single program, bit for bit (tested).
    """
    t = np.asarray(torque, np.float64)
    cols = [np.clip(t, lo, hi) - min(max(0.0, lo), hi) for lo, hi in model.segment_bounds]
    plain = term_signals(sig)
    if model.base_terms:
        cols += [np.asarray(c) for c in _base_column_list(model.base_terms, plain)]
    torque = jnp.asarray(t)
    for term in model.effect_terms:
        block = np.asarray(term_columns(term, sig if term.torque_kind == "path" else plain, torque))
        cols += [block[:, j] for j in range(block.shape[1])]
    seg = np.zeros(t.shape, np.int32)
    for knot in model.knots:  # as `ComplianceModel.segment_index`: knots at or below
        seg += t >= knot
    return cols, seg


def _compact_index(model: ComplianceModel) -> list[np.ndarray]:
    """For each segment, where the compact columns sit in the full coefficient vector."""
    n_seg, nb, ne = model.n_segments, model.n_base, model.n_effect
    out = []
    for s in range(n_seg if model.per_segment else 1):
        off = n_seg + (s * nb if model.per_segment else 0)
        eff = model.n_coef - ne
        out.append(np.r_[np.arange(n_seg), off + np.arange(nb), eff + np.arange(ne)])
    return out


class _SegmentedDesign:
    """The design of eq. (15) held compactly: per segment, its rows' `q` non-zero columns.

    A row of the per-segment model has non-zeros only in the hinge columns, its own segment's
    block and the effects, so $A^\\top A$, $A^\\top b$ and $Ax$ are sums over segments of small
    dense products (NumPy/BLAS), and the $n \\times p$ design is never formed.
    """

    def __init__(self, model: ComplianceModel, sig: Signals, torque, rows=None):
        cols, seg = compact_column_list(model, sig, torque)
        x = np.stack([np.asarray(c) for c in cols])  # q x n, rows contiguous for BLAS
        twist, torque = np.asarray(sig.twist), np.asarray(torque)
        if rows is not None:
            # the columns of every row (memory states run through them all), then the rows
            x, seg, twist, torque = x[:, rows], np.asarray(seg)[rows], twist[rows], torque[rows]
        self.p = model.n_coef
        self.shape = ShapeData(model)
        self.shape.add(x, twist, torque)
        self.blocks = []
        if model.per_segment:
            seg = np.asarray(seg)
            for s, idx in enumerate(_compact_index(model)):
                rows = np.flatnonzero(seg == s)
                self.blocks.append((idx, rows, x[:, rows]))
        else:
            self.blocks.append((_compact_index(model)[0], slice(None), x))

    def normal_equations(self, b: np.ndarray):
        g = np.zeros((self.p, self.p))
        atb = np.zeros(self.p)
        for idx, rows, xs in self.blocks:
            g[np.ix_(idx, idx)] += xs @ xs.T
            atb[idx] += xs @ b[rows]
        return g, atb

    def dense(self) -> np.ndarray:
        """The full `n x p` design (for the recursive solver, which takes rows in time order)."""
        n = sum(xs.shape[1] for _, _, xs in self.blocks)
        out = np.zeros((n, self.p))
        for idx, rows, xs in self.blocks:
            if isinstance(rows, slice):
                out[:, idx] = xs.T
            else:
                out[np.ix_(rows, idx)] = xs.T
        return out

    def residual_and_atr(self, b: np.ndarray, coef: np.ndarray):
        """$r = b - Ax$ and $A^\\top r$."""
        r = np.array(b, dtype=np.float64, copy=True)
        atr = np.zeros(self.p)
        for idx, rows, xs in self.blocks:
            r[rows] -= coef[idx] @ xs
            atr[idx] += xs @ r[rows]
        return r, atr


def _csne(design: _SegmentedDesign, b, g: np.ndarray, atb: np.ndarray, active: np.ndarray):
    """Corrected semi-normal equations on the scaled Gram matrix, or `None` when the scaled
    condition number exceeds `CSNE_MAX_COND` (then QR decides rank and solution)."""
    csne = scaled_cholesky(g, atb, active, CSNE_MAX_COND)
    if csne is None:
        return None
    coef, cond, solve = csne
    # one step of refinement with the true residual (the "corrected" in CSNE)
    _, atr = design.residual_and_atr(b, coef)
    return coef + solve(atr), cond


def select_active(model: ComplianceModel, A: np.ndarray, torque: np.ndarray):
    """Which coefficients the data can calibrate, and why the others cannot.

    A coefficient is dropped when its column is zero over the data (a segment no sample reaches)
    or, per segment, when the segment holds fewer than `MIN_SEGMENT_SAMPLES_PER_TERM` samples per
    coefficient of its block.
    """
    return _select_active(model, np.abs(A).max(axis=0) > 0, torque)


def _select_active(model: ComplianceModel, nonzero: np.ndarray, torque: np.ndarray):
    seg = np.searchsorted(np.asarray(model.knots), torque, side="right")
    return select_active_counts(model, nonzero, np.bincount(seg, minlength=model.n_segments))


def select_active_counts(model: ComplianceModel, nonzero: np.ndarray, counts):
    """[`select_active`][] from which columns are non-zero and the samples per segment (what a
    streaming fit accumulates); returns `(active, counts, dropped)`."""
    n_seg = model.n_segments
    counts = tuple(int(c) for c in counts)
    active = np.array(nonzero, dtype=bool)
    dropped = []
    names = model.term_names
    k_names = model.k_names
    for j in range(n_seg):
        if not active[j]:
            dropped.append(f"{k_names[j]} (no sample reaches torque segment {j})")
    if model.per_segment:
        nb = model.n_base
        for s in range(n_seg):
            sl = slice(n_seg + s * nb, n_seg + (s + 1) * nb)
            if counts[s] < MIN_SEGMENT_SAMPLES_PER_TERM * nb:
                if active[sl].any() or counts[s] > 0:
                    dropped.append(
                        f"block of segment {s} ({counts[s]} samples < "
                        f"{MIN_SEGMENT_SAMPLES_PER_TERM * nb} needed for its {nb} terms)"
                    )
                active[sl] = False
    for j in np.flatnonzero(~active[n_seg:]) + n_seg:
        if not model.per_segment or j >= model.n_coef - model.n_effect:
            dropped.append(f"{names[j]} (column is zero over the data)")
    return active, counts, tuple(dropped)


def collinear_terms(r: np.ndarray, names: list[str], rtol: float = RANK_RTOL) -> list[list[str]]:
    """Groups of term names spanning the numerical null space of the scaled design."""
    _, s, vt = np.linalg.svd(r)
    groups = []
    for sv, v in zip(s, vt):
        if sv <= rtol * s[0]:
            v = np.abs(v) / np.abs(v).max()
            group = [names[i] for i in np.flatnonzero(v > 0.05)]
            if group not in groups:  # a null space of dimension d repeats its span d times
                groups.append(group)
    return groups


def check_sample_count(n: int, p: int) -> None:
    """Refuse `n` samples for `p` coefficients when `n < p`, saying what to record instead."""
    if n < p:
        raise CalibrationError(
            f"{n} samples cannot calibrate {p} coefficients; record at least {p} samples "
            f"(better {10 * p}) or reduce the model (fewer segments, lower orders)"
        )


def calibrate_lstsq(
    model: ComplianceModel,
    data: CalibrationData,
    *,
    throw: bool = True,
    monotone: bool = True,
    rows: Int[ArrayLike, " m"] | None = None,
) -> Solution:
    """Calibrate by linear least squares (Song et al. eqs. (15)-(17)), column-scaled (see module).

    **Arguments:**

    - `model`: the structure to calibrate (coefficients are ignored).
    - `data`: a [`hdjax.Recording`][] with a reference `torque`, or a `(Signals, torque)` pair.
    - `throw`: raise on a rank-deficient design or a non-invertible compliance (default); with
      `False` the problem is returned as the solution's `result` (`RESULTS.rank_deficient`,
      `RESULTS.not_invertible` or `RESULTS.twist_reversed`).
    - `monotone`: constrain the twist to increase with torque everywhere (the
      shape-constrained least squares of [`hdjax.compliance.ShapeConstraint`][], default); where the
      plain solution already does, it is returned unchanged. `False`: eq. (17) as the paper
      writes it.
    - `rows`: the indices of the samples to fit (default all). The columns are computed over
      the whole record first, so memory states and derivatives run through the rows left out
      (a TRAIN part cut from one log with TEST blocks between).

    **Returns:** an [`hdjax.Solution`][] whose `value` is the calibrated
    [`hdjax.compliance.ComplianceModel`][]; its `stats` are listed in the module docstring.

    Segments and per-segment blocks the data does not reach are left out (and named in
    `stats["dropped"]`); the model's `torque_range` becomes the range of the reference torque
    within the calibrated segments, so estimates outside it are flagged.
    """
    t0 = time.perf_counter()
    sig, torque = prepare(model, data)
    rows = None if rows is None else np.asarray(rows, np.int64)
    pick = (lambda x: x) if rows is None else (lambda x: x[rows])
    t_np = pick(np.asarray(torque))
    b = pick(np.asarray(sig.twist, np.float64))
    n = b.size
    design = _SegmentedDesign(model, sig, torque, rows)
    g, atb = design.normal_equations(b)
    # a column is zero over the data exactly when its sum of squares is
    active, counts, dropped = _select_active(model, np.diag(g) > 0, t_np)
    p = int(active.sum())
    check_sample_count(n, p)
    fast = _csne(design, b, g, atb, active)
    if fast is not None:
        coef, cond = fast
        solved = (coef, p, cond, ())
    else:
        solved = _qr_solve(model, sig, torque, active, throw, rows)
    solved, shape = constrain_shape(
        model,
        solved,
        g,
        active,
        design.shape,
        monotone,
        lambda x, d=design: d.residual_and_atr(b, x)[1],
    )
    resid, _ = design.residual_and_atr(b, solved[0])
    del design
    calibrated = [s_ for s_ in range(model.n_segments) if active[s_]]
    t_in = t_np[np.isin(np.searchsorted(np.asarray(model.knots), t_np, side="right"), calibrated)]
    torque_range = (float(t_in.min()), float(t_in.max())) if t_in.size else model.torque_range
    return calibration_solution(
        model,
        solved,
        active,
        torque_range,
        throw=throw,
        residual_rms=float(np.sqrt(np.mean(resid**2))),
        n_samples=n,
        segment_counts=counts,
        dropped=dropped,
        t0=t0,
        shape=shape,
    )


def constrain_shape(
    model, solved: tuple, g, active, data: ShapeData, monotone: bool, residual_pass=None
):
    """The solve's `(coef, rank, condition, collinear)` with the coefficients projected onto
    the shape constraint ([`hdjax.compliance.ShapeConstraint`][]) when `monotone` and
    the design has full rank (refined with `residual_pass`, $x \\mapsto A^\\top(b - Ax)$), and
    the shape record `calibration_solution` keeps: the constraint (or `None`) and the data's
    overall compliance."""
    coef, rank, cond, collinear = solved
    shape = {"constraint": None, "compliance": data.compliance()}
    if not monotone or rank < int(np.sum(active)):
        return solved, shape
    constraint = ShapeConstraint.of(model, data, active)
    if constraint is None:
        return solved, shape
    shape["constraint"] = constraint
    shape["unconstrained_violation"] = constraint.violation(coef)
    shape["unconstrained_k"] = tuple(float(k) for k in np.asarray(coef)[: model.n_segments])
    return (constraint.solve(coef, g, active, residual_pass), rank, cond, collinear), shape


def calibration_solution(
    model: ComplianceModel,
    solved: tuple,
    active,
    torque_range: tuple[float, float],
    *,
    throw: bool,
    residual_rms: float,
    n_samples: int,
    segment_counts,
    dropped: Sequence[str],
    t0: float,
    shape: dict | None = None,
) -> Solution:
    """The [`hdjax.Solution`][] of a calibration of `model`, batch or streamed.

    Its value is `model` with the solved coefficients, its `active` terms and the calibrated
    `torque_range` ([`fitted_model`][]); its result a rank-deficient design first, then a
    non-invertible compliance, else success; its stats those of the module docstring.
    `solved` is the solve's `(coef, rank, condition, collinear)`, `t0` the
    `time.perf_counter()` the fit started at, `shape` the record of [`constrain_shape`][].
    """
    coef, rank, condition, collinear = solved
    n_terms = int(np.sum(active))
    shape = shape or {"constraint": None, "compliance": float("nan")}
    fitted, invertible = fitted_model(
        model, coef, active, torque_range, dropped, throw, shape["compliance"]
    )
    result = RESULTS.rank_deficient if rank < n_terms else invertible
    stats = {
        "rank": rank,
        "n_terms": n_terms,
        "condition": condition,
        "residual_rms": residual_rms,
        "n_samples": n_samples,
        "segment_counts": segment_counts,
        "dropped": dropped,
        "collinear": collinear,
        "fit_time_s": time.perf_counter() - t0,
        "data_compliance": shape["compliance"],
        "shape_constraint": shape["constraint"],
        "constrained": _constrained_notes(fitted, shape),
        "unconstrained_k": shape.get("unconstrained_k"),
    }
    return Solution(fitted, result, stats)


def _constrained_notes(model: ComplianceModel, shape: dict) -> tuple[str, ...]:
    """What the shape constraint changed, for a user: the segments held at the slope floor."""
    c = shape["constraint"]
    if c is None or not shape.get("unconstrained_violation", 0.0) > 0.0:
        return ()
    tight = c.active_segments(np.asarray(model.coef), model.n_segments)
    names = [
        f"{name} [{lo:.4g}, {hi:.4g}) N·m"
        for name, (lo, hi), t in zip(model.k_names, model.segment_bounds, tight)
        if t
    ]
    return (
        "the least-squares compliance was not increasing with torque; calibrated under the "
        f"constraint that its slope stays at least {c.floor:.3g} rad/(N·m) "
        f"({c.floor / c.compliance:.0%} of the data's compliance), held at that floor in "
        + (", ".join(names) if names else "the torque-dependent effects")
        + ": the data there does not determine the compliance (record more torque range, or "
        "use fewer segments)",
    )


def calibration_messages(solution: Solution) -> list[str]:
    """What a user should read about a calibration: the terms left out, and, if it failed, the
    collinear terms or the segments whose compliance is not positive.

    **Arguments:**

    - `solution`: from [`hdjax.compliance.calibrate_lstsq`][], `calibrate_stream` or
      `calibrate_rls` (with `throw=False` to see failures here rather than as errors).

    **Returns:** one line per problem, `[]` when there is nothing to say.
    """
    st = solution.stats
    out = [f"left out: {d}" for d in st["dropped"]]
    out += list(st.get("constrained", ()))
    if st["rank"] < st["n_terms"]:
        out.append(rank_message(st["rank"], st["n_terms"], st["collinear"]))
    msg = check_invertible(solution.value, st.get("data_compliance"))
    if msg:
        out.append(msg)
    return out


def failure_message(solution: Solution) -> str:
    """The detailed reason a calibration failed (the collinear terms of a rank-deficient design,
    or the segments whose compliance is not positive), `""` when it succeeded."""
    st = solution.stats
    if solution.result == RESULTS.rank_deficient:
        return rank_message(st["rank"], st["n_terms"], st["collinear"])
    return check_invertible(solution.value, st.get("data_compliance")) if not solution.ok else ""


def rank_message(rank: int, p: int, collinear) -> str:
    """The explanation of a rank-deficient design, naming its collinear term groups."""
    desc = "; ".join("{" + ", ".join(g) + "}" for g in collinear)
    return (
        f"rank-deficient design: rank {rank} < {p} terms; collinear terms: {desc}. The data "
        "does not excite these terms independently (e.g. a constant current makes the "
        "current polynomial collinear with the constant): add load variation or motion, or "
        "remove the terms from the model"
    )


def _qr_solve(model, sig, torque, active, throw, rows=None):
    """Scaled Householder QR on the dense design (of the rows `rows`, default all): rank,
    condition and (if full rank) solution."""
    A, b = design_columns(model, sig, torque), sig.twist
    if rows is not None:
        A, b = A[rows], b[rows]
    qtb, r, scale = _scaled_qr(A, b, jnp.asarray(active))
    return solve_from_r(model, np.asarray(r), np.asarray(qtb), np.asarray(scale), active, throw)


def solve_from_r(model, r, qtb, scale, active, throw):
    """Rank, condition, solution and collinear term groups from the factor `R` of the scaled
    design and `Q^T b` (the rank decision of [`calibrate_lstsq`][]; a rank-deficient design
    raises `CalibrationError` naming the collinear terms when `throw`)."""
    p = int(active.sum())
    r_np = np.asarray(r)[np.ix_(active, active)]
    s = np.linalg.svd(r_np, compute_uv=False)
    rank = int((s > RANK_RTOL * s[0]).sum())
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    names = [nm for nm, a in zip(model.term_names, active) if a]
    collinear: tuple = ()
    if rank < p:
        collinear = tuple(tuple(g) for g in collinear_terms(r_np, names))
        if throw:
            raise CalibrationError(rank_message(rank, p, collinear))
    x_scaled = np.zeros(model.n_coef)
    qb = np.asarray(qtb)[active]
    x_scaled[active] = (
        np.linalg.lstsq(r_np, qb, rcond=None)[0] if rank < p else _solve_tri(r_np, qb)
    )
    coef = x_scaled / np.asarray(scale)
    coef[~active] = 0.0
    return coef, rank, cond, collinear


def _solve_tri(r, b):
    import scipy.linalg

    return scipy.linalg.solve_triangular(r, b, lower=False)


def fitted_model(model, coef, active, torque_range, dropped, throw, data_compliance=None):
    """`model` with the solved coefficients, its active terms and calibrated torque range, and
    whether it can be inverted (a [`hdjax.RESULTS`][] member); an `InversionError` when it
    cannot and `throw`, and a warning naming the terms the data could not reach. Shared by the
    batch and streamed fits. `data_compliance` (the twist's least-squares slope on the torque
    over the data) decides whether the encoders count against the torque."""
    fitted = eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef))
    fitted = _with_static(fitted, active=tuple(bool(a) for a in active), torque_range=torque_range)
    invertible = invertibility(fitted, data_compliance)
    if invertible != RESULTS.successful and throw:
        raise InversionError(check_invertible(fitted, data_compliance))
    if dropped:
        warnings.warn(
            "calibration left out terms the data cannot reach: " + "; ".join(dropped),
            stacklevel=4,  # the caller of calibrate_lstsq / calibrate_stream
        )
    return fitted, invertible


def invertibility(model: ComplianceModel, data_compliance: float | None = None) -> RESULTS:
    """`RESULTS.successful` when the calibrated compliance can be inverted for torque;
    `RESULTS.twist_reversed` when the twist falls with torque over the data (or, without
    `data_compliance`, in every segment), else `RESULTS.not_invertible` (see
    [`check_invertible`][])."""
    if not check_invertible(model, data_compliance):
        return RESULTS.successful
    return RESULTS.twist_reversed if _reversed(model, data_compliance) else RESULTS.not_invertible


def _reversed(model: ComplianceModel, data_compliance: float | None) -> bool:
    """Whether the twist falls as torque rises: over the data when its overall slope is
    known, else in every calibrated segment."""
    if data_compliance is not None and np.isfinite(data_compliance):
        return data_compliance < 0
    k = np.asarray(model.k)
    return all(kj < 0 for kj, a in zip(k, model.active) if a)


def _with_static(model: ComplianceModel, **changes) -> ComplianceModel:
    d = {f: getattr(model, f) for f in model.__dataclass_fields__}
    d.update(changes)
    return ComplianceModel(**d)


def check_invertible(model: ComplianceModel, data_compliance: float | None = None) -> str:
    """An explanation if the calibrated compliance is not increasing in torque, else `""`.

    Every calibrated segment compliance $k_j$ must be positive for the inversion of eq. (27) to
    exist. A twist that falls as torque rises over the data (`data_compliance`, its
    least-squares slope on the torque, negative; without it: every $k_j$ negative) means the
    encoders count the other way, and only then is `twist_sign = -1` suggested.
    """
    k = np.asarray(model.k)
    bad = [
        f"{name}={kj:.4g}"
        for name, kj, a in zip(model.k_names, k, model.active[: model.n_segments])
        if a and not kj > 0
    ]
    if not bad:
        return _check_nonlinear_slope(model, k)
    hint = ""
    if _reversed(model, data_compliance):
        hint = (
            " The twist falls as torque rises over the data: the encoders count against the "
            "torque, so set twist_sign = -1 in the [joint] table."
        )
    return (
        "the calibrated compliance is not increasing with torque, so it cannot be inverted "
        f"(eq. (27)): {', '.join(bad)}.{hint}"
    )


def _check_nonlinear_slope(model: ComplianceModel, k: np.ndarray) -> str:
    """With effect terms nonlinear in torque (stiffening, backlash), the total slope
    $d\\Delta\\theta/dT$ must stay positive over the rated range (checked on a grid)."""
    terms, i = [], model.n_coef - model.n_effect
    for term in model.effect_terms:
        m = len(term.names())
        if term.torque_kind == "memoryless":
            terms.append((term, float(np.asarray(model.coef)[i])))
        i += m
    if not terms:
        return ""
    grid = torque_grid(model)
    seg = np.searchsorted(np.asarray(model.knots), grid, side="right")
    act = np.asarray(model.active[: model.n_segments])
    slope = np.where(act[seg], k[seg], np.nan)
    for term, c in terms:
        slope = slope + c * np.asarray(term.value_and_slope(grid)[1])
    worst = np.nanargmin(slope)
    if slope[worst] > 0:
        return ""
    return (
        "the calibrated compliance is not increasing with torque once "
        f"{', '.join(t.key for t, _ in terms)} is added: its slope is {slope[worst]:.3g} "
        f"rad/(N·m) at {grid[worst]:.4g} N·m, so it cannot be inverted over the rated range"
    )
