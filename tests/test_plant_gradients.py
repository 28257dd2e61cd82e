"""Differentiability (gradients vs finite differences) and identification (optimistix, optax)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hdjax import plant

DT = 5e-4


def test_gradient_of_trajectory_loss_matches_finite_differences():
    """d loss / d p for every leaf of the Song preset (all default effects on), 40 steps.

    Forward mode (`jax.jvp`), one parameter direction at a time through one compiled program
    (the batched `jax.jacfwd` of all 34 directions took twice as long, most of it compiling
    the vmapped scan); the reference is a central difference with a relative step of 1e-6
    (absolute 1e-8 for parameters that are 0).
    Tolerance: relative 1e-5 (truncation of the central difference) plus an absolute floor of
    100 round-off units of the loss divided by the step, `100 eps |L| / h`, the size of the
    difference's round-off error. The test checks that this floor lies at least ten times below
    every non-zero reference entry, so a zero (or sign-flipped) gradient cannot pass; entries
    the 40-step loss does not depend on are exactly zero in both.
    """
    eps = np.finfo(np.float64).eps
    p = plant.song_params()
    drive = plant.scenario_drive("fast", p, duration=0.02, dt=DT, key=jax.random.key(3))
    gains = plant.default_gains(p)
    s0 = plant.equilibrium_state(p, load_torque=-50.0)
    scales = (400.0, 10.0, 1e-3, 1e-2)

    def loss(q):
        sim = plant.simulate_signals(q, gains, drive, DT, state0=s0)
        return sum(jnp.sum((s / c) ** 2) for s, c in zip(sim, scales))

    loss_jit = eqx.filter_jit(loss)
    derivative = eqx.filter_jit(lambda q, t: jax.jvp(loss, (q,), (t,))[1])
    leaves, tree = jax.tree.flatten(p)
    checked = 0
    for i, x in enumerate(leaves):
        x = np.asarray(x)
        for j in range(x.size):
            unit = [jnp.zeros_like(leaf) for leaf in leaves]
            unit[i] = unit[i].at[np.unravel_index(j, x.shape)].set(1.0)
            g = float(derivative(p, jax.tree.unflatten(tree, unit)))
            assert np.isfinite(g), f"non-finite gradient for leaf {i}[{j}]"
            h = 1e-6 * abs(x.flat[j]) if x.flat[j] != 0 else 1e-8

            def at(v, i=i, j=j, x=x):
                y = x.copy()
                y.flat[j] = v
                new = list(leaves)
                new[i] = jnp.asarray(y)
                return float(loss_jit(jax.tree.unflatten(tree, new)))

            fd = (at(x.flat[j] + h) - at(x.flat[j] - h)) / (2 * h)
            floor = 100 * eps * abs(at(x.flat[j])) / h
            assert fd == 0 or floor < 0.1 * abs(fd), f"leaf {i}[{j}]: step too small to test"
            assert g == pytest.approx(fd, rel=1e-5, abs=floor), f"leaf {i}[{j}]"
            checked += 1
    assert checked == sum(np.asarray(x).size for x in leaves)


@pytest.fixture(scope="module")
def hashimoto_recording():
    true = plant.hashimoto_params(effects={"viscous_l": {"coefficient": 0.5}})
    drive = plant.scenario_drive("fast", true, duration=0.1, dt=DT, key=jax.random.key(5))
    rec = plant.simulate(
        true, drive, key=jax.random.key(6), sensors=plant.SensorConfig(noise=False)
    )
    return true, drive, rec


def _perturbed(true, names, factors):
    start = true
    for name, f in zip(names, factors):
        value = plant._identify._getter(name)(true) * f
        start = plant._identify._with_values(start, [name], [value])
    return start


def test_levenberg_marquardt_recovers_parameters(hashimoto_recording):
    true, drive, rec = hashimoto_recording
    names = ["compliance[0]", "inertia_l", "inertia_m", "effects.viscous_l.coefficient"]
    start = _perturbed(true, names, [1.2, 0.8, 1.15, 1.5])
    fit = plant.fit_plant(
        start, rec, drive, names, gains=plant.default_gains(true), method="lm", steps=40
    )
    truth = [plant._identify._getter(n)(true) for n in names]
    # noiseless data from the same model: recovered to 1e-6 relative
    for got, want in zip(fit.stats["values"], truth):
        assert float(got) == pytest.approx(float(want), rel=1e-6)
    assert float(fit.stats["loss"]) < 1e-12 and fit.ok
    # the fitted PlantParams carry the same values
    got = [plant._identify._getter(n)(fit.value) for n in names]
    np.testing.assert_allclose(np.asarray(got, float), np.asarray(fit.stats["values"], float))


def test_adam_recovers_stiffness_and_inertia(hashimoto_recording):
    true, drive, rec = hashimoto_recording
    names = ["compliance[0]", "inertia_l"]
    start = _perturbed(true, names, [1.1, 0.9])
    fit = plant.fit_plant(
        start,
        rec,
        drive,
        names,
        gains=plant.default_gains(true),
        method="adam",
        steps=60,
        learning_rate=0.03,
    )
    truth = [plant._identify._getter(n)(true) for n in names]
    # first-order optimiser, 60 steps from 10 % off: within 1 %
    for got, want in zip(fit.stats["values"], truth):
        assert float(got) == pytest.approx(float(want), rel=1e-2)


def test_fit_bad_names(hashimoto_recording):
    import hdjax

    true, drive, rec = hashimoto_recording
    with pytest.raises(hdjax.ConfigError, match="no such plant parameter"):
        plant.fit_plant(
            true, rec, drive, ["effects.backlash.width"], gains=plant.default_gains(true)
        )
    with pytest.raises(hdjax.ConfigError, match="must start positive"):
        plant.fit_plant(true, rec, drive, ["damping"], gains=plant.default_gains(true))


def test_truncated_windows_keep_the_forward_run(hashimoto_recording):
    """Windowed simulation (gradient stopped every 50 steps) is the same continuous run."""
    true, drive, _ = hashimoto_recording
    gains = plant.default_gains(true)
    s0 = plant.zero_state()
    whole = plant.simulate_signals(true, gains, drive, DT, state0=s0)
    cut = plant.simulate_signals(true, gains, drive, DT, window=50, state0=s0)
    for a, b in zip(whole, cut):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-12, atol=1e-12)
