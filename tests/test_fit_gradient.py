"""Gradient methods on the linear compliance model reach the closed-form LS solution (eq. 17)."""

import warnings

import numpy as np
import pytest

import hdjax
from hdjax import compliance as hc, fit

JOINT = hdjax.Joint(ratio=160.0, rated_torque=400.0)


@pytest.fixture(scope="session")
def problem():
    """A joint with known compliance, kinematic error and twist noise; seed 0."""
    rng = np.random.default_rng(0)
    n = 2000
    t = np.arange(n) * 1e-3
    tau = 330 * np.sin(2 * np.pi * 0.7 * t) + 60 * np.sin(2 * np.pi * 1.9 * t + 1.0)
    theta_l = 0.3 * np.sin(2 * np.pi * 0.25 * t)
    tw = tau / 2.0e4 + 1e-4 * np.sin(2 * 160 * theta_l) + 1e-6 * rng.normal(size=n)
    current = tau / 16.0 + rng.normal(scale=0.05, size=n)
    rec = hdjax.make_recording(t, 160 * (theta_l - tw), theta_l, current, tau)
    model = hc.ComplianceModel.paper(
        JOINT, per_segment=False, kinematic="harmonic", current_scale=25.0
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        closed = hc.calibrate_lstsq(model, rec).value
    prob = fit.linear_problem(model, rec)
    return rec, model, closed, prob


def test_closed_form_agrees_with_numpy(problem):
    """Second reference: numpy.linalg.lstsq on the same scaled problem."""
    _, _, closed, prob = problem
    u_np = np.linalg.lstsq(np.asarray(prob.a), np.asarray(prob.b), rcond=None)[0]
    coef_np = prob.to_coef(u_np, closed.n_coef)
    c = np.asarray(closed.coef)
    assert np.linalg.norm(coef_np - c) / np.linalg.norm(c) < 1e-9


@pytest.mark.parametrize("method", ["gauss_newton", "levenberg_marquardt", "adam"])
def test_gradient_reaches_closed_form(problem, method):
    rec, model, closed, prob = problem
    res = fit.fit_compliance_gradient(model, rec, method=method, steps=4000)
    c, c_star = np.asarray(res.value.coef), np.asarray(closed.coef)
    u, u_star = np.asarray(prob.to_u(c)), np.asarray(prob.to_u(c_star))
    loss_star = float(prob.loss(prob.to_u(c_star)))
    # Coefficients within 1e-6 relative (norm-wise, and each scaled coefficient against the
    # largest), loss within 1e-9 relative: the thresholds, float64.
    assert np.linalg.norm(c - c_star) / np.linalg.norm(c_star) < 1e-6
    assert np.max(np.abs(u - u_star)) / np.max(np.abs(u_star)) < 1e-6
    assert abs(res.stats["loss"] - loss_star) / loss_star < 1e-9
    assert res.ok and res.stats["method"] == method and res.stats["steps"] <= 4000


def test_unknown_method(problem):
    rec, model, _, _ = problem
    with pytest.raises(hdjax.ConfigError, match="unknown method 'sgd'"):
        fit.fit_compliance_gradient(model, rec, method="sgd")


def test_needs_reference_torque(problem):
    rec, model, _, _ = problem
    no_torque = hdjax.make_recording(rec.t, rec.theta_m, rec.theta_l, rec.current)
    with pytest.raises(hdjax.DataError, match="reference torque"):
        fit.fit_compliance_gradient(model, no_torque, method="adam")
