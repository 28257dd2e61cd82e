"""The vectorised NumPy Dahl state against the sequential recursion and the compiled scan.

`dahl_state_numpy` solves the clipped Dahl recursion as a linear recurrence in blocks; the
reference is the recursion written out sample by sample (the function's former body) and,
independently, the compiled `lax.scan` of `dahl_state`.
"""

import jax.numpy as jnp
import numpy as np
import pytest

from hdjax.effects import dahl_state, dahl_state_numpy


def _sequential(torque, torque_scale, reset):
    """The Dahl recursion, one sample at a time, clipped to [-1, 1]."""
    du = np.diff(torque, prepend=torque[:1]) / torque_scale
    z, out = 0.0, np.empty_like(du)
    for k, d in enumerate(du):
        if reset[k]:
            z, d = 0.0, 0.0
        z = min(1.0, max(-1.0, z + d * (1.0 - z * np.sign(d))))
        out[k] = z
    return out


def _path(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A torque path with slow swings, noise, steps larger than the scale, flat stretches and
    resets (the first sample of segments after gaps)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    torque = 80 * np.sin(2 * np.pi * t / rng.uniform(200, 2000)) + rng.normal(0, 0.5, n)
    jumps = rng.random(n) < 0.01
    torque[jumps] += rng.normal(0, 40, jumps.sum())
    flat = slice(n // 3, n // 3 + n // 10)
    torque[flat] = torque[n // 3 : n // 3 + 1]
    reset = rng.random(n) < 0.002
    reset[:1] = True
    return torque, reset


@pytest.mark.parametrize("n", [0, 1, 2, 7, 1024, 20_001])
def test_dahl_numpy_equals_the_sequential_recursion(n):
    swings = []
    for seed in range(4):
        torque, reset = _path(seed, n)
        for scale in (0.5, 4.0, 20.0, 200.0):
            ref = _sequential(torque, scale, reset)
            got = dahl_state_numpy(torque, scale, reset)
            assert got.shape == ref.shape
            # states are O(1) and the recurrence's multipliers lie in [0, 1], so rounding does
            # not grow: agreement to 1e-12 absolute (observed: a few 1e-16)
            np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12, err_msg=f"{seed=} {scale=}")
            swings.append(np.ptp(ref) if n else 0.0)
    if n > 1000:
        # the paths drive the state through loops, to saturation at the smallest scale
        assert min(swings[::4]) > 1.99 and min(swings) > 0.1


def test_dahl_numpy_equals_the_compiled_scan():
    torque, reset = _path(11, 30_000)
    for scale in (1.0, 30.0):
        ref = np.asarray(dahl_state(jnp.asarray(torque), scale, jnp.asarray(reset)))
        np.testing.assert_allclose(dahl_state_numpy(torque, scale, reset), ref, atol=1e-12)
    # without resets
    ref = np.asarray(dahl_state(jnp.asarray(torque), 10.0))
    np.testing.assert_allclose(dahl_state_numpy(torque, 10.0), ref, atol=1e-12)
