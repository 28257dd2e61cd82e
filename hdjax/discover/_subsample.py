"""Discover on a TRAIN log too long to hold: the structure chosen on whole blocks of it, the
final calibration streamed over every row.

The loop's passes (calibration, cross-validation, candidate scores, intervals, spectra) hold
vectors as long as TRAIN, so their memory grows with the log. Given `select_samples`, a longer
TRAIN log is read chunk by chunk and only `SELECT_BLOCKS` contiguous blocks of equal length are
kept, one centred in each of as many equal strata of the log: a systematic sample of whole
blocks. Every part of the log is represented; within a block the motion keeps its correlation
and the memory states run as they do in the log; where two blocks meet the time stamps jump,
which the loop treats as a long gap (no derivative across it, memory states restart).

The loop runs on those blocks as on any TRAIN. Then the starting structure and the final one
are calibrated again on every row of the TRAIN log by streamed least squares
([`hdjax.compliance.calibrate_stream`][]: the normal equations, the refinement and the shape
constraint accumulated chunk by chunk, memory bounded by the chunk), and both are scored on
TEST. These are the model written and the TEST errors reported, before and after. A final
structure whose hysteresis is driven by its own estimate (the estimate-driver rounds do not
stream) keeps the calibration on the blocks, and the report says so.

What stays on the blocks: the choice of effects, the cross-validated errors, the spectra, the
reference checks, and the effects' 95 % intervals (wider than the whole log's would be, by
about the square root of the ratio of the row counts where the residual's correlation is short
against a block).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._errors import DataError, HdjaxError
from .._formats import count_rows, load_recording, load_rows
from .._joint import Joint
from .._recording import Recording
from .._solution import Solution
from ..compliance import RecordingStream, calibrate_stream
from ._evaluate import test_errors
from ._pipeline import canonical, has_path

SELECT_BLOCKS = 20
"""Blocks of a selection sample (one per stratum of the log)."""

MIN_BLOCK = 1000
"""The fewest samples a block of the selection sample holds (fewer blocks when needed)."""


def selection_blocks(n_total: int, n_keep: int) -> list[tuple[int, int]]:
    """The `(start, stop)` rows of the selection sample: up to `SELECT_BLOCKS` blocks of equal
    length summing to about `n_keep` rows, each centred in its equal stratum of `n_total`
    rows (all rows as one block when `n_keep >= n_total`)."""
    if n_keep >= n_total:
        return [(0, n_total)]
    k = max(1, min(SELECT_BLOCKS, n_keep // MIN_BLOCK))
    length = n_keep // k
    stratum = n_total / k
    starts = [int(np.floor(b * stratum + (stratum - length) / 2)) for b in range(k)]
    return [(s, s + length) for s in starts]


def load_selection(path, n_keep: int, chunk: int) -> tuple[Recording, dict]:
    """TRAIN's selection sample ([`selection_blocks`][]), read `chunk` rows at a time: the rows
    kept as one [`hdjax.Recording`][], and a description of the selection (`{}` when the log
    holds no more than `n_keep` rows: then the whole log)."""
    n_total = count_rows(path, chunk=chunk)
    blocks = selection_blocks(n_total, n_keep)
    if len(blocks) == 1 and blocks[0] == (0, n_total):
        return load_recording(path, chunk=chunk), {}
    bounds = np.asarray(blocks)

    def keep(start: int, n: int) -> np.ndarray:
        rows = np.arange(start, start + n)
        b = np.searchsorted(bounds[:, 0], rows, side="right") - 1
        return (b >= 0) & (rows < bounds[np.maximum(b, 0), 1])

    selected = load_rows(path, keep, chunk=chunk)
    return selected, dict(
        samples_total=n_total,
        samples_selected=selected.n_samples,
        blocks=len(blocks),
        block_samples=blocks[0][1] - blocks[0][0],
    )


def _streamed_fit(model, stream: RecordingStream, chunk: int):
    res = calibrate_stream(canonical(model), stream, chunk=chunk, throw=False)
    if not res.ok:
        raise DataError(f"the streamed calibration of the whole TRAIN log failed: {res.result}")
    return canonical(res.value)


def refit_on_whole_log(
    solution: Solution, path, test: Recording, joint: Joint, chunk: int, selection: dict
) -> Solution:
    """`solution` (the loop's on the selection sample) with the starting and the final
    structure calibrated on every row of the TRAIN log at `path` (streamed, `chunk` rows at a
    time) and scored on `test`: the final model, the TEST errors before and after and the
    last step's model and estimate are the whole log's; the rest stays the selection's (see
    the module docstring). A note says which, and warns when the whole log's final model is
    worse on TEST than its starting model."""
    record = solution.aux
    notes = [
        f"structure chosen on {selection['samples_selected']} of the "
        f"{selection['samples_total']} TRAIN samples ({selection['blocks']} blocks of "
        f"{selection['block_samples']} samples, one centred in each equal part of the log); "
        "cross-validated errors, spectra, reference checks and the effects' intervals are "
        "the selection's"
    ]
    stream = RecordingStream.from_files(path, chunk=chunk)
    if has_path(solution.value) or has_path(record.baseline_model):
        notes.append(
            "the final model's hysteresis follows its own estimate, which a streamed "
            "calibration does not iterate: the model written and its TEST errors are the "
            "selection's calibration, not the whole log's; to calibrate it on every row, run "
            "discover on a TRAIN log that fits in memory"
        )
        return _with(solution, record, notes, selection | {"refit": "selection"})
    try:
        base = _streamed_fit(record.baseline_model, stream, chunk)
        final = _streamed_fit(solution.value, stream, chunk) if record.steps else base
    except HdjaxError as e:
        notes.append(
            f"warning: the whole-log calibration failed ({e}); the model written and its TEST "
            "errors are the selection's"
        )
        return _with(solution, record, notes, selection | {"refit": "selection"})
    base_m, base_est = test_errors(base, test, joint.rated_torque)
    final_m, final_est = (
        test_errors(final, test, joint.rated_torque) if record.steps else (base_m, base_est)
    )
    old = record.steps[-1].torque_estimate if record.steps else record.baseline_estimate
    moved = float(np.sqrt(np.mean((np.asarray(final_est) - np.asarray(old)) ** 2)))
    notes.append(
        f"the starting and the final model calibrated again on all {selection['samples_total']} "
        f"TRAIN samples (streamed): TEST torque RMS {record.baseline.rms:.4g} -> "
        f"{base_m.rms:.4g} N·m (start) and {record.final.rms:.4g} -> {final_m.rms:.4g} N·m "
        f"(final) against the selection's calibrations, whose final estimate on TEST differs "
        f"from the whole log's by {moved:.3g} N·m RMS"
    )
    if final_m.rms > base_m.rms:
        notes.append(
            f"warning: calibrated on the whole TRAIN log, the final model's TEST torque RMS "
            f"({final_m.rms:.4g} N·m) is {final_m.rms / base_m.rms - 1:.1%} above the starting "
            f"model's ({base_m.rms:.4g} N·m): the effects chosen on the selection do not help "
            "on TEST; use the starting model, or a larger --select-samples"
        )
    steps = list(record.steps)
    if steps:
        steps[-1] = dataclasses.replace(
            steps[-1], model=final, test=final_m, torque_estimate=final_est
        )
    record = dataclasses.replace(
        record,
        baseline_model=base,
        baseline=base_m,
        baseline_estimate=base_est,
        steps=steps,
        final=final_m,
    )
    stats = dict(solution.stats, baseline_test_rms=base_m.rms, final_test_rms=final_m.rms)
    solution = Solution(final, solution.result, stats, aux=solution.aux)
    return _with(
        solution,
        record,
        notes,
        selection | {"refit": "whole log", "test_estimate_change_rms": moved},
    )


def _with(solution: Solution, record, notes: list[str], selection: dict) -> Solution:
    record = dataclasses.replace(record, notes=record.notes + notes, selection=selection)
    return Solution(solution.value, solution.result, solution.stats, aux=record)
