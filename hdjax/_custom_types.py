"""Shape-annotated array aliases shared across hdjax."""

from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

Samples = Float[Array, " n"]
"""A float64 signal with one value per sample."""

Design = Float[Array, "n n_terms"]
"""A design matrix: one row per sample, one column per model term."""

__all__ = ["Array", "ArrayLike", "Bool", "Float", "Int", "PRNGKeyArray", "Samples", "Design"]
