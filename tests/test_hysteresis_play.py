"""The play on a Dahl state's driver: the operator, the noise it is sized from, and the state it
keeps at rest.

References are independent computations: a plain Python loop of the play, the deviation of the
noise that was added, and the Dahl state of the noise-free driver.
"""

import jax.numpy as jnp
import numpy as np
import pytest

from hdjax.effects import dahl_initial, dahl_state_numpy, driver_noise, play


def _play_loop(u, h, reset=None, start=None):
    out, y = np.empty_like(u), start
    for k, x in enumerate(u):
        if (k == 0 and start is None) or (reset is not None and reset[k]):
            y = x
        else:
            y = min(max(y, x - h), x + h)
        out[k] = y
    return out


@pytest.mark.parametrize("start", [None, 0.3])
def test_play_equals_a_plain_loop_in_numpy_and_jax(start):
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(0, 0.2, 500))
    reset = np.zeros(500, bool)
    reset[[120, 121, 400]] = True
    ref = _play_loop(u, 0.5, reset, start)
    got = play(u, 0.5, reset, start)
    assert isinstance(got, np.ndarray)
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(np.asarray(play(jnp.asarray(u), 0.5, reset, start)), ref)
    # the output never leaves the band around the input, and a zero width is the input itself
    assert np.max(np.abs(got - u)) <= 0.5 + 1e-15
    np.testing.assert_array_equal(play(u, 0.0, reset), u)


def _slow_sweep(n=6000, sigma=0.3, seed=1):
    """A Dahl driver [N·m of torque path]: at rest, a slow ramp, a pause, a ramp back; white
    noise of deviation `sigma` on top."""
    t = np.arange(n)
    clean = np.interp(t, [0, 1500, 3000, 3500, 5000, n], [0, 0, 120, 120, 40, 40])
    return clean, clean + np.random.default_rng(seed).normal(0, sigma, n)


@pytest.mark.parametrize("sigma", [0.05, 0.3, 1.0])
def test_driver_noise_is_the_deviation_of_the_added_noise(sigma):
    clean, noisy = _slow_sweep(sigma=sigma)
    assert driver_noise(noisy) == pytest.approx(sigma, rel=0.1)
    assert driver_noise(clean) == pytest.approx(0.0, abs=1e-12)
    reset = np.zeros(clean.size, bool)
    reset[3000] = True  # a joined record: the step at the join is left out
    joined = noisy + 500.0 * (np.arange(clean.size) >= 3000)
    assert driver_noise(joined, reset) == pytest.approx(sigma, rel=0.1)


def test_driver_noise_is_zero_where_the_motion_moves_the_differences():
    # a robot's motion at 100 Hz: its speed changes by more between samples than a small
    # noise moves the twist, so the differences are the motion's and no noise is read from them
    t = np.arange(3000) / 100.0
    u = 100.0 * np.sin(2 * np.pi * 1.5 * t) + 30.0 * np.sin(2 * np.pi * 4.1 * t)
    noisy = u + np.random.default_rng(2).normal(0, 0.05, t.size)
    assert driver_noise(noisy) == 0.0
    # the same noise on a slow motion is read
    slow = 100.0 * np.sin(2 * np.pi * 0.01 * t) + np.random.default_rng(2).normal(0, 0.05, t.size)
    assert driver_noise(slow) == pytest.approx(0.05, rel=0.1)


def test_a_play_keeps_the_state_of_a_noisy_driver_at_rest():
    """The fault: without the play the encoder noise random-walks the state at rest (it forgets
    the loaded initial state before the motion) and keeps it off saturation in motion."""
    width, sigma = 40.0, 0.3
    clean, noisy = _slow_sweep(sigma=sigma)

    def state(u):  # loaded the other way at the start, as a sweep from rest is
        return dahl_state_numpy(u, width) - dahl_initial(u, width)

    truth = state(clean)
    rms = lambda z: float(np.sqrt(np.mean((z - truth) ** 2)))  # noqa: E731
    without = rms(state(noisy))
    with_play = rms(state(play(noisy, 3 * driver_noise(noisy))))
    print(f"state error RMS: without play {without:.3f}, with {with_play:.4f}")
    assert without > 0.3
    assert with_play < 0.05


@pytest.mark.parametrize("bad", [-0.5, float("nan"), float("inf")])
def test_a_negative_or_non_finite_play_is_refused_with_what_it_is(bad):
    # at construction and from a saved model alike, before anything is traced
    from hdjax._errors import ConfigError
    from hdjax.compliance._terms import term_from_dict
    from hdjax.effects import TwistHysteresis

    with pytest.raises(ConfigError, match=r"TwistHysteresis: play .*N·m of torque path.*>= 0"):
        TwistHysteresis(torque_scale=10.0, compliance=1e-5, play=bad)
    saved = {"type": "TwistHysteresis", "torque_scale": 10.0, "compliance": 1e-5, "play": bad}
    with pytest.raises(ConfigError, match=r"play"):
        term_from_dict(saved)
    # a model saved before the play existed loads with none
    old = term_from_dict({"type": "TwistHysteresis", "torque_scale": 10.0, "compliance": 1e-5})
    assert old.play == 0.0
