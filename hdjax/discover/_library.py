"""The library of candidate effects: named groups of twist-model terms.

Each candidate is a term group proposed by a registered effect family ([`hdjax.effects`][]);
the built-in families give these keys (the report's `vocabulary`, [`hdjax.effects.vocabulary`][]):

- `harmonic:theta_m:K`: $\\cos K\\theta_m, \\sin K\\theta_m$, kinematic error of the wave
  generator side (order $K$, decimal);
- `harmonic:theta_l:K`: $\\cos K\\theta_l, \\sin K\\theta_l$, kinematic error of the output;
- `coulomb:omega_m`, `coulomb:omega_l`: $\\tanh(\\omega/\\omega_s)$, Coulomb friction between
  current and wave generator, or at the output bearing;
- `stribeck:omega_m`, `stribeck:omega_l`: $e^{-(\\omega/\\omega_{st})^2}\\tanh(\\omega/\\omega_s)$,
  the Stribeck excess, offered beside the Coulomb term of the same velocity;
- `viscous:omega_m`, `viscous:omega_l`: $\\omega$, viscous friction;
- `hysteresis:torque`: a Dahl state of the torque path, hysteresis of flexspline and wave
  generator;
- `backlash:torque`: $\\tanh(T/T_b)$, lost motion around zero torque;
- `stiffness:torque`: $(T/\\tau_0)^3$, stiffness beyond the piecewise segments;
- `ripple:theta_m:K`, `ripple:theta_l:K`: $T/\\tau_0 \\cdot (\\sin K\\theta, \\cos K\\theta)$, a
  compliance ripple (order from the spectrum of residual ÷ torque);
- `damping:twist_rate`: $s(\\omega_l - \\omega_m/N)$, structural damping of the flexspline;
- `column:NAME`: $(x - \\bar x)/s_x$, a drift with an extra column (e.g. temperature);
- `column:NAME*torque`: $(x - \\bar x)/s_x \\cdot T/\\tau_0$, a compliance that drifts with it.

Harmonic orders come from the order spectrum of the residual (peaks, refined), merged with the
integers and the combination orders $2 \\pm 2/N$; a spectrum peak is searched only where the
recording covers a full period, a named order as soon as it covers a third of one. A spectrum
peak that is a function of the torque along the path rather than of the angle (the starting
model's compliance misfit under a gravity-like load) is not offered
(`stands_apart_from_torque`).
Nonlinear parameters (the smoothing speed $\\omega_s$, the Dahl scale, the backlash width) are
scanned on a short grid; each grid member is a separate candidate of the same key, and the best
one wins.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .. import effects
from .._custom_types import ArrayLike, Float
from .._features import Signals
from ..compliance import ComplianceModel
from ..effects import (
    Candidate as Candidate,
    CandidateContext,
    harmonic_key as harmonic_key,
)
from ._spectrum import (
    OrderSpectrum,
    order_power,
    order_spectrum,
    refine_peak,
    spectrum_peaks,
    subsample,
)

FAMILIES = effects.discover_families()
"""The built-in families the loop can offer (registered families: `effects.discover_families()`)."""

VELOCITY_KEYS = ("skew:encoders", "viscous:omega_l", "viscous:omega_m")
"""Keys whose columns are, to first order, the same speed: an encoder time skew and viscous
friction at either side ($\\omega_m \\approx N \\omega_l$). The twist cannot tell them apart
(the current may), so a model holds at most one of them: beside one, another fits only the
second-order difference between them (an acceleration, or the twist rate that
`damping:twist_rate` names) with two large coefficients of opposite sign."""


def _library_options_class():
    fields = [
        (name, type(default), dataclasses.field(default=default))
        for name, default in effects.library_options().items()
    ]
    fields.append(
        (
            "families",
            tuple,
            dataclasses.field(default_factory=lambda: effects.discover_families()),
        )
    )
    doc = (
        "Which candidate effects to offer, and their grids.\n\n"
        "The fields are the registered families' options (see each family in `hdjax.effects`):\n\n"
        "- `orders_m`, `orders_l`: (min, max) trial orders of the motor and output angles.\n"
        "- `integer_orders_m`, `integer_orders_l`: grid orders always offered (if resolvable).\n"
        "- `n_peaks`: spectrum peaks taken per angle.\n"
        "- `smoothing_fractions`: $\\omega_s$ grid as fractions of the velocity's RMS.\n"
        "- `dahl_fractions`, `backlash_fractions`: Dahl scale and backlash width as fractions of\n"
        "  $\\tau_0$.\n"
        "- `dahl_play`: the play on a Dahl state's driver, in deviations of its noise (0: none).\n"
        "- `families`: the families to offer (default all registered ones).\n"
    )
    cls = dataclasses.make_dataclass("LibraryOptions", fields, frozen=True)
    cls.__doc__ = doc
    cls.__module__ = __name__
    return cls


LibraryOptions = _library_options_class()
"""Which candidate effects to offer, and their grids: one field per registered family option
(a family registered later reads its own defaults), plus `families`."""


def candidate_columns(term, sig, torque) -> np.ndarray:
    """A candidate's columns as a NumPy array, computed in NumPy where the term allows it.

    Scoring evaluates dozens of candidates once each; NumPy avoids compiling a JAX program per
    candidate (their orders and scales are static fields). The result equals `term.columns`
    (each term's `numpy_columns` is tested against it).
    """
    if term.score_in_numpy:
        return np.asarray(term.numpy_columns(sig, torque))
    return np.asarray(term.columns(sig, torque))


MIN_PERIOD_FRACTION = 1.0 / 3.0
"""The least share of a period that a named (grid) order's swing must cover to be offered."""


MAX_GAP_PHASE = math.pi / 2
"""The most phase ($K$ times the angle) that TRAIN's widest gap in an angle may span for order
$K$ of that angle to be offered, unless the record covers `GAP_EXEMPT_PERIODS` of its periods."""

GAP_EXEMPT_PERIODS = 10.0
"""Periods of an order inside the angle's span above which its gaps are bridged by periodicity
(the order is seen on many periods either side of every gap, and cross-validation tests that)."""


def widest_gap(theta) -> float:
    """The widest angle interval inside the span that holds no sample [rad]."""
    a = np.sort(np.asarray(theta, np.float64))
    return float(np.max(np.diff(a))) if a.size > 1 else 0.0


def bridges_gaps(order: float, span: float, gap: float) -> bool:
    """Whether order `order` of an angle is determined across its widest gap `gap`.

    Over a record that covers the order only a few times (a partial swing of the output), a
    harmonic is a smooth function of the angle fitted to the samples that exist: inside a gap
    wider than a quarter of its period it swings freely (a split into long time blocks of a
    one-way sweep leaves whole angle ranges to TEST). Offered only if the gap spans at most
    `MAX_GAP_PHASE` of its phase, or the span holds `GAP_EXEMPT_PERIODS` periods.
    """
    return order * gap <= MAX_GAP_PHASE or repeats_in_span(order, span)


PASS_BINS = 20
"""Angle bins over the span in which [`angle_passes`][] counts passes; a reversal shorter than
one bin is no new pass (encoder noise at rest makes none)."""

MIN_PASSES = 2
"""Passes over an angle below which a spectrum peak whose order covers fewer than
`GAP_EXEMPT_PERIODS` periods of the span is marked unconfirmed ([`spectrum_orders`][])."""

PASS_SAMPLES = 20_000
"""At most this many evenly strided samples enter [`angle_passes`][]."""


def angle_passes(theta) -> float:
    """How many times the record passes over each angle: the median, over `PASS_BINS` equal bins
    of the angle's span, of the number of monotone legs with a sample in the bin.

    Legs are cut at reversals of at least one bin's width (a zig-zag filter: a retreat from
    the running extreme by less than a bin is noise, not a new leg), so a one-way sweep is one
    pass however long its pauses, a back-and-forth motion is two or more, and sweeps one after
    the other (a jump back between logs) count once each. On at most `PASS_SAMPLES` evenly
    strided samples; 0 for an empty record, 1 for one that does not move.
    """
    th = np.asarray(theta, np.float64)
    if th.size == 0:
        return 0.0
    th = th[subsample(th.size, PASS_SAMPLES)]
    lo, span = float(th.min()), float(np.ptp(th))
    if not span > 0.0:
        return 1.0
    width = span / PASS_BINS
    starts: list[int] = []  # the first sample of every leg after the first
    direction, extreme, at = 0, float(th[0]), 0
    for i, x in enumerate(th.tolist()):
        if direction == 0:  # the first leg's direction: a departure of a bin from the start
            if abs(x - extreme) >= width:
                direction, extreme, at = (1 if x > extreme else -1), x, i
        elif direction * (x - extreme) > 0:
            extreme, at = x, i
        elif direction * (extreme - x) >= width:  # a reversal: a new leg after the extreme
            starts.append(at + 1)
            direction, extreme, at = -direction, x, i
    leg = np.searchsorted(np.asarray(starts, np.intp), np.arange(th.size), side="right")
    bins = np.minimum(((th - lo) / width).astype(np.intp), PASS_BINS - 1)
    pairs = np.unique(leg * PASS_BINS + bins)
    return float(np.median(np.bincount(pairs % PASS_BINS, minlength=PASS_BINS)))


def repeats_in_span(order: float, span: float) -> bool:
    """Whether a spectrum peak of order `order` found over one pass of an angle span repeats
    itself there `GAP_EXEMPT_PERIODS` times (if not, the peak is offered but marked
    unconfirmed: the loop says so).

    Over one pass of an angle (a one-way sweep) each angle is seen once, at one time, one
    speed and one load. A peak's order is then chosen by the same pass it is to explain: over
    a few periods the periodogram finds a peak in any smooth wiggle of the residual (a drift
    along the sweep, a load-path or speed change, an unmodelled transient), which
    cross-validation inside the sweep interpolates and a TEST on another sweep does not share.
    Only an order whose periods repeat it many times shows that the shape is locked to the
    angle. Such a peak is still offered: on LARA8's one sweep, leaving them out made the
    documented run worse on TEST (TEST there interleaves with TRAIN, which a smooth function of
    the sweep serves), so the loop keeps the choice to cross-validation and tells
    the user that the angle reading is unconfirmed. A named order (an integer,
    $2 \\pm 2/N$) is a hypothesis the joint's kinematics put forward before the data."""
    return order >= _limit(span)


def min_resolvable_order(theta) -> float:
    """The lowest order with at least one full period inside the angle's span."""
    span = float(np.ptp(np.asarray(theta)))
    return math.inf if span <= 0 else 2.0 * math.pi / span


TORQUE_BIN_SAMPLES = 50
"""Samples per torque bin (equal-count bins, at most `MAX_TORQUE_BINS`) of [`torque_free`][]."""

MAX_TORQUE_BINS = 200
"""Most torque bins of [`torque_free`][]."""


def _torque_bins(torque) -> tuple[np.ndarray, np.ndarray] | None:
    """Equal-count torque bins: `(bin of each sample, samples per bin)`, None if under two."""
    t = np.asarray(torque, np.float64)
    n = t.size
    n_bins = min(MAX_TORQUE_BINS, n // TORQUE_BIN_SAMPLES)
    if n_bins < 2:
        return None
    bins = np.empty(n, np.intp)
    bins[np.argsort(t, kind="stable")] = np.arange(n) * n_bins // n
    return bins, np.bincount(bins, minlength=n_bins)


def _less_bin_means(x, bins):
    if bins is None:
        return x - x.mean()
    b, counts = bins
    return x - (np.bincount(b, x, counts.size) / counts)[b]


def torque_free(
    residual: Float[ArrayLike, " n"], torque: Float[ArrayLike, " n"]
) -> Float[np.ndarray, " n"]:
    """The residual less its mean at each torque: the part that no function of the torque
    explains (means over equal-count torque bins of `TORQUE_BIN_SAMPLES` samples, at most
    `MAX_TORQUE_BINS` bins)."""
    r = np.asarray(residual, np.float64)
    return _less_bin_means(r, _torque_bins(torque)) if r.size else r


ANGLE_SHARE = 0.5
"""The least share, of what a genuine harmonic of the same order keeps, that a spectrum peak
must keep beyond a function of the torque ([`stands_apart_from_torque`][])."""


def stands_apart_from_torque(theta, residual, torque, order: float) -> bool:
    """Whether a spectrum peak of order `order` is a function of the angle, not of the torque.

    Under a gravity-like load the torque is a function of the output angle along the path
    ($T \\propto \\cos\\theta_l$ at one arm), so the starting model's compliance misfit, a
    function of the torque, is one of the angle too and shows as order-spectrum peaks that are
    no kinematic error. Let $h = (\\cos K\\theta, \\sin K\\theta)$ and $\\tilde x$ the part of
    $x$ that no function of the torque explains ([`torque_free`][]). A harmonic keeps a share
    $\\rho = \\|\\tilde h\\|^2 / \\|h - \\bar h\\|^2$ of its variance beyond the torque, a
    property of the path alone (about 1 when the torque does not follow the angle, a few
    tenths on a gravity swing whose arm changes). The peak stands if the variance that
    $\\tilde h$ explains in $\\tilde r$ is at least `ANGLE_SHARE` $\\cdot\\rho$ of what $h$
    explains in $r$ (the Frisch-Waugh-Lovell gain of the harmonic beside a torque function,
    against its gain alone); a function of the torque keeps almost none. On at most
    `MAX_SPECTRUM_SAMPLES` evenly spaced samples.
    """
    idx = subsample(np.asarray(theta).size)
    th = np.asarray(theta, np.float64)[idx]
    r = np.asarray(residual, np.float64)[idx]
    bins = _torque_bins(np.asarray(torque, np.float64)[idx])
    h = np.column_stack([np.cos(order * th), np.sin(order * th)])
    h0 = h - h.mean(axis=0)
    ht = np.column_stack([_less_bin_means(h[:, j], bins) for j in range(2)])
    total = float(np.sum(h0 * h0))
    rho = float(np.sum(ht * ht)) / total if total > 0 else 1.0
    r0, rt = r - r.mean(), _less_bin_means(r, bins)

    def explained(x, y):
        beta = np.linalg.lstsq(x, y, rcond=None)[0]
        return float(np.sum((x @ beta) ** 2))

    return explained(ht, rt) >= ANGLE_SHARE * rho * explained(h0, r0)


def spectrum_orders(
    theta,
    residual,
    *,
    signal: str,
    order_range: tuple[float, float],
    named: list[float],
    existing: list[float],
    n_peaks: int,
    torque=None,
    single_pass: list[float] | None = None,
) -> tuple[list[tuple[float, str]], OrderSpectrum | None]:
    """Orders to try for one angle: spectrum peaks (refined) plus the named orders it covers.

    Spectrum peaks are searched only among orders with a full period inside the angle's span
    (below that the periodogram cannot place a peak). A named order (an integer, $2 \\pm 2/N$,
    ...) is offered as soon as the span covers `MIN_PERIOD_FRACTION` (a third) of its period:
    a once-per-revolution error over a ±90° swing is a smooth bump that cross-validation weighs
    against the smooth terms (torque polynomial, Coulomb, the compliance of a gravity-like
    load). Orders within half a resolution of one already in the model (`existing`) are left
    out, and so are orders that TRAIN's widest angle gap leaves undetermined
    ([`bridges_gaps`][]). With `torque` (the reference torque of the same samples), a spectrum
    peak that is a function of the torque rather than of the angle is left out
    ([`stands_apart_from_torque`][]). Where TRAIN passes over the angle only once
    ([`angle_passes`][] below `MIN_PASSES`: a one-way sweep), an offered spectrum peak whose
    own periods do not repeat it ([`repeats_in_span`][]) is appended to `single_pass` (when
    given): unconfirmed as an error locked to the angle. Returns `[(order, origin)]` (origin
    `"spectrum"` or `"grid"`) and the spectrum (None when the record resolves no order in the
    range).
    """
    full = min_resolvable_order(theta)
    lowest = max(order_range[0], full)
    named = [k for k in named if max(order_range[0], MIN_PERIOD_FRACTION * full) <= k]
    named = [k for k in named if k <= order_range[1]]
    res = 2.0 * math.pi / max(float(np.ptp(np.asarray(theta))), 1e-12)
    spec = None
    if lowest < order_range[1]:
        spec = order_spectrum(
            theta, residual, signal=signal, min_order=lowest, max_order=order_range[1]
        )
    orders: list[tuple[float, str]] = []
    for k, _ in spectrum_peaks(spec, n_peaks=n_peaks) if spec is not None else []:
        k = refine_peak(theta, residual, k, res)
        # A peak within half a resolution of a named order (an integer, 2 - 2/N, ...) cannot be
        # told apart from it by this record: report the named order unless it fits clearly worse.
        near = [m for m in named if abs(m - k) < res / 2]
        if near:
            m = min(near, key=lambda m: abs(m - k))
            p_peak, p_named = order_power(theta, residual, [k, m])
            if p_named >= 0.95 * p_peak:
                k = m
        if torque is not None and not stands_apart_from_torque(theta, residual, torque, k):
            continue  # a function of the torque along this path, not of the angle
        orders.append((k, "spectrum"))
    orders += [(k, "grid") for k in named]
    span, gap = float(np.ptp(np.asarray(theta))), widest_gap(theta)
    once = bool(orders) and angle_passes(theta) < MIN_PASSES
    out, seen = [], []
    for k, origin in orders:
        if not bridges_gaps(k, span, gap):
            continue  # TRAIN leaves a gap this order is not determined across
        if any(abs(k - e) < res / 2 for e in existing):
            continue  # already in the model
        if any(abs(k - s) < 1e-6 for s in seen):
            continue
        seen.append(k)
        out.append((k, origin))
        if once and origin == "spectrum" and not repeats_in_span(k, span):
            if single_pass is not None:  # one pass: not told from a drift along the sweep
                single_pass.append(k)
    return out, spec


def build_library(
    sig: Signals,
    torque: Float[ArrayLike, " n"],
    residual: Float[ArrayLike, " n"],
    model: ComplianceModel,
    *,
    options: LibraryOptions | None = None,
    extra_columns: tuple[str, ...] = (),
    unidentified: list[str] | None = None,
) -> tuple[list[Candidate], dict[str, OrderSpectrum]]:
    """All candidate effects for the present residual, and the order spectra used.

    Asks every registered family ([`hdjax.effects.families`][]) for its candidates.

    **Arguments:** `sig` (training [`hdjax.compliance.Signals`][]), `torque` (reference),
    `residual` (twist residual of `model`), `model` (the present
    [`hdjax.compliance.ComplianceModel`][]: its joint gives the ratio, rated torque and twist
    sign, and its effects are not offered again), `options` ([`LibraryOptions`][], default all
    families), `extra_columns` (names of usable extra columns), `unidentified` (optional: a
    list the families' one-line reasons for offering nothing are appended to, see
    [`hdjax.effects.CandidateContext.cannot_identify`][]).
    """
    options = LibraryOptions() if options is None else options
    spectra: dict[str, OrderSpectrum] = {}
    single_pass: dict[str, float] = {}  # per angle with an unconfirmed peak: its span
    resid = residual
    t_ref = np.asarray(torque, np.float64)

    def _spectrum_orders(
        signal, order_range, named, existing, n_peaks, *, residual=None, where=None
    ):
        # a family may ask for the spectrum of another signal than the residual (the ripple:
        # residual / torque, on the samples `where` the torque is usable); it is not recorded
        own = residual is None and where is None
        theta = np.asarray(sig.get(signal))
        unconfirmed: list[float] = []
        orders, spec = spectrum_orders(
            theta if where is None else theta[where],
            resid if residual is None else residual,
            signal=signal,
            order_range=order_range,
            named=named,
            existing=existing,
            n_peaks=n_peaks,
            torque=t_ref if where is None else t_ref[where],
            single_pass=unconfirmed,
        )
        if spec is not None and own:
            spectra[signal] = spec
        if unconfirmed:
            single_pass[signal] = float(np.ptp(theta))  # TRAIN's span: one line per run
        return orders

    ctx = CandidateContext(
        sig=sig,
        torque=torque,
        residual=residual,
        ratio=model.ratio,
        rated_torque=model.rated_torque,
        twist_sign=model.twist_sign,
        existing_keys=model.effect_keys,
        existing_terms=tuple(model.effect_terms),
        extra_columns=tuple(extra_columns),
        families=frozenset(options.families),
        options=options,
        spectrum_orders=_spectrum_orders,
    )
    cands: list[Candidate] = []
    for family in effects.families():
        cands += family.candidates(ctx)
    # each screened as the model it would join reads it (a hysteresis beside a skew follows
    # the twist at one instant, `AbstractTerm.beside`)
    cands = [
        dataclasses.replace(c, term=c.term.beside((*ctx.existing_terms, c.term))) for c in cands
    ]
    held = [k for k in model.effect_keys if k in VELOCITY_KEYS]
    twins = sorted({c.key for c in cands if c.key in VELOCITY_KEYS} - set(held))
    if held and twins:
        cands = [c for c in cands if c.key not in VELOCITY_KEYS]
        ctx.cannot_identify(
            " and ".join(twins),
            f"beside {held[0]}, already in the model, the twist sees one speed column (an "
            "encoder skew and viscous friction both add a twist in proportion to the speed)",
            "the motor current's friction tells them apart: see the speed reading's note",
        )
    for signal, span in single_pass.items():  # one line per run: the same at every step
        ctx.barely_identify(
            f"a harmonic:{signal} or ripple:{signal} peak below order {_limit(span):.3g}",
            f"TRAIN passes over {signal} once (a one-way sweep of {span:.3g} rad), so such a "
            "peak, still offered as a candidate, cannot be told from a drift along the sweep; "
            "an effect the loop adds at such an order may not carry to another motion",
            "record the range at least twice (back and forth, or two sweeps) to confirm it",
        )
    if unidentified is not None:
        unidentified.extend(ctx.unidentified)
    return cands, spectra


def _limit(span: float) -> float:
    """The lowest order whose periods repeat `GAP_EXEMPT_PERIODS` times over `span` rad (the
    threshold of [`repeats_in_span`][], and the order the one-pass note names)."""
    return 2.0 * math.pi * GAP_EXEMPT_PERIODS / span if span > 0 else math.inf
