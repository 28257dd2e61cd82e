"""The Kalman-filtered current and the back-propagation network, Song et al. (2019) Section III.

- [`hdjax.network.kalman_filter`][], [`hdjax.network.filter_current`][]: eqs. (29)-(35).
- [`hdjax.network.build_features`][]: the input vector after eq. (28), with an optional
  periodic (sin/cos) encoding of the angles.
- [`hdjax.network.Network`][]: sigmoid hidden layers, eqs. (36)-(41).
- [`hdjax.network.train_backprop`][] (the paper's eqs. (42)-(46)) and
  [`hdjax.network.train_optax`][] (jitted, full batch or minibatch).
- [`hdjax.network.predict_torque`][]: torque from a recording with a trained network.
"""

from ._estimate import predict_torque as predict_torque
from ._features import (
    PAPER_INPUTS as PAPER_INPUTS,
    FeatureLayout as FeatureLayout,
    Features as Features,
    build_features as build_features,
    check_training_data as check_training_data,
    make_layout as make_layout,
)
from ._kalman import (
    PAPER_OUTPUT_PERIOD as PAPER_OUTPUT_PERIOD,
    PAPER_P0 as PAPER_P0,
    PAPER_Q as PAPER_Q,
    PAPER_R as PAPER_R,
    PAPER_RAW_PERIOD as PAPER_RAW_PERIOD,
    filter_current as filter_current,
    kalman_filter as kalman_filter,
    steady_state_gain as steady_state_gain,
    white_noise_std_ratio as white_noise_std_ratio,
)
from ._mlp import Network as Network, predict as predict, standardise as standardise
from .trainers import (
    backprop_step as backprop_step,
    train_backprop as train_backprop,
    train_optax as train_optax,
)
