"""What a trainer returns, and the checks every trainer shares."""

from __future__ import annotations

import math
import time

import numpy as np

from ..._errors import ConfigError
from ..._solution import RESULTS, Solution
from .._features import check_training_data
from .._mlp import Network, standardise


def train_solution(network: Network, history, val_rmse, steps: int, target, reached, t0):
    """What a trainer returns: an [`hdjax.Solution`][] with the trained network in `value`.

    `stats` holds `history` (training loss at each check, standardised units: the mean squared
    error of the torque divided by its variance, halved for back-propagation as eq. (42)),
    `val_rmse` (validation RMS error [N·m] at each check, NaN without validation data),
    `steps` (learnings or optimiser steps taken), `target_reached` and `fit_time_s`. The
    result is `RESULTS.max_steps_reached` when an error `target` was set and not `reached`.
    """
    result = RESULTS.max_steps_reached if target and not reached else RESULTS.successful
    stats = dict(
        history=history,
        val_rmse=val_rmse,
        steps=int(steps),
        target_reached=bool(reached),
        fit_time_s=time.perf_counter() - t0,
    )
    return Solution(network, result, stats)


def check_rate(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"learning rate {name} must be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise ConfigError(f"learning rate {name} must be positive and finite, got {value!r}")
    return float(value)


def check_count(name: str, value, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ConfigError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def prepare(network: Network, x, y, x_val, y_val, normalise: bool):
    """Validate data, set the stored normalisation, return standardised arrays."""
    if not isinstance(network, Network):
        raise ConfigError(f"expected an hdjax.network.Network, got {type(network).__name__}")
    x, y = check_training_data(x, y)
    if x.shape[1] != network.layout.n_features:
        raise ConfigError(
            f"training inputs have {x.shape[1]} columns but the network's layout has "
            f"{network.layout.n_features} ({', '.join(network.layout.names)})"
        )
    if normalise:
        network = standardise(network, x, y)
    xm, xs = np.asarray(network.x_mean), np.asarray(network.x_scale)
    ym, ys = float(network.y_mean), float(network.y_scale)
    z, t = (x - xm) / xs, (y - ym) / ys
    if (x_val is None) != (y_val is None):
        raise ConfigError("give both x_val and y_val, or neither")
    if x_val is not None:
        x_val, y_val = check_training_data(x_val, y_val, source="validation data")
        if x_val.shape[1] != x.shape[1]:
            raise ConfigError(
                f"validation inputs have {x_val.shape[1]} columns, training inputs {x.shape[1]}"
            )
        zv, tv = (x_val - xm) / xs, (y_val - ym) / ys
    else:
        zv, tv = z[:1], t[:1]
    return network, z, t, zv, tv
