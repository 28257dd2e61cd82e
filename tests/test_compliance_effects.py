"""Effect terms in the compliance model: forward model then inversion, and invertibility."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax.compliance import (
    Backlash,
    ColumnTimesTorque,
    ComplianceModel,
    Coulomb,
    Harmonics,
    Signals,
    Stiffening,
    check_invertible,
    estimate_torque,
)

JOINT = hdjax.Joint(ratio=160, rated_torque=400)


def _signals(n=4000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 40, n)
    torque = 350 * np.sin(2 * np.pi * 0.1 * t) + 20 * rng.standard_normal(n)
    z = jnp.asarray(np.zeros(n))
    sig = Signals(
        twist=z,
        current=jnp.asarray(torque / 16.0),
        theta_m=jnp.asarray(50 * np.sin(0.3 * t)),
        theta_l=jnp.asarray(0.3 * np.sin(0.3 * t)),
        omega_m=jnp.asarray(15 * np.cos(0.3 * t)),
        omega_l=jnp.asarray(0.09 * np.cos(0.3 * t)),
        extras={"temperature": jnp.asarray(25 + 5 * np.sin(0.05 * t))},
    )
    return sig, torque


def _model_with(*terms, effect_coef):
    m = ComplianceModel.paper(
        JOINT, per_segment=False, poly_order=2, current_scale=25.0, kinematic="none"
    ).with_effects(*terms)
    coef = np.zeros(m.n_coef)
    coef[: m.n_segments] = np.array([0.9, 1.0, 1.2, 1.0, 0.9]) / 6.7e4
    coef[m.n_segments : m.n_segments + 3] = [1e-5, 2e-5, -1e-5]
    coef[m.n_coef - m.n_effect :] = effect_coef
    return eqx.tree_at(lambda x: x.coef, m, jnp.asarray(coef))


@pytest.mark.parametrize(
    "terms,coef",
    [
        ((Harmonics("theta_m", (2.0,)), Coulomb("omega_l", 0.02)), [2e-5, -1e-5, 3e-5]),
        ((ColumnTimesTorque("temperature", 25.0, 5.0, 400.0),), [1e-4]),
        ((Stiffening(400.0),), [-2e-4]),
        ((Backlash(8.0),), [1.5e-4]),
    ],
)
def test_forward_then_inverse_returns_the_torque(terms, coef):
    sig, torque = _signals()
    model = _model_with(*terms, effect_coef=coef)
    twist = model.predict_twist(sig, jnp.asarray(torque))
    sig = eqx.tree_at(lambda x: x.twist, sig, twist)
    est = np.asarray(estimate_torque(model, sig).torque)
    # exact model, noiseless: only rounding and the Newton tolerance remain
    np.testing.assert_allclose(est, torque, atol=1e-6)


def test_stiffening_that_bends_the_compliance_back_is_refused():
    # slope k1 - 3 c T^2/tau^3 turns negative inside the rated range for this c
    model = _model_with(Stiffening(400.0), effect_coef=[-3e-3])
    msg = check_invertible(model)
    assert "not increasing" in msg and "stiffness:torque" in msg
    sig, _ = _signals(200)
    with pytest.raises(hdjax.InversionError, match="stiffness"):
        estimate_torque(model, sig)
