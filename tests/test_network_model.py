"""The network of Song et al. eqs. (36)-(46): features, layout, init, trainers, bad input."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax import network as hn

JOINT = hdjax.Joint(ratio=160.0, rated_torque=400.0)


def _synthetic_recording(n=3000, seed=0):
    """A joint with known compliance: twist = tau/k + 1e-4 sin(2 theta_m); current ~ tau."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    tau = 200 * np.sin(2 * np.pi * 0.7 * t) + 80 * np.sin(2 * np.pi * 1.9 * t + 1.0)
    theta_l = 0.3 * np.sin(2 * np.pi * 0.25 * t)
    tw = tau / 2.0e4 + 1e-4 * np.sin(2 * 160 * theta_l)
    theta_m = 160 * (theta_l - tw)
    current = tau / (160 * 0.1) + rng.normal(scale=0.05, size=n)
    return hdjax.make_recording(t, theta_m, theta_l, current, tau, source="synthetic")


@pytest.fixture(scope="session")
def data():
    rec = _synthetic_recording()
    feats = hn.build_features(rec, JOINT)
    return rec, feats


def test_features_follow_the_paper(data):
    rec, feats = data
    assert feats.layout.names == hn.PAPER_INPUTS
    x = np.asarray(feats.x)
    np.testing.assert_array_equal(x[:, 0], rec.current)
    np.testing.assert_array_equal(x[:, 1], rec.theta_m)
    # Backward difference (eqs. (13)-(14)) and twist (eq. (5)), computed independently.
    omega_m = np.diff(np.asarray(rec.theta_m)) / np.diff(np.asarray(rec.t))
    np.testing.assert_allclose(x[1:, 3], omega_m, rtol=1e-12)
    tw = np.asarray(rec.theta_l) - np.asarray(rec.theta_m) / 160.0
    np.testing.assert_allclose(x[:, 5], tw, rtol=1e-9, atol=1e-15)


def test_periodic_layout_names_and_values(data):
    rec, _ = data
    feats = hn.build_features(rec, JOINT, periodic=True, orders=(1, 2))
    names = feats.layout.names
    assert names[:3] == ("current", "sin1_theta_m", "cos1_theta_m")
    assert len(names) == 1 + 2 * 2 * 2 + 3
    j = names.index("cos2_theta_l")
    np.testing.assert_allclose(feats.x[:, j], np.cos(2 * np.asarray(rec.theta_l)), rtol=1e-14)


def test_initialisation_in_unit_interval():
    net = hn.Network(hn.make_layout(), (30, 10), key=jax.random.key(3))
    leaves = list(net.weights) + list(net.biases)
    assert [w.shape for w in net.weights] == [(6, 30), (30, 10), (10, 1)]
    for leaf in leaves:
        assert float(jnp.min(leaf)) > -1.0 and float(jnp.max(leaf)) < 1.0
    # Uniform on (-1, 1): the 180 first-layer weights should spread over most of the interval.
    assert float(jnp.max(net.weights[0]) - jnp.min(net.weights[0])) > 1.8


def test_backprop_step_is_sgd_on_the_sample_error():
    """The hand-written deltas of eqs. (43)-(46) equal jax.grad of e = (d - y)^2 / 2."""
    net = hn.Network(hn.make_layout(), (7, 5), key=jax.random.key(4))
    z = jnp.linspace(-1.0, 1.0, 6)
    d = jnp.asarray([0.3])
    mu, eta = 0.1, 0.03

    def sample_error(wb):
        n = eqx.tree_at(lambda m: (m.weights, m.biases), net, wb)
        return 0.5 * (d[0] - n.normalised(z)) ** 2

    wb = (net.weights, net.biases)
    g = jax.grad(sample_error)(wb)
    new_w, new_b = hn.backprop_step(*wb, z, d, mu, eta)
    rates = [eta, eta, mu]  # hidden layers eta, output layer mu
    for i, rate in enumerate(rates):
        np.testing.assert_allclose(new_w[i], wb[0][i] - rate * g[0][i], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(new_b[i], wb[1][i] - rate * g[1][i], rtol=1e-12, atol=1e-15)


@pytest.fixture(scope="session")
def trained(data):
    rec, feats = data
    x, y = np.asarray(feats.x), np.asarray(rec.torque)
    net = hn.Network(feats.layout, (16,), key=jax.random.key(0))
    bp = hn.train_backprop(
        net,
        x[:2000],
        y[:2000],
        mu=0.05,
        eta=0.05,
        error_target=2e-4,
        max_learnings=300_000,
        key=jax.random.key(1),
        check_every=5000,
    )
    # Validation on every third sample: interpolation, as the paper's training on mixed runs.
    val = np.arange(x.shape[0]) % 3 == 2
    opt = hn.train_optax(
        net,
        x[~val],
        y[~val],
        learning_rate=1e-2,
        steps=3000,
        key=jax.random.key(2),
        x_val=x[val],
        y_val=y[val],
        target_rmse=2.0,
    )
    return bp, opt


def test_backprop_reaches_error_target(trained, data):
    bp, _ = trained
    rec, feats = data
    assert bp.ok and bp.stats["target_reached"]
    assert float(bp.stats["history"][-1]) <= 2e-4
    # E (eq. (42)) on the standardised torque -> RMS in N·m: sqrt(2E) * std(torque).
    est = hn.predict(bp.value, feats)
    rms = float(np.sqrt(np.mean((np.asarray(est)[:2000] - np.asarray(rec.torque)[:2000]) ** 2)))
    e_final = float(bp.stats["history"][-1])
    assert rms == pytest.approx(np.sqrt(2 * e_final) * float(bp.value.y_scale))


def test_optax_reaches_validation_target(trained, data):
    _, opt = trained
    rec, _ = data
    assert opt.ok and opt.stats["target_reached"]
    assert float(opt.stats["val_rmse"][-1]) <= 2.0
    # Independent check of the reported validation error from the recording.
    est = np.asarray(hn.predict_torque(opt.value, rec, JOINT))
    val = np.arange(est.size) % 3 == 2
    err = est[val] - np.asarray(rec.torque)[val]
    assert np.sqrt(np.mean(err**2)) == pytest.approx(float(opt.stats["val_rmse"][-1]), rel=1e-9)


def test_predict_does_not_recompile(trained, data):
    _, opt = trained
    _, feats = data
    hn.predict(opt.value, feats)
    with jax.log_compiles():
        import logging

        records = []
        handler = logging.Handler()
        handler.emit = records.append
        logging.getLogger("jax").addHandler(handler)
        try:
            hn.predict(opt.value, feats).block_until_ready()
        finally:
            logging.getLogger("jax").removeHandler(handler)
    assert not [r for r in records if "Compiling" in r.getMessage()]


# ---- bad input -------------------------------------------------------------------------


def test_nan_in_training_data(data):
    rec, feats = data
    x = np.asarray(feats.x).copy()
    x[17, 2] = np.nan
    net = hn.Network(feats.layout, (4,), key=jax.random.key(0))
    with pytest.raises(hdjax.DataError, match="NaN/inf .* first at row 17"):
        hn.train_optax(net, x, rec.torque, learning_rate=1e-3, steps=10, key=jax.random.key(0))
    y = np.asarray(rec.torque).copy()
    y[5] = np.nan
    with pytest.raises(hdjax.DataError, match="target contain 1 NaN"):
        hn.train_backprop(
            net,
            feats.x,
            y,
            mu=0.1,
            eta=0.1,
            error_target=0.0,
            max_learnings=10,
            key=jax.random.key(0),
        )


def test_zero_variance_target(data):
    _, feats = data
    net = hn.Network(feats.layout, (4,), key=jax.random.key(0))
    y = np.full(feats.x.shape[0], 12.5)
    with pytest.raises(hdjax.DataError, match="zero variance"):
        hn.train_optax(net, feats.x, y, learning_rate=1e-3, steps=10, key=jax.random.key(0))


@pytest.mark.parametrize("hidden", [(0,), (8, 0), ()])
def test_zero_width_config(hidden):
    with pytest.raises(hdjax.ConfigError, match="hidden"):
        hn.Network(hn.make_layout(), hidden, key=jax.random.key(0))


def test_diverging_rates_are_named(data):
    rec, feats = data
    net = hn.Network(feats.layout, (8,), key=jax.random.key(0))
    with pytest.raises(hdjax.DivergenceError, match="learning rate 5000 is too large"):
        hn.train_optax(
            net,
            feats.x,
            rec.torque,
            learning_rate=5000.0,
            steps=500,
            key=jax.random.key(0),
            optimizer="sgd",
            eval_every=50,
        )
    with pytest.raises(hdjax.DivergenceError, match="mu=40, eta=40 are too large"):
        hn.train_backprop(
            net,
            feats.x,
            rec.torque,
            mu=40.0,
            eta=40.0,
            error_target=0.0,
            max_learnings=20_000,
            key=jax.random.key(0),
            check_every=500,
        )


def test_estimation_with_other_layout_is_refused(trained, data):
    _, opt = trained
    rec, _ = data
    periodic = hn.build_features(rec, JOINT, periodic=True)
    with pytest.raises(hdjax.ModelMismatchError, match="trained on .*current.*theta_m"):
        hn.predict(opt.value, periodic)
    filtered = hn.build_features(rec, JOINT, kalman=True)
    with pytest.raises(hdjax.ModelMismatchError, match="kalman=True"):
        hn.predict(opt.value, filtered)
