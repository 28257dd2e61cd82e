r"""The residual loop's design chunk by chunk: memory bounded by the chunk, not the record.

With `DiscoverOptions.chunk > 0` no $n \times p$ design (Song et al. eq. (15)) of the whole
training record is formed. Every least-squares quantity the loop needs is a sum over rows,
so it is accumulated over chunks of `chunk` samples: the calibration's normal equations and
refinement ([`hdjax.compliance._stream_fit.calibrate_chunks`][]), the per-fold Gram matrices
of cross-validation (each row adds to its fold's; folds are unions of contiguous blocks), the
per-block statistics that score the candidates, and the Gram matrix and projections of the
amplitude intervals.

The signals themselves (velocities that never cross a gap, the `SEGMENT_START` marker) are
derived once for the whole record ([`hdjax.discover.pipeline_signals`][]), so a chunk's rows
of every memoryless column are those of the whole record. A *sequential* column, a Dahl
hysteresis state (any term with a `dahl_driver`), carries its state and the last driver value
from the end of one chunk into the next ([`DahlCarry`][]), and restarts at a gap exactly as
on the whole record: a chunk's columns equal the whole record's rows to rounding.
"""

from __future__ import annotations

from collections.abc import Iterator

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Float
from .._errors import ConfigError
from .._features import Signals
from ..compliance import ComplianceModel
from ..compliance.internal import MIN_CHUNK, compact_column_list, design_columns
from ..effects.internal import BACK_SAMPLES, DahlCarry, is_sequential as sequential


def check_chunk(chunk, where: str = "discover chunk") -> int:
    """`chunk` as an int: 0 (the whole record at once) or at least `MIN_CHUNK` samples;
    otherwise a ConfigError that names `where`."""
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)):
        raise ConfigError(
            f"{where} must be an integer number of samples (0: the whole record at once), "
            f"got {chunk!r}"
        )
    if chunk != 0 and chunk < MIN_CHUNK:
        raise ConfigError(
            f"{where} must be 0 (the whole record at once) or at least {MIN_CHUNK} samples, "
            f"got {chunk}"
        )
    return int(chunk)


def chunk_bounds(n: int, chunk: int) -> list[tuple[int, int]]:
    """`(lo, hi)` of consecutive chunks of `chunk` rows (the last one shorter)."""
    return [(lo, min(lo + chunk, n)) for lo in range(0, n, chunk)]


def _pad(x, rows: int, size: int):
    """The first `rows` rows of `x`, the last one repeated up to `size` rows (one compiled
    shape for every chunk; the padding rows are never read)."""
    x = jnp.asarray(x)
    return x if rows == size else jnp.concatenate([x, jnp.repeat(x[-1:], size - rows, axis=0)])


def slice_signals(sig: Signals, lo: int, hi: int, size: int) -> Signals:
    """Rows `lo:hi` of every signal, padded to `size` rows."""
    return jax.tree_util.tree_map(lambda x: _pad(x[lo:hi], hi - lo, size), sig)


LOOKBACK = BACK_SAMPLES + 1
"""Rows before its own that a chunk's signals carry (a halo): the most samples back that a
column reads (an encoder skew's interpolation, a rate one sample late), so a chunk's columns
equal the whole record's rows."""


def own_rows(x, h: int):
    """A chunk's signals (or torque) without their `h` halo rows."""
    return None if x is None else jax.tree_util.tree_map(lambda a: a[h:], x)


def dahl_chunked(
    term, sig: Signals, torque, chunk: int, *, numpy: bool = False
) -> Float[np.ndarray, " n"]:
    """A sequential term's column over a whole record, computed `chunk` samples at a time with
    the state carried (equals `term.columns(sig, torque)[:, 0]` to rounding)."""
    n = sig.n_samples
    carry = DahlCarry()
    out = []
    for lo, hi in chunk_bounds(n, chunk):
        sc = slice_signals(sig, lo, hi, min(chunk, n))
        tc = None if torque is None else _pad(jnp.asarray(torque)[lo:hi], hi - lo, min(chunk, n))
        out.append(carry.column(0, term, sc, tc, hi - lo, numpy))
    return np.concatenate(out)


def _sequential_positions(model: ComplianceModel, first: int) -> list[tuple[int, object]]:
    """`(column, term)` of each sequential effect term, its columns starting at `first`."""
    out, i = [], first
    for term in model.effect_terms:
        m = len(term.names())
        if sequential(term):
            if m != 1:
                raise ConfigError(
                    f"discover chunk: the sequential term {term.key!r} has {m} columns; only "
                    "one-column Dahl states are carried across chunks (set chunk = 0)"
                )
            out.append((i, term))
        elif term.torque_kind == "path":
            raise ConfigError(
                f"discover chunk: no way to carry the state of the path-dependent term "
                f"{term.key!r} across chunks; set chunk = 0"
            )
        i += m
    return out


def _compiled_design(model: ComplianceModel, sig: Signals, torque) -> np.ndarray:
    return np.asarray(design_columns(model, sig, torque))


class Chunks:
    """A record's rows chunk by chunk: signals (with an optional hysteresis driver), reference
    torque, and the model's design rows with sequential states carried.

    **Arguments:** `sig` (the whole record's signals), `torque` (reference), `chunk` (rows),
    `design` (`design(model, sig, torque)`, a chunk's design matrix as a NumPy array; default
    the model's compiled design).
    """

    def __init__(self, sig: Signals, torque, chunk: int, design=None):
        self.design = _compiled_design if design is None else design
        self.sig = sig
        self.torque = np.asarray(torque, np.float64)
        self.n = int(self.torque.size)
        self.chunk = int(chunk)
        self.size = min(self.chunk, self.n)
        self.bounds = chunk_bounds(self.n, self.chunk)

    def signals(self) -> Iterator[tuple[int, int, Signals, jax.Array, int]]:
        """`(lo, hi, signals, torque, h)` of each chunk: its rows with `h` rows of halo before
        them (`LOOKBACK`, fewer at the record's start), padded to one length."""
        torque = jnp.asarray(self.torque)
        size = self.size + LOOKBACK
        for lo, hi in self.bounds:
            h = min(LOOKBACK, lo)
            yield (
                lo,
                hi,
                slice_signals(self.sig, lo - h, hi, size),
                _pad(torque[lo - h : hi], hi - lo + h, size),
                h,
            )

    def rows(self, model: ComplianceModel) -> Iterator[tuple]:
        """`(lo, hi, signals, torque, A, h)`: each chunk's signals (padded, with `h` halo rows
        first) and the full design's rows `lo:hi` (eq. (15)), `(hi - lo, p)`."""
        seq = _sequential_positions(model, model.n_coef - model.n_effect)
        carry = DahlCarry()
        for lo, hi, sc, tc, h in self.signals():
            a = np.array(self.design(model, sc, tc)[h : h + hi - lo])
            for col, term in seq:
                a[:, col] = carry.column(
                    col, term, own_rows(sc, h), own_rows(tc, h), hi - lo, numpy=False
                )
            yield lo, hi, sc, tc, a, h

    def designs(self, model: ComplianceModel) -> Iterator[tuple[int, int, np.ndarray]]:
        """`(lo, hi, A)`: the full design's rows `lo:hi` (eq. (15)), `(hi - lo, p)`."""
        for lo, hi, _, _, a, _ in self.rows(model):
            yield lo, hi, a

    def compact_passes(self, model: ComplianceModel):
        """A callable that starts a pass over the chunks, as
        [`hdjax.compliance._stream_fit.calibrate_chunks`][] reads them: `(x, b, torque, seg)`,
        the compact columns (`q x rows`) with the sequential states carried, the twist, the
        reference torque and the segment index."""
        seq = _sequential_positions(model, model.n_segments + model.n_base)

        def passes():
            carry = DahlCarry()
            for lo, hi, sc, tc, h in self.signals():
                cols, seg = compact_column_list(model, sc, tc)
                rows = hi - lo
                x = np.stack([np.asarray(c)[h : h + rows] for c in cols])
                for col, term in seq:
                    x[col] = carry.column(
                        col, term, own_rows(sc, h), own_rows(tc, h), rows, numpy=False
                    )
                twist = np.asarray(sc.twist)[h : h + rows]
                yield x, twist, self.torque[lo:hi], np.asarray(seg)[h : h + rows]

        return passes


def twist_residual(model: ComplianceModel, chunks: Chunks, coef=None) -> Float[np.ndarray, " n"]:
    """The twist residual $y - A\\beta$ (Song et al. eq. (15)) over the record, the design
    formed chunk by chunk."""
    coef = np.asarray(model.coef if coef is None else coef)
    out = np.empty(chunks.n)
    y = np.asarray(chunks.sig.twist)
    for lo, hi, a in chunks.designs(model):
        out[lo:hi] = y[lo:hi] - a @ coef
    return out
