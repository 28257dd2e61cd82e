"""The uncalibrated model an experiment describes: configuration only parses and validates the
`[model]` table ([`hdjax.config.resolve`][]); the model is built here."""

from __future__ import annotations

from collections.abc import Mapping

from .._joint import Joint
from ..compliance import ComplianceModel
from ..discover.internal import paper_model


def build_model(cfg: Mapping, joint: Joint, scale: float) -> ComplianceModel:
    """The uncalibrated [`hdjax.compliance.ComplianceModel`][] of a resolved config's `[model]`
    table (Song et al. 2019, eqs. (7)-(10)), with motor currents divided by `scale`."""
    return paper_model(cfg["model"], joint, scale)
