"""What the friction families share: the two speeds, their scale and the velocity grid.

Coulomb, viscous and Stribeck friction act on the motor speed (between the motor and the wave
generator) and on the link speed (in the output bearing, between the flexspline and the torque
sensor); each family has one plant effect per side and one discover family per velocity, and
scans its scale on a grid of fractions of the velocity's RMS.

References: Armstrong-Hélouvry, Dupont and Canudas de Wit, "A survey of models, analysis tools
and compensation methods for the control of machines with friction", Automatica 30(7), 1994.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ._base import Candidate, CandidateContext, both_sides
from ._fields import rounded

VELOCITIES = ("omega_m", "omega_l")
"""The two speeds a friction law can act on: motor and link."""


def velocity_rms(sig, signal: str) -> float:
    """RMS of a velocity signal (the scale of friction grids)."""
    w = np.asarray(sig.get(signal))
    return float(np.sqrt(np.mean(w**2)))


def friction_effects(stem: str, build: Callable, *, motor: Callable, output: Callable) -> tuple:
    """The plant effects `<stem>_m` (slot `motor_friction`) and `<stem>_l` (`output_friction`)
    of a friction family, with one builder and the defaults `motor` and `output` (see
    [`hdjax.effects.PlantEffect`][])."""
    return both_sides(stem, "friction", build, motor=motor, output=output)


def velocity_candidates(
    ctx: CandidateContext, stem: str, make: Callable, fractions: Sequence[float]
) -> list[Candidate]:
    """The candidates `<stem>:omega_m` and `<stem>:omega_l` of a friction family.

    For each velocity that moves and that the loop wants, one candidate per fraction of the
    velocity's RMS: the term `make(signal, scale)` at `scale` the fraction times the RMS (4
    significant digits), left out where `make` returns `None`.
    """
    out = []
    for signal in VELOCITIES:
        rms = velocity_rms(ctx.sig, signal)
        if rms == 0.0 or not ctx.wants(f"{stem}:{signal}"):
            continue
        terms = (make(signal, rounded(f * rms)) for f in fractions)
        out += [Candidate.of(term) for term in terms if term is not None]
    return out
