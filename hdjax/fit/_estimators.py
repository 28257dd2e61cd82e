"""One estimator interface: the compliance model, the network and the hybrid estimate torque the
same way.

An [`hdjax.fit.AbstractEstimator`][] turns a recording into a torque estimate [N·m], shape
`(n,)`. The method comparison and the periodic-feature experiment are loops over estimators, and
a fit that produces one returns an [`hdjax.Solution`][] whose `value` is the estimator.

- [`ComplianceEstimator`][]: the Song et al. model inverted for torque (eqs. (26)-(27)).
- [`NetworkEstimator`][]: the trained network of Song et al. Section III.B.
- [`HybridEstimator`][]: compliance inversion plus a network on the residual
  ([`hdjax.fit.HybridModel`][]).
"""

from __future__ import annotations

import abc

import equinox as eqx

from .._custom_types import Array, Float
from .._joint import Joint
from .._recording import Recording
from ..compliance import ComplianceModel, estimate_torque
from ..network import Network, predict_torque
from ._hybrid import HybridModel, predict_hybrid
from ._inputs import HybridInputs, hybrid_inputs


class AbstractEstimator(eqx.Module):
    """Something that estimates the output torque of every sample of a recording."""

    @abc.abstractmethod
    def estimate(self, recording: Recording) -> Float[Array, " n"]:
        """Torque [N·m] for every sample of `recording` (its torque column is not used)."""


class ComplianceEstimator(AbstractEstimator):
    """A calibrated [`hdjax.compliance.ComplianceModel`][] inverted for torque (eqs. (26)-(27))."""

    model: ComplianceModel

    def estimate(self, recording: Recording) -> Float[Array, " n"]:
        return estimate_torque(self.model, recording).torque


class NetworkEstimator(AbstractEstimator):
    """A trained [`hdjax.network.Network`][] on the joint's features (after eq. (28))."""

    network: Network
    joint: Joint = eqx.field(static=True)

    def estimate(self, recording: Recording) -> Float[Array, " n"]:
        return predict_torque(self.network, recording, self.joint)


class HybridEstimator(AbstractEstimator):
    """A fitted [`hdjax.fit.HybridModel`][] with the input options it was trained with.

    `options` are the keyword arguments of [`hdjax.fit.hybrid_inputs`][] besides the joint
    and the compliance model (e.g. `twist_rate`, `hysteresis`).
    """

    model: HybridModel
    compliance: ComplianceModel | None
    joint: Joint = eqx.field(static=True)
    options: tuple = eqx.field(static=True, default=())

    def inputs(self, recording: Recording) -> HybridInputs:
        """The model's inputs for `recording` ([`hdjax.fit.hybrid_inputs`][])."""
        return hybrid_inputs(
            recording, self.joint, compliance=self.compliance, **dict(self.options)
        )

    def estimate(self, recording: Recording) -> Float[Array, " n"]:
        return predict_hybrid(self.model, self.inputs(recording))
