"""The joint description: reduction ratio, rated torque and sensor facts, from a `[joint]` table."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path

from ._custom_types import PathLike
from ._errors import ConfigError, check_keys
from ._io import read_toml


@dataclasses.dataclass(frozen=True)
class Joint:
    """What is known about a joint before calibration.

    **Arguments:**

    - `ratio`: reduction ratio $N$ of the harmonic drive (Song et al. eq. (1): $\\theta_i = N
      \\theta_o$), positive.
    - `rated_torque`: rated output torque $\\tau_0$ [N·m]; sets the default flexspline knots
      $\\pm\\tau_0/3, \\pm 2\\tau_0/3$ (eq. (7)) and the error rate in % (Fig. 17).
    - `twist_sign`: $+1$ when the twist $\\theta_l - \\theta_m/N$ grows with torque, $-1$ when
      the encoders count the other way (as joint 3 of the LARA8 logs does).
    - `encoder_bits_motor`, `encoder_bits_load`: encoder resolutions in bits, if known.
    - `current_limit`: the driver's current limit [A], if known.
    - `torque_constant`: motor torque constant [N·m/A], if known.
    - `name`: a label.
    """

    ratio: float
    rated_torque: float
    twist_sign: float = 1.0
    encoder_bits_motor: int | None = None
    encoder_bits_load: int | None = None
    current_limit: float | None = None
    torque_constant: float | None = None
    name: str = "joint"

    def __post_init__(self):
        _check_positive("ratio", self.ratio)
        _check_positive("rated_torque", self.rated_torque)
        if self.twist_sign not in (1, -1, 1.0, -1.0):
            raise ConfigError(f"[joint] twist_sign must be 1 or -1, got {self.twist_sign!r}")
        for key in ("encoder_bits_motor", "encoder_bits_load"):
            bits = getattr(self, key)
            if bits is not None and (not isinstance(bits, int) or not 1 <= bits <= 40):
                raise ConfigError(f"[joint] {key} must be an integer in 1..40, got {bits!r}")
        for key in ("current_limit", "torque_constant"):
            if getattr(self, key) is not None:
                _check_positive(key, getattr(self, key))

    @classmethod
    def from_dict(cls, table: Mapping, *, where: str = "[joint]") -> Joint:
        """Build from a `[joint]` table; unknown keys get a "did you mean" answer."""
        check_keys(table, [f.name for f in dataclasses.fields(cls)], where)
        for key in ("ratio", "rated_torque"):
            if key not in table:
                raise ConfigError(f"{where}: missing required key {key!r} (a positive number)")
        # the numbers first, as __post_init__ would, so a TOML string gets this message
        for key in ("ratio", "rated_torque", "current_limit", "torque_constant"):
            if table.get(key) is not None:
                _check_positive(key, table[key])
        return cls(**dict(table))

    def to_dict(self) -> dict:
        """The description as a TOML-ready table (keys with `None` values left out)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


def _check_positive(key: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"[joint] {key} must be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise ConfigError(f"[joint] {key} must be a positive finite number, got {value!r}")


def load_joint(path: PathLike) -> Joint:
    """Read a [`hdjax.Joint`][] from the `[joint]` table of a TOML file."""
    path = Path(path)
    doc = read_toml(path)
    if "joint" not in doc:
        raise ConfigError(f"{path}: no [joint] table (it needs at least ratio and rated_torque)")
    return Joint.from_dict(doc["joint"], where=f"{path} [joint]")
