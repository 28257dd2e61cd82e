r"""The paper's per-sample back-propagation, Song et al. (2019) eqs. (36)-(46).

Each learning draws one sample $k$ at random (eqs. (36)-(37)), runs the forward pass
(eqs. (38)-(41)), and corrects the weights by gradient descent on the sample error
$e = \frac12 (d - y_o)^2$ with the deltas of eqs. (43)-(44): the output layer with rate $\mu$,
every hidden layer with rate $\eta$ (eqs. (45)-(46)). Training stops when the global error of
eq. (42), $E = \frac{1}{2m}\sum_k (d(k) - y_o(k))^2$, falls to the target or after $M$ learnings.

Deviations, stated: (i) eqs. (43)-(46) as printed apply the learning rate twice ($\Delta w$
already contains $\mu$, then $w \leftarrow w + \mu \Delta w$); we apply it once, which is what
the surrounding text describes. (ii) The global error is evaluated every `check_every` learnings
rather than after each one (it costs a pass over all $m$ samples). (iii) $E$ is computed on the
standardised torque (see [`hdjax.network.Network`][]), so $E = 0.005$ means an RMS error of 10%
of the torque's standard deviation. The output layer is linear, so $\delta_o = d - y_o$.

This is the paper's algorithm, kept for fidelity; [`hdjax.network.train_optax`][] trains the same
network an order of magnitude faster.
"""

from __future__ import annotations

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._custom_types import Array, ArrayLike, Float, PRNGKeyArray, Real, Scalar
from ..._errors import ConfigError, DivergenceError
from ..._solution import Solution
from .._mlp import Network
from ._result import check_count, check_rate, checked_loop, prepare, train_solution


def backprop_step(
    weights: tuple[Float[Array, "_n_in _n_out"], ...],
    biases: tuple[Float[Array, " _n_out"], ...],
    z: Float[Array, " n_features"],
    d: Float[Array, " 1"],
    mu: Scalar,
    eta: Scalar,
) -> tuple[tuple[Float[Array, "_n_in _n_out"], ...], tuple[Float[Array, " _n_out"], ...]]:
    r"""One learning on one standardised sample: forward, deltas, corrections (eqs. (38)-(46)).

    Written out by hand because the paper's update rule is the point; a test checks it against
    `jax.grad` of the sample error.
    """
    # Forward (eqs. (38)-(41)): keep each layer's output for the backward pass.
    outs = [z]
    for w, b in zip(weights[:-1], biases[:-1]):
        outs.append(jax.nn.sigmoid(outs[-1] @ w + b))
    y = outs[-1] @ weights[-1] + biases[-1]
    # Output delta (linear output: f' = 1) and its correction with rate mu (eqs. (43), (45)).
    delta = d - y  # shape (1,)
    new_w = [None] * len(weights)
    new_b = [None] * len(biases)
    new_w[-1] = weights[-1] + mu * jnp.outer(outs[-1], delta)
    new_b[-1] = biases[-1] + mu * delta
    # Hidden deltas back through the layers with f'(h) = f(h)(1 - f(h)), rate eta (eqs. (44), (46)).
    for i in range(len(weights) - 2, -1, -1):
        h = outs[i + 1]
        delta = (weights[i + 1] @ delta) * h * (1.0 - h)
        new_w[i] = weights[i] + eta * jnp.outer(outs[i], delta)
        new_b[i] = biases[i] + eta * delta
    return tuple(new_w), tuple(new_b)


def _global_error(weights, biases, z, t):
    h = z
    for w, b in zip(weights[:-1], biases[:-1]):
        h = jax.nn.sigmoid(h @ w + b[None, :])  # one bias per unit, for every sample
    y = (h @ weights[-1] + biases[-1][None, :])[:, 0]
    return 0.5 * jnp.mean((t - y) ** 2)  # eq. (42)


@eqx.filter_jit
def _train(weights, biases, z, t, zv, tv, key, mu, eta, target, check_every, n_checks):
    m = z.shape[0]
    e0 = _global_error(weights, biases, z, t)

    def _chunk(wb, i):
        idx = jax.random.randint(jax.random.fold_in(key, i), (check_every,), 0, m)

        def _learn(wb, k):
            return backprop_step(*wb, z[k], t[k][None], mu, eta), None

        # Random sample, forward, backward, correct: check_every learnings (eqs. (36)-(46)).
        wb, _ = jax.lax.scan(_learn, wb, idx)
        err = _global_error(*wb, z, t)
        return wb, err, jnp.sqrt(2.0 * _global_error(*wb, zv, tv))

    short = lambda err, _: err > target
    return checked_loop(_chunk, (weights, biases), e0, n_checks, short, floor=0.5)


def train_backprop(
    network: Network,
    x: Real[ArrayLike, "m n_features"],
    y: Real[ArrayLike, " m"],
    *,
    mu: float,
    eta: float,
    error_target: float,
    max_learnings: int,
    key: PRNGKeyArray,
    check_every: int = 1000,
    x_val: Real[ArrayLike, "m_val n_features"] | None = None,
    y_val: Real[ArrayLike, " m_val"] | None = None,
    normalise: bool = True,
) -> Solution:
    r"""Train a network by the paper's per-sample back-propagation (Song et al. eqs. (36)-(46)).

    **Arguments:**

    - `network`: an initialised [`hdjax.network.Network`][].
    - `x`: training inputs `(m, n_features)` (raw; standardised with the stored statistics).
    - `y`: training torques `(m,)` [N·m].
    - `mu`: learning rate of the output layer (eq. (45)).
    - `eta`: learning rate of the hidden layers (eq. (46)).
    - `error_target`: the acceptable global error $E$ of eq. (42) on the standardised torque.
    - `max_learnings`: the maximum number of learnings $M$ (rounded up to `check_every`).
    - `key`: PRNG key for the random choice of samples (keyword-only, no default).
    - `check_every`: learnings between evaluations of the global error.
    - `x_val`, `y_val`: optional validation data, reported as RMS error [N·m].
    - `normalise`: set the network's stored normalisation from `x`, `y` first.

    **Returns:** an [`hdjax.Solution`][] with the trained network in `value` and the stats of
    [`hdjax.network.train_optax`][]; `RESULTS.max_steps_reached` when a positive
    `error_target` was not reached in `max_learnings`.

    **Raises:** [`hdjax.DivergenceError`][] naming `mu` and `eta` when the global error becomes
    non-finite or grows 100-fold; [`hdjax.DataError`][] on NaN or a constant target.
    """
    t0 = time.perf_counter()
    mu = check_rate("mu", mu)
    eta = check_rate("eta", eta)
    check_every = check_count("check_every", check_every)
    max_learnings = check_count("max_learnings", max_learnings)
    if not error_target >= 0:
        raise ConfigError(f"error_target must be >= 0, got {error_target!r}")
    network, z, t, zv, tv = prepare(network, x, y, x_val, y_val, normalise)
    n_checks = -(-max_learnings // check_every)
    f64 = lambda v: jnp.asarray(v, jnp.float64)
    run = _train(
        network.weights,
        network.biases,
        f64(z),
        f64(t),
        f64(zv),
        f64(tv),
        key,
        f64(mu),
        f64(eta),
        f64(error_target),
        check_every,
        n_checks,
    )
    i, err = int(run.checks), float(run.loss)
    if bool(run.diverged):
        raise DivergenceError(
            f"back-propagation diverged after {i * check_every} learnings (global error "
            f"E={err:.3g}, eq. (42)); the learning rates mu={mu:g}, eta={eta:g} are too large "
            f"for this network; try mu={mu / 10:g}, eta={eta / 10:g}"
        )
    return train_solution(
        network,
        run.carry,
        run,
        every=check_every,
        val_scale=float(network.y_scale) if x_val is not None else np.nan,
        target=error_target > 0,
        reached=err <= error_target,
        t0=t0,
    )
