r"""Offset: the constant of the twist model.

$k_0 = \omega_0/N + a_0$ (Song et al. 2019, eq. (10)): the wave generator's deformation at zero
current and the kinematic error's mean, which also absorbs the encoders' zero offsets. It is
part of every model, never simulated on its own (the plant's angles start at zero) and never
proposed by the residual loop.

References: Song et al. 2019, eq. (10).
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Float, SamplesLike
from .._features import Signals
from ._base import AbstractColumnListTerm, AbstractFamily, Candidate, CandidateContext
from ._c import AbstractCEmitter, CSnippet


class Constant(AbstractColumnListTerm):
    """Constant offset $k_0 = \\omega_0/N + a_0$ (eq. (10)); also absorbs encoder offsets."""

    @property
    def key(self) -> str:
        return "constant"

    def names(self) -> tuple[str, ...]:
        return ("k0",)

    def column_list(self, sig: Signals) -> list[Float[Array, " n"]]:
        return [jnp.ones((sig.n_samples,), jnp.float64)]

    def numpy_columns(
        self, sig: Signals, torque: SamplesLike | None = None
    ) -> Float[np.ndarray, "n 1"]:
        return np.ones((sig.n_samples, 1))

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The constant's column for the exported estimator: 1 (eq. (10))."""
        return CSnippet(columns=(c.num(1.0),))


class OffsetFamily(AbstractFamily):
    """The constant of the twist model (no plant effect, not discovered)."""

    name: ClassVar[str] = "offset"
    terms: ClassVar[tuple] = (Constant,)

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        return []
