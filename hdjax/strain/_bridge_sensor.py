r"""The flexspline bridge as a joint torque sensor on a simulated joint.

The bridge of eqs. (5)-(13) is read at the joint torque the simulated drive transmits, with the
gauge angle $\beta$ set by the wave generator's angle relative to the flexspline. The wave
generator turns with the motor; the flexspline is either fixed to the casing (Type A of Fig. 10,
the sensor test rig) or turns with the output (Type B, the torque-control rig). The ellipse has
two lobes, so the modulation is $\Psi_0 \sin 2\beta$: twice per motor revolution, $2N$ times per
output revolution. A misalignment $\Delta\alpha$ leaves the ripple $\Psi\sin(2\beta + \gamma)$ of
eqs. (10)-(12) in the reading.

**References:** Hashimoto, Kiyosawa & Paul (1993), Sections III-A, III-B and Fig. 10.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax.numpy as jnp

from .._custom_types import Array, Float, RealLike, Scalar
from .._errors import ConfigError
from ._gauges import (
    PSI0_PAPER,
    FlexsplineGeometry,
    GaugeStrains,
    bridge_output,
    gauge_strains,
    residual_ripple,
    strain_per_torque,
)

_MOUNTINGS = ("output", "casing")


class AbstractTorqueSensor(eqx.Module):
    """A joint torque sensor read by the sampled controller.

    `read(torque, q_m, q_l)` returns the sensed joint torque [N·m] from the true transmitted
    torque and the motor and output angles [rad] (a sensor may use any of them).
    """

    @abc.abstractmethod
    def read(self, torque: RealLike, q_m: RealLike, q_l: RealLike) -> Float[Array, " ..."]:
        raise NotImplementedError


class IdealTorqueSensor(AbstractTorqueSensor):
    """The true joint torque, unaltered (the reference case)."""

    def read(self, torque: RealLike, q_m: RealLike, q_l: RealLike) -> Float[Array, " ..."]:
        return jnp.asarray(torque, jnp.float64)


class StrainGaugeSensor(AbstractTorqueSensor):
    r"""A four-gauge flexspline torque sensor, read through its amplifier and calibrated gain.

    **Arguments:**

    - `geometry`: the diaphragm, [`hdjax.strain.FlexsplineGeometry`][] (paper's by default).
    - `gauge_factor`: $K_{gf}$ (2.1).
    - `supply`: bridge excitation [V] (3).
    - `amplifier_gain`: the amplifier after the bridge (500).
    - `psi0`: wave-generator modulation amplitude $\Psi_0$ of $\epsilon_1 - \epsilon_2$ [strain]
      (100e-6, Sec. III-A).
    - `dalpha`: circumferential misalignment $\Delta\alpha$ of gauges R3/R4 [rad].
    - `beta0`: angle $\beta$ of gauges R1/R2 from the ellipse's major axis when the motor and
      output angles are zero [rad].
    - `mounting`: `"output"` (Type B, flexspline on the output: $\beta = \beta_0 + q_M - q_L$)
      or `"casing"` (Type A, flexspline fixed: $\beta = \beta_0 + q_M$).
    - `adc_bits`: resolution of the converter that samples the amplified voltage over
      $\pm$`adc_range` volts, or `None` for an ideal reading.
    - `adc_range`: the converter's full scale [V] (10).

    The reading is converted back to torque with the nominal sensitivity
    $K_R \times$ `amplifier_gain` of eq. (8), as a user calibrating from the datasheet would.
    """

    geometry: FlexsplineGeometry = FlexsplineGeometry()
    gauge_factor: Scalar = 2.1
    supply: Scalar = 3.0
    amplifier_gain: Scalar = 500.0
    psi0: Scalar = PSI0_PAPER
    dalpha: Scalar = 0.0
    beta0: Scalar = 0.0
    mounting: str = eqx.field(default="output", static=True)
    adc_bits: int | None = eqx.field(default=None, static=True)
    adc_range: float = eqx.field(default=10.0, static=True)

    def __check_init__(self):
        for name in ("gauge_factor", "supply", "amplifier_gain"):
            v = getattr(self, name)
            if isinstance(v, (int, float)) and not (math.isfinite(v) and v > 0):
                raise ConfigError(f"StrainGaugeSensor.{name} must be positive, got {v!r}")
        if isinstance(self.psi0, (int, float)) and not (self.psi0 >= 0):
            raise ConfigError(f"StrainGaugeSensor.psi0 must be >= 0, got {self.psi0!r}")
        if self.mounting not in _MOUNTINGS:
            raise ConfigError(
                f"StrainGaugeSensor.mounting must be one of {_MOUNTINGS}, got {self.mounting!r}"
            )
        if self.adc_bits is not None and (
            not isinstance(self.adc_bits, int) or not 2 <= self.adc_bits <= 32
        ):
            raise ConfigError(
                f"adc_bits must be an integer in 2..32 or None, got {self.adc_bits!r}"
            )
        if not self.adc_range > 0:
            raise ConfigError(f"adc_range must be positive, got {self.adc_range!r}")

    # -- geometry and calibration -------------------------------------------------------------
    def sensitivity(self) -> Float[Array, ""]:
        r"""Amplified sensitivity $K_R \times$ gain [V/(N·m)], eq. (8): 25 mV/(N·m) nominal."""
        return (
            self.amplifier_gain * self.gauge_factor * self.supply * strain_per_torque(self.geometry)
        )

    def beta(self, q_m: RealLike, q_l: RealLike) -> Float[Array, " ..."]:
        r"""Angle $\beta$ of gauges R1/R2 from the wave generator's major axis [rad]."""
        q_m = jnp.asarray(q_m, jnp.float64)
        if self.mounting == "output":
            return self.beta0 + q_m - jnp.asarray(q_l, jnp.float64)
        return self.beta0 + q_m

    def ripple_amplitude(self) -> Float[Array, ""]:
        r"""Torque-equivalent amplitude of the residual ripple, $\Psi/(4\,\epsilon_t/T)$ [N·m]."""
        psi = residual_ripple(self.dalpha, self.psi0).amplitude
        return psi / (4.0 * strain_per_torque(self.geometry))

    # -- reading ------------------------------------------------------------------------------
    def strains(
        self,
        torque: RealLike,
        q_m: RealLike,
        q_l: RealLike,
    ) -> GaugeStrains:
        """The four gauge strains under joint torque `torque` at motor/output angles q_m, q_l."""
        eps_t = jnp.asarray(torque, jnp.float64) * strain_per_torque(self.geometry)
        return gauge_strains(eps_t, self.beta(q_m, q_l), self.psi0, self.dalpha)

    def voltage(
        self,
        torque: RealLike,
        q_m: RealLike,
        q_l: RealLike,
    ) -> Float[Array, " ..."]:
        """Amplified bridge voltage [V], quantised by the ADC if `adc_bits` is set."""
        v = self.amplifier_gain * bridge_output(
            self.strains(torque, q_m, q_l), self.gauge_factor, self.supply
        )
        if self.adc_bits is not None:
            lsb = 2.0 * self.adc_range / 2**self.adc_bits
            v = jnp.clip(jnp.round(v / lsb) * lsb, -self.adc_range, self.adc_range)
        return v

    def read(self, torque: RealLike, q_m: RealLike, q_l: RealLike) -> Float[Array, " ..."]:
        r"""The sensor's torque reading [N·m]: voltage over the nominal sensitivity.

        Equals `torque` plus the ripple $\Psi\sin(2\beta+\gamma)/(4\epsilon_t/T)$ (and the ADC
        step if any); exactly `torque` when the gauges are aligned.
        """
        return self.voltage(torque, q_m, q_l) / self.sensitivity()
