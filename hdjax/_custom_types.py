"""Shape-annotated array aliases shared across hdjax."""

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray, Real, Shaped

Samples = Float[Array, " n"]
"""A float64 signal with one value per sample."""

Design = Float[Array, "n n_terms"]
"""A design matrix: one row per sample, one column per model term."""

SamplesLike = Real[ArrayLike, " n"]
"""A real signal with one value per sample, as an array of either library (a torque, a
residual)."""

NumpyDesign = Float[np.ndarray, "n n_terms"]
"""[`Design`][] computed in NumPy (the reference a JAX design is tested against)."""

Pointwise = Real[ArrayLike, "*shape"]
"""The input of a pointwise law (a speed, a torque, an angle): any shape, a number included;
the arguments so annotated in one call share their shape with a [`PointwiseOut`][] result."""

PointwiseOut = Float[Array, "*shape"]
"""The value of a pointwise law, shaped like its [`Pointwise`][] input."""

Scalar = Real[ArrayLike, ""]
"""A real number: a Python int or float, or a 0-d array (a module field that JAX may trace, as
under `vmap` or `grad`)."""

__all__ = [
    "Array",
    "ArrayLike",
    "Bool",
    "Float",
    "Int",
    "PRNGKeyArray",
    "Real",
    "Shaped",
    "Samples",
    "SamplesLike",
    "Design",
    "NumpyDesign",
    "Pointwise",
    "PointwiseOut",
    "Scalar",
]
