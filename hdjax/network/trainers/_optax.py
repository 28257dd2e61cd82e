r"""A jitted optax trainer for the network: full batch or minibatch, the whole run in one loop.

Beyond the paper: the loss is the mean squared error of the standardised torque over a batch,
its gradient comes from `eqx.filter_value_and_grad`, and the steps run inside one
`lax.while_loop` (chunks of `eval_every` steps scanned) that stops early when the validation RMS
error reaches `target_rmse` or when the loss diverges.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..._custom_types import ArrayLike, PRNGKeyArray, Real
from ..._errors import ConfigError, DivergenceError
from ..._solution import Solution
from .._mlp import Network
from ._result import check_count, check_rate, checked_loop, prepare, train_solution

_OPTIMIZERS: dict[str, Callable[[float], optax.GradientTransformation]] = {
    "adam": optax.adam,
    "adamw": optax.adamw,
    "sgd": optax.sgd,
}


@eqx.filter_jit
def _train(network, z, t, zv, tv, key, lr, target, factory, batch, eval_every, n_checks):
    opt = factory(lr)
    trainable = (network.weights, network.biases)
    state = opt.init(trainable)
    m = z.shape[0]
    loss0 = _mse(trainable, network, z, t)

    def _step(carry, k):
        trainable, state, _ = carry
        # Batch: all samples, or `batch` drawn at random (with replacement).
        if batch is None:
            zb, tb = z, t
        else:
            idx = jax.random.randint(k, (batch,), 0, m)
            zb, tb = z[idx], t[idx]
        # Loss and gradient, then the optimiser's correction.
        value, grads = jax.value_and_grad(_mse)(trainable, network, zb, tb)
        updates, state = opt.update(grads, state, trainable)
        trainable = optax.apply_updates(trainable, updates)
        return (trainable, state, value), None

    def _chunk(carry, i):
        trainable, state = carry
        keys = jax.random.split(jax.random.fold_in(key, i), eval_every)
        (trainable, state, loss), _ = jax.lax.scan(_step, (trainable, state, loss0), keys)
        return (trainable, state), loss, jnp.sqrt(_mse(trainable, network, zv, tv))

    short = lambda _, vrmse: vrmse > target
    return checked_loop(_chunk, (trainable, state), loss0, n_checks, short, floor=1.0)


def _mse(trainable, network, z, t):
    """The loss: mean squared error of the standardised torque."""
    net = eqx.tree_at(lambda n: (n.weights, n.biases), network, trainable)
    return jnp.mean((net.normalised(z) - t) ** 2)


def train_optax(
    network: Network,
    x: Real[ArrayLike, "m n_features"],
    y: Real[ArrayLike, " m"],
    *,
    learning_rate: float = 1e-3,
    steps: int,
    key: PRNGKeyArray,
    optimizer: str | Callable[[float], optax.GradientTransformation] = "adam",
    batch_size: int | None = None,
    eval_every: int = 100,
    x_val: Real[ArrayLike, "m_val n_features"] | None = None,
    y_val: Real[ArrayLike, " m_val"] | None = None,
    target_rmse: float | None = None,
    normalise: bool = True,
) -> Solution:
    r"""Train a network by an optax optimiser, jitted, full batch or minibatch.

    **Arguments:**

    - `network`: an initialised [`hdjax.network.Network`][].
    - `x`, `y`: training inputs `(m, n_features)` and torques `(m,)` [N·m].
    - `learning_rate`: the optimiser's step size (default 1e-3; named in the message if
      training diverges).
    - `steps`: maximum number of optimiser steps (rounded up to `eval_every`).
    - `key`: PRNG key for minibatch sampling (keyword-only, no default).
    - `optimizer`: `"adam"`, `"adamw"`, `"sgd"` or a function from the learning rate
      to an `optax.GradientTransformation`.
    - `batch_size`: samples per step, or `None` for the full batch.
    - `eval_every`: steps between checks of loss, validation error and divergence.
    - `x_val`, `y_val`: validation data; with `target_rmse` [N·m] training stops once the
      validation RMS error reaches it.
    - `normalise`: set the network's stored normalisation from `x`, `y` first.

    **Returns:** an [`hdjax.Solution`][] with the trained network in `value`; `stats["history"]`
    holds the training MSE of the standardised torque at each check, `stats["val_rmse"]` the
    validation RMS error [N·m]; `RESULTS.max_steps_reached` when `target_rmse` was not reached.

    **Raises:** [`hdjax.DivergenceError`][] naming the learning rate when the loss becomes
    non-finite or grows 100-fold.
    """
    t0 = time.perf_counter()
    lr = check_rate("learning_rate", learning_rate)
    steps = check_count("steps", steps)
    eval_every = check_count("eval_every", min(eval_every, steps))
    if isinstance(optimizer, str):
        if optimizer not in _OPTIMIZERS:
            raise ConfigError(
                f"unknown optimizer {optimizer!r}; known: {', '.join(_OPTIMIZERS)} (or pass a "
                "function learning_rate -> optax.GradientTransformation)"
            )
        factory = _OPTIMIZERS[optimizer]
    elif callable(optimizer):
        factory = optimizer
    else:
        raise ConfigError(f"optimizer must be a name or a callable, got {optimizer!r}")
    if batch_size is not None:
        batch_size = check_count("batch_size", batch_size)
    if target_rmse is not None and x_val is None:
        raise ConfigError("target_rmse needs validation data (x_val, y_val)")
    network, z, t, zv, tv = prepare(network, x, y, x_val, y_val, normalise)
    y_scale = float(network.y_scale)
    target = -1.0 if target_rmse is None else float(target_rmse) / y_scale
    n_checks = -(-steps // eval_every)
    f64 = lambda v: jnp.asarray(v, jnp.float64)
    # optax mixes Python floats with int32 step counts; allow that under strict promotion.
    with jax.numpy_dtype_promotion("standard"):
        run = _train(
            network,
            f64(z),
            f64(t),
            f64(zv),
            f64(tv),
            key,
            f64(lr),
            f64(target),
            factory,
            batch_size,
            eval_every,
            n_checks,
        )
    i, loss = int(run.checks), float(run.loss)
    if bool(run.diverged):
        name = factory.__name__ if hasattr(factory, "__name__") else "optimizer"
        raise DivergenceError(
            f"{name} training diverged after {i * eval_every} steps (loss {loss:.3g}); the "
            f"learning rate {lr:g} is too large; try learning_rate={lr / 10:g}"
        )
    return train_solution(
        network,
        run.carry[0],
        run,
        every=eval_every,
        val_scale=y_scale if x_val is not None else np.nan,
        target=target_rmse is not None,
        reached=float(run.val) <= target,
        t0=t0,
    )
