"""Closed-loop simulation, sensors, scenarios, figures and the bad-input checks."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax import plant

DURATION = 12.0
N = 24000


@pytest.fixture(scope="session")
def scenarios():
    # one batched run of all four experiments, 12 s each (seed 0)
    return plant.simulate_scenarios(key=jax.random.key(0), duration=DURATION, truth=True)


def test_scenarios_give_recordings_with_schema(scenarios):
    assert set(scenarios) == set(plant.SCENARIOS)
    for name, rec in scenarios.items():
        assert isinstance(rec, hdjax.Recording)
        assert rec.source == f"scenario:{name}"
        assert rec.n_samples == N
        np.testing.assert_allclose(np.diff(np.asarray(rec.t)), 5e-4, rtol=1e-9)
        assert rec.torque is not None and "temperature" not in rec.extras


def test_encoders_are_quantised_at_21_bits(scenarios):
    rec = scenarios["slow"]
    for col in ("theta_m", "theta_l"):
        counts = np.asarray(rec.column(col)) / (2 * math.pi / 2**21)
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    # and the quantisation error is below one count
    err = np.asarray(rec.extras["true_theta_l"] - rec.theta_l)
    assert 0 <= err.min() and err.max() < 2 * math.pi / 2**21


def test_noise_levels(scenarios):
    rec = scenarios["sudden"]
    torque_noise = np.std(np.asarray(rec.torque - rec.extras["true_torque"]))
    assert torque_noise == pytest.approx(0.002 * 400.0, rel=0.1)  # 0.2 % of rated, 4000 samples
    current_noise = np.std(np.asarray(rec.current - rec.extras["true_current"]))
    assert current_noise == pytest.approx(0.05, rel=0.1)


def test_twist_grows_with_recorded_torque_and_current(scenarios):
    for rec in scenarios.values():
        twist = np.asarray(hdjax.twist(rec.theta_m, rec.theta_l, 160.0))
        true_t = np.asarray(rec.extras["true_joint_torque"])
        if np.ptp(true_t) > 50:
            assert np.corrcoef(twist, true_t)[0, 1] > 0.98
            assert np.corrcoef(np.asarray(rec.current), true_t)[0, 1] > 0.9


def test_single_run_equals_batch_member_and_truth_only_on_request(scenarios):
    key = jax.random.split(jax.random.key(0), 4)[2]  # "sudden" is the third scenario
    rec = plant.simulate_scenario("sudden", key=key, duration=DURATION)
    assert rec.extras == {}
    batch = scenarios["sudden"]
    np.testing.assert_allclose(
        np.asarray(rec.torque), np.asarray(batch.torque), rtol=1e-9, atol=1e-9
    )
    np.testing.assert_array_equal(np.asarray(rec.theta_m), np.asarray(batch.theta_m))


_SPREAD_SCRIPT = """
import sys
import jax
jax.config.update("jax_num_cpu_devices", 2)
import numpy as np
import hdjax
from hdjax import plant
assert len(jax.local_devices()) == 2
recs = plant.simulate_scenarios(key=jax.random.key(0), duration=0.5)
np.save(sys.argv[1], np.stack([np.asarray(recs[n].torque) for n in plant.SCENARIOS]))
"""


def test_batch_spread_over_two_cpu_devices_equals_one_device(tmp_path):
    # simulate_scenarios splits the batch over the local devices (here 2 CPU devices, a fresh
    # process: the device count is fixed when JAX starts); the result must not change
    import subprocess
    import sys

    out = tmp_path / "spread.npy"
    subprocess.run([sys.executable, "-c", _SPREAD_SCRIPT, str(out)], check=True, timeout=300)
    recs = plant.simulate_scenarios(key=jax.random.key(0), duration=0.5)
    want = np.stack([np.asarray(recs[n].torque) for n in plant.SCENARIOS])
    np.testing.assert_allclose(np.load(out), want, rtol=1e-9, atol=1e-9)
    with_one = plant.spread_batch({"x": jnp.zeros((3, 2))})  # one device here: unchanged
    assert with_one["x"].shape == (3, 2)


def test_static_and_sudden_loads(scenarios):
    # static: six rope positions of 2 s each, the last one at 0.95 rated torque; the output
    # friction is zero at rest, so the sensor holds the load
    st = np.asarray(scenarios["static"].extras["true_torque"])
    for k in range(6):
        hold = st[(k + 1) * 4000 - 1000 : (k + 1) * 4000]
        assert hold.mean() == pytest.approx(0.95 * 400.0 * (k + 1) / 6, rel=0.01)
    # sudden: 0.8 rated until the cut at half the duration, then nothing
    su = np.asarray(scenarios["sudden"].extras["true_torque"])
    assert su[8000:11990].mean() == pytest.approx(0.8 * 400.0, rel=0.01)
    assert abs(su[-2000:].mean()) < 0.01 * 400.0


def test_fast_and_slow_reach_both_signs(scenarios):
    for name in ("fast", "slow"):
        tq = np.asarray(scenarios[name].extras["true_torque"])
        assert tq.max() > 0.3 * 400 and tq.min() < -0.3 * 400


def test_temperature_column_and_drift():
    rec = plant.simulate_scenario(
        "static", key=jax.random.key(3), duration=1.0, effects={"temperature": {"drift": 1.0}}
    )
    temp = np.asarray(rec.extras["temperature"])
    assert temp[-1] - temp[0] == pytest.approx(1.0, abs=0.2)  # 1 K/s drift over 1 s


def test_vmap_over_parameter_sets():
    p = plant.hashimoto_params()
    batch = jax.tree.map(lambda x: jnp.stack([x, x]), p)
    batch = eqx.tree_at(lambda q: q.inertia_l, batch, jnp.asarray([0.88, 1.76]))
    drive = plant.scenario_drive("slow", p, duration=0.1, dt=5e-4, key=jax.random.key(0))
    gains = plant.default_gains(p)
    s0 = plant.zero_state()
    out = eqx.filter_vmap(lambda q: plant.integrate(q, gains, s0, drive, 5e-4)[1])(batch)
    assert out.state.theta_l.shape == (2, 200)
    # the heavier link lags more behind the same commanded motion
    assert not np.allclose(np.asarray(out.state.theta_l[0]), np.asarray(out.state.theta_l[1]))


def test_hashimoto_preset_runs_the_scenarios():
    rec = plant.simulate_scenario(
        "static", key=jax.random.key(4), duration=0.6, params=plant.hashimoto_params(), truth=True
    )
    assert float(rec.extras["true_torque"][-1]) == pytest.approx(0.95 * 40.0, rel=0.02)


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------


def test_step_too_large_is_detected_before_running():
    with pytest.raises(hdjax.ConfigError) as err:
        plant.simulate_scenario("slow", key=jax.random.key(0), duration=0.1, dt=1e-2)
    msg = str(err.value)
    assert "too large" in msg and "joint mode" in msg and "use dt <=" in msg.lower()


def test_non_finite_state_raises_divergence():
    p = plant.song_params()
    drive = plant.scenario_drive("static", p, duration=DURATION, dt=5e-4, key=jax.random.key(0))
    bad = eqx.tree_at(lambda s: s.omega_l, plant.zero_state(), jnp.asarray(jnp.nan))
    with pytest.raises(hdjax.DivergenceError, match="diverged: non-finite state at t = 0"):
        plant.simulate(p, drive, key=jax.random.key(0), initial_state=bad)


def test_scenario_too_long_for_memory_says_how_much():
    with pytest.raises(hdjax.ConfigError, match=r"needs about [\d.e+]+ GiB.*limit is 2 GiB"):
        plant.simulate_scenario("slow", key=jax.random.key(0), duration=1e7)


def test_unknown_scenario_and_bad_options():
    with pytest.raises(hdjax.ConfigError, match="unknown scenario 'sloww'.*did you mean 'slow'"):
        plant.simulate_scenario("sloww", key=jax.random.key(0))
    with pytest.raises(hdjax.ConfigError, match="multiple of dt"):
        plant.simulate_scenario("slow", key=jax.random.key(0), duration=0.1, output_period=7e-4)
    with pytest.raises(TypeError):
        plant.simulate_scenario("slow", duration=0.1)  # key is keyword-only and required
    with pytest.raises(hdjax.ConfigError, match="encoder_bits_motor"):
        plant.SensorConfig(encoder_bits_motor=0)
    # the batch takes simulate_scenario's keywords, checked before anything runs
    with pytest.raises(TypeError, match="simulate_scenarios: .*'durations'"):
        plant.simulate_scenarios(key=jax.random.key(0), durations=0.1)
    with pytest.raises(TypeError, match="simulate_scenarios: .*'name'"):
        plant.simulate_scenarios(["slow"], key=jax.random.key(0), name="fast")
    with pytest.raises(hdjax.ConfigError, match="multiple of dt"):
        plant.simulate_scenarios(["slow"], key=jax.random.key(0), output_period=7e-4)


def test_plot_scenario_writes_png(scenarios, tmp_path):
    from .helpers import assert_figure

    out = plant.plot_scenario(scenarios["sudden"], tmp_path / "sudden.png")
    assert_figure(out, (1210, 770), min_ink=0.03)  # 11 x 7 in at 110 dpi, four panels drawn
    with pytest.raises(hdjax.ConfigError, match="does not exist"):
        plant.plot_scenario(scenarios["sudden"], tmp_path / "nope" / "x.png")
