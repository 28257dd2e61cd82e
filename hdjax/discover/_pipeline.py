"""The whole estimation pipeline, as the loop runs it on TRAIN, on each fold and on TEST.

Everything a candidate is judged by goes through the same three steps: derive the signals
(derivatives that never cross a gap, a marker where memory states restart after a long one),
calibrate by least squares (Song et al. eqs. (15)-(17)), and invert for torque (eqs.
(26)-(27)). Path-dependent terms (hysteresis) need a torque path at calibration; it is the
model's *own* estimate, computed causally exactly as at estimation, found by a few rounds of
calibrate-then-estimate starting from the previous model's estimate. The reference torque
never drives a state.

The cross-validated torque error refits the structure on each fold's training part (the same
calibration, the same driver rounds from that fold's previous estimate) and inverts the whole
TRAIN record with the fold's coefficients, scoring the held-out samples only: the states run
through the record causally from the estimate, as they run through TEST.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Bool, Float, Int, Shaped
from .._errors import DataError, InversionError
from .._recording import Recording
from ..compliance import (
    ComplianceModel,
    ShapeConstraint,
    ShapeData,
    Signals,
    calibrate_lstsq,
    signals_from_recording,
)
from ..compliance.internal import (
    base_term_columns,
    calibrate_chunks,
    design_columns,
    effect_groups,
    invert_twist,
    join_model_hypers,
    split_model_hypers,
    term_columns,
    term_signals,
)
from ..effects import SEGMENT_START, TORQUE_PATH
from ..effects.internal import join_hypers, run_split, split_hypers
from ._chunked import Chunks
from ._fold_solver import FoldSolver, one_block
from ._folds import memory_starts, segment_starts

DRIVER_ROUNDS = 3
"""Calibrate-then-estimate rounds that make a hysteresis state's calibration driver the
model's own estimate (the change after the third round is far below the noise)."""


@dataclasses.dataclass(frozen=True)
class PipelineData:
    """Signals (gap-safe), reference torque and segment starts of one recording, or of one
    part of it (`rows`)."""

    sig: Signals
    torque: Float[np.ndarray, " n"]
    starts: Bool[np.ndarray, " n"]
    chunk: int = 0
    """With a chunk (the loop's `chunk` setting), `estimate` inverts a model without a
    path term chunk by chunk, so its program's working memory is bounded by the chunk."""
    rows: Int[np.ndarray, " m"] | None = None
    """The rows this part owns, when it was cut from one log with other rows between (TRAIN
    and TEST blocks of one sweep): signals, derivatives and memory states run through the
    whole record, as the estimator runs on the robot, while fits use and scores read these
    rows only (the reference torque of the others is NaN here, so none leaks). `None`: all."""

    @property
    def n(self) -> int:
        return int(self.torque.size)

    def part(self, x: Shaped[ArrayLike, "n ..."]) -> Shaped[np.ndarray, "m ..."]:
        """`x` (one value per row of the record) on this part's rows."""
        x = np.asarray(x)
        return x if self.rows is None else x[self.rows]

    @property
    def part_starts(self) -> Bool[np.ndarray, " m"]:
        """Segment starts on the part's rows: a gap of the record, or a join where rows of
        another part lie between."""
        if self.rows is None:
            return self.starts
        starts = self.starts[self.rows].copy()
        starts[1:] |= np.diff(self.rows) != 1
        starts[:1] = True
        return starts

    def view(self, sig: Signals | None = None) -> PipelineData:
        """The part on its own rows (signals, torque and starts taken; `rows` `None`), for
        pointwise statistics of columns already computed on the whole record."""
        if self.rows is None and sig is None:
            return self
        return PipelineData(
            self.part_signals(sig), self.part(self.torque), self.part_starts, self.chunk
        )

    def part_signals(self, sig: Signals | None = None) -> Signals:
        """The signals (default the record's) on the part's rows, for pointwise statistics;
        columns with memory are computed on the whole record first, then taken."""
        sig = self.sig if sig is None else sig
        if self.rows is None:
            return sig
        return jax.tree.map(lambda x: jnp.asarray(np.asarray(x)[self.rows]), sig)

    @property
    def twist(self) -> Float[np.ndarray, " n"]:
        return np.asarray(self.sig.twist)

    def with_driver(self, driver: Float[ArrayLike, " n"]) -> Signals:
        """The signals with `driver` as the torque path of hysteresis columns."""
        extras = dict(self.sig.extras)
        extras[TORQUE_PATH] = jnp.asarray(driver, jnp.float64)
        return eqx.tree_at(lambda s: s.extras, self.sig, extras)

    def pair(
        self, driver: Float[ArrayLike, " n"] | None = None
    ) -> tuple[Signals, Float[Array, " n"]]:
        """`(Signals, torque)` for calibration, with the driver when given."""
        sig = self.sig if driver is None else self.with_driver(driver)
        return sig, jnp.asarray(self.torque)


def pipeline_signals(
    rec: Recording, ratio: float, twist_sign: float, velocity: str
) -> PipelineData:
    """Model signals of a recording with gaps: velocities at the first sample after a gap take
    the next sample's value (a backward difference across a gap is no derivative), and the
    signal `SEGMENT_START` marks where memory states restart: after gaps over 0.1 s
    (`MEMORY_GAP`; across shorter ones, dropped samples, the state carries on). **Returns:** a
    PipelineData."""
    sig = signals_from_recording(rec, ratio, twist_sign, velocity=velocity)
    starts = segment_starts(rec.t)
    fix = np.flatnonzero(starts)[1:]
    if fix.size:
        n = starts.size
        nxt = np.minimum(fix + 1, n - 1)
        ok = ~starts[nxt] & (nxt != fix)  # a one-sample segment has no derivative: 0
        repl = {}
        for name in ("omega_m", "omega_l"):
            w = np.asarray(getattr(sig, name)).copy()
            w[fix] = np.where(ok, w[nxt], 0.0)
            repl[name] = jnp.asarray(w)
        sig = eqx.tree_at(lambda s: (s.omega_m, s.omega_l), sig, (repl["omega_m"], repl["omega_l"]))
    extras = dict(sig.extras)
    extras[SEGMENT_START] = jnp.asarray(memory_starts(rec.t).astype(np.float64))
    sig = eqx.tree_at(lambda s: s.extras, sig, extras)
    torque = None if rec.torque is None else np.asarray(rec.torque, np.float64)
    return PipelineData(sig, torque, starts)


def context_parts(
    context: Recording, parts: list[Recording], ratio: float, twist_sign: float, velocity: str
) -> list[PipelineData]:
    """TRAIN and TEST (`parts`) cut from one log `context`, each as a [`PipelineData`][] over
    the whole log with its own `rows`, found by their timestamps; each part's view holds the
    reference torque of its own rows only (NaN elsewhere). `DataError` when a part's
    timestamps are not rows of the log, or two parts share a row."""
    whole = pipeline_signals(context, ratio, twist_sign, velocity)
    t = np.asarray(context.t, np.float64)
    if np.any(np.diff(t) <= 0):
        raise DataError(
            f"{context.source}: the log's timestamps must increase strictly to place TRAIN and "
            "TEST in it"
        )
    taken = np.zeros(t.size, bool)
    out = []
    for part in parts:
        tp = np.asarray(part.t, np.float64)
        idx = np.searchsorted(t, tp)
        ok = (idx < t.size) & (t[np.minimum(idx, t.size - 1)] == tp)
        if not ok.all():
            raise DataError(
                f"{part.source}: {int((~ok).sum())} of its {tp.size} timestamps are not rows of "
                f"the log {context.source} it was said to be cut from; pass the whole log it "
                "was cut from, or no context"
            )
        if taken[idx].any():
            raise DataError(
                f"{part.source}: {int(taken[idx].sum())} rows are also in another part: TRAIN "
                "and TEST must not share samples"
            )
        taken[idx] = True
        torque = np.full(t.size, np.nan)
        if part.torque is not None:
            torque[idx] = np.asarray(part.torque, np.float64)
        out.append(dataclasses.replace(whole, torque=torque, rows=idx.astype(np.int64)))
    return out


HYSTERESIS_MARGIN = 0.25
"""Least share of the compliance that must remain in the twist slope right after a torque
reversal once a hysteresis state is added (below it the inversion amplifies the twist noise
more than four-fold there, and at zero it has no solution)."""


def hysteresis_invertible(model: ComplianceModel) -> str:
    """Why a model's hysteresis cannot be inverted well (its twist slope right after a reversal,
    $-2|c|/T_h$, leaves less than `HYSTERESIS_MARGIN` of the compliance), else `""`."""
    i = model.n_coef - model.n_effect
    coef = np.asarray(model.coef)
    act = np.asarray(model.active[: model.n_segments])
    k_min = float(np.asarray(model.k)[act].min())
    for term in model.effect_terms:
        m = len(term.names())
        if term.torque_kind == "path":
            c = float(coef[i])
            worst = 2.0 * abs(c) / term.torque_scale
            if c < 0 and worst > (1.0 - HYSTERESIS_MARGIN) * k_min:
                return (
                    f"{term.key} with scale {term.torque_scale:.4g} N·m: its twist slope after a "
                    f"reversal ({-worst:.3g} rad/(N·m)) leaves less than "
                    f"{HYSTERESIS_MARGIN:.0%} of the compliance ({k_min:.3g} rad/(N·m))"
                )
        i += m
    return ""


def has_path(model: ComplianceModel) -> bool:
    return any(t.torque_kind == "path" for t in model.effect_terms)


def canonical(model: ComplianceModel) -> ComplianceModel:
    """`model` with the torque range set to the rated range.

    The range is a static field that only sets the `in_range` flags; each calibration sets it
    to the data's range, which would make every compiled function (design, inversion) compile
    again for every fit. The loop uses torques only, so it runs on this canonical form.
    """
    rng = (-float(model.rated_torque), float(model.rated_torque))
    if tuple(model.torque_range) == rng:
        return model
    d = {f: getattr(model, f) for f in model.__dataclass_fields__}
    d["torque_range"] = rng
    return ComplianceModel(**d)


@eqx.filter_jit
def _base_columns(terms: tuple, sig: Signals) -> Float[Array, "n n_base"]:
    # stacked inside the program, as the model's own design stacks them (the same roundings)
    return jnp.stack(base_term_columns(terms, sig), axis=1)


def design_by_terms(model: ComplianceModel, sig: Signals, torque) -> np.ndarray | None:
    """The design matrix $A$ of eq. (15), assembled in NumPy from one compiled program per
    term, or `None` when `model` has a torque-path term (its state depends on the driver).

    The same numbers as [`hdjax.compliance.ComplianceModel.design`][], bit for bit (the hinges
    and segment blocks are exact in NumPy; each term's columns come from the same JAX ops):
    the loop asks for the design of every structure it tries, on TRAIN and TEST, and a
    structure made of terms already seen traces, lowers and loads nothing, where a program
    per structure would (a cached one still takes about 0.1 s to trace and load).
    """
    if has_path(model):
        return None
    torque_np = np.asarray(torque, np.float64)
    torque = jnp.asarray(torque_np)
    sig = term_signals(sig)  # no term here reads the torque path
    n, n_seg = torque_np.shape[0], model.n_segments
    out = np.empty((n, model.n_coef))
    for j, (lo, hi) in enumerate(model.segment_bounds):
        out[:, j] = np.clip(torque_np, lo, hi) - min(max(0.0, lo), hi)
    i, nb = n_seg, model.n_base
    if nb:
        base = np.asarray(_base_columns(model.base_terms, sig))
        if model.per_segment:
            seg = np.searchsorted(np.asarray(model.knots, np.float64), torque_np, side="right")
            for s in range(n_seg):
                out[:, i + s * nb : i + (s + 1) * nb] = base * (seg == s)[:, None]
            i += n_seg * nb
        else:
            out[:, i : i + nb] = base
            i += nb
    for term in model.effect_terms:
        c = np.asarray(term_columns(term, sig, torque))
        out[:, i : i + c.shape[1]] = c
        i += c.shape[1]
    return out


def design(model: ComplianceModel, sig, torque) -> np.ndarray:
    """The design matrix (eq. (15)) as a NumPy array: by terms ([`design_by_terms`][]), or
    with a torque-path term compiled once per structure."""
    a = design_by_terms(model, sig, torque)
    if a is not None:
        return a
    return np.asarray(design_columns(canonical(model), sig, jnp.asarray(torque)))


def chunks_of(sig: Signals, torque, chunk: int) -> Chunks:
    """A record's rows chunk by chunk ([`hdjax.discover._chunked.Chunks`][]), each chunk's
    design formed as [`design`][] forms the whole record's."""
    return Chunks(sig, torque, chunk, design)


def _less_columns(term, sig: Signals, coef, r) -> Float[Array, " n"]:
    # as `term_columns`: one program per group structure, the hyperparameters as values
    return run_split(_less_columns_jit, split_hypers, term, sig, coef, r)


@eqx.filter_jit
def _less_columns_jit(skeleton, values, sig: Signals, coef, r) -> Float[Array, " n"]:
    return r - join_hypers(skeleton, values).columns(sig, None) @ coef


def _torque_gain(term, sig: Signals, coef) -> Float[Array, " n"]:
    return run_split(_torque_gain_jit, split_hypers, term, sig, coef)


@eqx.filter_jit
def _torque_gain_jit(skeleton, values, sig: Signals, coef) -> Float[Array, " n"]:
    return join_hypers(skeleton, values).torque_gain(sig, coef)


@eqx.filter_jit
def _gain_sum(g, gi) -> Float[Array, " n"]:
    return g + gi


def _invert_rest(core: ComplianceModel, sig: Signals, r, g):
    # one program per structure: the terms' float hyperparameters are handed in as values
    split = functools.partial(split_model_hypers, keep_active=True)
    return run_split(_invert_rest_jit, split, core, sig, r, g)


@eqx.filter_jit
def _invert_rest_jit(skeleton: ComplianceModel, values: tuple, sig: Signals, r, g):
    core = join_model_hypers(skeleton, values)
    # linear groups left in `core` (beside a memoryless one) add their gain inside this program
    for term, c in effect_groups(core)["linear"]:
        g = term.torque_gain(sig, c) if g is None else g + term.torque_gain(sig, c)
    return invert_twist(core, sig, r, g)


def _inversion_core(model: ComplianceModel) -> tuple[ComplianceModel, list, list]:
    """`model` without its torque-free and linear effect groups (what [`invert_twist`][] reads
    again), and those groups with their coefficients. Beside a memoryless group the linear
    groups stay in the model: their gain meets the Newton steps' products inside one program,
    where XLA may fuse them into other roundings than when it arrives as an input."""
    memoryless = any(t.torque_kind == "memoryless" for t in model.effect_terms)
    keep, free, linear = [], [], []
    coef = np.asarray(model.coef)
    i = model.n_coef - model.n_effect
    idx = list(range(i))
    for term in model.effect_terms:
        m = len(term.names())
        group = (term, jnp.asarray(coef[i : i + m]))  # a NumPy slice: no program per shape
        if term.torque_kind == "none":
            free.append(group)
        elif term.torque_kind == "linear" and not memoryless:
            linear.append(group)
        else:
            keep.append(term)
            idx += range(i, i + m)
        i += m
    if not free and not linear:
        return model, [], []
    d = {f: getattr(model, f) for f in model.__dataclass_fields__}
    d["effect_terms"] = tuple(keep)
    d["coef"] = jnp.asarray(coef[idx])
    d["active"] = tuple(model.active[j] for j in idx)
    return ComplianceModel(**d), free, linear


def estimate(model: ComplianceModel, data: PipelineData) -> Float[np.ndarray, " n"]:
    """Torque estimate by inversion (eqs. (26)-(27)); non-finite values where it fails.

    The torque-free and linear effect groups are evaluated one compiled program per group
    (as [`design_by_terms`][] does), and the inversion proper runs on the model without them:
    every structure that differs only in such groups shares one compiled inversion (the same
    numbers, bit for bit, as [`hdjax.compliance.estimate_torque`][]'s single program). With
    `data.chunk`, a model without a path term is inverted chunk by chunk (the same to about
    1e-13: XLA may round a chunk's fused operations differently).
    """
    core, free, linear = _inversion_core(canonical(model))
    sig = data.sig
    r = sig.twist
    for term, c in free:
        r = _less_columns(term, sig, c, r)
    g = None
    for term, c in linear:
        gi = _torque_gain(term, sig, c)
        g = gi if g is None else _gain_sum(g, gi)
    if data.chunk and data.n > data.chunk and not has_path(core):
        return _invert_in_chunks(core, sig, r, g, data.chunk)
    return np.asarray(_invert_rest(core, sig, r, g).torque)


def _invert_in_chunks(core: ComplianceModel, sig: Signals, r, g, chunk: int) -> np.ndarray:
    """[`_invert_rest`][] over consecutive chunks of `chunk` samples (the last one padded with
    its final sample, so one program serves every chunk). Exact for a model without a path
    term: the inversion is pointwise, a fixed number of Newton steps per sample (eq. (27))."""
    n = int(np.asarray(r).shape[0])
    out = np.empty(n)
    for lo in range(0, n, chunk):
        hi = min(n, lo + chunk)

        def take(x, lo=lo, hi=hi):
            part = np.asarray(x)[lo:hi]
            return part if hi - lo == chunk else np.pad(part, (0, chunk - (hi - lo)), "edge")

        part = _invert_rest(core, jax.tree.map(take, sig), take(r), None if g is None else take(g))
        out[lo:hi] = np.asarray(part.torque)[: hi - lo]
    return out


def quiet_calibrate(model, pair, notes, throw=True, chunk: int = 0, rows=None):
    """`calibrate_lstsq` with its warnings turned into notes (on the rows `rows` of the pair,
    default all); with `chunk`, the same fit with the normal equations and the refinement
    accumulated over chunks of that many samples
    ([`hdjax.compliance._stream_fit.calibrate_chunks`][], always refined, as in memory)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if chunk:
            passes = chunks_of(pair[0], pair[1], chunk).compact_passes(model)
            res = calibrate_chunks(model, passes, label="TRAIN", throw=throw, refine_above=0.0)
        else:
            res = calibrate_lstsq(model, pair, throw=throw, rows=rows)
    for w in caught:
        notes.append(str(w.message))
    return res


REFINE_ROUNDS = 6
"""Most refits that bring a term whose hyperparameter follows its own fitted coefficient (an
encoder skew built for the delay it finds) to its fixed point."""


def refined_structure(model: ComplianceModel) -> ComplianceModel | None:
    """`model`'s structure with every term that has a `refined(coef)` method (its column built
    for the coefficient the fit found, [`hdjax.effects.EncoderSkew.refined`][]) replaced by
    its refined term, or `None` when none changes."""
    coef = np.asarray(model.coef)
    i, terms, changed = model.n_coef - model.n_effect, [], False
    for term in model.effect_terms:
        m = len(term.names())
        new = term.refined(coef[i : i + m]) if hasattr(term, "refined") else None
        terms.append(term if new is None else new)
        changed |= new is not None
        i += m
    return model.restructured(effect_terms=terms) if changed else None


def calibrate(
    structure: ComplianceModel,
    data: PipelineData,
    notes,
    previous_estimate,
    chunk: int = 0,
    fits: list | None = None,
    refine: bool = True,
):
    """Calibrate `structure` on all of `data`; with path terms, driver rounds from
    `previous_estimate`; with `chunk`, the fits accumulated chunk by chunk; terms whose column
    follows their own coefficient are refitted to their fixed point ([`refined_structure`][];
    not with `refine=False`: one fit, the columns as given, for a reading whose first-order
    coefficient is enough and whose programs are then compiled once, not once per record).
    Each fit's Solution is appended to `fits` when given (the last one's value is the model).
    **Returns:** (model, its torque estimate on `data`)."""
    for _ in range(REFINE_ROUNDS if refine else 1):
        model, est = _calibrate_once(structure, data, notes, previous_estimate, chunk, fits)
        structure = refined_structure(model)
        if structure is None:
            break
    return model, est


def held_outer_segments(res) -> list[int]:
    """The outer torque segments (not the one holding 0 N·m) whose compliance the shape
    constraint of calibration `res` holds at its floor and least squares alone makes
    non-positive: the data there does not determine it."""
    model, shape = res.value, res.stats.get("shape_constraint")
    plain = res.stats.get("unconstrained_k")
    if shape is None or not res.stats.get("constrained") or plain is None:
        return []
    tight = shape.active_segments(np.asarray(model.coef), model.n_segments)
    return [
        j
        for j, (lo, hi) in enumerate(model.segment_bounds)
        if tight[j] and not plain[j] > 0 and not lo <= 0.0 < hi
    ]


def merge_knot(model: ComplianceModel, j: int) -> ComplianceModel:
    """`model`'s structure without the knot between segment `j` and its neighbour towards
    0 N·m (coefficients reset)."""
    lo, hi = model.segment_bounds[j]
    knot = lo if lo > 0.0 else hi
    return model.restructured(knots=[k for k in model.knots if k != knot])


def fit_merging(structure, pair, notes, chunk=0, rows=None, throw=True):
    """[`quiet_calibrate`][], merging inwards every outer segment the shape constraint holds
    at its floor ([`held_outer_segments`][]; the outermost first, one at a time) and refitting:
    the neighbour's compliance continues there, rather than a compliance the data does not
    determine. Each merge is noted. **Returns:** the final calibration's Solution."""
    while True:
        trial: list[str] = []
        res = quiet_calibrate(structure, pair, trial, throw=False, chunk=chunk, rows=rows)
        held = held_outer_segments(res) if res.ok else []
        if not held:
            notes.extend(trial)
            if throw and not res.ok:
                quiet_calibrate(structure, pair, [], throw=True, chunk=chunk, rows=rows)
            return res
        j = max(held, key=lambda j: abs(sum(structure.segment_bounds[j][:1])))
        lo, hi = structure.segment_bounds[j]
        notes.append(
            f"torque segment [{lo:.4g}, {hi:.4g}) N·m calibrates to a non-positive compliance "
            f"by least squares ({res.stats['unconstrained_k'][j]:.3g} rad/(N·m)): merged into "
            "its neighbour"
        )
        structure = merge_knot(structure, j)


def _calibrate_once(structure, data, notes, previous_estimate, chunk, fits=None):
    fits = [] if fits is None else fits
    structure = canonical(structure)
    if not has_path(structure):
        fits.append(fit_merging(structure, data.pair(), notes, chunk=chunk, rows=data.rows))
        model = fits[-1].value
        return model, estimate(model, data)
    driver = previous_estimate
    for _ in range(DRIVER_ROUNDS):
        fits.append(fit_merging(structure, data.pair(driver), notes, chunk=chunk, rows=data.rows))
        model = fits[-1].value
        structure = canonical(model)
        why = hysteresis_invertible(model)
        if why:
            raise InversionError(why)
        est = estimate(model, data)
        if not np.all(np.isfinite(data.part(est))):
            raise InversionError(
                f"the model with {structure.effect_keys[-1]} gives a non-finite torque estimate"
            )
        driver = est
    return model, driver


@dataclasses.dataclass
class CrossValidation:
    """Held-out errors of one structure over one fold assignment."""

    torque_rms: float
    twist_rms_arcsec: float
    fold_torque_rms: list[float]
    fold_models: list[ComplianceModel]
    """Per fold, the model calibrated on the fold's training part. The next structure's
    driver rounds start from its estimate over the whole record
    (`fold_estimate`), recomputed when asked for rather than kept: a
    structure holds no full-length vector per fold, and the loop's memory does not grow by
    `n_folds` records per candidate tried."""
    squared_errors: np.ndarray | None = None
    """Per TRAIN sample, the squared held-out torque error of the fold that holds it out (NaN
    where it is not scored): candidates are compared block by block on the same samples."""

    def fold_estimate(self, f: int, data: PipelineData) -> np.ndarray:
        """Fold `f`'s torque estimate over the whole of `data` (the record it was
        cross-validated on): the same numbers, bit for bit, as the estimate that scored it."""
        return estimate(self.fold_models[f], data)


def structure_shape(model: ComplianceModel, a: np.ndarray, y, torque):
    """The shape constraint of `model`'s structure on the rows of its full-layout design `a`
    (twist `y`, reference `torque`), as the calibration on them sets it; `None` when the
    twist does not rise with the torque there."""
    data = ShapeData(model, layout="full")
    data.add(a, y, torque)
    return ShapeConstraint.of(model, data, np.asarray(model.active))


MIN_FOLD_SEGMENT_SAMPLES = 30


def _fold_model(model: ComplianceModel, coef: np.ndarray, train_torque) -> ComplianceModel:
    """The structure with a fold's coefficients; a torque segment the fold's training part
    barely reaches (fewer than `MIN_FOLD_SEGMENT_SAMPLES` samples) or calibrates to a
    non-positive compliance is left out of that fold's inversion, as the full calibration
    leaves out segments without data."""
    n_seg = model.n_segments
    seg = np.searchsorted(np.asarray(model.knots), train_torque, side="right")
    counts = np.bincount(seg, minlength=n_seg)
    active = list(model.active)
    for j in range(n_seg):
        if active[j] and (counts[j] < MIN_FOLD_SEGMENT_SAMPLES or not coef[j] > 0):
            active[j] = False
            coef[j] = 0.0
    fitted = eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef))
    if tuple(active) == tuple(model.active) or not any(active[:n_seg]):
        return fitted
    d = {f: getattr(fitted, f) for f in fitted.__dataclass_fields__}
    d["active"] = tuple(active)
    return ComplianceModel(**d)


REST_FRACTION = 0.02
"""A sample is at rest when its link speed is at most this fraction of the record's 99th
percentile speed (a regime of its own for the cross-validation's coverage check)."""

FAST_FRACTION = 0.5
"""Above this fraction of the 99th percentile speed a motion is fast, below it slow (speeding
up or slowing down: where speed-dependent effects, a skew or friction, change)."""

N_REGIMES = 5


def motion_regime(omega: ArrayLike) -> Int[np.ndarray, " n"]:
    """Per sample: 0 at rest, 1 / 2 moving forwards slowly / fast, 3 / 4 backwards slowly /
    fast (see `REST_FRACTION` and `FAST_FRACTION`)."""
    w = np.asarray(omega, np.float64)
    if w.size == 0:
        return np.zeros(0, int)
    top = np.quantile(np.abs(w), 0.99)
    rest = np.abs(w) <= REST_FRACTION * top
    fast = np.abs(w) > FAST_FRACTION * top
    return np.where(rest, 0, np.where(w > 0, 1, 3) + fast)


def coverage_arguments(model: ComplianceModel, data: PipelineData) -> list[np.ndarray]:
    """The signals `model`'s base terms extrapolate in outside their fitted range
    ([`hdjax.effects.AbstractTerm.extrapolating_arguments`][]): the paper's kinematic
    argument $\\theta_l\\omega_l$, the current of the wave-generator polynomial."""
    return [a for t in model.base_terms for a in t.extrapolating_arguments(data.sig)]


def scored_rows(
    data: PipelineData, folds: list[np.ndarray], arguments: Sequence[np.ndarray] = ()
) -> list[np.ndarray]:
    """Per fold, the held-out rows it scores: those whose regime the fold's training part
    covers, as a TEST recording is covered by TRAIN. A row is covered when the training rows
    in its motion regime ([`motion_regime`][]: at rest, moving slowly or fast forwards or
    backwards) reach torques on both sides of its own, and the training rows reach values on
    both sides of its own of each of `arguments` (the signals the starting model's base terms
    extrapolate in, [`coverage_arguments`][]): the fit then interpolates there rather than
    extrapolating (a block held out at the end of a one-way sweep asks it to extrapolate, and
    so does a sweep held out at a speed the training part reaches only at other angles, where
    the paper's kinematic columns of $\\theta_l\\omega_l$ are fitted; TEST never does). The
    mask depends on the data and `arguments` only, so the loop, which takes them from its
    starting model, scores every structure on the same rows."""
    fit = np.zeros(data.n, bool)
    fit[np.arange(data.n) if data.rows is None else data.rows] = True
    regime = motion_regime(np.asarray(data.sig.omega_l))
    out = []
    for te in folds:
        train = fit.copy()
        train[te] = False
        keep = np.zeros(te.size, bool)
        for r in range(N_REGIMES):
            tr = data.torque[train & (regime == r)]
            if tr.size:
                here = regime[te] == r
                keep |= here & (data.torque[te] >= tr.min()) & (data.torque[te] <= tr.max())
        for x in arguments:
            if train.any():
                keep &= (x[te] >= x[train].min()) & (x[te] <= x[train].max())
        out.append(te[keep])
    return out


def cross_validate(
    model: ComplianceModel,
    data: PipelineData,
    folds: list[np.ndarray],
    previous: CrossValidation | None = None,
    chunk: int = 0,
    scored: list[np.ndarray] | None = None,
) -> CrossValidation:
    """Cross-validated torque and twist error of `model`'s structure (see the module docstring).

    `model` is the structure calibrated on all of TRAIN: its active coefficients and torque
    range are kept, so every fold model compiles to the same program. `folds` are the held-out
    rows of each fold (rows of the record; with `data.rows`, among them). Each fold scores the
    held-out rows its training part covers ([`scored_rows`][]; `scored`, when given, are those
    rows: the loop fixes them from its starting model, so that every structure is scored on the
    same rows; else the coverage of `model`'s base terms). With `chunk`, the fold fits
    are accumulated over chunks of that many samples; in memory and chunked, the folds are
    solved by the same [`FoldSolver`][hdjax.discover._fold_solver.FoldSolver].
    """
    path = has_path(model)
    active = np.asarray(model.active)
    y = data.twist
    n = data.n
    rounds = DRIVER_ROUNDS if path else 1
    sse_t, sse_w, cnt, per_fold, fold_models = 0.0, 0.0, 0, [], []
    sq = np.full(n, np.nan)
    model = canonical(model)
    torque = jnp.asarray(data.torque)
    # the fits read the part's rows only: their own row numbers there ("local")
    fit = np.arange(n) if data.rows is None else data.rows
    local = np.full(n, -1)
    local[fit] = np.arange(fit.size)
    fold_id = np.full(fit.size, -1)
    for f, te in enumerate(folds):
        fold_id[local[te]] = f
    if scored is None:
        scored = scored_rows(data, folds, coverage_arguments(model, data))
    masks = []
    for s_ in scored:
        masks.append(np.zeros(fit.size, bool))
        masks[-1][local[s_]] = True

    def solver_for(sig, folds_, shape=None):
        # the design as a row source: chunk by chunk, or the part's rows in one block
        if chunk:
            c = chunks_of(sig, data.torque, chunk)
            rows = lambda: c.designs(model)  # noqa: E731
        else:
            a = design(model, sig, torque)
            rows = one_block(a if data.rows is None else a[fit])  # all rows: no copy
        return FoldSolver(
            rows,
            y[fit],
            fold_id,
            masks,
            active,
            folds=folds_,
            shape=shape,
            model=model,
            torque=data.torque[fit],
        )

    fixed_solver = None if path else solver_for(data.sig, None)
    shape = None  # found by the first solver, then held for every fold and round
    for f, te in enumerate(folds):
        train_rows = np.zeros(n, bool)
        train_rows[fit] = True
        train_rows[te] = False
        driver = previous.fold_estimate(f, data) if (path and previous is not None) else np.zeros(n)
        for _ in range(rounds):
            solver = fixed_solver or solver_for(data.with_driver(driver), (f,), shape)
            shape = solver.shape
            coef = solver.solve(f)
            fold_model = _fold_model(model, coef, data.torque[train_rows])
            est = estimate(fold_model, data)
            driver = np.where(np.isfinite(est), est, 0.0)
        sse_w += solver.twist_sse(f)
        te = scored[f]
        e = est[te] - data.torque[te]
        sse = float(np.sum(e**2)) if np.all(np.isfinite(e)) else np.inf
        sq[te] = np.where(np.isfinite(e), e**2, np.inf)
        sse_t += sse
        cnt += te.size
        per_fold.append(float(np.sqrt(sse / te.size)) if te.size else float("nan"))
        fold_models.append(fold_model)
    # no held-out sample inside the folds' calibrated ranges: the error is unknown (NaN), so no
    # step can be accepted on it (a zero here would accept anything)
    none = np.nan if cnt == 0 else 0.0
    return CrossValidation(
        torque_rms=float(np.sqrt(sse_t / max(cnt, 1))) + none,
        twist_rms_arcsec=float(np.sqrt(sse_w / max(cnt, 1)) * 180 * 3600 / np.pi) + none,
        fold_torque_rms=per_fold,
        fold_models=fold_models,
        squared_errors=sq,
    )


def within_one_se(candidate: CrossValidation, best: CrossValidation, blocks: np.ndarray) -> bool:
    """Whether `candidate`'s cross-validated torque error is within one standard error of
    `best`'s (the one-standard-error rule, Hastie, Tibshirani & Friedman, *The Elements of
    Statistical Learning*, Section 7.10), the error of the difference taken pairwise over the
    held-out blocks: both structures are scored on the same samples, and whole blocks no
    shorter than the residual's correlation length are close to independent.

    The difference of the summed squared errors is $D = \\sum_b d_b$ over the $m$ scored
    blocks; its standard error is $\\sqrt{m}\\,s_d$, with $s_d$ the blocks' sample standard
    deviation. Within when $D \\le \\sqrt{m}\\,s_d$.
    """
    a, b = candidate.squared_errors, best.squared_errors
    if a is None or b is None:
        return candidate.torque_rms <= best.torque_rms
    scored = np.isfinite(b) & ~np.isnan(a)
    if not np.all(np.isfinite(a[scored])):
        return False
    d = np.bincount(blocks[scored], weights=a[scored] - b[scored], minlength=int(blocks.max()) + 1)
    d = d[np.bincount(blocks[scored], minlength=d.size) > 0]
    if d.size < 2:
        return float(d.sum()) <= 0.0
    return float(d.sum()) <= float(np.sqrt(d.size) * np.std(d, ddof=1))
