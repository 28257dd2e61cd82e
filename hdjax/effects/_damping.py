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

import equinox as eqx
import numpy as np

from ._base import AbstractFamily, AbstractTorqueFreeTerm, Candidate, check_positive, fmt


class TwistRate(AbstractTorqueFreeTerm):
    """Structural damping signature: the twist rate $\\dot{\\Delta\\theta} = s(\\omega_l -
    \\omega_m/N)$ (eq. (5) differentiated), divided by `scale`. A damped flexspline carries
    $c\\dot{\\Delta\\theta}$ on top of its elastic torque, which the twist alone cannot show."""

    ratio: float = eqx.field(default=1.0, static=True)
    sign: float = eqx.field(default=1.0, static=True)
    scale: float = eqx.field(default=1.0, static=True)

    def __check_init__(self):
        check_positive("TwistRate", "ratio", self.ratio)
        check_positive("TwistRate", "scale", self.scale)

    @property
    def key(self) -> str:
        return "damping:twist_rate"

    def names(self) -> tuple[str, ...]:
        return (f"twist_rate/{fmt(self.scale)}",)

    def columns(self, sig, torque=None):
        rate = self.sign * (sig.omega_l - sig.omega_m / self.ratio)
        return (rate / self.scale)[:, None]

    def numpy_columns(self, sig, torque=None) -> np.ndarray:
        rate = self.sign * (np.asarray(sig.omega_l) - np.asarray(sig.omega_m) / self.ratio)
        return (rate / self.scale)[:, None]


class DampingFamily(AbstractFamily):
    """Structural damping: the plant's `damping` parameter; term `TwistRate`."""

    name: ClassVar[str] = "damping"
    terms: ClassVar[tuple] = (TwistRate,)
    plant_effects: ClassVar[tuple] = ()
    discover_families: ClassVar[tuple] = ("damping:twist_rate",)
    vocabulary: ClassVar[str] = "damping:twist_rate"
    options: ClassVar[dict] = {}

    def candidates(self, ctx):
        if not ctx.wants("damping:twist_rate"):
            return []
        rate = np.asarray(ctx.sig.omega_l) - np.asarray(ctx.sig.omega_m) / ctx.ratio
        rms = float(np.sqrt(np.mean(rate**2)))
        if rms == 0.0:
            return []
        term = TwistRate(
            ratio=float(ctx.ratio), sign=float(ctx.twist_sign), scale=float(f"{rms:.4g}")
        )
        return [Candidate(term.key, term.key, term)]
