"""Shape-annotated array aliases shared across hdjax."""

from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray, Real

Samples = Float[Array, " n"]
"""A float64 signal with one value per sample."""

Design = Float[Array, "n n_terms"]
"""A design matrix: one row per sample, one column per model term."""

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
    "Samples",
    "Design",
    "Scalar",
]
