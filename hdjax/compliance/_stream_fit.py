r"""Calibration streamed chunk by chunk: Song et al. eqs. (15)-(17) with memory bounded by a chunk.

[`calibrate_stream`][] gives the coefficients of [`hdjax.compliance.calibrate_lstsq`][] (the same
column-scaled corrected semi-normal equations, or QR when the design is ill-conditioned) from
a [`RecordingStream`][]: recordings held in memory, or files read chunk by chunk
([`hdjax._formats.iter_recordings`][]). Two passes over the data: the first accumulates the
Gram matrix ([`hdjax.compliance.NormalEquations`][]), the second (only when the scaled
condition number exceeds `REFINE_ABOVE_COND`) the refinement $A^\top (b - Ax)$ or, for an
ill-conditioned design, the QR factor ([`hdjax.compliance.StreamingQR`][]).

Sequential signals are computed as in one pass: each chunk is read with a halo of samples of
its neighbours (one before for the paper's backward-difference velocity, eqs. (13)-(14); the
half window on both sides for the smoothed velocity), and the Dahl hysteresis state of a
path-dependent term carries from the end of one chunk to the start of the next, as does the
torque it differences.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import PathLike
from .._errors import CalibrationError, DataError
from .._formats import iter_recordings
from .._io import ColumnMap
from .._recording import Recording
from .._solution import Solution
from ..effects.internal import DahlCarry, is_sequential
from ._lstsq import (
    CSNE_MAX_COND,
    _compact_index,
    calibration_solution,
    check_sample_count,
    constrain_shape,
    select_active_counts,
    solve_from_r,
)
from ._model import ComplianceModel
from ._shape import ShapeData
from ._signals import signals_from_recording
from ._stream import NormalEquations, StreamingQR, scaled_cholesky
from ._stream_fast import fast_path_supported, fused_columns

REFINE_ABOVE_COND = 1e3
r"""The refinement pass over the data runs only above this scaled condition number $\kappa$:
below it the semi-normal equations alone are accurate to $\kappa^2 u \le 2.2\cdot10^{-10}$
relative (Bjorck 1987), well inside the $10^{-9}$ agreement with the in-memory fit, and the
log is read once instead of twice."""

SMOOTH_HALF_WINDOW = 5
"""Half window of the smoothed velocity (the default of `signals_from_recording`)."""


class RecordingStream:
    """Recordings delivered as chunks, re-iterable (a streaming fit passes over them twice).

    Iterating gives, for each recording in turn, an iterator of its consecutive chunks (each a
    [`hdjax.Recording`][]). Build one with [`RecordingStream.from_recordings`][] or
    [`RecordingStream.from_files`][].
    """

    def __init__(self, opener: Callable[[], Iterable[Iterable[Recording]]], label: str = ""):
        self.opener = opener
        self.label = label

    def __iter__(self) -> Iterator[Iterable[Recording]]:
        return iter(self.opener())

    @classmethod
    def from_recordings(
        cls, recordings: Recording | Iterable[Recording], chunk: int
    ) -> RecordingStream:
        """In-memory recordings cut into chunks of `chunk` samples."""
        recs = [recordings] if isinstance(recordings, Recording) else list(recordings)
        _check_chunk(chunk)

        def cut(rec):
            return (rec.select(slice(i, i + chunk)) for i in range(0, rec.n_samples, chunk))

        return cls(lambda: (cut(r) for r in recs), ", ".join(r.source for r in recs))

    @classmethod
    def from_files(
        cls,
        paths: PathLike | Iterable[PathLike],
        columns: ColumnMap | None = None,
        *,
        chunk: int,
        check_units: bool = True,
    ) -> RecordingStream:
        """Log files (any format of `hdjax.load_recording`) read `chunk` samples at a time."""
        paths = [paths] if isinstance(paths, str) or hasattr(paths, "suffix") else list(paths)
        _check_chunk(chunk)

        def opener():
            return (
                iter_recordings(p, columns, chunk=chunk, check_units=check_units) for p in paths
            )

        return cls(opener, ", ".join(str(p) for p in paths))


MIN_CHUNK = 16
"""The fewest samples a chunk of a streamed fit may hold (0 means: no chunks)."""


def _check_chunk(chunk) -> None:
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < MIN_CHUNK:
        raise DataError(f"chunk must be an integer of at least {MIN_CHUNK} samples, got {chunk!r}")


def peak_abs(stream: RecordingStream, column: str = "current") -> float:
    """The largest |value| of a column over a stream (for `current_scale = "auto"`)."""
    peak = 0.0
    for chunks in stream:
        for c in chunks:
            peak = max(peak, float(np.max(np.abs(np.asarray(c.column(column))))))
    return peak


# ---------------------------------------------------------------------------------------------
# Windows: a chunk with its halo, as one recording


def recording_arrays(rec: Recording, need_torque: bool = True) -> dict[str, np.ndarray]:
    out = {k: np.asarray(getattr(rec, k)) for k in ("t", "theta_m", "theta_l", "current")}
    if rec.torque is None:
        if need_torque:
            raise DataError(
                f"{rec.source}: calibration needs a reference 'torque' column (a torque sensor "
                "or another reference); the recording has none"
            )
    else:
        out["torque"] = np.asarray(rec.torque)
    out.update({f"x:{k}": np.asarray(v) for k, v in rec.extras.items()})
    return out


def recording_from_arrays(cols: dict[str, np.ndarray], source: str) -> Recording:
    j = lambda k: jnp.asarray(cols[k])
    return Recording(
        t=j("t"),
        theta_m=j("theta_m"),
        theta_l=j("theta_l"),
        current=j("current"),
        torque=j("torque") if "torque" in cols else None,
        extras={k[2:]: j(k) for k in cols if k.startswith("x:")},
        source=source,
    )


def _pad(cols: dict[str, np.ndarray], length: int) -> dict[str, np.ndarray]:
    """Extend to `length` rows after the end (time continued, values held): rows a backward
    difference never looks at from the real ones."""
    n = cols["t"].shape[0]
    k = length - n
    if k <= 0:
        return cols
    t = cols["t"]
    dt = t[-1] - t[-2] if n > 1 else 1.0
    out = {name: np.concatenate([v, np.full(k, v[-1])]) for name, v in cols.items()}
    out["t"] = np.concatenate([t, t[-1] + dt * np.arange(1, k + 1)])
    return out


def windows(
    stream: RecordingStream,
    before: int,
    after: int,
    pad_to: int | None,
    *,
    need_torque: bool = True,
):
    """`(window, lo, hi)`: each chunk with up to `before` / `after` samples of its neighbours
    in the same recording; rows `lo:hi` of `window` are the chunk's own. A recording without
    a reference torque is refused unless `need_torque` is false (an estimate needs none)."""
    for chunks in stream:
        it = iter(chunks)
        cur_rec = next(it, None)
        cur = None if cur_rec is None else recording_arrays(cur_rec, need_torque)
        prev = None
        while cur is not None:
            nxt_rec = next(it, None)
            nxt = None if nxt_rec is None else recording_arrays(nxt_rec, need_torque)
            parts, lo = [], 0
            if prev is not None and before:
                parts.append({k: v[-before:] for k, v in prev.items()})
                lo = parts[0]["t"].shape[0]
            parts.append(cur)
            if nxt is not None and after:
                parts.append({k: v[:after] for k, v in nxt.items()})
            win = {k: np.concatenate([p[k] for p in parts]) for k in cur}
            hi = lo + cur["t"].shape[0]
            if pad_to is not None:
                win = _pad(win, pad_to)
            yield recording_from_arrays(win, cur_rec.source), lo, hi
            prev, cur, cur_rec = cur, nxt, nxt_rec


# ---------------------------------------------------------------------------------------------
# Columns of one window


@eqx.filter_jit
def _window_columns(model: ComplianceModel, sig, torque):
    """Compact columns (hinges, base, effects; `None` for path terms) and each row's segment."""
    cols = [jnp.clip(torque, lo, hi) - min(max(0.0, lo), hi) for lo, hi in model.segment_bounds]
    cols += model.base_column_list(sig)
    for term in model.effect_terms:
        if term.torque_kind == "path" or is_sequential(term):
            cols += [None] * len(term.names())  # carried across chunks: `_PathState`
            continue
        block = term.columns(sig, torque)
        cols += [block[:, j] for j in range(block.shape[1])]
    return cols, model.segment_index(torque)


def _carried(model: ComplianceModel) -> list:
    """The effect terms whose column carries a state across chunks: every Dahl state, of the
    torque path (`Hysteresis`) or of the measured twist (`TwistHysteresis`); a path term
    without one is refused."""
    out = []
    for t in model.effect_terms:
        if not (t.torque_kind == "path" or is_sequential(t)):
            continue
        if not is_sequential(t) or len(t.names()) != 1:
            raise CalibrationError(
                f"streaming calibration does not know how to carry the state of the "
                f"path-dependent term {t.key!r}; calibrate in memory (fit.chunk = 0)"
            )
        out.append(t)
    return out


class _PathState:
    """The carried Dahl state of each sequential term ([`hdjax.effects._dahl_carry`][])."""

    def __init__(self, model: ComplianceModel):
        self.terms = _carried(model)
        self.carry = DahlCarry()

    def columns(self, sig, torque, lo: int, hi: int) -> list[np.ndarray]:
        """Each sequential term's state over a window's own rows `lo:hi` (its halo left out)."""
        own = jax.tree_util.tree_map(lambda x: x[lo:], sig)
        torque = jnp.asarray(torque)[lo:]
        return [
            self.carry.column(i, term, own, torque, hi - lo, numpy=False)
            for i, term in enumerate(self.terms)
        ]


def _chunk_design(model, win, lo, hi, paths: _PathState):
    """`(x, b, torque, seg)`: compact columns (q x rows) of a window's own rows."""
    sig = signals_from_recording(win, model.ratio, model.twist_sign, velocity=model.velocity)
    cols, seg = _window_columns(model, sig, win.torque)
    path_cols = iter(paths.columns(sig, win.torque, lo, hi)) if paths.terms else None
    x = np.stack([next(path_cols) if c is None else np.asarray(c)[lo:hi] for c in cols])
    b = np.asarray(sig.twist)[lo:hi]
    return x, b, np.asarray(win.torque)[lo:hi], np.asarray(seg)[lo:hi]


def _blocks(model, x, seg):
    """`(columns, rows)` of each segment's block (or the one shared block)."""
    idx = _compact_index(model)
    if not model.per_segment:
        return [(idx[0], slice(None))]
    return [(i, np.flatnonzero(seg == s)) for s, i in enumerate(idx)]


def _passes(model, stream, chunk):
    """Iterate `(x, b, torque, seg)` over every chunk of the stream, path states carried."""
    if fast_path_supported(model):
        yield from _fused_passes(model, stream, chunk)
        return
    smoothed = model.velocity == "smoothed"
    before = SMOOTH_HALF_WINDOW if smoothed else 1
    after = SMOOTH_HALF_WINDOW if smoothed else 0
    paths = _PathState(model)
    pad = None if smoothed else chunk + before
    for win, lo, hi in windows(stream, before, after, pad):
        yield _chunk_design(model, win, lo, hi, paths)


def _fused_passes(model, stream, chunk):
    """`_passes` for the backward-difference velocity: windows of one length (`chunk + 1`),
    each in one compiled program ([`fused_columns`][]), the Dahl states carried in it."""
    n_paths = len(_carried(model))
    z = jnp.asarray(np.tile([0.0, np.nan], (max(n_paths, 1), 1)))  # (state, last driver)
    for win, lo, hi in windows(stream, 1, 0, chunk + 1):
        w = np.zeros(win.t.shape[0])  # chunk + 1, or more for a file's folded one-row tail
        w[lo:hi] = 1.0
        cols, b, tq, seg, z = fused_columns(model, win, jnp.asarray(w), z)
        x = np.stack([np.asarray(c)[lo:hi] for c in cols])
        yield x, np.asarray(b)[lo:hi], np.asarray(tq)[lo:hi], np.asarray(seg)[lo:hi]


# ---------------------------------------------------------------------------------------------


def calibrate_stream(
    model: ComplianceModel, stream: RecordingStream, *, chunk: int, throw: bool = True
) -> Solution:
    """Calibrate by linear least squares from a stream of chunks (Song et al. eqs. (15)-(17)).

    **Arguments:**

    - `model`: the structure to calibrate (coefficients are ignored).
    - `stream`: a [`RecordingStream`][] of recordings with a reference torque, cut into chunks
      of at most `chunk` samples.
    - `chunk`: the chunk length the stream delivers (fixes the compiled shapes).
    - `throw`: as in [`hdjax.compliance.calibrate_lstsq`][].

    **Returns:** the [`hdjax.Solution`][] `calibrate_lstsq` gives on the concatenated
    recordings; memory is bounded by the chunk, not the log.
    """
    t0 = time.perf_counter()
    _check_chunk(chunk)
    return calibrate_chunks(
        model, lambda: _passes(model, stream, chunk), label=stream.label, throw=throw, t0=t0
    )


def calibrate_chunks(
    model: ComplianceModel,
    passes: Callable[[], Iterable[tuple]],
    *,
    label: str,
    throw: bool = True,
    refine_above: float = REFINE_ABOVE_COND,
    t0: float | None = None,
    monotone: bool = True,
) -> Solution:
    """[`calibrate_stream`][] from design chunks (Song et al. eqs. (15)-(17)).

    `passes()` starts a pass over the data: an iterator of `(x, b, torque, seg)` per chunk,
    `x` the compact columns (`q x rows`, as `compact_column_list` orders them), `b` the twist,
    `torque` the reference torque and `seg` each row's torque segment. The refinement pass
    runs above the scaled condition number `refine_above` (0: always, as
    [`hdjax.compliance.calibrate_lstsq`][] does); `monotone` as there (the shape constraint's
    data accumulated in the first pass).
    """
    t0 = time.perf_counter() if t0 is None else t0
    n_seg, p = model.n_segments, model.n_coef
    ne = NormalEquations(p)
    counts = np.zeros(n_seg, dtype=np.int64)
    t_lo, t_hi = np.full(n_seg, np.inf), np.full(n_seg, -np.inf)
    shape = ShapeData(model)
    # -- pass 1: Gram matrix, segment counts, torque ranges, the shape constraint's data ----
    for x, b, tq, seg in passes():
        for idx, rows in _blocks(model, x, seg):
            ne.add(x[:, rows], b[rows], idx)
        ne.add_rhs(b)
        shape.add(x, b, tq)
        cnt = np.bincount(seg, minlength=n_seg)
        counts += cnt
        for s_ in np.flatnonzero(cnt):
            sel = tq[seg == s_]
            t_lo[s_], t_hi[s_] = min(t_lo[s_], sel.min()), max(t_hi[s_], sel.max())
    g, atb, btb, n = ne.total()
    if n == 0:
        raise DataError(f"{label}: the stream holds no samples")
    active, counts_t, dropped = select_active_counts(model, np.diag(g) > 0, counts)
    n_act = int(active.sum())
    check_sample_count(n, n_act)
    collinear: tuple = ()

    def residual_pass(x):
        # A^T (b - A x) and |b - A x|^2 over one pass (a refinement with the true residual)
        atr, rss_x = np.zeros(p), 0.0
        for xc, b, _, seg in passes():
            r = np.array(b, copy=True)
            blocks = _blocks(model, xc, seg)
            for idx, rows in blocks:
                r[rows] -= x[idx] @ xc[:, rows]
            for idx, rows in blocks:
                atr[idx] += xc[:, rows] @ r[rows]
            rss_x += float(r @ r)
        return atr, rss_x

    csne = scaled_cholesky(g, atb, active, CSNE_MAX_COND)
    # -- pass 2: refinement with the true residual, or the QR factor ------------------------
    if csne is not None and csne[1] <= refine_above:
        # well conditioned: the semi-normal equations are already accurate to kappa^2 u
        coef, cond, _ = csne
        rss = btb - 2.0 * coef @ atb + coef @ g @ coef
        rank = n_act
    elif csne is not None:
        coef, cond, solve = csne
        atr, rss0 = residual_pass(coef)
        dx = solve(atr)
        coef = coef + dx
        rss = rss0 - 2.0 * dx @ atr + dx @ g @ dx
        rank = n_act
    else:
        norms = np.sqrt(np.diag(g))
        qr = StreamingQR(norms[active])
        for x, b, _, seg in passes():
            dense = np.zeros((b.shape[0], p))
            for idx, rows in _blocks(model, x, seg):
                if isinstance(rows, slice):
                    dense[:, idx] = x.T
                else:
                    dense[np.ix_(rows, idx)] = x[:, rows].T
            qr.add(dense[:, active], b)
        r_c, qtb_c, rss = qr.factor()
        r_full, qtb_full = np.zeros((p, p)), np.zeros(p)
        r_full[np.ix_(active, active)] = r_c
        qtb_full[active] = qtb_c
        scale = np.where(active, norms, 1.0)
        coef, rank, cond, collinear = solve_from_r(model, r_full, qtb_full, scale, active, throw)
    coef_ls = coef
    (coef, rank, cond, collinear), shape_rec = constrain_shape(
        model,
        (coef, rank, cond, collinear),
        g,
        active,
        shape,
        monotone,
        lambda x: residual_pass(x)[0],
    )
    if coef is not coef_ls:  # the residual sum of squares at the constrained solution
        dx = coef - coef_ls
        rss = rss + dx @ g @ dx
    calibrated = active[:n_seg]
    if calibrated.any() and np.isfinite(t_lo[calibrated]).any():
        torque_range = (float(t_lo[calibrated].min()), float(t_hi[calibrated].max()))
    else:
        torque_range = model.torque_range
    return calibration_solution(
        model,
        (coef, rank, cond, collinear),
        active,
        torque_range,
        throw=throw,
        residual_rms=float(np.sqrt(max(rss, 0.0) / n)),
        n_samples=n,
        segment_counts=counts_t,
        dropped=dropped,
        t0=t0,
        shape=shape_rec,
    )
