r"""The bench's sensors: two quantised encoders, a noisy current feedback and a torque sensor.

Song et al. Section IV.A: two 21-bit encoders (motor side and output side), the current fed back
by the driver every 0.5 ms, a commercial torque sensor between the reducer and the link.
"""

from __future__ import annotations

import dataclasses
import math

from .._errors import ConfigError


@dataclasses.dataclass(frozen=True)
class SensorConfig:
    """Resolution and noise of the simulated sensors (plain Python numbers, static under jit).

    **Arguments:**

    - `encoder_bits_motor`: counts per motor revolution = 2**bits (default 21, Song Section IV.A).
    - `encoder_bits_load`: counts per output revolution = 2**bits (default 21).
    - `current_noise`: standard deviation of the current feedback [A] (default 0.05 A, 0.5 % of
      the ~10 A that holds the rated torque of the Song preset).
    - `current_period`: the driver's current feedback period [s] (default 0.5 ms, Song IV.A).
    - `torque_noise`: standard deviation of the torque sensor [N·m]; `None` means 0.2 % of the
      rated torque (commercial strain-gauge sensors: 0.1-0.5 % of full scale).
    - `temperature_resolution`: quantisation of the temperature column [°C].
    - `noise`: `False` switches noise and quantisation off (for tests and identification).
    """

    encoder_bits_motor: int = 21
    encoder_bits_load: int = 21
    current_noise: float = 0.05
    current_period: float = 5e-4
    torque_noise: float | None = None
    temperature_resolution: float = 0.1
    noise: bool = True

    def __post_init__(self):
        for key in ("encoder_bits_motor", "encoder_bits_load"):
            bits = getattr(self, key)
            if isinstance(bits, bool) or not isinstance(bits, int) or not 1 <= bits <= 40:
                raise ConfigError(f"sensors: {key} must be an integer in 1..40, got {bits!r}")
        for key in ("current_noise", "temperature_resolution"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"sensors: {key} must be a non-negative number, got {v!r}")
        if self.torque_noise is not None and not (
            isinstance(self.torque_noise, (int, float))
            and math.isfinite(self.torque_noise)
            and self.torque_noise >= 0
        ):
            raise ConfigError(
                f"sensors: torque_noise must be >= 0 or None, got {self.torque_noise!r}"
            )
        if not (isinstance(self.current_period, (int, float)) and self.current_period > 0):
            raise ConfigError(
                f"sensors: current_period must be positive, got {self.current_period!r}"
            )

    def motor_step(self) -> float:
        """Motor encoder quantum [rad]."""
        return 2.0 * math.pi / 2**self.encoder_bits_motor

    def load_step(self) -> float:
        """Load encoder quantum [rad]."""
        return 2.0 * math.pi / 2**self.encoder_bits_load
