r"""The fused chunk step of [`hdjax.compliance.calibrate_stream`][] for the paper's velocity.

With the backward-difference velocity (Song et al. eqs. (13)-(14)) a chunk needs one sample of
halo and nothing after it, so every window has the same length (`chunk + 1`, the tail padded)
and one compiled XLA program per pass does the whole chunk: signals, compact columns, the Dahl
state of hysteresis terms (from the carried state), and the per-segment blocks of
$A^\top A$, $A^\top b$ (pass 1) or of $A^\top (b - Ax)$ (pass 2). A weight $w$ (1 on the
chunk's own rows, 0 on the halo and the padding) keeps the sums to the chunk's rows.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._lstsq import _compact_index
from ._signals import signals_from_recording
from ._terms import TORQUE_PATH


def fast_path_supported(model) -> bool:
    """Backward-difference velocity, and path terms only of the Dahl kind (one column)."""
    paths = [t for t in model.effect_terms if t.torque_kind == "path"]
    ok = all(hasattr(t, "torque_scale") and len(t.names()) == 1 for t in paths)
    return model.velocity == "difference" and ok


def _dahl(du, z0):
    def _step(z, d):
        z = jnp.clip(z + d * (1.0 - z * jnp.sign(d)), -1.0, 1.0)
        return z, z

    return jax.lax.scan(_step, z0, du)


def _columns(model, win, w, z0s):
    """Compact columns (n x q), twist, torque, segment, and the path states at the end."""
    sig = signals_from_recording(win, model.ratio, model.twist_sign, velocity="difference")
    torque = win.torque
    cols = [jnp.clip(torque, lo, hi) - min(max(0.0, lo), hi) for lo, hi in model.segment_bounds]
    cols += model.base_column_list(sig)
    z_ends, k = [], 0
    last_row = jnp.max(jnp.where(w > 0, jnp.arange(w.shape[0]), 0))
    for term in model.effect_terms:
        if term.torque_kind == "path":
            driver = sig.extras.get(TORQUE_PATH, torque)
            # the state z and the driver value before this window are carried (NaN: none yet,
            # as at the very start); halo and padding rows (w = 0) leave the state unchanged
            z0, prev = z0s[k, 0], z0s[k, 1]
            prev = jnp.where(jnp.isnan(prev), driver[0], prev)
            du = jnp.diff(driver, prepend=prev[None]) * w / term.torque_scale
            z_end, z = _dahl(du, z0)
            z_ends.append(jnp.stack([z_end, driver[last_row]]))
            cols.append(z)
            k += 1
            continue
        block = term.columns(sig, torque)
        cols += [block[:, j] for j in range(block.shape[1])]
    c = jnp.stack(cols, axis=1)
    return c, sig.twist, torque, model.segment_index(torque), jnp.stack(z_ends) if z_ends else z0s


def _masks(model, w, seg):
    if not model.per_segment:
        return [w]
    return [w * (seg == s).astype(w.dtype) for s in range(model.n_segments)]


@eqx.filter_jit
def gram_step(model, win, w, z0s):
    """Pass 1 on one window: `(G, A^T b, b^T b, counts, torque min, torque max, z_end)`."""
    c, b, torque, seg, z_end = _columns(model, win, w, z0s)
    p = model.n_coef
    g = jnp.zeros((p, p), c.dtype)
    atb = jnp.zeros((p,), c.dtype)
    for idx, m in zip(_compact_index(model), _masks(model, w, seg)):
        cm = c * m[:, None]
        g = g.at[np.ix_(idx, idx)].add(cm.T @ c)
        atb = atb.at[idx].add(cm.T @ b)
    n_seg = model.n_segments
    in_seg = [(seg == s) & (w > 0) for s in range(n_seg)]
    counts = jnp.stack([jnp.sum(m) for m in in_seg])
    t_lo = jnp.stack([jnp.min(jnp.where(m, torque, jnp.inf)) for m in in_seg])
    t_hi = jnp.stack([jnp.max(jnp.where(m, torque, -jnp.inf)) for m in in_seg])
    return g, atb, jnp.sum(w * b * b), counts, t_lo, t_hi, z_end


@eqx.filter_jit
def refine_step(model, win, w, z0s, coef):
    r"""Pass 2 on one window: `(A^T r, r^T r, z_end)` with $r = b - Ax$."""
    c, b, _, seg, z_end = _columns(model, win, w, z0s)
    blocks = list(zip(_compact_index(model), _masks(model, w, seg)))
    fit = sum(m * (c @ coef[idx]) for idx, m in blocks)
    r = w * b - fit
    atr = jnp.zeros((model.n_coef,), c.dtype)
    for idx, m in blocks:
        atr = atr.at[idx].add((c * m[:, None]).T @ r)
    return atr, jnp.sum(r * r), z_end
