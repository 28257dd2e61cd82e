r"""Wave-generator compliance: the elliptical cam and its bearing deform with the torque they carry.

Song et al. model the wave generator's torsional deformation as a polynomial in the motor
current, $\Delta\theta_{wg} = \sum_{i=1}^m \omega_i I^i$ (eq. (8)), which enters the joint
twist divided by the ratio (eq. (6)). The plant writes the same polynomial in the torque the
wave generator transmits, $u = T/N$, and adds $\Delta\theta_{wg}(u)/N$ in series with the
flexspline. The regression term is eq. (8) itself, a base column group of every paper model.

References: Song et al. 2019, eqs. (6), (8), (10).
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Float, NumpyDesign, Pointwise, PointwiseOut, SamplesLike
from .._errors import ConfigError
from .._features import Signals
from ._base import (
    AbstractColumnListTerm,
    AbstractFamily,
    AbstractPlantEffect,
    Candidate,
    CandidateContext,
    PlantEffect,
)
from ._c import AbstractCEmitter, CSnippet
from ._fields import concrete, hyper


class CurrentPolynomial(AbstractColumnListTerm):
    """Wave-generator deformation as a polynomial in current, eq. (8), without its constant.

    Columns $I, I^2, \\dots, I^p$; the fitted coefficient of $I^i$ is $\\omega_i / N$ (eq. (10)).
    `scale` divides the current first (the rated current, say) so high powers stay O(1).
    """

    order: int = hyper(6)
    scale: float = hyper(1.0, positive=True)

    @property
    def key(self) -> str:
        return "current:poly"

    def names(self) -> tuple[str, ...]:
        return tuple(f"w{i}" for i in range(1, self.order + 1))

    def column_list(self, sig: Signals) -> list[Float[Array, " n"]]:
        x = sig.current / self.scale
        out = [x]
        for _ in range(1, self.order):
            out.append(out[-1] * x)
        return out

    def extrapolating_arguments(self, sig: Signals) -> tuple[Float[np.ndarray, " n"], ...]:
        """The current: a polynomial extrapolates outside the range it was fitted on."""
        return (np.asarray(sig.current, np.float64),)

    def numpy_columns(self, sig: Signals, torque: SamplesLike | None = None) -> NumpyDesign:
        x = np.asarray(sig.current) / self.scale
        return np.column_stack([x ** (i + 1) for i in range(self.order)])

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """Eq. (8)'s powers of the scaled current for the exported estimator, each the previous
        one times $I/s$ (as `column_list` computes them)."""
        powers = [c.local("p1")]
        lines = [f"const {c.real} {powers[0]} = {c.signal('current')} / {c.num(self.scale)};"]
        for i in range(2, self.order + 1):
            powers.append(c.local(f"p{i}"))
            lines.append(f"const {c.real} {powers[-1]} = {powers[-2]} * {powers[0]};")
        return CSnippet(columns=tuple(powers), lines=tuple(lines))


class WaveGenerator(AbstractPlantEffect):
    r"""Wave-generator compliance, Song et al. eq. (8) with the WG torque in place of the current.

    $\Delta\theta_{wg} = \sum_{j=1}^m w_j u^j$ [rad at the motor side], $u = T/N$ [N·m] the torque
    the wave generator transmits. Its share of the joint deflection is $\Delta\theta_{wg}/N$
    (eq. (6)). `coefficients` are $w_1..w_m$; the polynomial must increase on the working range.
    """

    coefficients: Float[Array, " m"]

    def deflection(self, u: Pointwise, inv: dict | None = None) -> PointwiseOut:
        # Horner: u * (w1 + u * (w2 + ...)), exact and NaN-free at u = 0
        acc = jnp.zeros_like(u)
        for j in range(self.coefficients.shape[0] - 1, -1, -1):
            acc = acc * u + self.coefficients[j]
        return acc * u

    def slope(self, u: Pointwise, inv: dict | None = None) -> PointwiseOut:
        acc = jnp.zeros_like(u)
        for j in range(self.coefficients.shape[0] - 1, -1, -1):
            acc = acc * u + (j + 1.0) * self.coefficients[j]
        return acc


def _build(name: str, p: dict) -> WaveGenerator:
    wg = WaveGenerator.from_params(name, p)
    arr = concrete(wg.coefficients)
    if arr is not None and (arr.shape[0] < 1 or arr[0] <= 0):
        raise ConfigError(
            "effect 'wg_compliance': the linear coefficient w_1 must be positive (the wave "
            f"generator deflects with its torque), got coefficients {arr.tolist()}"
        )
    return wg


WG_COMPLIANCE = "wg_compliance"
"""The plant's name of the wave-generator compliance."""


class WaveGeneratorFamily(AbstractFamily):
    """Wave-generator compliance: plant `wg_compliance`, base term `CurrentPolynomial` (part of
    every paper model, so never proposed by the residual loop)."""

    name: ClassVar[str] = "wave_generator"
    terms: ClassVar[tuple] = (CurrentPolynomial,)
    plant_effects: ClassVar[tuple] = (
        PlantEffect(
            WG_COMPLIANCE,
            "wave_generator",
            lambda rated, k1, given: dict(coefficients=[0.02, 0.0, 0.002]),
            _build,
        ),
    )

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        return []
