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

from typing import ClassVar

import equinox as eqx
import numpy as np

from .._custom_types import Array, Float
from ._base import (
    AbstractFamily,
    AbstractLinearTorqueTerm,
    AbstractPlantEffect,
    AbstractSignalTerm,
    Candidate,
    PlantEffect,
    check_positive,
    f64,
    fmt,
    require,
)


class Column(AbstractSignalTerm):
    """An extra recording column (e.g. `temperature`), centred and scaled: a twist drift."""

    name: str = eqx.field(static=True)
    center: float = eqx.field(default=0.0, static=True)
    scale: float = eqx.field(default=1.0, static=True)

    def __check_init__(self):
        check_positive("Column", "scale", self.scale)

    @property
    def key(self) -> str:
        return f"column:{self.name}"

    def names(self) -> tuple[str, ...]:
        return (f"({self.name}-{fmt(self.center)})/{fmt(self.scale)}",)

    @property
    def signal_name(self) -> str:
        return self.name

    def transform(self, x, xp):
        return (x - self.center) / self.scale


class ColumnTimesTorque(AbstractLinearTorqueTerm):
    """An extra column times torque: a compliance that drifts with e.g. temperature,
    $\\psi = \\frac{x - x_0}{s} \\frac{T}{\\tau_0}$ (linear in torque, inverted in closed form)."""

    name: str = eqx.field(static=True)
    center: float = eqx.field(default=0.0, static=True)
    scale: float = eqx.field(default=1.0, static=True)
    torque_scale: float = eqx.field(default=1.0, static=True)

    def __check_init__(self):
        check_positive("ColumnTimesTorque", "scale", self.scale)
        check_positive("ColumnTimesTorque", "torque_scale", self.torque_scale)

    @property
    def key(self) -> str:
        return f"column:{self.name}*torque"

    def names(self) -> tuple[str, ...]:
        return (f"({self.name}-{fmt(self.center)})/{fmt(self.scale)}*T/{fmt(self.torque_scale)}",)

    def torque_slope(self, sig):
        """$u(x)$ with $\\psi = u(x) T$."""
        return (sig.get(self.name) - self.center) / (self.scale * self.torque_scale)

    def numpy_torque_slope(self, sig) -> np.ndarray:
        return (np.asarray(sig.get(self.name)) - self.center) / (self.scale * self.torque_scale)


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
    time_constant: Float[Array, ""]
    heating: Float[Array, ""]
    drift: Float[Array, ""]

    def reciprocals(self):
        return {"time_constant": 1.0 / self.time_constant}

    def rate(self, temp, current, inv=None):
        inv = self.reciprocals() if inv is None else inv
        return (
            (self.ambient - temp) * inv["time_constant"]
            + self.heating * current * current
            + self.drift
        )


def _build(name: str, p: dict) -> Temperature:
    for f in ("reference", "ambient", "initial", "alpha", "beta", "drift"):
        require(name, f, p[f], shape=())
    require(name, "time_constant", p["time_constant"], positive=True, shape=())
    require(name, "heating", p["heating"], nonneg=True, shape=())
    return Temperature(**{k: f64(v) for k, v in p.items()})


class ThermalFamily(AbstractFamily):
    """Thermal drift: plant `temperature`; terms `Column`, `ColumnTimesTorque` on any extra
    column (discover family `column`)."""

    name: ClassVar[str] = "thermal"
    terms: ClassVar[tuple] = (Column, ColumnTimesTorque)
    plant_effects: ClassVar[tuple] = (
        PlantEffect(
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
            _build,
        ),
    )
    discover_families: ClassVar[tuple] = ("column",)
    vocabulary: ClassVar[str] = "column:NAME, column:NAME*torque"
    options: ClassVar[dict] = {}

    def candidates(self, ctx):
        if "column" not in ctx.families:
            return []
        out = []
        for name in ctx.extra_columns:
            x = np.asarray(ctx.sig.get(name))
            center, scale = float(f"{x.mean():.6g}"), float(f"{x.std():.4g}")
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
