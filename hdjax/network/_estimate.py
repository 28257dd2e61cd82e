"""Torque from a recording with a trained network (Song et al. 2019, end of Section III.B)."""

from __future__ import annotations

from .._custom_types import Array, Float
from .._errors import ModelMismatchError
from .._joint import Joint
from .._recording import Recording
from ._features import Features, build_features
from ._mlp import Network, predict


def predict_torque(
    network: Network, recording: Recording, joint: Joint, *, causal: bool = False
) -> Float[Array, " n"]:
    """Predict the output torque of every sample of `recording` with a trained network.

    The input vector is built with the options the network was trained with (its stored
    [`hdjax.network.FeatureLayout`][]: periodic angles, orders, Kalman-filtered current).

    **Arguments:**

    - `network`: a trained [`hdjax.network.Network`][].
    - `recording`: the [`hdjax.Recording`][] to estimate on (no torque needed).
    - `joint`: the [`hdjax.Joint`][].
    - `causal`: build every sample's input from that sample and earlier ones only (see
      [`hdjax.network.build_features`][]), as `hdjax export`'s C code does.

    **Returns:** torque [N·m], shape `(n,)`.
    """
    if not isinstance(network, Network):
        raise ModelMismatchError(
            f"predict_torque needs an hdjax.network.Network, got {type(network).__name__}"
        )
    return predict(network, network_features(network, recording, joint, causal=causal))


def network_features(
    network: Network, recording: Recording, joint: Joint, *, causal: bool = False
) -> Features:
    """The input vector of every sample, built with the options `network` was trained with
    (its stored [`hdjax.network.FeatureLayout`][]; see [`hdjax.network.build_features`][])."""
    lay = network.layout
    return build_features(
        recording,
        joint,
        periodic=lay.periodic,
        orders=lay.orders or (1, 2),
        kalman=lay.kalman,
        causal=causal,
    )
