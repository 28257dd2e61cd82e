r"""Structural damping: the flexspline carries a torque proportional to its twist rate.

Material damping of the flexspline adds $c\,\dot{\Delta\theta}$ to the elastic torque
(Hashimoto et al. model the joint as a spring with a parallel damper); the twist alone cannot
show it, so a damped joint leaves a residual that follows the twist rate
$\dot{\Delta\theta} = s(\omega_l - \omega_m/N)$ (Song et al. eq. (5) differentiated). The plant
has it as the `damping` parameter of [`hdjax.plant.PlantParams`][] (always present, zero by
default in the Song preset's discover tests); the regression term is the twist rate divided by
its RMS.

References: Hashimoto et al. 1993, eq. (17); Song et al. 2019, eq. (5).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from .._custom_types import Array, Float, SamplesLike
from .._features import Signals
from ._base import (
    SEGMENT_START,
    AbstractFamily,
    AbstractTorqueFreeTerm,
    Candidate,
    CandidateContext,
    late,
)
from ._c import AbstractCEmitter, CSnippet
from ._fields import hyper, labels, rounded
from ._traced import opaque_hypers


class TwistRate(AbstractTorqueFreeTerm):
    """Structural damping signature: the twist rate $\\dot{\\Delta\\theta} = s(\\omega_l -
    \\omega_m/N)$ (eq. (5) differentiated), divided by `scale`. A damped flexspline carries
    $c\\dot{\\Delta\\theta}$ on top of its elastic torque, which the twist alone cannot show.

    **The encoders' noise.** The column at sample $k$ is the rate at sample $k-1$ (the backward
    difference of samples $k-1$ and $k-2$): the rate at $k$ differences the present sample,
    whose encoder noise is then both in the column and in the twist it explains, and a
    regression on it fits that noise (a "damping" on a joint that has none). One sample of
    delay is far below a damped mode's period at the sampling rates it can be seen at. Where a
    segment starts (`SEGMENT_START`: the record's start, a join, a long gap) the column is the
    sample's own rate, as the velocities never reach across a gap."""

    ratio: float = hyper(1.0, positive=True)
    sign: float = hyper(1.0)
    scale: float = hyper(1.0, positive=True)

    key, names = labels("damping:twist_rate", "twist_rate/{scale}")

    def columns(self, sig: Signals, torque: SamplesLike | None = None) -> Float[Array, "n 1"]:
        # constants round as traced values do (`opaque_hypers`)
        reset = sig.extras.get(SEGMENT_START)
        return opaque_hypers(self)._column(sig.omega_m, sig.omega_l, reset)[:, None]

    def numpy_columns(
        self, sig: Signals, torque: SamplesLike | None = None
    ) -> Float[np.ndarray, "n 1"]:
        reset = sig.extras.get(SEGMENT_START)
        reset = None if reset is None else np.asarray(reset)
        return self._column(np.asarray(sig.omega_m), np.asarray(sig.omega_l), reset)[:, None]

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The scaled twist rate for the exported estimator, one sample late (the previous
        sample's rate; at the first, its own)."""
        rate = f"({c.signal('omega_l')} - {c.signal('omega_m')} / {c.num(self.ratio)})"
        now, prev, out = c.local("now"), c.state("prev"), c.state("out")
        update = (
            f"const {c.real} {now} = {c.num(self.sign)} * {rate} / {c.num(self.scale)};",
            f"if ({c.first}) {prev} = {now};",
            f"{out} = {prev};",
            f"{prev} = {now};",
        )
        return CSnippet(columns=(out,), state=(("prev", 0.0), ("out", 0.0)), update=update)

    def _column(self, omega_m, omega_l, reset):
        # the same arithmetic for JAX and NumPy arrays; one sample late (class docstring)
        rate = self.sign * (omega_l - omega_m / self.ratio) / self.scale
        return late(rate, reset, None)


class DampingFamily(AbstractFamily):
    """Structural damping: the plant's `damping` parameter (no switchable effect); term
    `TwistRate`, one candidate scaled by the twist rate's RMS."""

    name: ClassVar[str] = "damping"
    terms: ClassVar[tuple] = (TwistRate,)
    plant_effects: ClassVar[tuple] = ()
    discover_families: ClassVar[tuple] = ("damping:twist_rate",)

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        if not ctx.wants("damping:twist_rate"):
            return []
        rate = np.asarray(ctx.sig.omega_l) - np.asarray(ctx.sig.omega_m) / ctx.ratio
        rms = float(np.sqrt(np.mean(rate**2)))
        if rms == 0.0:
            return []
        term = TwistRate(ratio=float(ctx.ratio), sign=float(ctx.twist_sign), scale=rounded(rms))
        return [Candidate.of(term)]
