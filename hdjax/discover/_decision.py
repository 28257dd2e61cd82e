"""The loop's decision: which scored candidates are eligible, which trial is added, and when
the loop stops (the rule in words: [`hdjax.discover._options.stopping_rule`][]).

Records, not tuples, travel between the stages:

- [`Scored`][]: a candidate's cross-validated twist gain on the standard folds and on every
  resampled fold assignment ([`hdjax.discover._loop.score_candidates`][]);
- [`Ranked`][]: the best grid member of one key, with the key's stability;
- [`Trial`][]: a shortlisted candidate calibrated into the model and cross-validated in the
  torque domain.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from ..compliance import ComplianceModel
from ..effects import current_viscous_slope, velocity_reading
from ._library import VELOCITY_KEYS
from ._options import DiscoverOptions, _percent
from ._pipeline import CrossValidation, PipelineData, within_one_se


class Scored(NamedTuple):
    """One candidate's scores in one step."""

    candidate: Any
    gain: float
    """The share of the cross-validated twist error it removes (standard folds)."""
    fold_gains: np.ndarray
    selected: bool
    """Whether pysindy's STLSQ keeps one of its columns."""
    resampled: np.ndarray
    """Its gains over the resampled fold assignments."""


class Ranked(NamedTuple):
    """The best grid member of a key, with the key's stability and all its members."""

    candidate: Any
    gain: float
    fold_gains: np.ndarray
    selected: bool
    stability: float
    """The share of resampled fold assignments in which some member removes `min_gain`."""
    members: list[tuple[float, Any, np.ndarray]]
    """`(gain, candidate, fold gains)` of every grid member of the key, best first."""


@dataclasses.dataclass(frozen=True)
class Trial:
    """A shortlisted candidate, calibrated into the model and cross-validated in the torque
    domain (whole pipeline per fold)."""

    candidate: Any
    gain: float
    fold_gains: np.ndarray
    stability: float
    model: ComplianceModel | None
    estimate: np.ndarray | None
    cv: CrossValidation

    @property
    def cv_rms(self) -> float:
        """The cross-validated torque RMS [N·m] with the candidate added."""
        return self.cv.torque_rms

    @property
    def key(self) -> str:
        return self.candidate.key


def rank(scored: list[Scored], min_gain: float) -> list[Ranked]:
    """The best grid member of each key, best gain first, with the key's stability: the share
    of resampled fold assignments in which some member of the key removes at least
    `min_gain`."""
    best, stable, members = {}, {}, {}
    for s in scored:
        key = s.candidate.key
        res = s.resampled
        hit = res >= min_gain if res.size else np.ones(1, bool) * (s.gain >= min_gain)
        stable[key] = stable.get(key, np.zeros_like(hit)) | hit
        members.setdefault(key, []).append((s.gain, s.candidate, s.fold_gains))
        if key not in best or s.gain > best[key].gain:
            best[key] = s
    out = [
        Ranked(
            s.candidate,
            s.gain,
            s.fold_gains,
            s.selected,
            float(np.mean(stable[k])),
            sorted(members[k], key=lambda m: -m[0]),
        )
        for k, s in best.items()
    ]
    return sorted(out, key=lambda r: -r.gain)


def eligible(
    ranked: list[Ranked],
    options: DiscoverOptions,
    aliased: Callable[[Ranked, Ranked], bool] | None = None,
) -> list[Ranked]:
    """The shortlist of [`rank`][]'s ranking: selected by the sparse regression, removing at
    least `min_gain` of the cross-validated twist error on the standard folds, and stable
    (doing so in at least `min_stability` of the resampled fold assignments), best first
    ([`shortlist_rounds`][] takes them in rounds).

    With `aliased(r, s)` (whether TRAIN can tell `r` from an earlier `s`), an alias of a
    candidate already on the list takes no place of its own: its trial would score the same
    column again (an encoder skew and viscous friction on the motor and on the output are one
    speed column on most records), where the place can go to a different reading of the
    residual. The report still names it among the step's aliases.
    """
    out: list[Ranked] = []
    for r in ranked:
        if not (r.selected and r.gain >= options.min_gain and r.stability >= options.min_stability):
            continue
        if aliased is not None and any(aliased(r, s) for s in out):
            continue
        out.append(r)
    return out


def shortlist_rounds(
    eligible_: list[Ranked],
    options: DiscoverOptions,
    current_rms: float,
    try_round: Callable[[list[Ranked], list[Trial]], list[Trial]],
) -> tuple[list[Ranked], list[Trial]]:
    """The shortlist and its trials: the eligible candidates in rounds of `n_shortlist`, at
    most `n_shortlist_rounds` of them, a round tried (`try_round(round, trials so far)` returns
    all trials after it) only when no trial before it [`qualifies`][] against the model's
    cross-validated torque error `current_rms`.

    The twist gain that ranks the candidates is not the torque error that accepts them: on a
    sweep, an effect that explains much of the twist can extrapolate badly where a fold's
    held-out block leaves its training part (a memory state, a harmonic over less than a
    period), while a smaller, simpler one predicts. When every trial of a round is refused,
    the next eligible candidates get their trials before the loop stops; no round follows one
    that qualifies, so the cost and the chance of a false step grow only where the loop would
    otherwise stop.
    """
    n = options.n_shortlist
    shortlist: list[Ranked] = []
    trials: list[Trial] = []
    for i in range(0, min(len(eligible_), n * options.n_shortlist_rounds), n):
        if any(qualifies(t.cv_rms, current_rms, options) for t in trials):
            break
        part = eligible_[i : i + n]
        shortlist += part
        trials = try_round(part, trials)
    return shortlist, trials


def qualifies(cv_rms: float, current_rms: float, options: DiscoverOptions) -> bool:
    """Whether a cross-validated torque RMS lowers the current one by `min_torque_gain` (the
    acceptance test of every trial, written once)."""
    return bool(cv_rms <= (1.0 - options.min_torque_gain) * current_rms)


COLLINEAR_SHARE = 0.1
"""A determined share ([`hdjax.discover._aliases.determination`][]) below this, a variance
inflation factor over 10, marks a seriously collinear candidate (the usual rule of thumb:
Kutner, Nachtsheim & Neter, *Applied Linear Regression Models*, Section 10.5)."""

DETERMINED_RATIO = 0.5
"""A seriously collinear tied trial is set aside when another tied trial's determined share is
more than 1 / this times its own: a variance inflation up to twice the lowest counts as
equally determined."""


def choose(
    trials: list[Trial],
    current: CrossValidation,
    blocks: np.ndarray,
    options: DiscoverOptions,
    notes: list[str],
    determined: Callable[[Trial], float] | None = None,
) -> Trial | None:
    """The trial to add, or `None` (then the loop stops) when none [`qualifies`][].

    Of the trials that qualify and lie within one standard error of the lowest
    ([`hdjax.discover._pipeline.within_one_se`][], paired over the held-out `blocks`), the one
    with the fewest columns, then the lowest error: cross-validated errors the held-out blocks
    cannot tell apart do not choose; the simpler effect is named, and a richer one must earn
    its columns.

    **Ties.** Trials whose errors differ by less than `min_torque_gain` (the least gain the
    loop counts, [`qualifies`][]) are tied. A tied trial that is seriously collinear with the
    model's columns (`determined`, the share of its column variance they do not span, below
    `COLLINEAR_SHARE`) is set aside when another tied trial is determined more than twice as
    well (`DETERMINED_RATIO`); the lowest error of the rest is added. Of two effects that fit
    TRAIN alike, the one whose coefficient TRAIN fixes only through a cancellation with the
    model's columns (a speed column on a sweep at one speed, where the compliance absorbs it)
    predicts worst where TEST leaves TRAIN's regime.
    """
    trials = sorted(trials, key=lambda t: t.cv_rms)
    if not trials or not qualifies(trials[0].cv_rms, current.torque_rms, options):
        return None
    lowest = trials[0]
    near = [
        t
        for t in trials
        if qualifies(t.cv_rms, current.torque_rms, options)
        and (t is lowest or within_one_se(t.cv, lowest.cv, blocks))
    ]
    fewest = min(len(t.candidate.term.names()) for t in near)
    near = [t for t in near if len(t.candidate.term.names()) == fewest]
    best = near[0]
    tied = [t for t in near if not qualifies(best.cv_rms, t.cv_rms, options)]
    if determined is not None and len(tied) > 1:
        share = {t.key: determined(t) for t in tied}
        top = max(share.values())
        kept = [
            t
            for t in tied
            if share[t.key] >= COLLINEAR_SHARE or share[t.key] >= DETERMINED_RATIO * top
        ]
        if kept != tied:
            gone = ", ".join(f"{t.key} ({share[t.key]:.3g})" for t in tied if t not in kept)
            notes.append(
                f"{gone}: tied with the best (errors within {_percent(options.min_torque_gain)}"
                f"), but seriously collinear with the model's columns (a share of its column's "
                f"variance they do not span below {COLLINEAR_SHARE:g}) and determined less than "
                f"half as well as {max(kept, key=lambda t: share[t.key]).key} ({top:.3g})"
            )
        best = kept[0]
    if best is not lowest:
        why = (
            "with fewer columns"
            if fewest < len(lowest.candidate.term.names())
            else "tied and better determined by TRAIN"
        )
        notes.append(
            f"{best.key} ({best.cv_rms:.4g} N·m) chosen over {lowest.key} ({lowest.cv_rms:.4g} "
            f"N·m): within one standard error over the held-out blocks, {why}"
        )
    return best


def beats_start(path: list[CrossValidation], blocks: np.ndarray) -> bool:
    """Whether the loop's path as a whole beats the starting model: the final model's
    cross-validated torque error lies beyond one standard error below the starting model's
    ([`hdjax.discover._pipeline.within_one_se`][], paired over the held-out `blocks`; the
    one-standard-error rule of Hastie, Tibshirani & Friedman, *The Elements of Statistical
    Learning*, Section 7.10).

    `path[i]` is the cross-validation of the model after `i` effects, `path[0]` the starting
    model's. The test of the whole path comes before the single steps (a protected procedure,
    as Fisher's least significant difference follows the overall test): on a joint without an
    undeclared effect, a step of a few percent that the held-out blocks cannot confirm is the
    typical false discovery, and it is refused; once the path is confirmed, a weak step after
    a strong one is judged by `min_torque_gain` alone, which keeps true small effects. A path
    without steps beats nothing and keeps nothing: `True`.
    """
    return len(path) < 2 or not within_one_se(path[0], path[-1], blocks)


def taken_back_note(steps, path: list[CrossValidation]) -> str:
    """The note of a path that [`beats_start`][] refuses: which steps are taken back and why,
    and what the user can do next."""
    keys = ", ".join(s.key for s in steps)
    errors = " -> ".join(f"{c.torque_rms:.4g}" for c in path)
    return (
        f"taken back: {keys}. The final model's cross-validated torque error lies within one "
        f"standard error of the starting model's (after each step: {errors} N·m), paired over "
        "the held-out blocks: TRAIN cannot confirm that the joint has an effect the starting "
        "model lacks, so the starting model is kept (the one-standard-error rule). A longer "
        "TRAIN record (more held-out blocks) can confirm a small effect"
    )


def _twist_per_speed(model: ComplianceModel, key: str) -> float:
    """The twist [rad] per rad/s of link speed that the fitted term `key` adds."""
    coef = np.asarray(model.coef)
    i = model.n_coef - model.n_effect
    for term in model.effect_terms:
        m = len(term.names())
        if term.key == key:
            c = float(coef[i])
            if key == "skew:encoders":
                return c  # the coefficient is the delay: twist = delay * speed
            per = c / term.scale
            return per * model.ratio if term.signal == "omega_m" else per
        i += m
    return float("nan")


def _reading(trial: Trial, data: PipelineData) -> tuple[str | None, str]:
    """Which key of [`VELOCITY_KEYS`][] the data supports for a speed-term trial, and the
    sentence ([`hdjax.effects.velocity_reading`][]): the trial's twist per speed, over the
    data's compliance where the speed is, against the current's own viscous slope. The key is
    `None` when the log has no current to decide by."""
    model = trial.model
    view = data.view()
    # the model's own compliance where the speed is (weighted by the speed's square)
    w = np.asarray(view.sig.omega_l) ** 2
    seg = np.searchsorted(np.asarray(model.knots), view.torque, side="right")
    k_local = np.asarray(model.k)[seg]
    k = float(np.sum(w * k_local) / np.sum(w)) if np.sum(w) > 0 else float("nan")
    per_speed = _twist_per_speed(model, trial.key) / k if k else float("nan")
    slope = current_viscous_slope(
        np.asarray(view.sig.current), view.torque, np.asarray(view.sig.omega_l)
    )
    sentence = velocity_reading(per_speed, slope)
    if slope is None:
        return None, sentence
    return supported_key(trial.key, sentence.startswith("skew")), sentence


def supported_key(key: str, skew: bool) -> str:
    """The key of [`VELOCITY_KEYS`][] that a reading supports for a trial of `key`: the skew
    when the current's viscous slope is too small for the twist's speed term (`skew`), else
    friction on the trial's own side (`viscous:omega_l` for a skew trial: friction the twist
    sees against the output torque acts at the output). The current holds the friction of
    both sides in one slope, so it tells a skew from friction, never one side from the other.
    """
    if skew:
        return "skew:encoders"
    return key if key.startswith("viscous:") else "viscous:omega_l"


def read_speed_trials(
    trials: list[Trial],
    data: PipelineData,
    try_key: Callable[[str], Trial | None],
    taken: frozenset[str] = frozenset(),
) -> list[Trial]:
    """The trials with each speed-term trial ([`VELOCITY_KEYS`][]) replaced by the trial of
    the reading the current supports ([`_reading`][]), tried through `try_key(key)` unless
    the reading's key is among the trials or `taken` (tried in an earlier round).

    An encoder skew and viscous friction fit one speed column to first order, so the shortlist
    gives the group one place ([`eligible`][]), to whichever member the twist gain ranks first.
    Their trials still differ: the skew is refitted exactly (one encoder interpolated by the
    delay), a motor-side friction column carries the harmonics of the motor's speed. The group's
    place is therefore tried with the member the data supports before the trials compete: a
    trial the current contradicts is replaced when the reading's own trial qualifies, and
    kept otherwise (the chosen trial is read again by [`speed_reading`][], which writes the
    sentence).
    """
    out, seen = [], {t.key for t in trials} | taken
    for t in trials:
        if t.key in VELOCITY_KEYS:
            want, _ = _reading(t, data)
            if want is not None and want != t.key and want not in seen:
                other = try_key(want)
                if other is not None:
                    seen.add(want)
                    out.append(other)
                    continue
        out.append(t)
    return out


def speed_reading(
    best: Trial,
    trials: list[Trial],
    data: PipelineData,
    notes: list[str],
    try_key: Callable[[str], Trial | None] | None = None,
) -> Trial:
    """When the chosen trial is a speed term ([`VELOCITY_KEYS`][]), which reading the data
    supports ([`_reading`][]). The chosen trial is swapped for the other reading's (tried now
    through `try_key(key)` when it was not among the trials), and the sentence is noted either
    way."""
    key = best.key
    if key not in VELOCITY_KEYS:
        return best
    want, sentence = _reading(best, data)
    if want is not None and key != want:
        other = [t for t in trials if t.key == want]
        if not other and try_key is not None:
            other = [t for t in [try_key(want)] if t is not None]
        if other:
            notes.append(f"{want} chosen over {key}, which fits the same speed column: {sentence}")
            return other[0]
    notes.append(f"{key}: {sentence}")
    return best


def ranking_rows(ranked: list[Ranked]) -> list[dict]:
    """The report's ranking: the ten best keys and their scores."""
    return [
        dict(
            key=r.candidate.key,
            cv_gain=r.gain,
            min_fold_gain=float(np.min(r.fold_gains)),
            sindy=r.selected,
            stability=r.stability,
            origin=r.candidate.origin,
        )
        for r in ranked[:10]
    ]


def no_step_note(trials, shortlist, cv, options) -> str:
    """Why no candidate was added."""
    if shortlist and not trials:
        return (
            "stopped: the eligible candidates ("
            + ", ".join(r.candidate.key for r in shortlist)
            + ") could not be calibrated to an invertible model"
        )
    if not trials:
        return (
            "stopped: no candidate selected by the sparse regression removes at least "
            f"{_percent(options.min_gain)} of the cross-validated twist error in at least "
            f"{_percent(options.min_stability)} of {options.n_resamples} resampled fold assignments"
        )
    tried = ", ".join(f"{t.key} {t.cv_rms:.4g} N·m" for t in sorted(trials, key=lambda t: t.cv_rms))
    return (
        f"stopped: no candidate lowers the cross-validated torque error "
        f"({cv.torque_rms:.4g} N·m) by {_percent(options.min_torque_gain)} (tried: {tried})"
    )
