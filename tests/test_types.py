"""The test configuration itself: hdjax's jaxtyping annotations are checked by beartype in every
test (also in pytest-xdist workers, and at trace time under `jax.jit`), and JAX refuses implicit
rank promotion (tests/conftest.py, pyproject's pytest `addopts`)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jaxtyping import TypeCheckError

import hdjax.reference as hr

ARM = hr.dh_arm([[0.4, 0.0, 0.0, 0.0], [0.3, 0.0, 0.0, 0.0], [0.2, 0.0, 0.0, 0.0]])


def test_hdjax_is_instrumented():
    # the import hook wraps every function of hdjax; a plain function has no __wrapped__
    assert hasattr(hr.geometric_jacobian, "__wrapped__")


def test_a_wrong_shape_is_refused():
    q = np.zeros(3)
    assert hr.geometric_jacobian(ARM, q).shape == (6, 3)
    with pytest.raises(TypeCheckError, match="q"):
        hr.geometric_jacobian(ARM, np.zeros((2, 3)))  # annotated " n_joints": one axis


def test_a_wrong_dtype_is_refused():
    with pytest.raises(TypeCheckError):
        hr.geometric_jacobian(ARM, np.zeros(3, dtype=np.int64))  # annotated Float


def test_dimensions_bind_across_arguments_and_result():
    # 2 angles for a 3-joint arm: JAX clamps the out-of-range index silently; the annotation
    # `q: " n_joints"` -> `"6 n_joints"` says the result must have as many columns as q has angles
    with pytest.raises(TypeCheckError):
        hr.geometric_jacobian(ARM, np.zeros(2))


def test_checked_at_trace_time_under_jit():
    f = jax.jit(lambda q: hr.geometric_jacobian(ARM, q))
    assert f(jnp.zeros(3)).shape == (6, 3)
    with pytest.raises(TypeCheckError):
        f(jnp.zeros((2, 3)))


def test_rank_promotion_raises():
    with pytest.raises(ValueError, match="rank_promotion"):
        jnp.ones(3) - jnp.ones((2, 3))
    np.testing.assert_array_equal(jnp.ones((2, 3)) - jnp.ones(3)[None, :], np.zeros((2, 3)))
