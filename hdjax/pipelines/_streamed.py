r"""The steps of an experiment on streamed parts: estimates and errors accumulated chunk by chunk.

With `[fit] chunk > 0` an experiment's files arrive as [`hdjax.compliance.RecordingStream`][]s
(see [`hdjax.pipelines.StreamedDataset`][]). The calibration streams through
[`hdjax.compliance.calibrate_stream`][]; here the rest of [`hdjax.pipelines`][]' steps follow
with memory bounded by the chunk:

- the model's torque estimate (Song et al. eqs. (26)-(27)) and the network's (after eq. (28))
  run on each chunk with a halo of neighbouring samples for the backward-difference velocities
  of eqs. (13)-(14), so every sample's estimate is the one of the whole recording;
- the Kalman-filtered current of the network's inputs (eqs. (29)-(35)) carries the filter's
  mean and covariance from the end of one chunk into the next;
- the errors are accumulated ([`ErrorSums`][]: sum, sum of squares, largest |error|), and a
  figure keeps the samples the in-memory figure would plot (per block the first sample and the
  one of largest |error|);
- the network trains on every k-th sample of the calibration parts, k chosen from the total
  count as in memory, gathered chunk by chunk.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import network as nw
from .._errors import ConfigError, DataError
from .._features import signals
from ..compliance import RecordingStream, estimate_torque
from ..compliance.internal import (
    SMOOTH_HALF_WINDOW,
    recording_arrays,
    recording_from_arrays,
    windows,
)
from ..effects import Column
from ..effects.internal import DahlCarry, is_sequential
from ..network import PAPER_P0, PAPER_Q, PAPER_R, kalman_filter

FIGURE_LIMIT = 6000
"""Samples a torque figure plots at most (`hdjax.report` decimates to this)."""


class ErrorSums:
    """Running error statistics, giving what [`hdjax.error_metrics`][] gives on all samples."""

    def __init__(self):
        self.n = 0
        self.total = 0.0
        self.squares = 0.0
        self.peak = 0.0
        self.peak_t = None
        self.out_of_range = 0
        self.finite = True

    def add(
        self, err: np.ndarray, in_range: np.ndarray | None = None, t: np.ndarray | None = None
    ) -> None:
        """Add a chunk's errors (and, with its timestamps `t`, track when the largest was: the
        first of equal ones, as `np.argmax` over the whole record)."""
        self.finite = self.finite and bool(np.isfinite(err).all())
        self.n += err.shape[0]
        self.total += float(np.sum(err))
        self.squares += float(np.sum(err * err))
        if err.size:
            k = int(np.argmax(np.abs(err)))
            if self.peak_t is None or abs(float(err[k])) > self.peak:
                self.peak_t = None if t is None else float(np.asarray(t)[k])
            self.peak = max(self.peak, abs(float(err[k])))
        if in_range is not None:
            self.out_of_range += int(np.sum(~np.asarray(in_range, bool)))

    def merged(self, other: ErrorSums) -> ErrorSums:
        out = ErrorSums()
        for k in ("n", "total", "squares", "out_of_range"):
            setattr(out, k, getattr(self, k) + getattr(other, k))
        out.peak, out.finite = max(self.peak, other.peak), self.finite and other.finite
        out.peak_t = self.peak_t if self.peak >= other.peak else other.peak_t
        return out

    @property
    def rms(self) -> float:
        return math.sqrt(self.squares / self.n)

    def as_dict(self, rated: float, in_range: bool = False) -> dict:
        """`rms, max, bias, rms_pct, max_pct, n` (and `out_of_range_pct`), as in memory."""
        if self.n == 0:
            raise DataError("no samples to compute error metrics on")
        if not self.finite:
            raise DataError("the estimate contains NaN or inf; cannot compute error metrics")
        out = {
            "rms": self.rms,
            "max": self.peak,
            "bias": self.total / self.n,
            "rms_pct": 100.0 * self.rms / rated,
            "max_pct": 100.0 * self.peak / rated,
            "n": self.n,
        }
        if self.peak_t is not None:
            out["max_at_s"] = self.peak_t
        if in_range:
            out["out_of_range_pct"] = 100.0 * self.out_of_range / self.n
        return out


class _Envelope:
    """The samples a decimated figure of `n` samples plots: per block of `step` samples the
    first one and the one of largest |error| (the first of equal ones), as `_envelope`."""

    def __init__(self, n: int, limit: int = FIGURE_LIMIT):
        self.step = max(1, -(-2 * n // limit))
        m = -(-n // self.step)
        self.best = np.full(m, -1.0)
        self.rows = {}  # global index -> (t, measured, estimated)
        self.peak_at = np.full(m, -1, np.int64)
        self.start = 0

    def add(self, t, measured, estimated) -> None:
        idx = self.start + np.arange(t.shape[0])
        self.start += t.shape[0]
        err = np.abs(estimated - measured)
        block = idx // self.step
        for i in np.flatnonzero(idx % self.step == 0):
            self.rows[int(idx[i])] = (t[i], measured[i], estimated[i])
        for b in np.unique(block):
            sel = np.flatnonzero(block == b)
            j = sel[int(np.argmax(err[sel]))]
            if err[j] > self.best[b]:
                old = self.peak_at[b]
                if old >= 0 and old % self.step:
                    self.rows.pop(int(old), None)
                self.best[b], self.peak_at[b] = err[j], idx[j]
                self.rows[int(idx[j])] = (t[j], measured[j], estimated[j])

    def series(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        keys = sorted(self.rows)
        arr = np.array([self.rows[k] for k in keys]).reshape(-1, 3)
        return arr[:, 0], arr[:, 1], arr[:, 2]


@dataclasses.dataclass
class StreamedEstimate:
    """A method's estimate on one streamed test part: its error sums and figure samples."""

    errors: ErrorSums
    t: np.ndarray
    measured: np.ndarray
    torque: np.ndarray
    in_range: bool = False


# ---------------------------------------------------------------------------------------------
# The compliance model


def check_streamable(model) -> None:
    """Refuse a model whose estimate is sequential (hysteresis) beyond what chunks carry."""
    paths = [t.key for t in model.effect_terms if t.torque_kind == "path"]
    if paths:
        raise ConfigError(
            f"the model's hysteresis term(s) {', '.join(paths)} are estimated sample by sample "
            "from the estimated torque, which a streamed run does not carry across chunks; set "
            "[fit] chunk = 0"
        )


STATE_COLUMN = "_carried_dahl_state_{}"
"""The extra column that holds the carried Dahl state of a model's k-th twist-driven term."""


def _carried_states(model):
    """`(model, terms)`: the model with each twist-driven Dahl term (`TwistHysteresis`, a
    torque-free state of the measured twist) replaced by a [`hdjax.effects.Column`][] reading
    its state from an extra column (same coefficient, the same estimate), and those terms."""
    seq = [t for t in model.effect_terms if is_sequential(t) and t.torque_kind != "path"]
    if not seq:
        return model, []
    terms, k = [], 0
    for t in model.effect_terms:
        if t in seq:
            terms.append(Column(name=STATE_COLUMN.format(k)))
            k += 1
        else:
            terms.append(t)
    return dataclasses.replace(model, effect_terms=tuple(terms)), seq


def _with_states(model, terms, carry: DahlCarry, win, lo: int, hi: int):
    """The window's signals with each carried state over its own rows `lo:hi` as an extra
    column (the halo rows hold the neighbouring value; their estimates are not used)."""
    sig = signals(win, model.joint, velocity=model.velocity)
    own = jax.tree_util.tree_map(lambda x: x[lo:], sig)
    extras = dict(sig.extras)
    for k, term in enumerate(terms):
        z = carry.column(k, term, own, None, hi - lo, numpy=False)
        full = np.empty(win.n_samples)
        full[:lo], full[lo:hi], full[hi:] = z[0], z, z[-1]
        extras[STATE_COLUMN.format(k)] = jnp.asarray(full)
    return eqx.tree_at(lambda s: s.extras, sig, extras)


def model_estimates(model, stream: RecordingStream, chunk: int, *, need_torque: bool = True):
    """The model's estimate (eqs. (26)-(27)) chunk by chunk: `(rows, estimate)` for each
    chunk of the stream, `rows` the chunk's own samples (a [`hdjax.Recording`][]) and
    `estimate` the [`hdjax.compliance.TorqueEstimate`][] of those rows, equal to the whole
    recording's.

    Velocities read a halo of neighbouring samples; a twist-driven hysteresis state (the
    residual loop's `hysteresis:torque`) is carried from each chunk into the next
    ([`hdjax.effects._dahl_carry.DahlCarry`][]) and restarts with each recording, as the
    in-memory estimate does. Recordings without a reference torque are refused unless
    `need_torque` is false.
    """
    check_streamable(model)
    smoothed = model.velocity == "smoothed"
    before = SMOOTH_HALF_WINDOW if smoothed else 1
    after = SMOOTH_HALF_WINDOW if smoothed else 0
    pad = None if smoothed else chunk + before  # one compiled shape for every full chunk
    inner, carried = _carried_states(model)
    carry = DahlCarry()
    for win, lo, hi in windows(stream, before, after, pad, need_torque=need_torque):
        data = win
        if carried:
            if lo == 0:  # a new recording: its state starts afresh
                carry = DahlCarry()
            data = _with_states(model, carried, carry, win, lo, hi)
        est = estimate_torque(inner, data)
        yield jax.tree_util.tree_map(lambda x: x[lo:hi], (win, est))


def estimate_model_streamed(model, stream: RecordingStream, n: int, chunk: int):
    """The model's estimate on a streamed part (eqs. (26)-(27)), as a [`StreamedEstimate`][]
    ([`model_estimates`][]: every sample's estimate is the one of the whole recording)."""
    sums, env = ErrorSums(), _Envelope(n)
    for rows, est in model_estimates(model, stream, chunk):
        torque, ref = np.asarray(est.torque), np.asarray(rows.torque)
        sums.add(torque - ref, np.asarray(est.in_range), np.asarray(rows.t))
        env.add(np.asarray(rows.t), ref, torque)
    return StreamedEstimate(sums, *env.series(), in_range=True)


# ---------------------------------------------------------------------------------------------
# The network


def stream_features(stream: RecordingStream, joint, *, periodic, orders, kalman):
    r"""`(features, torque, t)` of each chunk: the network's inputs (after Song et al. eq. (28)) as
    [`hdjax.network.build_features`][] gives them on the whole recording.

    The backward-difference velocities read one sample of the previous chunk; the Kalman
    filter (eqs. (29)-(35)) restarts from the first measurement of each recording and carries
    its mean and covariance from one chunk into the next, so the filtered current is the one
    of a single pass.
    """
    layout = nw.make_layout(periodic=periodic, orders=orders, kalman=kalman)
    state = None
    for win, lo, hi in windows(stream, 1, 0, None):
        if lo == 0:  # a new recording: the filter starts afresh
            state = None
        if kalman:
            z = np.asarray(win.current)[lo:hi]
            x0, p0 = (None, PAPER_P0) if state is None else state
            mean, cov = kalman_filter(z, q=PAPER_Q, r=PAPER_R, p0=p0, x0=x0)
            mean, cov = np.asarray(mean), np.asarray(cov)
            state = (float(mean[-1]), float(cov[-1]))
            current = np.concatenate([np.asarray(win.current)[:lo], mean])
            win = _with_current(win, current)
        feats = nw.build_features(win, joint, periodic=periodic, orders=orders, kalman=False)
        x = nw.Features(x=np.asarray(feats.x)[lo:hi], layout=layout)
        yield x, np.asarray(win.torque)[lo:hi], np.asarray(win.t)[lo:hi]


def _with_current(rec, current):
    return eqx.tree_at(lambda r: r.current, rec, jnp.asarray(current, jnp.float64))


def training_rows(stream: RecordingStream, joint, n_total: int, max_samples: int, n_cfg):
    """Every k-th sample of the calibration parts (k from the total count, as in memory)."""
    stride = max(1, -(-n_total // max_samples))
    xs, ys, start = [], [], 0
    kw = dict(periodic=n_cfg["periodic"], orders=tuple(n_cfg["orders"]), kalman=n_cfg["kalman"])
    layout = None
    for feats, y, _ in stream_features(stream, joint, **kw):
        m = y.shape[0]
        first = (-start) % stride
        # copies, not views: a view keeps the whole chunk alive, so memory would grow with
        # the log instead of staying bounded by the chunk (and the kept rows)
        xs.append(np.array(np.asarray(feats.x)[first::stride]))
        ys.append(np.array(y[first::stride]))
        layout = feats.layout
        start += m
    return np.concatenate(xs), np.concatenate(ys), layout


def estimate_network_streamed(net, joint, stream: RecordingStream, n: int):
    """The network's estimate on a streamed part, as a [`StreamedEstimate`][]."""
    lay = net.layout
    kw = dict(periodic=lay.periodic, orders=lay.orders or (1, 2), kalman=lay.kalman)
    sums, env = ErrorSums(), _Envelope(n)
    for feats, ref, t in stream_features(stream, joint, **kw):
        torque = np.asarray(nw.predict(net, feats))
        sums.add(torque - ref, t=t)
        env.add(t, ref, torque)
    return StreamedEstimate(sums, *env.series())


# ---------------------------------------------------------------------------------------------
# Timing


def head(stream: RecordingStream, n: int):
    """The first `n` samples of a stream's first recording (a [`hdjax.Recording`][])."""
    parts, got = [], 0
    for chunks in stream:
        for c in chunks:
            parts.append(recording_arrays(c))
            got += c.n_samples
            if got >= n:
                break
        break
    cols = {k: np.concatenate([p[k] for p in parts])[:n] for k in parts[0]}
    return recording_from_arrays(cols, stream.label)
