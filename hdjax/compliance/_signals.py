"""The per-sample signals a compliance model reads: twist, current, angles, velocities, extras."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, Float
from .._errors import DataError
from .._features import finite_difference_velocity, smoothed_velocity, twist
from .._recording import Recording

VELOCITY_METHODS = ("difference", "smoothed")


class Signals(eqx.Module):
    """Model inputs derived from a recording (Song et al. eqs. (5), (11)-(14)).

    `theta_m` is the wave-generator input angle $\\theta_{wgi}$, `theta_l` the flexspline output
    angle $\\theta_{fso}$, `omega_*` their velocities and `twist` the total torsional angle
    $\\Delta\\theta$ of eq. (5) (with the joint's `twist_sign`).
    """

    twist: Float[Array, " n"]
    current: Float[Array, " n"]
    theta_m: Float[Array, " n"]
    theta_l: Float[Array, " n"]
    omega_m: Float[Array, " n"]
    omega_l: Float[Array, " n"]
    extras: dict[str, Float[Array, " n"]]

    @property
    def n_samples(self) -> int:
        return int(self.twist.shape[0])

    def get(self, name: str) -> Float[Array, " n"]:
        """A signal by name (`current`, `theta_m`, `omega_l`, ... or an extra column)."""
        if name in ("twist", "current", "theta_m", "theta_l", "omega_m", "omega_l"):
            return getattr(self, name)
        if name in self.extras:
            return self.extras[name]
        raise DataError(
            f"no signal {name!r}; available: twist, current, theta_m, theta_l, omega_m, omega_l"
            + "".join(f", {k}" for k in sorted(self.extras))
        )


def signals_from_recording(
    recording: Recording,
    ratio: float,
    twist_sign: float = 1.0,
    *,
    velocity: str = "difference",
    half_window: int = 5,
) -> Signals:
    """Derive [`hdjax.compliance.Signals`][] from a recording.

    Velocities by the paper's backward difference (eqs. (13)-(14)) or, with
    `velocity="smoothed"`, by a local least-squares line over `2*half_window+1` samples.
    """
    if velocity not in VELOCITY_METHODS:
        raise DataError(f"velocity must be one of {VELOCITY_METHODS}, got {velocity!r}")
    diff = (
        finite_difference_velocity
        if velocity == "difference"
        else (lambda t, x: smoothed_velocity(t, x, half_window))
    )
    return Signals(
        twist=twist(recording.theta_m, recording.theta_l, ratio, twist_sign),
        current=jnp.asarray(recording.current, jnp.float64),
        theta_m=jnp.asarray(recording.theta_m, jnp.float64),
        theta_l=jnp.asarray(recording.theta_l, jnp.float64),
        omega_m=diff(recording.t, recording.theta_m),
        omega_l=diff(recording.t, recording.theta_l),
        extras={k: jnp.asarray(v, jnp.float64) for k, v in recording.extras.items()},
    )
