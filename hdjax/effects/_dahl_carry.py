r"""The Dahl state of a hysteresis term carried from one chunk of a record into the next.

A Dahl state ([`hdjax.effects.dahl_state`][]) has unbounded memory, so a record read in
chunks (a streamed calibration, a streamed estimate, the residual loop's chunked fits) gets the
state of one pass over the whole record only if each chunk starts from the state, and the
driver value (after the term's `play`, when it has one), that the previous chunk ended with.
[`DahlCarry`][] does that for every term
with a `dahl_driver` ([`is_sequential`][]): the torque-path `Hysteresis` and the twist-driven
`TwistHysteresis` (what the residual loop adds) alike, restarting wherever `SEGMENT_START` is
set, exactly as on the whole record.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._features import Signals
from ._base import SEGMENT_START
from ._hysteresis import _affine_recurrence, after_play


def is_sequential(term) -> bool:
    """Whether a term's column carries a state from sample to sample (a Dahl state)."""
    return hasattr(term, "dahl_driver")


@jax.jit
def _dahl_scan_from(du, reset, z0):
    # the scan of hdjax.effects.dahl_state, started from a carried state
    def _step(z, x):
        d, rs = x
        z, d = jnp.where(rs, 0.0, z), jnp.where(rs, 0.0, d)
        z = jnp.clip(z + d * (1.0 - z * jnp.sign(d)), -1.0, 1.0)
        return z, z

    return jax.lax.scan(_step, z0, (du, reset))


def _dahl_numpy_from(du: np.ndarray, reset: np.ndarray, z0: float) -> np.ndarray:
    # hdjax.effects.dahl_state_numpy's affine recurrence, entered with the state z0
    ad = np.abs(du)
    small = ad < 1.0
    a = np.where(small, 1.0 - ad, 0.0)
    b = np.where(small, du, np.sign(du))
    a[reset], b[reset] = 0.0, 0.0
    b[0] += a[0] * z0
    return np.clip(_affine_recurrence(a, b), -1.0, 1.0)


class DahlCarry:
    """The Dahl state of sequential columns carried from chunk to chunk.

    `column(key, term, sig, torque, rows, numpy)` gives rows `:rows` of the term's state over a
    chunk (`sig`, `torque` the chunk's, possibly padded), started from the state and driver
    value the previous chunk of the same `key` ended with (at the record's start: state 0 and
    no step, as [`hdjax.effects.dahl_state`][]); it restarts wherever `SEGMENT_START` is set.
    `numpy` follows [`hdjax.effects.dahl_state_numpy`][] (candidates' columns), else the
    compiled scan (the model's design). A new pass over the record needs a new carry.
    """

    def __init__(self) -> None:
        self.state: dict = {}
        self.history: dict = {}

    def _driver(self, key, term, sig: Signals, torque, rows: int) -> np.ndarray:
        # a driver that reads samples before its own (`lookback`, the hysteresis aligned at
        # an encoder skew) reads them from the previous chunk's last own rows, as on the
        # whole record; at the record's start there are none
        back = getattr(term, "lookback", 0)
        past = self.history.get(key)
        if back:
            self.history[key] = jax.tree_util.tree_map(lambda x: x[max(0, rows - back) : rows], sig)
        if not back or past is None:
            return np.asarray(term.dahl_driver(sig, torque), np.float64)
        h = past.n_samples
        joined = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), past, sig)
        return np.asarray(term.dahl_driver(joined, None), np.float64)[h:]

    def column(self, key, term, sig: Signals, torque, rows: int, numpy: bool) -> np.ndarray:
        driver = self._driver(key, term, sig, torque, rows)
        reset = sig.extras.get(SEGMENT_START)
        reset = np.zeros(driver.shape, bool) if reset is None else np.asarray(reset) != 0
        z0, prev = self.state.get(key, (0.0, None))
        driver = after_play(term, driver, reset, prev)  # its output carried as `prev`
        prev = driver[0] if prev is None else prev
        du = np.diff(driver[:rows], prepend=prev) / term.torque_scale
        r = reset[:rows]
        if numpy:
            z = _dahl_numpy_from(du, r.copy(), z0)
        else:
            size = driver.shape[0]
            pad = size - rows  # zero steps without reset leave the state unchanged
            _, zs = _dahl_scan_from(
                jnp.asarray(np.r_[du, np.zeros(pad)]),
                jnp.asarray(np.r_[r, np.zeros(pad, bool)]),
                jnp.asarray(z0, jnp.float64),
            )
            z = np.asarray(zs)[:rows]
        self.state[key] = (float(z[-1]), float(driver[rows - 1]))
        if getattr(term, "lag", False):
            # one sample late (the column excludes the sample it explains): the state the
            # previous chunk ended with at this chunk's first sample, 0 where a restart is
            first = 0.0 if r[0] else z0
            z = np.where(r, 0.0, np.r_[first, z[:-1]])
        return z
