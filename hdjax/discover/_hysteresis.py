"""Hysteresis whose memory state is driven by the measured deformation.

The flexspline's hysteresis (Song et al. 2019, Fig. 2) is a torque $z$ in parallel with the
elastic torque whose state follows the *deflection* path: $T = T_s(\\Delta\\theta) + z$,
$\\dot z$ a Dahl law in $\\dot{\\Delta\\theta}$ (the plant's model). In the twist domain that is
$\\Delta\\theta \\approx f(T) - k\\,z(\\Delta\\theta)$: a state of the measured twist, which
needs no torque at all. So the state is computed causally from the measurement, the same way
at calibration, in every cross-validation fold and on TEST; the inversion only subtracts a
known column (a torque-free term), which is always stable, whatever the loop's sharpness.

The twist is divided by `compliance` (the starting model's small-torque compliance) so the
Dahl scale `torque_scale` reads in N·m of torque path, as for the torque-driven state.
"""

from __future__ import annotations

import dataclasses

from ..compliance._signals import Signals
from ..compliance._terms import SEGMENT_START, _fmt, dahl_state


@dataclasses.dataclass(frozen=True)
class TwistHysteresis:
    """Dahl state ([`hdjax.compliance.dahl_state`][]) of the measured twist over `compliance`,
    scale `torque_scale` [N·m]; restarts at gaps (`SEGMENT_START`)."""

    torque_scale: float = 1.0
    compliance: float = 1.0
    key: str = "hysteresis:torque"
    torque_kind: str = "none"

    def names(self) -> tuple[str, ...]:
        return (f"dahl(twist/{_fmt(self.compliance)}/{_fmt(self.torque_scale)})",)

    def columns(self, sig: Signals, torque=None):
        driver = sig.twist / self.compliance
        return dahl_state(driver, self.torque_scale, sig.extras.get(SEGMENT_START))[:, None]
