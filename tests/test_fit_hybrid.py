"""Hybrid and joint fits on plant data: variants (a), (b), (c) of issue 4."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax import compliance as hc, fit, plant

JOINT = hdjax.Joint(ratio=160.0, rated_torque=400.0)


@pytest.fixture(scope="session")
def setup():
    # 4 s of the slow experiment (same horizon as the Kalman test: one plant compilation).
    rec = plant.simulate_scenario("slow", key=jax.random.key(0), duration=4.0)
    structure = hc.ComplianceModel.paper(
        JOINT, per_segment=False, kinematic="none", current_scale=10.0, poly_order=2
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ls = hc.calibrate_lstsq(structure, rec).value
    inp = fit.hybrid_inputs(rec, JOINT, compliance=ls)
    return rec, ls, inp


def _loss(model, inp):
    return float(jnp.mean((fit.predict_hybrid(model, inp) - inp.torque) ** 2))


def test_hybrid_starts_at_the_compliance_estimate(setup):
    """The network's output layer starts at zero, so it adds only the stored mean residual."""
    rec, ls, inp = setup
    model = fit.make_hybrid(inp, compliance=ls, hidden=(8,), key=jax.random.key(0))
    ref = np.asarray(hc.estimate_torque(ls, rec).torque)
    offset = np.mean(np.asarray(rec.torque) - ref)
    np.testing.assert_allclose(fit.predict_hybrid(model, inp), ref + offset, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("variant", ["a", "b", "c"])
def test_joint_fit_reduces_the_loss(setup, variant):
    rec, ls, inp = setup
    comp = None if variant == "a" else ls
    pl = plant.song_params() if variant == "c" else None
    if comp is None:
        inp = fit.hybrid_inputs(rec, JOINT)
    model = fit.make_hybrid(inp, compliance=comp, hidden=(8,), plant=pl, key=jax.random.key(0))
    before = _loss(model, inp)
    res = fit.fit_hybrid(
        model, inp, steps=1000, learning_rate=1e-2, batch_size=256, key=jax.random.key(1)
    )
    after = _loss(res.value, inp)
    # (a) starts from a zero network (predicts the mean torque): must fall far below the
    # torque variance; (b), (c) start at least squares and must improve on it.
    assert after < (0.05 if variant == "a" else 0.8) * before, (before, after)
    if variant == "c":
        # The plant parameters moved (they are fitted jointly) and stayed finite.
        assert np.all(np.isfinite(res.value.plant_log))
        assert np.max(np.abs(res.value.plant_log)) > 1e-4
    if variant != "a":
        assert np.max(np.abs(res.value.coef_delta)) > 0.0


def test_levenberg_marquardt_on_hybrid(setup):
    _, ls, inp = setup
    sub = inp.take(jnp.arange(0, inp.n_samples, 40))  # 200 residuals
    model = fit.make_hybrid(sub, compliance=ls, hidden=(3,), key=jax.random.key(0))
    before = _loss(model, sub)
    res = fit.fit_hybrid(model, sub, method="levenberg_marquardt", steps=15, key=jax.random.key(0))
    assert _loss(res.value, sub) < 0.8 * before


def test_plant_gradient_matches_finite_difference(setup):
    """d loss / d plant_log by autodiff against a central difference (step 1e-5, rtol 1e-5)."""
    _, ls, inp = setup
    model = fit.make_hybrid(
        inp, compliance=ls, hidden=(4,), plant=plant.song_params(), key=jax.random.key(0)
    )
    # Give the output layer weights so the motor torque reaches the loss.
    net = model.network
    net = eqx.tree_at(lambda n: n.weights[-1], net, jnp.full_like(net.weights[-1], 0.3))
    model = eqx.tree_at(lambda m: m.network, model, net)

    def loss(v):
        m = eqx.tree_at(lambda q: q.plant_log, model, v)
        return jnp.mean((m(inp) - inp.torque) ** 2)

    v0 = jnp.zeros(4)
    g = jax.grad(loss)(v0)
    h = 1e-5
    fd = [(loss(v0.at[i].set(h)) - loss(v0.at[i].set(-h))) / (2 * h) for i in range(4)]
    np.testing.assert_allclose(g, np.asarray(fd), rtol=1e-5, atol=1e-8 * float(jnp.abs(g).max()))


def test_bad_input(setup):
    rec, ls, inp = setup
    with pytest.raises(hdjax.ConfigError, match="coulomb_m"):
        fit.make_hybrid(
            inp,
            compliance=ls,
            hidden=(4,),
            plant=plant.song_params(effects={"coulomb_m": None}),
            key=jax.random.key(0),
        )
    model = fit.make_hybrid(inp, compliance=ls, hidden=(4,), key=jax.random.key(0))
    nan_torque = np.where(np.arange(inp.n_samples) == 3, np.nan, np.asarray(inp.torque))
    bad = eqx.tree_at(lambda i: i.torque, inp, jnp.asarray(nan_torque))
    with pytest.raises(hdjax.DataError, match="NaN"):
        fit.fit_hybrid(model, bad, steps=2, key=jax.random.key(0))
    with pytest.raises(hdjax.ConfigError, match="unknown method"):
        fit.fit_hybrid(model, inp, method="bfgs", key=jax.random.key(0))


# ---- dynamic inputs: twist rate and Dahl memory states ---------------------------------


@pytest.fixture(scope="session")
def dynamic(setup):
    rec, ls, _ = setup
    scales = fit.dahl_scales(ls)
    inp = fit.hybrid_inputs(rec, JOINT, compliance=ls, twist_rate=True, hysteresis=scales)
    return scales, inp


def test_dahl_scales_from_the_central_compliance(setup):
    """Fractions of the rated torque times k1, the compliance of the segment [-tau0/3, tau0/3)
    (the middle one of the five, Song et al. eq. (7)), read independently from the model."""
    _, ls, _ = setup
    k1 = float(np.asarray(ls.k)[2])
    assert ls.segment_bounds[2] == (-400.0 / 3.0, 400.0 / 3.0)
    np.testing.assert_allclose(
        fit.dahl_scales(ls, (0.01, 0.1)), [0.01 * 400.0 * k1, 0.1 * 400.0 * k1], rtol=1e-15
    )


def test_dynamic_columns_match_independent_formulas(setup, dynamic):
    """Twist rate: the least-squares slope over five equally spaced samples,
    sum_j j x_{k+j} / (10 dt), in NumPy. Dahl states: the recursion of the docstring as a Python
    loop. Both from the recorded angles only."""
    rec, _, base = setup
    scales, inp = dynamic
    names = inp.layout.names
    assert names[: len(base.layout.names)] == base.layout.names
    assert names[len(base.layout.names) :] == ("twist_rate",) + tuple(
        f"dahl(twist/{s:.4g})" for s in scales
    )
    x = np.asarray(inp.x)
    t = np.asarray(rec.t)
    tw = np.asarray(rec.theta_l) - np.asarray(rec.theta_m) / 160.0
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.diff(t), dt, rtol=1e-9)  # the plant samples evenly
    k = np.arange(2, tw.size - 2)
    slope = sum(j * tw[k + j] for j in (-2, -1, 1, 2)) / (10.0 * dt)
    rate = x[:, names.index("twist_rate")]
    # Round-off: the twist is a difference of angles of ~1e2 rad (1e-14 rad), over 5e-4 s.
    np.testing.assert_allclose(rate[k], slope, rtol=0, atol=1e-9 * np.abs(slope).max())
    for s in scales:
        z, ref = 0.0, []
        for d in np.diff(tw, prepend=tw[:1]) / s:
            z = min(1.0, max(-1.0, z + d * (1.0 - z * np.sign(d))))
            ref.append(z)
        np.testing.assert_allclose(x[:, names.index(f"dahl(twist/{s:.4g})")], ref, atol=1e-12)
    # The states sweep the loop (the slow experiment reverses the twist several times).
    z = x[:, names.index(f"dahl(twist/{scales[0]:.4g})")]
    assert z.min() < -0.5 and z.max() > 0.5


def test_inputs_must_match_the_model(setup, dynamic):
    _, ls, plain = setup
    _, inp = dynamic
    model = fit.make_hybrid(inp, compliance=ls, hidden=(4,), key=jax.random.key(0))
    with pytest.raises(hdjax.ModelMismatchError, match="twist_rate"):
        fit.predict_hybrid(model, plain)
    with pytest.raises(hdjax.ModelMismatchError, match="twist_rate"):
        fit.fit_hybrid(model, plain, steps=2, key=jax.random.key(0))
    no_sig = eqx.tree_at(lambda i: i.sig, inp, None, is_leaf=lambda v: v is None)
    with pytest.raises(hdjax.ModelMismatchError, match="compliance signals"):
        fit.predict_hybrid(model, no_sig)
    assert np.all(np.isfinite(np.asarray(fit.predict_hybrid(model, inp))))


@pytest.mark.parametrize("scales", [(0.0,), (-1e-4,), (float("nan"),), ("1e-4",), 1e-4])
def test_bad_hysteresis_scales(setup, scales):
    rec, ls, _ = setup
    with pytest.raises(hdjax.ConfigError, match="hysteresis"):
        fit.hybrid_inputs(rec, JOINT, compliance=ls, hysteresis=scales)
