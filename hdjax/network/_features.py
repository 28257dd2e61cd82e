r"""The network's input vector, Song et al. (2019) the line after eq. (28).

$\mathrm{Input} = [I, \theta_{wgi}, \theta_{fso}, \omega_{wgi}, \omega_{fso}, \Delta\theta]$: motor
current, wave-generator (motor) angle, flexspline-output (load) angle, their velocities by the
backward difference of eqs. (13)-(14), and the twist of eq. (5).

Beyond the paper, `periodic=True` replaces each unwrapped angle by $\sin(k\theta)$ and
$\cos(k\theta)$ at `orders` $k$: a multi-turn motor angle is an unbounded input that a sigmoid
network can only extrapolate, while the kinematic error it is meant to carry is periodic in the
angles (eq. (9)).

The layout (names, in order) travels with the features and with a trained network, so that an
estimate refuses inputs built differently from the training inputs.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import ArrayLike, Float, RealLike
from .._errors import ConfigError, DataError, ModelMismatchError
from .._features import signals
from .._joint import Joint
from .._recording import Recording
from ._kalman import filter_current

PAPER_INPUTS = ("current", "theta_m", "theta_l", "omega_m", "omega_l", "twist")
r"""The paper's six inputs in its order: $I$, $\theta_{wgi}$, $\theta_{fso}$, $\omega_{wgi}$,
$\omega_{fso}$, $\Delta\theta$."""


class FeatureLayout(eqx.Module):
    """How an input vector was built: names of the columns, in order.

    **Arguments:**

    - `names`: column names, e.g. `("current", "sin1_theta_m", ...)`.
    - `periodic`: whether angles enter as sines and cosines.
    - `orders`: the harmonic orders used when `periodic`.
    - `kalman`: whether the current was Kalman-filtered (eqs. (29)-(35)) before use.
    """

    names: tuple[str, ...] = eqx.field(static=True)
    periodic: bool = eqx.field(static=True, default=False)
    orders: tuple[int, ...] = eqx.field(static=True, default=())
    kalman: bool = eqx.field(static=True, default=False)

    @property
    def n_features(self) -> int:
        return len(self.names)

    def check_matches(self, other: FeatureLayout, what: str = "estimation input") -> None:
        """Raise [`hdjax.ModelMismatchError`][] when `other` differs from this layout."""
        if other.names != self.names or other.kalman != self.kalman:
            raise ModelMismatchError(
                f"{what} has feature layout {list(other.names)} (kalman={other.kalman}) but the "
                f"network was trained on {list(self.names)} (kalman={self.kalman}); build the "
                f"features with the same options (periodic={self.periodic}, "
                f"orders={self.orders}, kalman={self.kalman})"
            )


def make_layout(
    *, periodic: bool = False, orders: tuple[int, ...] = (1, 2), kalman: bool = False
) -> FeatureLayout:
    """The layout [`hdjax.network.build_features`][] produces for these options."""
    if not periodic:
        return FeatureLayout(PAPER_INPUTS, False, (), bool(kalman))
    orders = tuple(orders)
    if not orders or any(not isinstance(k, int) or k < 1 for k in orders):
        raise ConfigError(f"periodic orders must be positive integers, got {orders!r}")
    names = ["current"]
    for angle in ("theta_m", "theta_l"):
        for k in orders:
            names += [f"sin{k}_{angle}", f"cos{k}_{angle}"]
    names += ["omega_m", "omega_l", "twist"]
    return FeatureLayout(tuple(names), True, orders, bool(kalman))


class Features(eqx.Module):
    """A design of network inputs: `x` of shape `(n, n_features)` and its `layout`."""

    x: Float[ArrayLike, "n n_features"]  # NumPy where the Kalman features are built in chunks
    layout: FeatureLayout


def build_features(
    recording: Recording,
    joint: Joint,
    *,
    periodic: bool = False,
    orders: tuple[int, ...] = (1, 2),
    kalman: bool = False,
    causal: bool = False,
) -> Features:
    r"""The network input vector for every sample of a recording (Song et al., after eq. (28)).

    **Arguments:**

    - `recording`: the [`hdjax.Recording`][].
    - `joint`: the [`hdjax.Joint`][] (ratio and twist sign for eq. (5)).
    - `periodic`: feed angles as $\sin(k\theta)$, $\cos(k\theta)$ instead of raw radians.
    - `orders`: harmonic orders $k$ when `periodic`.
    - `kalman`: Kalman-filter the current first ([`hdjax.network.filter_current`][] with the
      paper's variances, every sample handed on).
    - `causal`: velocities from each sample and earlier ones only (the first sample at rest;
      see [`hdjax.signals`][]), as `hdjax export`'s C code computes them.

    **Returns:** a [`hdjax.network.Features`][] with `x` of shape `(n, n_features)`.
    """
    layout = make_layout(periodic=periodic, orders=orders, kalman=kalman)
    if recording.n_samples < 2:
        raise DataError(f"{recording.source}: need at least 2 samples to build features")
    if kalman:
        recording = filter_current(recording, output_period=None)
    sig = signals(recording, joint, causal=causal)
    cols = {name: sig.get(name) for name in ("current", "omega_m", "omega_l", "twist")}
    if periodic:
        for angle in ("theta_m", "theta_l"):
            theta = getattr(recording, angle)
            for k in orders:
                cols[f"sin{k}_{angle}"] = jnp.sin(k * theta)
                cols[f"cos{k}_{angle}"] = jnp.cos(k * theta)
    else:
        cols["theta_m"] = recording.theta_m
        cols["theta_l"] = recording.theta_l
    x = jnp.stack([jnp.asarray(cols[name], jnp.float64) for name in layout.names], axis=1)
    return Features(x=x, layout=layout)


def check_training_data(
    x: RealLike, y: RealLike, source: str = "training data"
) -> tuple[Float[np.ndarray, "m n_features"], Float[np.ndarray, " m"]]:
    """Validate a training set in plain Python: shapes, finiteness, a target that varies."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    if x.ndim != 2 or y.ndim != 1 or x.shape[0] != y.shape[0]:
        raise DataError(
            f"{source}: inputs must be (n, n_features) and target (n,), got {x.shape} and {y.shape}"
        )
    if x.shape[0] < 2:
        raise DataError(f"{source}: need at least 2 samples, got {x.shape[0]}")
    for name, arr in (("inputs", x), ("target", y)):
        bad = ~np.isfinite(arr)
        if bad.any():
            rows = np.flatnonzero(bad.reshape(arr.shape[0], -1).any(axis=1))
            raise DataError(
                f"{source}: {name} contain {int(bad.sum())} NaN/inf value(s) in {rows.size} "
                f"row(s), first at row {int(rows[0])}; drop or interpolate those rows first"
            )
    spread = float(np.std(y))
    if not spread > 1e-12 * max(1.0, float(np.max(np.abs(y)))):
        raise DataError(
            f"{source}: the target torque has zero variance (constant {float(y[0])!r}); a "
            "network cannot learn from it; record a load that varies"
        )
    return x, y
