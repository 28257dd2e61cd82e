r"""The back-propagation network of Song et al. (2019), Section III.B, eqs. (36)-(41), Fig. 6.

A fully connected network with sigmoid hidden layers $f(x) = 1/(1+e^{-x})$ and one torque
output. The paper draws one hidden layer of $p$ neurons and says more layers and neurons fit
better at a higher computing cost; here width and depth are configurable. Weights and thresholds
start uniformly in $(-1, 1)$ as the paper's first step prescribes.

Two choices the paper leaves open, stated here:

- **Normalisation.** Inputs are standardised with the training set's mean and standard deviation
  and the torque is standardised likewise; both are stored in the network, so an estimate uses
  the training statistics. Without it the unwrapped motor angle (hundreds of radians) saturates
  every sigmoid.
- **Output layer.** Eq. (41) passes the output through $f$ too, which restricts the output to
  $(0, 1)$; with a standardised target we keep the output layer linear (the usual choice for
  regression). The paper's thresholds enter with a minus sign (eqs. (38), (40)); we add a bias,
  which is the same family with the sign absorbed.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float, PRNGKeyArray, Real
from .._errors import ConfigError, DataError
from ._features import FeatureLayout, Features


def _check_hidden(hidden) -> tuple[int, ...]:
    try:
        hidden = tuple(hidden)
    except TypeError:
        raise ConfigError(f"hidden must be a tuple of layer widths, got {hidden!r}") from None
    if not hidden:
        raise ConfigError("hidden must name at least one hidden layer, e.g. hidden=(20,)")
    for i, width in enumerate(hidden):
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
            raise ConfigError(
                f"hidden layer {i} has width {width!r}; every hidden layer needs a positive "
                "integer number of neurons (the paper's p >= 1)"
            )
    return tuple(int(w) for w in hidden)


class Network(eqx.Module):
    r"""A sigmoid multilayer perceptron from the input vector to the output torque.

    **Arguments:**

    - `layout`: the [`hdjax.network.FeatureLayout`][] of its inputs.
    - `hidden`: widths of the hidden layers, e.g. `(20,)` for the paper's single layer of
      $p = 20$ neurons.
    - `key`: a JAX PRNG key for the uniform $(-1, 1)$ initialisation (keyword-only).
    - `x_mean`, `x_scale`: input standardisation, shape `(n_features,)`; identity when `None`.
    - `y_mean`, `y_scale`: torque standardisation (scalars); identity when `None`.
    """

    weights: tuple[Float[Array, "_n_in _n_out"], ...]
    biases: tuple[Float[Array, " _n_out"], ...]
    x_mean: Float[Array, " n_features"]
    x_scale: Float[Array, " n_features"]
    y_mean: Float[Array, ""]
    y_scale: Float[Array, ""]
    layout: FeatureLayout
    hidden: tuple[int, ...] = eqx.field(static=True)

    def __init__(
        self,
        layout: FeatureLayout,
        hidden: Sequence[int] = (20,),
        *,
        key: PRNGKeyArray,
        x_mean: Real[ArrayLike, " n_features"] | Sequence[float] | None = None,
        x_scale: Real[ArrayLike, " n_features"] | Sequence[float] | None = None,
        y_mean: Real[ArrayLike, ""] | None = None,
        y_scale: Real[ArrayLike, ""] | None = None,
    ) -> None:
        hidden = _check_hidden(hidden)
        sizes = (layout.n_features,) + hidden + (1,)
        keys = jax.random.split(key, 2 * (len(sizes) - 1))
        uniform = lambda k, shape: jax.random.uniform(
            k, shape, jnp.float64, minval=-1.0, maxval=1.0
        )
        self.weights = tuple(
            uniform(keys[2 * i], (sizes[i], sizes[i + 1])) for i in range(len(sizes) - 1)
        )
        self.biases = tuple(
            uniform(keys[2 * i + 1], (sizes[i + 1],)) for i in range(len(sizes) - 1)
        )
        n = layout.n_features
        f64 = lambda v, default: jnp.asarray(default if v is None else v, jnp.float64)
        self.x_mean = f64(x_mean, np.zeros(n))
        self.x_scale = f64(x_scale, np.ones(n))
        self.y_mean = f64(y_mean, 0.0)
        self.y_scale = f64(y_scale, 1.0)
        self.layout = layout
        self.hidden = hidden

    def normalised(self, z: Float[Array, "... n_features"]) -> Float[Array, " ..."]:
        """Forward pass on standardised inputs, standardised output (eqs. (38)-(41))."""
        lead = (None,) * (z.ndim - 1)  # the biases broadcast over the batch axes explicitly
        h = z
        for w, b in zip(self.weights[:-1], self.biases[:-1]):
            h = jax.nn.sigmoid(h @ w + b[lead])  # eqs. (38)-(39)
        return (h @ self.weights[-1] + self.biases[-1][lead])[..., 0]  # eq. (40), linear output

    def __call__(self, x: Float[ArrayLike, "... n_features"]) -> Float[Array, " ..."]:
        """Torque [N·m] for one input vector `(n_features,)` or a batch `(n, n_features)`."""
        lead = (None,) * (x.ndim - 1)  # one mean and scale per feature, for every batch row
        z = (x - self.x_mean[lead]) / self.x_scale[lead]
        return self.y_mean + self.y_scale * self.normalised(z)

    @property
    def n_parameters(self) -> int:
        return sum(int(w.size) + int(b.size) for w, b in zip(self.weights, self.biases))


def standardise(
    network: Network, x: Real[ArrayLike, "m n_features"], y: Real[ArrayLike, " m"]
) -> Network:
    """The network with its stored normalisation set from training inputs `x` and torques `y`.

    Columns of zero spread (a constant angle in a static test) get scale 1.
    """
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    x_scale = x.std(axis=0)
    x_scale = np.where(x_scale > 1e-12 * np.maximum(1.0, np.abs(x).max(axis=0)), x_scale, 1.0)
    y_scale = float(y.std())
    y_scale = y_scale if y_scale > 0 else 1.0
    return eqx.tree_at(
        lambda n: (n.x_mean, n.x_scale, n.y_mean, n.y_scale),
        network,
        (
            jnp.asarray(x.mean(axis=0)),
            jnp.asarray(x_scale),
            jnp.asarray(float(y.mean()), jnp.float64),
            jnp.asarray(y_scale, jnp.float64),
        ),
    )


@eqx.filter_jit
def _predict(network: Network, x):
    return network(x)


def predict(network: Network, features: Features) -> Float[Array, " n"]:
    """Torque estimates for a batch of input vectors built by [`hdjax.network.build_features`][].

    Refuses ([`hdjax.ModelMismatchError`][]) features whose layout differs from the one the
    network was trained on.

    **Arguments:**

    - `network`: a trained [`hdjax.network.Network`][].
    - `features`: a [`hdjax.network.Features`][].

    **Returns:** torque [N·m], shape `(n,)`.
    """
    if not isinstance(features, Features):
        raise DataError(
            "predict needs hdjax.network.Features (from build_features), which carry the feature "
            f"layout; got {type(features).__name__}"
        )
    network.layout.check_matches(features.layout)
    return _predict(network, features.x)
