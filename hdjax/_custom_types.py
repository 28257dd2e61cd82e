"""Shape-annotated array aliases shared across hdjax."""

import os
from collections.abc import Sequence
from typing import Any

from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray, PyTree, Real, Shaped

Samples = Float[Array, " n"]
"""A float64 signal with one value per sample."""

Design = Float[Array, "n n_terms"]
"""A design matrix: one row per sample, one column per model term."""

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
    "Shaped",
    "Array",
    "ArrayLike",
    "Bool",
    "Float",
    "Int",
    "PRNGKeyArray",
    "PyTree",
    "Real",
    "Samples",
    "Design",
    "Scalar",
]
