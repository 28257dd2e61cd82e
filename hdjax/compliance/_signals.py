"""The per-sample signals a compliance model reads (see [`hdjax.signals`][], the one place they
are derived)."""

from __future__ import annotations

from .._errors import ConfigError
from .._features import (
    VELOCITY_METHODS as VELOCITY_METHODS,
    Signals as Signals,
    derive_signals,
    velocity_estimator,
)
from .._joint import Joint
from .._recording import Recording


def signals_from_recording(
    recording: Recording,
    joint: Joint | float,
    twist_sign: float | None = None,
    *,
    velocity: str = "difference",
    half_window: int = 5,
) -> Signals:
    """Derive [`hdjax.compliance.Signals`][] from a recording: [`hdjax.signals`][].

    `joint` is an [`hdjax.Joint`][] (preferred), or the ratio with `twist_sign` given next to it
    (the sign defaults to +1 only in that older form).

    Velocities by the paper's backward difference (eqs. (13)-(14)) or, with
    `velocity="smoothed"`, by a local least-squares line over `2*half_window+1` samples.
    """
    if isinstance(joint, Joint):
        if twist_sign is not None and float(twist_sign) != joint.twist_sign:
            raise ConfigError(
                f"twist_sign {twist_sign} contradicts the joint's twist_sign {joint.twist_sign}"
            )
        ratio, sign = joint.ratio, joint.twist_sign
    else:
        ratio, sign = joint, 1.0 if twist_sign is None else twist_sign
    diff = velocity_estimator(velocity, half_window, causal=False)
    return derive_signals(recording, ratio, sign, diff)
