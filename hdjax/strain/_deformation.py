r"""Torque from deformation: joint stiffness times the twist of two quantised encoders.

$$\hat T = K\left(\frac{\hat q_M}{N} - \hat q_L\right),$$

eq. (17) read backwards, with $\hat q$ the encoder angles rounded to whole counts. This is the
linear-stiffness version of the deformation-based estimate of Song et al. (2019), who replace
$K$ by a calibrated nonlinear compliance with hysteresis; it is the competitor of the flexspline
bridge in [`hdjax.pipelines.compare_feedback`][].
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, Float, RealLike, Scalar
from .._errors import ConfigError
from ._bridge_sensor import AbstractTorqueSensor
from ._control import TABLE_I


def quantise(angle: RealLike, bits: int | None) -> Float[Array, " ..."]:
    """Round an angle [rad] to the nearest count of a `bits`-bit-per-revolution encoder."""
    angle = jnp.asarray(angle, jnp.float64)
    if bits is None:
        return angle
    lsb = 2.0 * jnp.pi / 2**bits
    return jnp.round(angle / lsb) * lsb


class DeformationSensor(AbstractTorqueSensor):
    r"""Joint torque as stiffness times the encoder twist, eq. (17) with quantised angles.

    **Arguments:**

    - `stiffness`: the assumed joint stiffness $K$ [N·m/rad] (Table I: 8800).
    - `ratio`: $N$.
    - `motor_bits`, `load_bits`: encoder resolutions in counts per revolution $= 2^\text{bits}$
      (`None` for an exact angle). Defaults: 14 bits at the motor (a 4096-line encoder read
      ×4) and 19 bits at the output, i.e. output steps of 12 µrad = 0.105 N·m at $K$ = 8800.
    """

    stiffness: Scalar = TABLE_I["stiffness"]
    ratio: Scalar = TABLE_I["ratio"]
    motor_bits: int | None = eqx.field(default=14, static=True)
    load_bits: int | None = eqx.field(default=19, static=True)

    def __check_init__(self):
        for name in ("stiffness", "ratio"):
            v = getattr(self, name)
            if isinstance(v, (int, float)) and not (math.isfinite(v) and v > 0):
                raise ConfigError(f"DeformationSensor.{name} must be positive, got {v!r}")
        for name in ("motor_bits", "load_bits"):
            v = getattr(self, name)
            if v is not None and (not isinstance(v, int) or not 1 <= v <= 40):
                raise ConfigError(f"DeformationSensor.{name} must be an int in 1..40, got {v!r}")

    def torque_step(self) -> Scalar:
        """Torque equivalent of one output-encoder count [N·m] (0 for an exact encoder)."""
        if self.load_bits is None:
            return 0.0
        return self.stiffness * 2 * math.pi / 2**self.load_bits

    def read(self, torque: RealLike, q_m: RealLike, q_l: RealLike) -> Float[Array, " ..."]:
        twist = quantise(q_m, self.motor_bits) / self.ratio - quantise(q_l, self.load_bits)
        return self.stiffness * twist
