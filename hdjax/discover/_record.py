"""What the residual loop returns: one record per added effect, and the record of the run."""

from __future__ import annotations

import dataclasses

import numpy as np

from .._custom_types import Float
from .._metrics import ErrorMetrics
from .._recording import Recording
from ..compliance import ComplianceModel
from ..effects import AbstractTerm
from ._spectrum import OrderSpectrum


@dataclasses.dataclass
class DiscoveryStep:
    """One effect the residual loop added, with its scores and the errors after adding it."""

    key: str
    family: str
    term: AbstractTerm
    cv_gain: float
    fold_gains: list[float]
    test: ErrorMetrics
    twist_rms_arcsec: float
    ranking: list[dict]
    spectra: dict[str, OrderSpectrum]
    model: ComplianceModel
    torque_estimate: Float[np.ndarray, " n_test"]
    stability: float = 1.0
    cv_torque_rms: float = float("nan")
    cv_twist_rms_arcsec: float = float("nan")
    amplitude: dict | None = None
    aliases: list[dict] = dataclasses.field(default_factory=list)
    """Candidates TRAIN cannot tell apart from this one: `{"key", "cosine"}`, the smallest
    principal-angle cosine between the centred column spans (at least 0.99)."""
    carried: bool = False
    """Added first on a path from another starting structure, as the configured path found
    it, whatever its own gain (not chosen by the stopping rule: the path is judged whole)."""


@dataclasses.dataclass
class DiscoveryRecord:
    """What the residual loop did, step by step: the `aux` of the [`hdjax.Solution`][] that
    [`hdjax.discover.discover`][] returns (its `value` is the final model)."""

    baseline_model: ComplianceModel
    baseline: ErrorMetrics
    baseline_twist_rms_arcsec: float
    baseline_estimate: Float[np.ndarray, " n_test"]
    steps: list[DiscoveryStep]
    final: ErrorMetrics
    final_spectra: dict[str, OrderSpectrum]
    final_ranking: list[dict]
    notes: list[str]
    test: Recording
    train_residual_final: Float[np.ndarray, " n_train"]
    baseline_cv_torque_rms: float = float("nan")
    baseline_cv_twist_rms_arcsec: float = float("nan")
    unexplained: list = dataclasses.field(default_factory=list)
    cv_block_samples: int = 0
    reference_checks: dict = dataclasses.field(default_factory=dict)
    """Per part (`"TRAIN"`, `"TEST"`), the findings of
    [`hdjax.reference.reference_checks`][] on the final model's estimate."""
    cv_test_ratio: float = float("nan")
    """The final cross-validated torque RMS over the TEST RMS: far from 1 (above 2 or below
    1/2), cross-validation does not represent TEST."""
    stopping_rule: str = ""
    """The rule the loop stopped by, in words, with its settings
    (see `DiscoverOptions`)."""
    start_structure: dict = dataclasses.field(default_factory=dict)
    """Empty when the steps start from the configured starting model. Otherwise the start
    they come from (the structure without the paper's kinematic columns, whose path beat the
    configured one's): `label`, `note` (why, in words), TEST `rms` and `max` [N·m],
    `cv_torque_rms` [N·m] and `cv_twist_rms_arcsec`."""
    selection: dict = dataclasses.field(default_factory=dict)
    """With a selection sample of a long TRAIN log (`hdjax discover --select-samples`): its
    rows and blocks, and whether the model written was calibrated on the whole log; else
    `{}`."""

    @property
    def effects(self) -> list[str]:
        return [s.key for s in self.steps]
