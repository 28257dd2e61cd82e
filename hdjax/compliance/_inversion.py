"""Torque estimation by inverting the calibrated compliance, Song et al. eqs. (26)-(27).

Eq. (26) removes the wave-generator and kinematic-error terms from the measured twist to get
the flexspline deflection; eq. (27) inverts the piecewise-linear flexspline compliance. With
per-segment coefficients (Table I) the terms removed depend on the segment, so the segment is
resolved self-consistently:

1. for every calibrated segment $s$, invert with that segment's terms: a candidate $T_s$;
2. a candidate is *valid* when it falls inside its own segment $[l_s, u_s)$ (the outer
   segments extend without bound);
3. exactly one valid candidate: take it. **Several** (the twist ranges of neighbouring segments
   overlap): take the one lying deepest inside its segment, measured in units of the segment
   width, and flag the sample `ambiguous`. **None** (the twist falls in a gap between
   segments): take the candidate nearest to its own segment, clipped onto that segment's edge,
   and flag the sample `unresolved`.

With shared coefficients the compliance is monotone, so exactly one candidate is valid
(up to ties at a knot). Effects that depend nonlinearly on the present torque (stiffening,
backlash) are then solved by safeguarded Newton steps, and effects on the torque path
(hysteresis) by a fixed-point iteration on the estimated path, causally.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Bool, Float, Int
from .._errors import InversionError
from .._recording import Recording
from ._lstsq import check_invertible
from ._model import ComplianceModel
from ._signals import Signals, signals_from_recording

NEWTON_STEPS = 8
PATH_ITERATIONS = 4


class TorqueEstimate(eqx.Module):
    """Estimated output torque with per-sample flags.

    **Fields:** `torque` [N·m]; `segment` (resolved segment index); `in_range` (inside the
    calibrated torque range); `ambiguous` (several segments were self-consistent);
    `unresolved` (none was; the torque sits on a segment edge).
    """

    torque: Float[Array, " n"]
    segment: Int[Array, " n"]
    in_range: Bool[Array, " n"]
    ambiguous: Bool[Array, " n"]
    unresolved: Bool[Array, " n"]


def _segment_candidates(model: ComplianceModel, r, base_h, g):
    """Eq. (27) per segment: candidates, validity and distance outside each segment."""
    k = model.k
    cands, dist, width = [], [], []
    for s, (lo, hi) in enumerate(model.segment_bounds):
        a = min(max(0.0, lo), hi)  # point of segment s nearest to 0 N·m
        f_a = model.hinge_basis(jnp.asarray([a], jnp.float64))[0] @ k
        h = base_h[:, s] if model.per_segment else base_h[:, 0]
        t_s = (r - h - f_a + k[s] * a) / (k[s] + g)
        cands.append(t_s)
        below = jnp.where(jnp.isfinite(lo), lo - t_s, -jnp.inf)
        above = jnp.where(jnp.isfinite(hi), t_s - hi, -jnp.inf)
        dist.append(jnp.maximum(below, above))  # <= 0 inside, > 0 outside
        w = (hi - lo) if math.isfinite(hi - lo) else 2.0 * model.rated_torque / model.n_segments
        width.append(w)
    return jnp.stack(cands, 1), jnp.stack(dist, 1), jnp.asarray(width)


def _calibrated_segments(model: ComplianceModel) -> np.ndarray:
    n_seg, nb = model.n_segments, model.n_base
    act = np.asarray(model.active)
    ok = act[:n_seg].copy()
    if model.per_segment and nb:
        for s in range(n_seg):
            ok[s] &= act[n_seg + s * nb : n_seg + (s + 1) * nb].any()
    return ok


def _piecewise(model: ComplianceModel, r, base_h, g):
    cands, dist, width = _segment_candidates(model, r, base_h, g)
    ok = jnp.asarray(_calibrated_segments(model))
    valid = (dist <= 0.0) & (cands == cands) & ok[None, :]  # also rejects NaN candidates
    n_valid = valid.sum(axis=1)
    depth = jnp.where(valid, -dist / width[None, :], -jnp.inf)
    pick_valid = jnp.argmax(depth, axis=1)
    pick_near = jnp.argmin(jnp.where(ok[None, :], dist, jnp.inf), axis=1)
    seg = jnp.where(n_valid > 0, pick_valid, pick_near)
    t = jnp.take_along_axis(cands, seg[:, None], axis=1)[:, 0]
    lo = jnp.asarray([b[0] for b in model.segment_bounds])[seg]
    hi = jnp.asarray([b[1] for b in model.segment_bounds])[seg]
    t = jnp.where(n_valid > 0, t, jnp.clip(t, lo, hi))
    return t, seg, n_valid > 1, n_valid == 0


def _split_effects(model: ComplianceModel):
    """Effect groups by torque dependence, with their coefficient slices."""
    out = {"none": [], "linear": [], "memoryless": [], "path": []}
    i = model.n_coef - model.n_effect
    for term in model.effect_terms:
        m = len(term.names())
        out[term.torque_kind].append((term, model.coef[i : i + m]))
        i += m
    return out


@eqx.filter_jit
def _estimate(model: ComplianceModel, sig: Signals):
    effects = _split_effects(model)
    n = sig.n_samples
    # eq. (26): twist minus the torque-free terms
    r = sig.twist
    for term, c in effects["none"]:
        r = r - term.columns(sig, None) @ c
    base = model.base_columns(sig)
    base_h = base @ model.base_coef.T  # (n, n_seg) or (n, 1)
    g = jnp.zeros(n, jnp.float64)
    for term, c in effects["linear"]:
        g = g + term.torque_slope(sig) * c[0]

    def solve(r_eff):
        t, seg, amb, unres = _piecewise(model, r_eff, base_h, g)
        if effects["memoryless"]:
            t = _newton(model, t, seg, r_eff, base_h, g, effects["memoryless"])
        return t, seg, amb, unres

    t, seg, amb, unres = solve(r)
    if effects["path"]:
        # Path-dependent terms (hysteresis) from the estimated torque, causally; fixed point.
        def body(_, t_prev):
            r_eff = r
            for term, c in effects["path"]:
                r_eff = r_eff - term.columns(sig, t_prev) @ c
            return solve(r_eff)[0]

        t = jax.lax.fori_loop(0, PATH_ITERATIONS, body, t)
        r_eff = r
        for term, c in effects["path"]:
            r_eff = r_eff - term.columns(sig, t) @ c
        t, seg, amb, unres = solve(r_eff)
    lo, hi = model.torque_range
    return TorqueEstimate(
        torque=t, segment=seg, in_range=(t >= lo) & (t <= hi), ambiguous=amb, unresolved=unres
    )


def _newton(model, t, seg, r, base_h, g, terms):
    k = model.k
    span = model.rated_torque / 4.0
    h = jnp.take_along_axis(base_h, seg[:, None], 1)[:, 0] if model.per_segment else base_h[:, 0]

    def body(_, t):
        f = model.hinge_basis(t) @ k + g * t + h
        slope = k[model.segment_index(t)] + g
        for term, c in terms:
            v, dv = term.value_and_slope(t)
            f = f + c[0] * v
            slope = slope + c[0] * dv
        step = jnp.clip((f - r) / slope, -span, span)
        return t - jnp.where(slope > 0, step, 0.0)

    return jax.lax.fori_loop(0, NEWTON_STEPS, body, t)


def estimate_torque(model: ComplianceModel, data) -> TorqueEstimate:
    """Estimate the output torque from twist, current and angles (eqs. (26)-(27)).

    **Arguments:**

    - `model`: a calibrated [`hdjax.compliance.ComplianceModel`][].
    - `data`: a [`hdjax.Recording`][] (its `torque`, if any, is not used) or
      [`hdjax.compliance.Signals`][].

    **Returns:** a [`hdjax.compliance.TorqueEstimate`][] (torque and per-sample flags; see the
    module docstring for the segment rules).

    Raises [`hdjax.InversionError`][] when the calibrated compliance is not increasing in torque.
    """
    msg = check_invertible(model)
    if msg:
        raise InversionError(msg)
    if not np.asarray(model.active)[: model.n_segments].any():
        raise InversionError("the model has no calibrated segment; calibrate it first")
    if isinstance(data, Recording):
        data = signals_from_recording(data, model.ratio, model.twist_sign, velocity=model.velocity)
    missing = [
        name
        for term in model.base_terms + model.effect_terms
        for name in (getattr(term, "name", None), getattr(term, "signal", None))
        if name is not None
        and name not in ("twist", "current", "theta_m", "theta_l", "omega_m", "omega_l")
        and name not in data.extras
    ]
    if missing:
        from .._errors import ModelMismatchError

        raise ModelMismatchError(
            f"the model uses column(s) {', '.join(sorted(set(missing)))} that the data lacks; "
            "supply them or use a model calibrated without them"
        )
    return _estimate(model, data)


def estimate_torque_arrays(model: ComplianceModel, sig: Signals) -> Float[Array, " n"]:
    """The torque alone, for use inside other jitted code (no Python-side checks)."""
    return _estimate(model, sig).torque
