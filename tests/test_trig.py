"""The vectorisable sine and cosine (`hdjax._trig`) against NumPy's libm."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax  # noqa: F401  (float64)
from hdjax import _trig


@pytest.mark.parametrize("scale", [1.0, 1e3, 1e6, 1e9])
def test_sin_cos_within_two_ulp_of_libm(scale):
    x = np.random.default_rng(1).uniform(-scale, scale, 20_000)
    x[:4] = [0.0, np.pi / 2, -np.pi, 2.5 * np.pi]
    s, c = jax.jit(lambda v: (_trig.sin(v), _trig.cos(v)))(jnp.asarray(x))
    for got, want in ((s, np.sin(x)), (c, np.cos(x))):
        err = np.abs(np.asarray(got) - want)
        # two units in the last place of the result (at least of 2**-53, near the zeros)
        assert np.all(err <= 2.0 * np.spacing(np.maximum(np.abs(want), 2.0**-53)))


def test_derivatives_are_the_exact_functions():
    x = jnp.asarray([-1e4, -2.0, 0.3, 7.0, 5e5])
    np.testing.assert_array_equal(
        np.asarray(jax.vmap(jax.grad(_trig.sin))(x)), np.asarray(_trig.cos(x))
    )
    np.testing.assert_array_equal(
        np.asarray(jax.vmap(jax.grad(_trig.cos))(x)), -np.asarray(_trig.sin(x))
    )
    # second derivative through the jvp rule
    np.testing.assert_allclose(
        np.asarray(jax.vmap(jax.grad(jax.grad(_trig.sin)))(x)), -np.sin(np.asarray(x)), atol=3e-16
    )
