"""The compliance model's structure: hinge basis (eq. (7)), design (eqs. (8)-(10)), metadata."""

import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax._trig import sincos
from hdjax.compliance import (
    ColumnTimesTorque,
    ComplianceModel,
    Coulomb,
    Harmonics,
    Stiffening,
    paper_knots,
    term_from_dict,
    term_to_dict,
)
from hdjax.effects import harmonic_pairs
from tests.helpers import JOINT, make_signals, numpy_design, simulate


def printed_eq7(T, k, tau0):
    """Song et al. eq. (7) exactly as printed (k1 central, k2/k3 negative, k4/k5 positive)."""
    k1, k2, k3, k4, k5 = k
    b, c = 2 * tau0 / 3, tau0 / 3
    if T < -b:
        return -k1 * tau0 / 3 - k2 * tau0 / 3 + k3 * (T + 2 * tau0 / 3)
    if T < -c:
        return -k1 * tau0 / 3 + k2 * (T + tau0 / 3)
    if T < c:
        return k1 * T
    if T < b:
        return k1 * tau0 / 3 + k4 * (T - tau0 / 3)
    # beyond the rated torque the outer segment extends (extrapolation, flagged at estimation)
    return k1 * tau0 / 3 + k4 * tau0 / 3 + k5 * (T - 2 * tau0 / 3)


def test_paper_knots_and_names():
    assert paper_knots(90.0) == pytest.approx((-60.0, -30.0, 30.0, 60.0))
    m = ComplianceModel.paper(JOINT)
    assert m.knots == pytest.approx((-60.0, -30.0, 30.0, 60.0))
    assert m.k_names == ("k3", "k2", "k1", "k4", "k5")  # torque order, paper's names
    # five segments: 5 compliances + 5 x (1 + 6 + 12) base coefficients (Table I layout)
    assert m.n_base == 19 and m.n_coef == 5 + 5 * 19
    assert len(m.term_names) == m.n_coef and m.term_names[5] == "k0[seg 0]"
    shared = ComplianceModel.paper(JOINT, per_segment=False)
    assert shared.n_coef == 5 + 19


def test_hinge_basis_reproduces_printed_eq7():
    # paper's flexspline compliances (Table, Section II-C), in the paper's k1..k5 naming
    k_paper = (0.26305, 0.19913, 0.04946, 0.29008, 0.08434)
    m = ComplianceModel.paper(JOINT)
    k_torque_order = jnp.asarray([k_paper[2], k_paper[1], k_paper[0], k_paper[3], k_paper[4]])
    T = np.linspace(-1.2 * JOINT.rated_torque, 1.2 * JOINT.rated_torque, 2001)
    T = np.r_[T, np.asarray(m.knots), 0.0]  # knots themselves: the printed [l, u) convention
    ours = np.asarray(m.hinge_basis(jnp.asarray(T)) @ k_torque_order)
    ref = np.array([printed_eq7(t, k_paper, JOINT.rated_torque) for t in T])
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)  # exact up to rounding


def test_segment_index_matches_eq7_intervals():
    m = ComplianceModel.paper(JOINT)
    T = jnp.asarray([-100.0, -60.0, -59.9, -30.0, 0.0, 29.99, 30.0, 60.0, 200.0])
    np.testing.assert_array_equal(np.asarray(m.segment_index(T)), [0, 1, 1, 2, 2, 2, 3, 4, 4])


@pytest.mark.parametrize("per_segment", [True, False])
@pytest.mark.parametrize("kinematic", ["paper", "harmonic"])
def test_design_matches_independent_numpy(per_segment, kinematic):
    m = ComplianceModel.paper(
        JOINT,
        per_segment=per_segment,
        kinematic=kinematic,
        harmonic_orders_m=(1.0, 2.0, 0.5),
        current_scale=2.0,
    )
    sig, torque = make_signals(500, seed=11)
    A = np.asarray(m.design(sig, torque))
    B = numpy_design(m, sig, torque)
    assert A.shape == (500, m.n_coef)
    # 3*theta*omega reaches ~500 rad, where one ulp of the argument is ~1e-13
    np.testing.assert_allclose(A, B, rtol=0, atol=5e-13)


def test_paper_form_depends_on_theta_times_omega():
    m = ComplianceModel.paper(JOINT, per_segment=False, poly_order=0)
    sig, torque = make_signals(50, seed=3)
    import equinox as eqx

    # doubling theta_m and halving omega_m keeps every paper-form column unchanged
    sig2 = eqx.tree_at(lambda s: (s.theta_m, s.omega_m), sig, (sig.theta_m * 2, sig.omega_m / 2))
    np.testing.assert_allclose(
        np.asarray(m.design(sig, torque)), np.asarray(m.design(sig2, torque)), atol=1e-12
    )


def test_sincos_and_recurrence_accuracy():
    x = np.r_[np.random.default_rng(0).uniform(-2000, 2000, 20000), np.linspace(-7, 7, 1001)]
    s, c = sincos(jnp.asarray(x))
    np.testing.assert_allclose(np.asarray(s), np.sin(x), rtol=0, atol=4e-16)
    np.testing.assert_allclose(np.asarray(c), np.cos(x), rtol=0, atol=4e-16)
    for n, (cn, sn) in enumerate(harmonic_pairs(jnp.asarray(x), 3), start=1):
        # np.cos(n*x) itself carries the rounding of n*x (~n*|x|*1.1e-16)
        np.testing.assert_allclose(np.asarray(cn), np.cos(n * x), atol=n * 2000 * 2.3e-16)
        np.testing.assert_allclose(np.asarray(sn), np.sin(n * x), atol=n * 2000 * 2.3e-16)


def test_predict_twist_is_design_times_coef():
    case = simulate("shared", 300, per_segment=False, seed=4)
    A = numpy_design(case.model, case.sig, case.torque)
    np.testing.assert_allclose(np.asarray(case.sig.twist), A @ case.truth, rtol=1e-12, atol=0)


def test_to_dict_round_trip_and_effects():
    m = ComplianceModel.paper(JOINT, kinematic="harmonic", harmonic_orders_l=(1.98,))
    m = m.with_effects(Coulomb(omega_s=0.5), Stiffening(torque_scale=90.0))
    m2 = ComplianceModel.from_dict(m.to_dict())
    assert m2.term_names == m.term_names and m2.effect_keys == m.effect_keys
    assert m.n_effect == 2 and m.term_names[-1] == "(T/90)^3"
    for term in m.base_terms + m.effect_terms:
        assert term_from_dict(term_to_dict(term)) == term
    assert Harmonics(orders=(1.0, 1.98)).names()[2] == "cos(1.98*theta_m)"


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(knots=(30.0, -30.0)), "strictly increasing"),
        (dict(knots=(-30.0, 0.0, 30.0)), "strictly inside"),
        (dict(poly_order=-1), "poly_order"),
        (dict(kinematic="fourier"), "kinematic must be one of"),
        (dict(n_segments=0), "n_segments"),
        (dict(velocity="spline"), "velocity"),
    ],
)
def test_bad_structure_is_a_config_error(kwargs, match):
    with pytest.raises(hdjax.ConfigError, match=match):
        ComplianceModel.paper(JOINT, **kwargs)


def test_linear_effect_design_column():
    m = ComplianceModel.paper(JOINT, per_segment=False, poly_order=0, kinematic="none")
    m = m.with_effects(ColumnTimesTorque("temperature", center=25.0, scale=10.0, torque_scale=90))
    sig, torque = make_signals(20, seed=1)
    import equinox as eqx

    temp = jnp.linspace(20.0, 40.0, 20)
    sig = eqx.tree_at(lambda s: s.extras, sig, {"temperature": temp})
    col = np.asarray(m.design(sig, torque))[:, -1]
    np.testing.assert_allclose(col, (np.asarray(temp) - 25.0) / 10.0 * torque / 90.0, rtol=1e-14)
