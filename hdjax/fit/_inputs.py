r"""What a hybrid model reads from a recording: compliance signals, network features, dynamics.

[`hdjax.fit.hybrid_inputs`][] computes everything once per recording, from the four recorded
columns only ($t$, $\theta_m$, $\theta_l$, $I$; the torque column is kept as the training target):

- the compliance signals of Song et al. eqs. (5), (11)-(14);
- the network's input vector (after eq. (28), optionally with periodic angles);
- the motor velocity and acceleration for the motor-side equation of variant (c);
- two optional *dynamic* network inputs beyond the paper:

  - `twist_rate`: $\dot{\Delta\theta}$, eq. (5) differentiated by a local least-squares line over
    five samples. A damped flexspline carries $c\dot{\Delta\theta}$ on top of its elastic torque,
    which the twist alone cannot show; it matters when the joint rings (a load released at
    once).
  - `hysteresis`: Dahl states of the recorded twist ([`hdjax.compliance.dahl_state`][]) at a few
    twist scales, a causal memory of the twist path. The hysteresis torque of the joint (the loop
    of Song et al. Fig. 2) depends on the direction the twist last moved, which no
    instantaneous input carries; several scales let the network build a loop without knowing its
    width (a Preisach-like superposition).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike, Float, Int
from .._errors import ConfigError
from .._features import signals, smoothed_velocity
from .._joint import Joint
from .._recording import Recording
from ..compliance import ComplianceModel, Signals, dahl_state
from ..network import FeatureLayout, build_features

TWIST_RATE_HALF_WINDOW = 2
"""Half-width (samples) of the local line that differentiates the twist. At 2 kHz a +-1 ms line
passes a 50 Hz joint mode with under 1 % attenuation and no delay."""

DAHL_FRACTIONS = (0.01, 0.03, 0.1)
"""Default widths of the Dahl memory states, in fractions of the rated torque (converted to
twist by the central-segment compliance, see [`hdjax.fit.dahl_scales`][])."""


class HybridInputs(eqx.Module):
    """Everything the hybrid model reads from a recording, computed once (all `(n,)` or `(n, f)`).

    **Fields:** `sig` (compliance signals or `None`), `x` (network features), `current`,
    `omega_m`, `alpha_m` (recorded motor velocity and acceleration), `torque` (reference or
    `None`), `layout` (names of the columns of `x`).
    """

    sig: Signals | None
    x: Float[Array, "n n_features"]
    current: Float[Array, " n"]
    omega_m: Float[Array, " n"]
    alpha_m: Float[Array, " n"]
    torque: Float[Array, " n"] | None
    layout: FeatureLayout

    @property
    def n_samples(self) -> int:
        return int(self.x.shape[0])

    def take(self, idx: Int[ArrayLike, " m"] | slice) -> HybridInputs:
        """Rows `idx` (inside jit)."""
        return jax.tree.map(lambda a: a[idx], self)


def dahl_scales(
    compliance: ComplianceModel, fractions: tuple[float, ...] = DAHL_FRACTIONS
) -> tuple[float, ...]:
    r"""Twist scales [rad] for the Dahl memory inputs: $f\,\tau_0\,k_c$ for each fraction $f$.

    $k_c$ is the compliance of the segment holding 0 N·m (eq. (7), $k_1$ in the paper's naming) of
    a calibrated [`hdjax.compliance.ComplianceModel`][], $\tau_0$ its rated torque: a fraction $f$
    is the torque change (relative to the rated torque) over which the state saturates.
    """
    fractions = _check_positive("fractions", fractions)
    n_neg = sum(1 for k in compliance.knots if k < 0.0)
    k_c = float(compliance.k[n_neg])
    if not (math.isfinite(k_c) and k_c > 0):
        raise ConfigError(
            f"dahl_scales needs a calibrated compliance model with a positive central compliance, "
            f"got k = {k_c!r}; calibrate it first (hdjax.compliance.calibrate_lstsq)"
        )
    return tuple(f * compliance.rated_torque * k_c for f in fractions)


def _check_positive(name, values) -> tuple[float, ...]:
    try:
        values = tuple(values)
    except TypeError:
        raise ConfigError(f"{name} must be a tuple of positive numbers, got {values!r}") from None
    for v in values:
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float))
            or not (math.isfinite(v) and v > 0)
        ):
            raise ConfigError(f"{name} must hold positive finite numbers, got {values!r}")
    return tuple(float(v) for v in values)


def dynamic_columns(
    recording: Recording,
    joint: Joint,
    *,
    twist_rate: bool,
    hysteresis,  # validated below (a tuple of positive scales), with a readable error
) -> dict[str, Float[Array, " n"]]:
    r"""The dynamic network inputs (see the module docstring), name -> `(n,)` column.

    `twist_rate`: $\dot{\Delta\theta}$ of eq. (5) [rad/s]; `hysteresis`: twist scales [rad] of
    Dahl states $z_k = z_{k-1} + \frac{\Delta\theta_k - \Delta\theta_{k-1}}{s}
    (1 - z_{k-1}\,\mathrm{sgn}(\cdot))$, each starting at 0 at the first sample.
    """
    scales = _check_positive("hysteresis", hysteresis)
    tw = signals(recording, joint).twist
    cols = {}
    if twist_rate:
        cols["twist_rate"] = smoothed_velocity(recording.t, tw, TWIST_RATE_HALF_WINDOW)
    for s in scales:
        cols[f"dahl(twist/{s:.4g})"] = dahl_state(tw, s)
    return cols


def hybrid_inputs(
    recording: Recording,
    joint: Joint,
    *,
    compliance: ComplianceModel | None = None,
    periodic: bool = True,
    kalman: bool = False,
    twist_rate: bool = False,
    hysteresis=(),  # validated below (a tuple of positive scales), with a readable error
) -> HybridInputs:
    """Precompute the inputs of a [`hdjax.fit.HybridModel`][] from a recording.

    **Arguments:**

    - `recording`: the [`hdjax.Recording`][] (its torque, if any, becomes the target).
    - `joint`: the [`hdjax.Joint`][].
    - `compliance`: the model whose signals are needed (Song et al. eqs. (5), (11)-(14)), or
      `None`.
    - `periodic`, `kalman`: network feature options (see [`hdjax.network.build_features`][]).
    - `twist_rate`: append the twist rate (eq. (5) differentiated) to the network inputs.
    - `hysteresis`: twist scales [rad] of Dahl memory states of the twist to append (e.g.
      [`hdjax.fit.dahl_scales`][] of the compliance model); `()` for none.

    **Returns:** a [`hdjax.fit.HybridInputs`][]; its `layout` names every network column.
    """
    sig = None
    if compliance is not None:
        sig = signals(recording, compliance.joint, velocity=compliance.velocity)
    feats = build_features(recording, joint, periodic=periodic, kalman=kalman)
    extra = dynamic_columns(recording, joint, twist_rate=twist_rate, hysteresis=hysteresis)
    x, layout = feats.x, feats.layout
    if extra:
        x = jnp.concatenate([x] + [c[:, None] for c in extra.values()], axis=1)
        layout = FeatureLayout(
            layout.names + tuple(extra), layout.periodic, layout.orders, layout.kalman
        )
    omega = smoothed_velocity(recording.t, recording.theta_m, 5)
    alpha = smoothed_velocity(recording.t, omega, 5)
    return HybridInputs(
        sig=sig,
        x=x,
        current=jnp.asarray(recording.current, jnp.float64),
        omega_m=omega,
        alpha_m=alpha,
        torque=recording.torque,
        layout=layout,
    )
