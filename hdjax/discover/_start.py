"""The starting model: one function that builds and calibrates it, for `hdjax run` and
`hdjax discover` alike, so that the same data and the same `[model]` settings give the same
starting model and the same starting error."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .._custom_types import ArrayLike, Float, Int
from .._errors import CalibrationError, ConfigError, InversionError
from .._features import Signals
from .._joint import Joint
from .._recording import Recording
from .._solution import Solution
from ..compliance import ComplianceModel, merge_sparse_segments
from ..compliance.internal import failure_message
from ..config.internal import structure_settings
from ._options import DiscoverOptions
from ._pipeline import (
    PipelineData,
    calibrate,
    estimate,
    fit_merging,
    has_path,
    pipeline_signals,
)
from ._scores import _as_data


def paper_model(table: Mapping, joint: Joint, scale: float) -> ComplianceModel:
    """The paper's model structure (Song et al. 2019, eqs. (7)-(10)) from a validated `[model]`
    table, the starting model of `hdjax run` and of the loop; keys it does not hold take
    `ComplianceModel.paper`'s defaults (a fleet manifest's table holds fewer). Motor currents
    are divided by `scale`."""
    return ComplianceModel.paper(joint, current_scale=scale, **structure_settings(table))


def fallback_tables(table: Mapping) -> list[dict]:
    """The structures tried in turn when a calibration fails: `table`'s own, then with shared
    coefficients (`per_segment = false`), then without the current polynomial
    (`poly_order = 0`), then without the kinematic-error term (`kinematic = "none"`); each
    one only once."""
    first = structure_settings(table)
    chain = [first, {**first, "per_segment": False}]
    chain.append({**chain[-1], "poly_order": 0})
    chain.append({**chain[-1], "kinematic": "none", "fourier_order": 0})
    out: list[dict] = []
    for kw in chain:
        if kw not in out:
            out.append(kw)
    return out


def toml_settings(kw: Mapping) -> str:
    """`kw` as `[model]` lines of an experiment file, on one line (`a = 1, b = true`)."""

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return f"{v:g}" if isinstance(v, float) else str(v)

    return ", ".join(f"{k} = {value(v)}" for k, v in kw.items())


def calibrate_start(
    table: Mapping,
    joint: Joint,
    pair: tuple[Signals, Float[ArrayLike, " n"]],
    notes: list[str],
    *,
    scale: float,
    chunk: int = 0,
    rows: Int[np.ndarray, " m"] | None = None,
    throw: bool = True,
) -> Solution:
    """The starting model of the `[model]` structure `table` (Song et al. 2019, eqs. (7)-(10),
    currents divided by `scale`), calibrated on `pair` = (signals, reference torque) by
    shape-constrained least squares (eq. (17) with every segment compliance above a floor).

    Before calibrating, segments the torque hardly covers are merged into their inner
    neighbour ([`hdjax.compliance.merge_sparse_segments`][]); after it, every outer segment
    the constraint holds at its floor is merged too and the model refitted. When the design is
    rank-deficient on the data (e.g. a current that is the reference torque itself), the
    structures of `fallback_tables` are tried in turn. Every merge and fallback is said in
    `notes`. `rows`: the rows of `pair` that are TRAIN (default all); `chunk`: the fits
    accumulated over chunks of that many samples.

    **Returns:** the calibration's [`hdjax.Solution`][] (`value`: the calibrated model).

    **Raises:** [`hdjax.CalibrationError`][] when no structure can be calibrated, unless
    `throw` is false: then the failed calibration of `table`'s own structure is returned (its
    `result` says why).
    """
    torque = np.asarray(pair[1])
    torque = torque if rows is None else torque[rows]
    last = first = None
    tables = fallback_tables(table)
    for i, kw in enumerate(tables):
        model, merged = merge_sparse_segments(paper_model(kw, joint, scale), torque)
        trial = list(merged)
        try:
            res = fit_merging(model, pair, trial, chunk=chunk, rows=rows, throw=False)
            first = res if first is None else first
            if not res.ok:
                raise CalibrationError(failure_message(res))
        except (CalibrationError, InversionError) as err:
            last = err
            notes.append(f"starting model ({toml_settings(kw)}) not calibrated: {err}")
            continue
        notes.extend(trial)
        if i:
            changed = {k: v for k, v in kw.items() if tables[0].get(k) != v}
            notes.append(f"starting model fell back to {toml_settings(changed)}")
        return res
    if not throw and first is not None:
        return first
    raise CalibrationError(f"no starting model could be calibrated on the training data: {last}")


def calibrate_structure(structure: ComplianceModel, train: Recording, notes: list[str]) -> Solution:
    """Calibrate the structure of `structure` (a saved model: its segments, terms and effects,
    as `hdjax discover` found them; its coefficients are not used) on the recording `train` by
    the residual loop's own fit: shape-constrained least squares (eq. (17)), the hysteresis
    driver the model's own estimate (three rounds, from `structure`'s estimate), and terms
    whose column follows their coefficient (an encoder skew) refitted to their fixed point.
    This is what `hdjax run` does with `[model] structure`: on the loop's TRAIN it gives the
    loop's final model.

    **Returns:** the last fit's [`hdjax.Solution`][] (`value`: the calibrated model).
    """
    data = pipeline_signals(train, structure.ratio, structure.twist_sign, structure.velocity)
    if data.torque is None:
        raise ConfigError(f"{train.source}: no 'torque' column to calibrate the structure on")
    start = estimate(structure, data) if has_path(structure) else None
    fits: list[Solution] = []
    calibrate(structure, data, notes, start, fits=fits)
    return fits[-1]


def start_table(options: DiscoverOptions) -> dict:
    """The `[model]` settings of the loop's starting model (those `hdjax run` reads too)."""
    return {
        "n_segments": options.n_segments,
        "poly_order": options.poly_order,
        "kinematic": "paper" if options.fourier_order else "none",
        "fourier_order": options.fourier_order,
        "per_segment": options.per_segment,
        "velocity": "difference",
    }


def calibrate_baseline(
    train: Recording | PipelineData, joint: Joint, options: DiscoverOptions, notes: list[str]
) -> ComplianceModel:
    """The starting model (paper structure, settings `start_table(options)`) calibrated on
    `train` by [`hdjax.discover.calibrate_start`][], the function `hdjax run` calibrates
    through: segments the data does not determine merged, documented fallbacks, said in
    `notes`. `train` is a recording, or its pipeline signals (a part of a log with `rows`).
    """
    data = _as_data(None, train, joint)
    current = data.part(data.sig.current)
    scale = options.current_scale or float(np.max(np.abs(current))) or 1.0
    res = calibrate_start(
        start_table(options),
        joint,
        data.pair(),
        notes,
        scale=scale,
        chunk=options.chunk,
        rows=data.rows,
    )
    return res.value
