"""Adapting the flexspline segments to the torque range a recording actually covers."""

from __future__ import annotations

import numpy as np

from .._custom_types import ArrayLike, Float
from ._model import ComplianceModel

MIN_SEGMENT_SAMPLES = 30
MIN_SEGMENT_COVER = 0.25


def merge_sparse_segments(
    model: ComplianceModel,
    torque: Float[ArrayLike, " n"],
    *,
    min_samples: int = MIN_SEGMENT_SAMPLES,
    min_cover: float = MIN_SEGMENT_COVER,
) -> tuple[ComplianceModel, list[str]]:
    """Merge segments the data cannot calibrate into their inner neighbour.

    A segment's compliance $k_j$ (eq. (7)) is only determined by torques spread across the
    segment. A segment holding fewer than `min_samples` samples, or whose samples span less
    than `min_cover` of its width (outer segments: of the width of the paper's segments), is
    merged with its neighbour towards 0 N·m by removing the knot between them, so the
    neighbour's slope continues. Segments without any sample are left for the calibration to
    drop (the model then flags torques beyond the calibrated range).

    **Returns:** the model with the new knots (coefficients reset) and one note per merge.
    """
    t = np.asarray(torque, np.float64)
    knots = list(model.knots)
    notes = []
    changed = True
    while changed and knots:
        changed = False
        edges = [-np.inf] + knots + [np.inf]
        widths = np.diff([k for k in knots])
        typical = float(np.min(widths)) if widths.size else model.rated_torque / 3
        for j in range(len(edges) - 1):
            lo, hi = edges[j], edges[j + 1]
            if lo <= 0.0 < hi:
                continue  # the central segment stays
            inside = t[(t >= lo) & (t < hi)]
            if inside.size == 0:
                continue
            width = (hi - lo) if np.isfinite(hi - lo) else typical
            cover = float(np.ptp(inside)) / width
            if inside.size >= min_samples and cover >= min_cover:
                continue
            # remove the knot on the side facing 0 N·m
            knot = lo if lo > 0.0 else hi
            knots.remove(knot)
            notes.append(
                f"torque segment [{lo:.4g}, {hi:.4g}) N·m holds {inside.size} samples covering "
                f"{cover:.0%} of its width: merged into its neighbour (knot {knot:.4g} removed)"
            )
            changed = True
            break
    if not notes:
        return model, notes
    return model.restructured(knots=knots), notes
