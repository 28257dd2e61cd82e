"""Shape-annotated array aliases shared across hdjax."""

import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray, PyTree, Real, Shaped

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

RealLike = Real[ArrayLike, " ..."]
"""Real numbers of any shape, a Python number included (a signal a function converts itself)."""

Scalar = Real[ArrayLike, ""]
"""A real number: a Python int or float, or a 0-d array (a module field that JAX may trace, as
under `vmap` or `grad`)."""

ArrayInput = Shaped[ArrayLike, " ..."] | Sequence[Any]
"""An array as a user gives it, before validation (an array, or a list of numbers or of rows):
the function that takes it checks dtype, shape and finiteness itself and says what is wrong."""

PathLike = str | os.PathLike[str]
"""A file or folder path."""

__all__ = [
    "ArrayInput",
    "PathLike",
    "Array",
    "ArrayLike",
    "Bool",
    "Float",
    "Int",
    "PRNGKeyArray",
    "PyTree",
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
