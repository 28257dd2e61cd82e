r"""The fused chunk step of [`hdjax.compliance.calibrate_stream`][] for the paper's velocity.

With the backward-difference velocity (Song et al. eqs. (13)-(14)) a chunk needs one sample of
halo and nothing after it, so every window has the same length (`chunk + 1`, the tail padded)
and one compiled XLA program does the whole chunk's signals, compact columns and the Dahl
state of hysteresis terms (from the carried state; a weight $w$, 1 on the chunk's own rows and
0 on the halo and the padding, keeps the state to the chunk's rows). The sums of
$A^\top A$, $A^\top b$ and $A^\top (b - Ax)$ are left to NumPy's BLAS, which on CPU is
faster than XLA's dot for a long contraction (measured 2-6x).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ..effects.internal import after_play, is_sequential
from ._signals import signals_from_recording


def fast_path_supported(model) -> bool:
    """Backward-difference velocity, and path terms only of the Dahl kind (one column) whose
    driver reads no sample before the window's one-sample halo (`lookback`)."""
    paths = [t for t in model.effect_terms if t.torque_kind == "path" or is_sequential(t)]
    ok = all(
        is_sequential(t) and len(t.names()) == 1 and not getattr(t, "lookback", 0) for t in paths
    )
    return model.velocity == "difference" and ok


def _dahl(du, z0):
    def _step(z, d):
        z = jnp.clip(z + d * (1.0 - z * jnp.sign(d)), -1.0, 1.0)
        return z, z

    return jax.lax.scan(_step, z0, du)


@eqx.filter_jit
def fused_columns(model, win, w, z0s):
    """One window's compact columns (separate 1-D arrays: XLA on CPU stacks columns slowly,
    NumPy does it), twist, torque, segment index, and the path states at its end."""
    sig = signals_from_recording(win, model.ratio, model.twist_sign, velocity="difference")
    torque = win.torque
    cols = [jnp.clip(torque, lo, hi) - min(max(0.0, lo), hi) for lo, hi in model.segment_bounds]
    cols += model.base_column_list(sig)
    z_ends, k = [], 0
    last_row = jnp.max(jnp.where(w > 0, jnp.arange(w.shape[0]), 0))
    for term in model.effect_terms:
        if is_sequential(term):
            # the Dahl state of the term's own driver: the torque path (`Hysteresis`, the
            # signal TORQUE_PATH when present) or the measured twist (`TwistHysteresis`)
            driver = term.dahl_driver(sig, torque)
            # the state z and the driver value before this window are carried (NaN: none yet,
            # as at the very start); halo and padding rows (w = 0) leave the state unchanged
            z0, prev = z0s[k, 0], z0s[k, 1]
            prev = jnp.where(jnp.isnan(prev), driver[0], prev)
            # the driver after its play (TwistHysteresis), from the play's output carried as
            # the driver value: the halo row is the previous window's last, within the band of
            # that value, so the play holds it there
            driver = after_play(term, driver, None, prev)
            du = jnp.diff(driver, prepend=prev[None]) * w / term.torque_scale
            z_end, z = _dahl(du, z0)
            z_ends.append(jnp.stack([z_end, driver[last_row]]))
            if getattr(term, "lag", False):  # one sample late (TwistHysteresis' column)
                z = jnp.concatenate([z0[None], z[:-1]])
            cols.append(z)
            k += 1
            continue
        block = term.columns(sig, torque)
        cols += [block[:, j] for j in range(block.shape[1])]
    z_end = jnp.stack(z_ends) if z_ends else z0s
    return cols, sig.twist, torque, model.segment_index(torque), z_end
