"""What a trainer returns, and the loop and checks every trainer shares."""

from __future__ import annotations

import collections
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._custom_types import Scalar
from ..._errors import ConfigError
from ..._solution import RESULTS, Solution
from .._features import check_training_data
from .._mlp import Network, standardise

DIVERGENCE_FACTOR = 100.0
"""A run has diverged when its loss grows this many times over its start (or its floor)."""


class CheckedRun(
    collections.namedtuple("CheckedRun", "carry checks loss val history val_history diverged")
):
    """What `checked_loop` returns (a pytree, so a jitted trainer returns it whole): the
    trainer's `carry`, the number of `checks` made, the last `loss` and validation value `val`,
    their `history` and `val_history` (NaN past the checks made), and whether the run
    `diverged`."""

    __slots__ = ()


def checked_loop(chunk, carry, loss0: Scalar, n_checks: int, short, *, floor: float) -> CheckedRun:
    """Run a trainer's `chunk(carry, i) -> (carry, loss, val)` (the learnings or optimiser
    steps between two checks) up to `n_checks` times inside one `lax.while_loop`.

    After each chunk it keeps the training `loss` and the validation value `val`. It goes on
    while `short(loss, val)` (the error target is not met), the loss is finite and below
    `DIVERGENCE_FACTOR` times the larger of `loss0` (the loss before training) and `floor`;
    past that limit, or not finite, the run has diverged.
    """
    limit = DIVERGENCE_FACTOR * jnp.maximum(loss0, floor)
    hist = jnp.full((n_checks,), jnp.nan)

    def _body(state):
        carry, i, _, _, hist, vhist = state
        carry, loss, val = chunk(carry, i)
        return carry, i + 1, loss, val, hist.at[i].set(loss), vhist.at[i].set(val)

    def _go_on(state):
        _, i, loss, val, _, _ = state
        return (i < n_checks) & short(loss, val) & jnp.isfinite(loss) & (loss < limit)

    init = (carry, jnp.asarray(0), loss0, jnp.asarray(jnp.inf), hist, hist)
    carry, i, loss, val, hist, vhist = jax.lax.while_loop(_go_on, _body, init)
    return CheckedRun(carry, i, loss, val, hist, vhist, ~jnp.isfinite(loss) | (loss >= limit))


def train_solution(
    network: Network, trainable, run: CheckedRun, *, every: int, val_scale, target, reached, t0
) -> Solution:
    """What a trainer returns: an [`hdjax.Solution`][] with `network` trained to the weights and
    biases `trainable` of its `run` (one check every `every` learnings or steps) in `value`.

    `stats` holds `history` (training loss at each check, standardised units: the mean squared
    error of the torque divided by its variance, halved for back-propagation as eq. (42)),
    `val_rmse` (validation RMS error [N·m] at each check, the validation values times
    `val_scale`; NaN without validation data), `steps` (learnings or optimiser steps taken),
    `target_reached` and `fit_time_s`. The result is `RESULTS.max_steps_reached` when an error
    `target` was set and not `reached`.
    """
    i = int(run.checks)
    result = RESULTS.max_steps_reached if target and not reached else RESULTS.successful
    stats = dict(
        history=run.history[:i],
        val_rmse=run.val_history[:i] * val_scale,
        steps=i * every,
        target_reached=bool(reached),
        fit_time_s=time.perf_counter() - t0,
    )
    trained = eqx.tree_at(lambda n: (n.weights, n.biases), network, trainable)
    return Solution(trained, result, stats)


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
