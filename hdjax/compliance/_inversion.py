"""Torque estimation by inverting the calibrated compliance, Song et al. eqs. (26)-(27).

Eq. (26) removes the wave-generator and kinematic-error terms from the measured twist to get
the flexspline deflection; eq. (27) inverts the piecewise-linear flexspline compliance. With
per-segment coefficients (Table I) the terms removed depend on the segment, so the segment is
resolved self-consistently:

1. for every calibrated segment $s$, invert with that segment's terms: a candidate $T_s$;
2. a candidate is *valid* when it falls inside its own segment, edges included, $[l_s, u_s]$,
   with a slack of `EDGE_TOLERANCE` ($10^{-9}\tau_0$) for rounding (the outer segments extend
   without bound); segments the calibration left out never are;
3. exactly one valid candidate: take it. **Several** (the twist ranges of neighbouring segments
   overlap): take the one lying deepest inside its segment, measured in units of the segment
   width (outer segments: the paper's width $2\tau_0/n$), the lower segment on a tie, and
   flag the sample `ambiguous`. **None** (the twist falls in a gap between segments): take
   the candidate nearest to its own segment, clipped onto that segment's edge, and flag the
   sample `unresolved`.

With shared coefficients the compliance is continuous and increasing, so exactly one candidate
is valid, except for a torque on a knot (to rounding), valid in both neighbours and then
flagged `ambiguous` with the same torque. Forward data from a per-segment model is never
`unresolved` (its own segment's candidate is always valid); when `ambiguous`, the error is at
most the jump of $h$ between neighbouring segments divided by the smaller compliance.
`in_range` is `torque_range[0] <= T <= torque_range[1]` (the calibrated range).

Effects that depend nonlinearly on the present torque (stiffening, backlash) are then solved
by safeguarded Newton steps, and effects on the torque path (hysteresis) are driven by the
torque being estimated, causally, by an implicit step per sample (`_path_states`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Bool, Float, Int
from .._errors import ConfigError, InversionError, ModelMismatchError
from .._features import signals
from .._recording import Recording
from ..effects import SEGMENT_START
from ..effects.internal import opaque
from ._lstsq import check_invertible
from ._model import ComplianceModel
from ._signals import Signals

EDGE_TOLERANCE = 1e-9
"""A candidate counts as inside its segment up to this fraction of the rated torque."""

NEWTON_STEPS = 8


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


def _base_h(model: ComplianceModel, sig: Signals) -> list:
    """Torque-free part $h$ of eq. (10) per segment (one entry when coefficients are shared).

    Built column by column with scalar coefficients so XLA fuses it into one elementwise loop
    (no `n x n_terms` design is materialised).
    """
    cols = model.base_column_list(sig)
    coef = model.base_coef
    rows = coef.shape[0]
    if not cols:
        return [jnp.zeros(sig.n_samples, jnp.float64)] * rows
    out = []
    for s in range(rows):
        h = cols[0] * coef[s, 0]
        for j in range(1, len(cols)):
            h = h + cols[j] * coef[s, j]
        out.append(h)
    return out


def calibrated_segments(model: ComplianceModel, active=None) -> np.ndarray:
    """Which segments a model with these active flags (default its own) can invert in: the
    segment's compliance and, per segment, at least one of its base terms are calibrated."""
    n_seg, nb = model.n_segments, model.n_base
    act = np.asarray(model.active if active is None else active)
    ok = act[:n_seg].copy()
    if model.per_segment and nb:
        for s in range(n_seg):
            ok[s] &= act[n_seg + s * nb : n_seg + (s + 1) * nb].any()
    return ok


def _piecewise(model: ComplianceModel, r, hs: list, g):
    """Eq. (27) with the segment resolved by the rules of the module docstring.

    Written as a running selection over the segments (elementwise only, so it fuses): for each
    segment the candidate $T_s$, its signed distance outside the segment and its depth inside.
    """
    k = model.k
    ok = calibrated_segments(model)
    bounds = model.segment_bounds
    default_width = 2.0 * model.rated_torque / model.n_segments
    tol = EDGE_TOLERANCE * model.rated_torque
    n_valid = None
    for s, (lo, hi) in enumerate(bounds):
        if not ok[s]:
            continue
        a = min(max(0.0, lo), hi)  # point of segment s nearest to 0 N·m
        phi_a = np.asarray([min(max(a, l_), h_) - min(max(0.0, l_), h_) for l_, h_ in bounds])
        f_a = jnp.asarray(phi_a, jnp.float64) @ k
        h = hs[s] if model.per_segment else hs[0]
        num = r - h - (f_a - k[s] * a)
        t_s = num / k[s] if g is None else num / (k[s] + g)
        # signed distance outside the segment (<= 0 inside) and clipped candidate
        parts = []
        if math.isfinite(lo):
            parts.append(lo - t_s)
        if math.isfinite(hi):
            parts.append(t_s - hi)
        if not parts:
            dist = jnp.full_like(t_s, -jnp.inf)
        else:
            dist = parts[0] if len(parts) == 1 else jnp.maximum(parts[0], parts[1])
        width = (hi - lo) if math.isfinite(hi - lo) else default_width
        # edges included, with slack for rounding: a torque on a knot inverts to the knot
        # +- a few ulps, which must not make its own segment's candidate invalid
        valid = (dist <= tol) & (t_s == t_s)  # also rejects NaN candidates
        depth = jnp.where(valid, -dist / width, -jnp.inf)
        t_clip = jnp.clip(t_s, lo, hi)
        seg = jnp.full(t_s.shape, s, jnp.int32)
        if n_valid is None:
            n_valid = valid.astype(jnp.int32)
            best_depth, best_t, best_seg = depth, t_s, seg
            near_dist, near_t, near_seg = dist, t_clip, seg
            continue
        n_valid = n_valid + valid.astype(jnp.int32)
        # strict comparisons keep the first segment on ties (as argmax/argmin would)
        take = depth > best_depth
        best_depth = jnp.where(take, depth, best_depth)
        best_t = jnp.where(take, t_s, best_t)
        best_seg = jnp.where(take, s, best_seg)
        closer = dist < near_dist
        near_dist = jnp.where(closer, dist, near_dist)
        near_t = jnp.where(closer, t_clip, near_t)
        near_seg = jnp.where(closer, s, near_seg)
    any_valid = n_valid > 0
    t = jnp.where(any_valid, best_t, near_t)
    seg = jnp.where(any_valid, best_seg, near_seg)
    return t, seg, n_valid > 1, ~any_valid


def effect_groups(model: ComplianceModel):
    """Effect groups by torque dependence, with their coefficient slices."""
    out = {"none": [], "linear": [], "memoryless": [], "path": []}
    i = model.n_coef - model.n_effect
    for term in model.effect_terms:
        m = len(term.names())
        out[term.torque_kind].append((term, model.coef[i : i + m]))
        i += m
    return out


def _effect_parts(model: ComplianceModel, sig: Signals):
    """Eq. (26)'s twist minus the torque-free effect groups, and the torque gain of the groups
    linear in torque (`None` without any)."""
    effects = effect_groups(model)
    r = sig.twist
    for term, c in effects["none"]:
        r = r - term.columns(sig, None) @ c
    g = None
    for term, c in effects["linear"]:
        g = term.torque_gain(sig, c) if g is None else g + term.torque_gain(sig, c)
    return r, g


def _estimate_impl(model: ComplianceModel, sig: Signals):
    r, g = _effect_parts(model, sig)
    return invert_twist(model, sig, r, g)


def invert_twist(model: ComplianceModel, sig: Signals, r, g):
    """Eqs. (26)-(27) from the twist `r` less the torque-free effect groups and the linear
    groups' torque gain `g` ([`_effect_parts`][]); `model`'s torque-free and linear effect
    groups are not read again (the residual loop passes a model without them, so that one
    compiled inversion serves every structure that differs only in those groups)."""
    effects = effect_groups(model)
    hs = _base_h(model, sig)

    def solve(r_eff):
        t, seg, amb, unres = _piecewise(model, r_eff, hs, g)
        if effects["memoryless"]:
            t = _newton(model, t, seg, r_eff, hs, g, effects["memoryless"])
        return t, seg, amb, unres

    t, seg, amb, unres = solve(r)
    if effects["path"]:
        # Path-dependent terms (hysteresis) are driven by the torque being estimated, causally:
        # each sample's state and torque are solved together (implicitly, see `_path_states`),
        # then the whole record is inverted once more with the states removed.
        slope = model.k[seg] + (0.0 if g is None else g)
        for term, c in effects["memoryless"]:
            slope = slope + c[0] * term.value_and_slope(t)[1]
        # a segment the calibration left out has no compliance: use the largest one there
        slope = jnp.where(slope > 0, slope, jnp.max(model.k))
        z = _path_states(t, slope, sig.extras.get(SEGMENT_START), effects["path"])
        r_eff = r
        for (_, c), zi in zip(effects["path"], z):
            r_eff = r_eff - zi * c[0]
        t, seg, amb, unres = solve(r_eff)
    lo, hi = model.torque_range
    return TorqueEstimate(
        torque=t, segment=seg, in_range=(t >= lo) & (t <= hi), ambiguous=amb, unresolved=unres
    )


_estimate = eqx.filter_jit(_estimate_impl)

MIN_PATH_SLOPE = 0.05
"""Floor of the total slope $1 + \\sum_i (c_i/k)\\,\\partial z_i/\\partial T$ of a sample's
implicit equation (a hysteresis whose twist slope right after a reversal cancels the compliance
has no inverse there; the floor keeps the step bounded instead)."""


def _path_states(t0, slope, reset, terms):
    r"""Causal Dahl states of the torque being estimated, solved implicitly sample by sample.

    With the torque-free and memoryless parts inverted to $T^0_k$ and the local compliance
    $k_k = \partial\Delta\theta/\partial T$, sample $k$ solves
    $T_k + \sum_i a_i z_i(T_k) = T^0_k$, $a_i = c_i / k_k$, with the Dahl step
    $z_i(T) = z_{i,k-1} + \frac{T - T_{k-1}}{T_{h,i}}(1 - z_{i,k-1}\,s)$ on the side
    $s = \mathrm{sgn}(T_k - T_{k-1})$ - the same state the calibration computes from the
    estimate ([`hdjax.compliance.dahl_state`][]). The left side is piecewise linear and
    increasing in $T$ while the hysteresis slope stays below the compliance, so the side is
    found from its value at $T_{k-1}$ and the step is exact: an implicit (backward) step, stable
    for any loop gain, where an explicit one oscillates once $|a_i| / T_{h,i}$ exceeds 1.
    States restart at 0 where `reset` is set (a gap). **Returns:** one state array per term.
    """
    scales = [opaque(term.torque_scale) for term, _ in terms]  # as traced values round
    coefs = [c[0] for _, c in terms]
    reset = jnp.zeros(t0.shape, bool) if reset is None else jnp.asarray(reset).astype(bool)

    def _step(carry, x):
        zs, tp = carry
        t0k, kk, rs = x
        # a new segment starts with no memory and no step across the gap
        zs = tuple(jnp.where(rs, 0.0, z) for z in zs)
        tp = jnp.where(rs, t0k, tp)
        a = [c / kk for c in coefs]
        at_prev = tp + sum(ai * z for ai, z in zip(a, zs))
        s = jnp.where(t0k >= at_prev, 1.0, -1.0)
        gain = 1.0 + sum(ai * (1.0 - z * s) / th for ai, z, th in zip(a, zs, scales))
        tk = tp + (t0k - at_prev) / jnp.maximum(gain, MIN_PATH_SLOPE)
        zs = tuple(
            jnp.clip(z + (tk - tp) / th * (1.0 - z * s), -1.0, 1.0) for z, th in zip(zs, scales)
        )
        return (zs, tk), jnp.stack(zs)

    zero = jnp.zeros((), t0.dtype)
    init = (tuple(zero for _ in terms), t0[0])
    _, z = jax.lax.scan(_step, init, (t0, slope, reset))
    return [z[:, i] for i in range(len(terms))]


def _newton(model, t, seg, r, hs, g, terms):
    k = model.k
    span = model.rated_torque / 4.0
    h = hs[0]
    if model.per_segment:
        for s in range(1, len(hs)):
            h = jnp.where(seg == s, hs[s], h)
    g = jnp.zeros_like(t) if g is None else g

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


def estimate_torque(
    model: ComplianceModel, data: Recording | Signals, *, causal: bool = False
) -> TorqueEstimate:
    """Estimate the output torque from twist, current and angles (eqs. (26)-(27)).

    **Arguments:**

    - `model`: a calibrated [`hdjax.compliance.ComplianceModel`][].
    - `data`: a [`hdjax.Recording`][] (its `torque`, if any, is not used) or
      [`hdjax.compliance.Signals`][].
    - `causal`: estimate every sample from that sample and earlier ones only, as a controller
      computing one sample at a time does (the estimate `hdjax export`'s C code computes): the
      velocities are derived causally ([`hdjax.signals`][] with `causal=True`). The inversion
      itself is causal either way. Only for a `Recording` (`Signals` carry their velocities).

    **Returns:** a [`hdjax.compliance.TorqueEstimate`][] (torque and per-sample flags; see the
    module docstring for the segment rules).

    Raises [`hdjax.InversionError`][] when the calibrated compliance is not increasing in torque.
    """
    check_estimable(model)
    if isinstance(data, Recording):
        data = signals(data, model.joint, velocity=model.velocity, causal=causal)
    elif causal:
        raise ConfigError(
            "causal=True derives the velocities from a Recording; these Signals carry their "
            "velocities already (pass the Recording, or derive the Signals with "
            "hdjax.signals(..., causal=True))"
        )
    missing = [
        name
        for term in model.base_terms + model.effect_terms
        for name in (getattr(term, "name", None), getattr(term, "signal", None))
        if name is not None
        and name not in ("twist", "current", "theta_m", "theta_l", "omega_m", "omega_l")
        and name not in data.extras
    ]
    if missing:
        raise ModelMismatchError(
            f"the model uses column(s) {', '.join(sorted(set(missing)))} that the data lacks; "
            "supply them or use a model calibrated without them"
        )
    return _estimate(model, data)


def estimate_torque_arrays(model: ComplianceModel, sig: Signals) -> Float[Array, " n"]:
    """The torque alone, for use inside other jitted code (no Python-side checks)."""
    return _estimate(model, sig).torque


class SingleEstimate(NamedTuple):
    """One sample's estimate (see [`hdjax.compliance.TorqueEstimate`][] for the flags)."""

    torque: float
    segment: int
    in_range: bool
    ambiguous: bool
    unresolved: bool


_SINGLE_CACHE: dict[int, tuple[ComplianceModel, object]] = {}
_SINGLE_CACHE_SIZE = 8


def check_estimable(model: ComplianceModel) -> None:
    msg = check_invertible(model)
    if msg:
        raise InversionError(msg)
    if not calibrated_segments(model).any():
        raise InversionError("the model has no calibrated segment; calibrate it first")


def torque_estimator(model: ComplianceModel) -> Callable[[Float[Array, " 6"]], Float[Array, " 5"]]:
    """A compiled one-sample estimator specialised to `model` (checked once, here).

    **Returns:** a function of a float64 array `[twist, current, theta_m, theta_l, omega_m,
    omega_l]` returning the float64 array `[torque, segment, in_range, ambiguous, unresolved]`
    (flags as 0/1). One packed output keeps the call from Python at a few microseconds.
    Models whose terms read extra columns (e.g. `temperature`) are not supported here.
    """
    check_estimable(model)
    needs = {
        name
        for term in model.base_terms + model.effect_terms
        for name in (getattr(term, "name", None), getattr(term, "signal", None))
        if name is not None
    } - {"twist", "current", "theta_m", "theta_l", "omega_m", "omega_l"}
    if needs:
        raise ModelMismatchError(
            f"the one-sample estimator takes no extra columns, but the model uses "
            f"{', '.join(sorted(needs))}; use estimate_torque with Signals instead"
        )

    def one(x):
        sig = Signals(
            twist=x[0:1],
            current=x[1:2],
            theta_m=x[2:3],
            theta_l=x[3:4],
            omega_m=x[4:5],
            omega_l=x[5:6],
            extras={},
        )
        e = _estimate_impl(model, sig)
        f = lambda a: a[0].astype(jnp.float64)
        return jnp.stack(
            [f(e.torque), f(e.segment), f(e.in_range), f(e.ambiguous), f(e.unresolved)]
        )

    return jax.jit(one)


def estimate_torque_single(
    model: ComplianceModel,
    twist: float,
    current: float,
    theta_m: float,
    theta_l: float,
    omega_m: float,
    omega_l: float,
) -> SingleEstimate:
    """Estimate the torque of one sample (eqs. (26)-(27)) with low latency from Python.

    The compiled estimator of [`torque_estimator`][] is cached per model object (the last
    few models), so repeated calls cost one dispatch of a few microseconds.

    **Arguments:** `model` (calibrated), then the sample's twist [rad] (eq. (5)), current [A],
    angles [rad] and velocities [rad/s].

    **Returns:** a [`SingleEstimate`][] of Python scalars.
    """
    hit = _SINGLE_CACHE.get(id(model))
    if hit is None or hit[0] is not model:
        fn = torque_estimator(model)
        if len(_SINGLE_CACHE) >= _SINGLE_CACHE_SIZE:
            _SINGLE_CACHE.pop(next(iter(_SINGLE_CACHE)))
        _SINGLE_CACHE[id(model)] = (model, fn)
    else:
        fn = hit[1]
    out = np.asarray(
        fn(np.array([twist, current, theta_m, theta_l, omega_m, omega_l], dtype=np.float64))
    )
    return SingleEstimate(float(out[0]), int(out[1]), bool(out[2]), bool(out[3]), bool(out[4]))
