r"""Thermal drift: the joint's twist and compliance change with its temperature.

Heat from the motor current and the surroundings changes the lubricant's viscosity and the
parts' dimensions, so the zero point drifts and the compliance scales with temperature. The
plant carries a temperature state, $\dot\vartheta = (\vartheta_a - \vartheta)/\tau_{th} + h i^2 +
r$, that scales the flexspline compliance by $1 + \alpha(\vartheta - \vartheta_0)$ and offsets
the twist by $\beta(\vartheta - \vartheta_0)$; the recording gets a `temperature` column. The
regression terms work on any extra recording column (a temperature, a humidity, ...): a drift
$(x - \bar x)/s_x$, and a compliance that drifts with it, $(x - \bar x)/s_x \cdot T/\tau_0$, linear
in torque and so inverted in closed form. The loop offers both for every usable extra column.

References: Song et al. 2019, Section IV.C (temperature among the unmodelled effects);
Harmonic Drive CSG/CSF catalogue, efficiency and temperature.
"""

from __future__ import annotations

from types import ModuleType
from typing import ClassVar

import jax
import numpy as np

from .._custom_types import Array, ArrayLike, Float, Pointwise, PointwiseOut, Samples, SamplesLike
from .._features import Signals
from ._base import (
    AbstractFamily,
    AbstractLinearTorqueTerm,
    AbstractPlantEffect,
    AbstractSignalTerm,
    Candidate,
    CandidateContext,
)
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, hyper, labels, rounded
from ._traced import opaque, opaque_in


class Column(AbstractSignalTerm):
    """An extra recording column (e.g. `temperature`), centred and scaled: a twist drift."""

    name: str = hyper()
    center: float = hyper(0.0)
    scale: float = hyper(1.0, positive=True)

    key, names = labels("column:{name}", "({name}-{center})/{scale}")

    @property
    def signal(self) -> str:
        """The extra column the drift reads (its `name`)."""
        return self.name

    def transform(self, x: SamplesLike, xp: ModuleType) -> Float[ArrayLike, " n"]:
        center, scale = opaque_in(xp, self.center, self.scale)  # as traced values round
        return (x - center) / scale

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The centred, scaled column for the exported estimator."""
        x = c.signal(self.name)
        return CSnippet(columns=(f"({x} - {c.num(self.center)}) / {c.num(self.scale)}",))


class ColumnTimesTorque(AbstractLinearTorqueTerm):
    """An extra column times torque: a compliance that drifts with e.g. temperature,
    $\\psi = \\frac{x - x_0}{s} \\frac{T}{\\tau_0}$ (linear in torque, inverted in closed form)."""

    name: str = hyper()
    center: float = hyper(0.0)
    scale: float = hyper(1.0, positive=True)
    torque_scale: float = hyper(1.0, positive=True)

    key, names = labels("column:{name}*torque", "({name}-{center})/{scale}*T/{torque_scale}")

    def torque_slope(self, sig: Signals) -> Samples:
        """$u(x)$ with $\\psi = u(x) T$."""
        return self._slope(sig.get(self.name))

    def numpy_torque_slope(self, sig: Signals) -> Float[np.ndarray, " n"]:
        return self._slope(np.asarray(sig.get(self.name)))

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The torque slope $u(x)$ for the exported estimator."""
        x, s = c.signal(self.name), c.num(self.scale * self.torque_scale)
        return CSnippet(columns=(f"({x} - {c.num(self.center)}) / {s}",))

    def _slope(self, x):
        # the same arithmetic for JAX and NumPy arrays; in JAX the constants made opaque, so
        # that they round as traced values do (XLA would fold them into the inversion's own)
        center, scale = self.center, self.scale * self.torque_scale
        if isinstance(x, jax.Array):
            center, scale = opaque(center), opaque(scale)
        return (x - center) / scale


class Temperature(AbstractPlantEffect):
    r"""Thermal drift: a temperature state heated by the motor current.

    $\dot\vartheta = (\vartheta_a - \vartheta)/\tau_{th} + h\, i^2 + r$ ($r$ a slow ambient
    drift [K/s]). The flexspline compliance scales as $1 + \alpha(\vartheta - \vartheta_0)$ and
    the twist gains an offset $\beta(\vartheta - \vartheta_0)$; the recording gets a `temperature`
    column.
    """

    reference: Float[Array, ""]
    ambient: Float[Array, ""]
    initial: Float[Array, ""]
    alpha: Float[Array, ""]
    beta: Float[Array, ""]
    time_constant: Float[Array, ""] = bound("positive", inverse=True)
    heating: Float[Array, ""] = bound("nonneg")
    drift: Float[Array, ""]

    def rate(self, temp: Pointwise, current: Pointwise, inv: dict | None = None) -> PointwiseOut:
        inv = self.reciprocals() if inv is None else inv
        return (
            (self.ambient - temp) * inv["time_constant"]
            + self.heating * current * current
            + self.drift
        )


class ThermalFamily(AbstractFamily):
    """Thermal drift: plant `temperature`; terms `Column`, `ColumnTimesTorque` on any extra
    column (discover family `column`)."""

    name: ClassVar[str] = "thermal"
    terms: ClassVar[tuple] = (Column, ColumnTimesTorque)
    plant_effects: ClassVar[tuple] = (
        Temperature.entry(
            "temperature",
            "temperature",
            lambda rated, k1, given: dict(
                reference=25.0,
                ambient=25.0,
                initial=25.0,
                alpha=3e-3,
                beta=1e-6,
                time_constant=300.0,
                heating=3e-3,
                drift=0.02,
            ),
        ),
    )
    discover_families: ClassVar[tuple] = ("column",)
    vocabulary: ClassVar[str] = "column:NAME, column:NAME*torque"

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        if "column" not in ctx.families:
            return []
        out = []
        for name in ctx.extra_columns:
            x = np.asarray(ctx.sig.get(name))
            center, scale = rounded(x.mean(), 6), rounded(x.std())
            if scale == 0.0:
                continue
            t1 = Column(name=name, center=center, scale=scale)
            t2 = ColumnTimesTorque(
                name=name, center=center, scale=scale, torque_scale=float(ctx.rated_torque)
            )
            for term in (t1, t2):
                if term.key not in ctx.existing_keys:
                    out.append(Candidate(term.key, "column", term))
        return out
