"""The residual loop: find what the model gets wrong, name the effect, add it, refit, repeat.

1. Calibrate the starting model (the paper's, Song et al. Section II) by least squares on the
   training recording.
2. Compute its twist residual on the training data and the order spectra of that residual
   against both angles; build the candidate library ([`hdjax.discover.build_library`][]).
3. Select with sparse regression (pysindy STLSQ on the library made orthogonal to the model)
   and rank the selected candidates by their cross-validated explained variance of the
   residual, *within the training data only*.
4. **Stopping rule.** Add the best-ranked selected candidate that removes at least `min_gain`
   (default 5 %) of the model's cross-validated twist error overall *and* at least half of that
   in every fold (a candidate that helps on average but not everywhere is fitting a
   coincidence of part of the record, such as an angle harmonic standing in for a function of
   torque on a trajectory where the load follows the angle). Stop when no candidate qualifies,
   or after `max_effects` effects.
5. Refit by least squares with the new columns, re-estimate torque on the test recording by
   inversion (eqs. (26)-(27)) and record the errors. The test recording is never used to choose.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable

import equinox as eqx
import numpy as np

from .._errors import CalibrationError, DataError, HdjaxError, InversionError
from .._joint import Joint
from .._metrics import ErrorMetrics, error_metrics
from .._recording import Recording
from ..compliance import (
    ComplianceModel,
    calibrate_lstsq,
    estimate_torque,
    merge_sparse_segments,
)
from ..compliance._lstsq import _design, prepare
from ..effects import TORQUE_PATH
from ._library import LibraryOptions, build_library, candidate_columns
from ._select import cv_gains, fold_basis, sindy_select
from ._spectrum import OrderSpectrum, order_spectrum

ARCSEC = 180.0 * 3600.0 / np.pi


@dataclasses.dataclass(frozen=True)
class DiscoverOptions:
    """Settings of the residual loop (see the module docstring for the stopping rule)."""

    max_effects: int = 5
    min_gain: float = 0.05
    n_folds: int = 5
    block: int = 200
    sindy_threshold: float = 0.02
    library: LibraryOptions = dataclasses.field(default_factory=LibraryOptions)
    n_segments: int = 5
    poly_order: int = 6
    fourier_order: int = 3
    per_segment: bool = False
    current_scale: float | None = None


@dataclasses.dataclass
class StepResult:
    """One added effect with its scores and the errors after adding it."""

    key: str
    family: str
    term: object
    cv_gain: float
    fold_gains: list[float]
    test: ErrorMetrics
    twist_rms_arcsec: float
    ranking: list[dict]
    spectra: dict[str, OrderSpectrum]
    model: ComplianceModel
    torque_estimate: np.ndarray


@dataclasses.dataclass
class DiscoveryResult:
    """Everything the loop found (see [`hdjax.discover.discover`][])."""

    baseline_model: ComplianceModel
    baseline: ErrorMetrics
    baseline_twist_rms_arcsec: float
    baseline_estimate: np.ndarray
    steps: list[StepResult]
    final_model: ComplianceModel
    final: ErrorMetrics
    final_spectra: dict[str, OrderSpectrum]
    final_ranking: list[dict]
    notes: list[str]
    test: Recording
    train_residual_final: np.ndarray
    seconds: float

    @property
    def effects(self) -> list[str]:
        return [s.key for s in self.steps]


def _quiet_calibrate(model, data, notes, throw=True):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = calibrate_lstsq(model, data, throw=throw)
    for w in caught:
        notes.append(str(w.message))
    return res


def _merge_knot(model: ComplianceModel, j: int) -> ComplianceModel:
    """Remove the knot between segment `j` and its neighbour towards 0 N·m."""
    lo, hi = model.segment_bounds[j]
    knot = lo if lo > 0.0 else hi
    return model.restructured(knots=[k for k in model.knots if k != knot])


def _calibrate_monotone(model, train, notes):
    """Calibrate; while an outer segment's compliance comes out non-positive, merge it inwards."""
    while True:
        res = _quiet_calibrate(model, train, notes, throw=False)
        k = np.asarray(res.model.k)
        act = np.asarray(res.model.active[: model.n_segments])
        bad = [
            j
            for j, (lo, hi) in enumerate(model.segment_bounds)
            if act[j] and not k[j] > 0 and not lo <= 0.0 < hi
        ]
        if not bad:
            if any(m.startswith("rank-deficient") or "not increasing" in m for m in res.messages):
                raise CalibrationError(
                    next(m for m in res.messages if "rank" in m or "not increasing" in m)
                )
            return res
        j = max(bad, key=lambda j: abs(sum(model.segment_bounds[j][:1])))
        lo, hi = model.segment_bounds[j]
        notes.append(
            f"torque segment [{lo:.4g}, {hi:.4g}) N·m calibrated to a non-positive compliance "
            f"({k[j]:.3g} rad/(N·m)): merged into its neighbour"
        )
        model = _merge_knot(model, j)


def calibrate_baseline(train: Recording, joint: Joint, options: DiscoverOptions, notes: list):
    """The starting model (paper structure) calibrated on `train`, with documented fallbacks.

    Segments the torque hardly covers, or whose compliance comes out non-positive, are merged
    into their inner neighbour. If the model is rank-deficient on the data (e.g. a current that
    is the reference torque itself), fall back in order to shared coefficients, then without
    the current polynomial, then without the kinematic-error term, and say so in `notes`.
    """
    scale = options.current_scale or float(np.max(np.abs(np.asarray(train.current)))) or 1.0
    attempts = []
    for kw in (
        dict(
            per_segment=options.per_segment,
            poly_order=options.poly_order,
            fourier_order=options.fourier_order,
        ),
        dict(per_segment=False, poly_order=options.poly_order, fourier_order=options.fourier_order),
        dict(per_segment=False, poly_order=0, fourier_order=options.fourier_order),
        dict(per_segment=False, poly_order=0, fourier_order=0),
    ):
        if kw not in attempts:
            attempts.append(kw)
    last = None
    for i, kw in enumerate(attempts):
        model = ComplianceModel.paper(
            joint,
            n_segments=options.n_segments,
            current_scale=scale,
            kinematic="paper" if kw["fourier_order"] else "none",
            **kw,
        )
        model, merged = merge_sparse_segments(model, np.asarray(train.torque))
        trial_notes = list(merged)
        try:
            res = _calibrate_monotone(model, train, trial_notes)
        except (CalibrationError, InversionError) as err:
            last = err
            notes.append(f"starting model {kw} not calibrated: {err}")
            continue
        notes.extend(trial_notes)
        if i:
            notes.append(f"starting model fell back to {kw}")
        return res.model
    raise CalibrationError(f"no starting model could be calibrated on the training data: {last}")


def _test_errors(model, test, rated):
    est = estimate_torque(model, test)
    torque = np.asarray(est.torque)
    return error_metrics(torque, test.torque, rated), torque


def _twist_rms(model, data) -> float:
    sig, torque = training_data(model, data)  # path terms driven as at calibration
    r = np.asarray(sig.twist) - np.asarray(model.predict_twist(sig, torque))
    return float(np.sqrt(np.mean(r**2)) * ARCSEC)


def _usable_columns(train: Recording) -> tuple[str, ...]:
    return tuple(name for name, x in train.extras.items() if float(np.ptp(np.asarray(x))) > 0.0)


def training_data(model: ComplianceModel, train: Recording):
    """Training signals and reference torque, with the present model's torque *estimate* as the
    driver of path-dependent candidates (hysteresis is computed from the torque being
    estimated, causally, never from the reference sensor)."""
    sig, torque = prepare(model, train)
    t_est = estimate_torque(model, sig).torque
    extras = dict(sig.extras)
    extras[TORQUE_PATH] = t_est
    return eqx.tree_at(lambda s: s.extras, sig, extras), torque


def score_candidates(model, train, options: DiscoverOptions, extra_columns):
    """Library, spectra, and per-candidate (gain, fold gains, sindy-selected) for one step."""
    sig, torque = training_data(model, train)
    a_full = np.asarray(_design(model, sig, torque))
    active = np.asarray(model.active)
    a = a_full[:, active]
    y = np.asarray(sig.twist)
    resid = y - a_full @ np.asarray(model.coef)
    cands, spectra = build_library(
        sig,
        torque,
        resid,
        ratio=model.ratio,
        rated_torque=model.rated_torque,
        existing_keys=model.effect_keys,
        existing_terms=model.effect_terms,
        options=options.library,
        extra_columns=extra_columns,
        twist_sign=model.twist_sign,
    )
    if not cands:
        return [], spectra, resid
    cols = [candidate_columns(c.term, sig, torque) for c in cands]
    basis = fold_basis(a, y, options.n_folds, options.block)
    flat_cols, owner = [], []
    for i, c in enumerate(cols):
        for j in range(c.shape[1]):
            flat_cols.append(c[:, j])
            owner.append(i)
    selected = sindy_select(
        a, resid, flat_cols, [str(o) for o in owner], threshold=options.sindy_threshold
    )
    owner = np.asarray(owner)
    usable = [i for i, c in enumerate(cols) if np.isfinite(c).all() and np.ptp(c, axis=0).max() > 0]
    gains = cv_gains(basis, [cols[i] for i in usable])
    scored = [
        (cands[i], gain, folds, bool(selected[owner == i].any()))
        for i, (gain, folds) in zip(usable, gains)
    ]
    return scored, spectra, resid


def _best_per_key(scored):
    best = {}
    for cand, gain, folds, sel in scored:
        if cand.key not in best or gain > best[cand.key][1]:
            best[cand.key] = (cand, gain, folds, sel)
    return sorted(best.values(), key=lambda s: -s[1])


def discover(
    train: Recording,
    test: Recording,
    joint: Joint,
    options: DiscoverOptions = DiscoverOptions(),
    *,
    progress: Callable[[str], None] | None = None,
) -> DiscoveryResult:
    """Run the residual loop (see the module docstring).

    **Arguments:** `train` (calibration and selection), `test` (reporting only; needs a
    reference torque), `joint`, `options`, `progress` (called with one line per stage).

    **Returns:** a [`hdjax.discover.DiscoveryResult`][].
    """
    say = progress or (lambda _: None)
    t_start = time.perf_counter()
    for rec, name in ((train, "TRAIN"), (test, "TEST")):
        if rec.torque is None:
            raise DataError(f"{name} ({rec.source}) has no 'torque' column; the loop needs it")
    notes: list[str] = []
    model = baseline_model = calibrate_baseline(train, joint, options, notes)
    base_metrics, base_est = _test_errors(model, test, joint.rated_torque)
    base_twist = _twist_rms(model, test)
    say(f"baseline: test torque RMS {base_metrics.rms:.4g} N·m, max {base_metrics.max:.4g} N·m")
    extra_columns = _usable_columns(train)
    steps: list[StepResult] = []
    excluded: set[str] = set()
    ranking: list[dict] = []
    spectra: dict = {}
    resid = None
    while True:
        scored, spectra, resid = score_candidates(model, train, options, extra_columns)
        ranked = _best_per_key([s for s in scored if s[0].key not in excluded])
        ranking = [
            dict(key=c.key, cv_gain=g, min_fold_gain=float(np.min(f)), sindy=s, origin=c.origin)
            for c, g, f, s in ranked[:10]
        ]
        if len(steps) >= options.max_effects:
            notes.append(f"stopped: reached max_effects = {options.max_effects}")
            break
        chosen = next(
            (
                (cand, gain, folds)
                for cand, gain, folds, sel in ranked
                if sel and gain >= options.min_gain and np.all(folds >= options.min_gain / 2)
            ),
            None,
        )
        if chosen is None:
            notes.append(
                "stopped: no candidate selected by the sparse regression removes at least "
                f"{options.min_gain:.0%} of the cross-validated twist error (and half of that in "
                "every fold)"
            )
            break
        cand, gain, folds = chosen
        try:
            data = training_data(model, train) if cand.term.torque_kind == "path" else train
            new_model = _quiet_calibrate(model.with_effects(cand.term), data, notes).model
            metrics, est = _test_errors(new_model, test, joint.rated_torque)
        except (CalibrationError, InversionError) as err:
            notes.append(f"candidate {cand.key} could not be added: {err}")
            excluded.add(cand.key)
            continue
        model = new_model
        steps.append(
            StepResult(
                key=cand.key,
                family=cand.family,
                term=cand.term,
                cv_gain=gain,
                fold_gains=[float(x) for x in folds],
                test=metrics,
                twist_rms_arcsec=_twist_rms(model, test),
                ranking=ranking,
                spectra=spectra,
                model=model,
                torque_estimate=est,
            )
        )
        say(
            f"step {len(steps)}: added {cand.key} (CV gain {gain:.1%}); test torque RMS "
            f"{metrics.rms:.4g} N·m, max {metrics.max:.4g} N·m"
        )
    final = steps[-1].test if steps else base_metrics
    return DiscoveryResult(
        baseline_model=baseline_model,
        baseline=base_metrics,
        baseline_twist_rms_arcsec=base_twist,
        baseline_estimate=base_est,
        steps=steps,
        final_model=model,
        final=final,
        final_spectra=spectra,
        final_ranking=ranking,
        notes=list(dict.fromkeys(notes)),
        test=test,
        train_residual_final=resid,
        seconds=time.perf_counter() - t_start,
    )


def residual_spectra(model: ComplianceModel, data, *, orders=(0.5, 8.0)) -> dict:
    """Order spectra of a model's twist residual against both angles (for reports)."""
    sig, torque = prepare(model, data)
    r = np.asarray(sig.twist) - np.asarray(model.predict_twist(sig, torque))
    out = {}
    for signal in ("theta_m", "theta_l"):
        theta = np.asarray(sig.get(signal))
        lo = max(orders[0], 2 * np.pi / max(np.ptp(theta), 1e-12))
        if lo < orders[1]:
            out[signal] = order_spectrum(theta, r, signal=signal, min_order=lo, max_order=orders[1])
    return out


__all__ = ["DiscoverOptions", "DiscoveryResult", "StepResult", "discover", "HdjaxError"]
