"""Closed-form least-squares calibration, Song et al. eqs. (15)-(17).

The paper writes the solution through the normal equations, $x^* = (A^\\top A)^{-1} A^\\top b$
(eq. (17)). We compute the same minimiser by a QR factorisation of the column-scaled design
$A D^{-1}$, which squares neither the condition number nor the rounding error, and read the rank
and condition number from the singular values of the small triangular factor. A rank-deficient
design is refused with the names of the collinear terms.
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import CalibrationError, DataError, InversionError
from .._recording import Recording
from ._model import ComplianceModel
from ._signals import Signals, signals_from_recording

RANK_RTOL = 1e-10
"""Singular values of the scaled design below `RANK_RTOL * max` count as zero."""

MIN_SEGMENT_SAMPLES_PER_TERM = 3
"""A segment's own block is calibrated only with at least this many samples per coefficient."""


class CalibrationResult(eqx.Module):
    """A calibrated model with its diagnostics (returned by the calibration functions).

    **Fields:** `model` (the fitted [`hdjax.compliance.ComplianceModel`][]), `rank`, `n_terms`
    (active coefficients), `condition` (2-norm condition number of the column-scaled design),
    `residual_rms` (twist residual [rad]), `n_samples`, `segment_counts` (samples per torque
    segment), `dropped` (terms left out, with the reason) and `messages`.
    """

    model: ComplianceModel
    rank: int = eqx.field(static=True)
    n_terms: int = eqx.field(static=True)
    condition: float = eqx.field(static=True)
    residual_rms: float = eqx.field(static=True)
    n_samples: int = eqx.field(static=True)
    segment_counts: tuple[int, ...] = eqx.field(static=True)
    dropped: tuple[str, ...] = eqx.field(static=True)
    messages: tuple[str, ...] = eqx.field(static=True)


def prepare(model: ComplianceModel, data) -> tuple[Signals, jax.Array]:
    """Signals and reference torque from a recording (or a `(Signals, torque)` pair)."""
    if isinstance(data, Recording):
        if data.torque is None:
            raise DataError(
                f"{data.source}: calibration needs a reference 'torque' column (a torque sensor "
                "or another reference); the recording has none"
            )
        sig = signals_from_recording(data, model.ratio, model.twist_sign, velocity=model.velocity)
        return sig, data.torque
    if isinstance(data, tuple) and len(data) == 2 and isinstance(data[0], Signals):
        return data[0], jnp.asarray(data[1], jnp.float64)
    raise DataError(f"expected a Recording or a (Signals, torque) pair, got {type(data).__name__}")


@eqx.filter_jit
def _design(model: ComplianceModel, sig: Signals, torque):
    return model.design(sig, torque)


@jax.jit
def _scaled_qr(A, b, active):
    act = active.astype(A.dtype)
    norms = jnp.sqrt(jnp.sum(A * A, axis=0))
    scale = jnp.where((norms > 0) & active, norms, 1.0)
    As = A * (act / scale)[None, :]
    q, r = jnp.linalg.qr(As, mode="reduced")
    return q.T @ b, r, scale


def select_active(model: ComplianceModel, A: np.ndarray, torque: np.ndarray):
    """Which coefficients the data can calibrate, and why the others cannot.

    A coefficient is dropped when its column is zero over the data (a segment no sample reaches)
    or, per segment, when the segment holds fewer than `MIN_SEGMENT_SAMPLES_PER_TERM` samples per
    coefficient of its block.
    """
    n_seg = model.n_segments
    seg = np.searchsorted(np.asarray(model.knots), torque, side="right")
    counts = tuple(int((seg == s).sum()) for s in range(n_seg))
    active = np.abs(A).max(axis=0) > 0
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
            groups.append([names[i] for i in np.flatnonzero(v > 0.05)])
    return groups


def calibrate_lstsq(model: ComplianceModel, data, *, throw: bool = True) -> CalibrationResult:
    """Calibrate by linear least squares (Song et al. eqs. (15)-(17)), solved by scaled QR.

    **Arguments:**

    - `model`: the structure to calibrate (coefficients are ignored).
    - `data`: a [`hdjax.Recording`][] with a reference `torque`, or a `(Signals, torque)` pair.
    - `throw`: raise on a rank-deficient design or a non-invertible compliance (default); with
      `False` the problems are returned in `messages`.

    **Returns:** a [`hdjax.compliance.CalibrationResult`][] whose `model` carries the coefficients.

    Segments and per-segment blocks the data does not reach are left out (and named in
    `dropped`); the model's `torque_range` becomes the range of the reference torque within the
    calibrated segments, so estimates outside it are flagged.
    """
    sig, torque = prepare(model, data)
    n = sig.n_samples
    A = _design(model, sig, torque)
    A_np = np.asarray(A)
    t_np = np.asarray(torque)
    active, counts, dropped = select_active(model, A_np, t_np)
    p = int(active.sum())
    if n < p:
        raise CalibrationError(
            f"{n} samples cannot calibrate {p} coefficients; record at least {p} samples "
            f"(better {10 * p}) or reduce the model (fewer segments, lower orders)"
        )
    qtb, r, scale = _scaled_qr(A, sig.twist, jnp.asarray(active))
    r_np = np.asarray(r)[np.ix_(active, active)]
    s = np.linalg.svd(r_np, compute_uv=False)
    rank = int((s > RANK_RTOL * s[0]).sum())
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    names = [nm for nm, a in zip(model.term_names, active) if a]
    messages = list(dropped and [f"left out: {d}" for d in dropped])
    if rank < p:
        groups = collinear_terms(r_np, names)
        desc = "; ".join("{" + ", ".join(g) + "}" for g in groups)
        msg = (
            f"rank-deficient design: rank {rank} < {p} terms; collinear terms: {desc}. The data "
            "does not excite these terms independently (e.g. a constant current makes the "
            "current polynomial collinear with the constant): add load variation or motion, or "
            "remove the terms from the model"
        )
        if throw:
            raise CalibrationError(msg)
        messages.append(msg)
    x_scaled = np.zeros(model.n_coef)
    rr = np.asarray(r)[np.ix_(active, active)]
    qb = np.asarray(qtb)[active]
    x_scaled[active] = np.linalg.lstsq(rr, qb, rcond=None)[0] if rank < p else _solve_tri(rr, qb)
    coef = x_scaled / np.asarray(scale)
    coef[~active] = 0.0
    resid = A_np @ coef - np.asarray(sig.twist)
    calibrated = [s_ for s_ in range(model.n_segments) if active[s_]]
    t_in = t_np[np.isin(np.searchsorted(np.asarray(model.knots), t_np, side="right"), calibrated)]
    torque_range = (float(t_in.min()), float(t_in.max())) if t_in.size else model.torque_range
    fitted = eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef))
    fitted = _with_static(fitted, active=tuple(bool(a) for a in active), torque_range=torque_range)
    msg = check_invertible(fitted)
    if msg:
        if throw:
            raise InversionError(msg)
        messages.append(msg)
    if dropped:
        warnings.warn(
            "calibration left out terms the data cannot reach: " + "; ".join(dropped),
            stacklevel=2,
        )
    return CalibrationResult(
        model=fitted,
        rank=rank,
        n_terms=p,
        condition=cond,
        residual_rms=float(np.sqrt(np.mean(resid**2))),
        n_samples=n,
        segment_counts=counts,
        dropped=dropped,
        messages=tuple(messages),
    )


def _solve_tri(r, b):
    import scipy.linalg

    return scipy.linalg.solve_triangular(r, b, lower=False)


def _with_static(model: ComplianceModel, **changes) -> ComplianceModel:
    d = {f: getattr(model, f) for f in model.__dataclass_fields__}
    d.update(changes)
    return ComplianceModel(**d)


def check_invertible(model: ComplianceModel) -> str:
    """An explanation if the calibrated compliance is not increasing in torque, else `""`.

    Every calibrated segment compliance $k_j$ must be positive for the inversion of eq. (27) to
    exist (a twist that falls as torque rises means the encoders count the other way).
    """
    k = np.asarray(model.k)
    bad = [
        f"{name}={kj:.4g}"
        for name, kj, a in zip(model.k_names, k, model.active[: model.n_segments])
        if a and not kj > 0
    ]
    if not bad:
        return ""
    hint = ""
    if all(kj < 0 for kj, a in zip(k, model.active) if a):
        hint = (
            " The twist falls as torque rises in every segment: the encoders count against the "
            "torque, so set twist_sign = -1 in the [joint] table."
        )
    return (
        "the calibrated compliance is not increasing with torque, so it cannot be inverted "
        f"(eq. (27)): {', '.join(bad)}.{hint}"
    )
