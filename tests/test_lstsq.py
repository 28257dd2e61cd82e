"""Closed-form calibration, Song et al. eqs. (15)-(17): truth, numpy.linalg.lstsq, bad designs."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax.compliance import (
    ColumnTimesTorque,
    ComplianceModel,
    Coulomb,
    Harmonics,
    Hysteresis,
    _lstsq as lstsq_mod,
    calibrate_lstsq,
    calibration_messages,
)
from hdjax.compliance._lstsq import _base_column_list, _term_columns, compact_column_list
from hdjax.effects import TORQUE_PATH, Backlash
from tests.helpers import JOINT, make_signals, numpy_design, sim_recording, simulate

CASES = {
    "per_segment": dict(per_segment=True, seed=1),
    "shared": dict(per_segment=False, seed=2),
    "harmonic": dict(per_segment=False, kinematic="harmonic", seed=3),
}


@pytest.fixture(scope="session", params=sorted(CASES))
def exact_case(request):
    return simulate(request.param, 3000, **CASES[request.param])


@pytest.fixture(scope="session")
def noisy_case():
    # 0.1 arcsec of encoder noise on a twist of ~500 arcsec
    return simulate("noisy", 3000, per_segment=True, noise=5e-7, seed=7)


def test_recovers_truth_on_exact_data(exact_case):
    print("seed", exact_case.seed)
    res = calibrate_lstsq(exact_case.model, (exact_case.sig, exact_case.torque))
    assert res.stats["rank"] == res.stats["n_terms"] == exact_case.model.n_coef
    assert not res.stats["dropped"]
    # noise-free float64 data, scaled condition ~70: the coefficients are recovered to ~1e-13
    scale = np.abs(exact_case.truth).max()
    np.testing.assert_allclose(np.asarray(res.value.coef), exact_case.truth, atol=1e-11 * scale)
    assert res.stats["residual_rms"] < 1e-15


def test_matches_numpy_lstsq_on_noisy_data(noisy_case):
    c = noisy_case
    res = calibrate_lstsq(c.model, (c.sig, c.torque))
    A = numpy_design(c.model, c.sig, c.torque)
    ref, *_ = np.linalg.lstsq(A, np.asarray(c.sig.twist), rcond=None)
    # two backward-stable solvers on a design of scaled condition ~70: agree to ~1e-12 relative
    np.testing.assert_allclose(
        np.asarray(res.value.coef), ref, rtol=0, atol=1e-10 * np.abs(ref).max()
    )
    resid = A @ ref - np.asarray(c.sig.twist)
    assert res.stats["residual_rms"] == pytest.approx(np.sqrt(np.mean(resid**2)), rel=1e-10)
    # the noise is recovered as the residual (p/n = 3 % of it is absorbed)
    assert res.stats["residual_rms"] == pytest.approx(5e-7, rel=0.05)
    # condition number of the column-scaled design, as numpy computes it
    As = A / np.linalg.norm(A, axis=0)
    assert res.stats["condition"] == pytest.approx(np.linalg.cond(As), rel=1e-6)


def test_qr_path_with_an_unreached_segment_ahead_of_calibrated_ones(monkeypatch):
    """The Householder QR fallback agrees with the semi-normal equations and numpy.linalg.lstsq,
    with inactive columns (segment 0 is never reached: its hinge and its own block) ahead of the
    active ones. The QR path must solve the active design alone: its Householder step on a
    zeroed column would otherwise leave part of the later columns' factor in a row of R that is
    then dropped."""
    sig, torque = make_signals(3000, seed=11)
    torque = jnp.asarray(np.clip(np.asarray(torque), -50.0, 85.0))  # nothing below -60 N·m
    truth = simulate("x", 10, per_segment=True, seed=11)
    model = eqx.tree_at(lambda m: m.coef, truth.model, jnp.asarray(truth.truth))
    noise = 5e-7 * np.random.default_rng(3).standard_normal(3000)
    twist = np.asarray(model.predict_twist(sig, torque)) + noise
    sig = eqx.tree_at(lambda s: s.twist, sig, jnp.asarray(twist))
    with pytest.warns(UserWarning, match="left out"):
        fast = calibrate_lstsq(model, (sig, torque))
    monkeypatch.setattr(lstsq_mod, "CSNE_MAX_COND", 1.0)  # force the Householder QR path
    with pytest.warns(UserWarning, match="left out"):
        slow = calibrate_lstsq(model, (sig, torque))
    active = np.asarray(slow.value.active)
    assert not active[0] and active[1:5].all() and slow.ok
    A = numpy_design(model, sig, torque)
    ref = np.zeros(A.shape[1])
    ref[active] = np.linalg.lstsq(A[:, active], twist, rcond=None)[0]
    # both paths are backward stable on a design of scaled condition ~100: ~1e-13 relative
    # (the column-dropping bug gave 1e-4 on a shared model)
    for res in (slow, fast):
        np.testing.assert_allclose(
            np.asarray(res.value.coef), ref, rtol=0, atol=1e-10 * np.abs(ref).max()
        )
    assert slow.stats["condition"] == pytest.approx(fast.stats["condition"], rel=1e-6)


def test_calibrates_from_a_recording():
    from tests.helpers import sim_recording

    rec = sim_recording(400)
    model = ComplianceModel.paper(JOINT, per_segment=False, poly_order=1, kinematic="none")
    res = calibrate_lstsq(model, rec)
    # the simulated twist is exactly 3e-5 rad per N·m in every segment (torque +-80 N·m)
    np.testing.assert_allclose(np.asarray(res.value.k), 3e-5, rtol=1e-6)
    assert res.value.torque_range == pytest.approx(
        (float(rec.torque.min()), float(rec.torque.max()))
    )


def test_unreached_segments_are_dropped_and_range_narrowed():
    sig, torque = make_signals(2000, seed=5)
    torque = np.clip(torque, -50.0, 85.0)  # never below -60 N·m: segment 0 unreached
    model = ComplianceModel.paper(JOINT, per_segment=True)
    truth_case = simulate("x", 10, per_segment=True, seed=5)
    model = eqx.tree_at(lambda m: m.coef, model, jnp.asarray(truth_case.truth))
    twist = model.predict_twist(sig, torque)
    sig = eqx.tree_at(lambda s: s.twist, sig, twist)
    with pytest.warns(UserWarning, match="left out"):
        res = calibrate_lstsq(model, (sig, torque))
    dropped = res.stats["dropped"]
    assert any(d.startswith("k3 (no sample reaches torque segment 0)") for d in dropped)
    assert not any(res.value.active[5 : 5 + 19])  # segment 0's own block is left out too
    assert res.stats["segment_counts"][0] == 0 and sum(res.stats["segment_counts"]) == 2000
    assert res.value.torque_range == pytest.approx((-50.0, 85.0))
    assert not res.value.active[0] and float(res.value.coef[0]) == 0.0
    np.testing.assert_allclose(np.asarray(res.value.k)[1:], truth_case.truth[1:5], rtol=1e-9)


# ------------------------------------------------------------------------------------------
# Bad input


def test_constant_current_names_the_polynomial_terms():
    sig, torque = make_signals(500, seed=8)
    sig = eqx.tree_at(lambda s: s.current, sig, jnp.full(500, 0.7))
    sig = eqx.tree_at(lambda s: s.twist, sig, jnp.asarray(3e-5 * torque))
    model = ComplianceModel.paper(JOINT, per_segment=False, poly_order=3, kinematic="none")
    with pytest.raises(hdjax.CalibrationError) as err:
        calibrate_lstsq(model, (sig, torque))
    msg = str(err.value)
    assert "rank-deficient" in msg and "rank 6 < 9" in msg
    for name in ("k0", "w1", "w2", "w3"):
        assert name in msg
    assert "constant current" in msg and "add load variation" in msg
    res = calibrate_lstsq(model, (sig, torque), throw=False)
    assert res.result == hdjax.RESULTS.rank_deficient and not res.ok
    assert res.stats["rank"] == 6 and res.stats["n_terms"] == 9
    assert any({"k0", "w1"} <= set(g) for g in res.stats["collinear"])
    assert "add load variation" in res.message  # the result's own actionable message
    assert calibration_messages(res) == [msg]  # the raised error's text, nothing left out


def test_fewer_samples_than_coefficients():
    c = simulate("small", 60, per_segment=False, seed=9)  # 24 coefficients... with 60 rows ok
    sig = jax.tree_util.tree_map(lambda x: x[:20], c.sig)
    with pytest.raises(hdjax.CalibrationError, match="20 samples cannot calibrate 24 coeff"):
        calibrate_lstsq(c.model, (sig, c.torque[:20]))


def test_falling_twist_is_not_invertible_and_suggests_twist_sign():
    c = simulate("flip", 1500, per_segment=False, seed=10)
    sig = eqx.tree_at(lambda s: s.twist, c.sig, -c.sig.twist)
    with pytest.raises(hdjax.InversionError) as err:
        calibrate_lstsq(c.model, (sig, c.torque))
    msg = str(err.value)
    assert "not increasing with torque" in msg and "twist_sign = -1" in msg and "k1=" in msg
    res = calibrate_lstsq(c.model, (sig, c.torque), throw=False)
    assert res.result == hdjax.RESULTS.twist_reversed and "twist_sign = -1" in res.message
    assert calibration_messages(res) == [msg]


def test_recording_without_torque_is_refused():
    from tests.helpers import sim_recording

    rec = sim_recording(50, with_torque=False)
    with pytest.raises(hdjax.DataError, match="needs a reference 'torque' column"):
        calibrate_lstsq(ComplianceModel.paper(JOINT), rec)


def test_no_recompilation_on_second_call(exact_case):
    c = exact_case
    calibrate_lstsq(c.model, (c.sig, c.torque))
    before = [f._cached._cache_size() for f in (_base_column_list, _term_columns)]
    with warnings.catch_warnings():
        calibrate_lstsq(c.model, (c.sig, c.torque))
    assert [f._cached._cache_size() for f in (_base_column_list, _term_columns)] == before


def test_compact_columns_equal_a_single_program_bit_for_bit():
    """The calibration's columns, from a program per base-term set and per effect group with
    the hinges in NumPy, are the numbers one program for the whole structure gives."""

    @eqx.filter_jit
    def single(model, sig, torque):
        cols = [jnp.clip(torque, lo, hi) - min(max(0.0, lo), hi) for lo, hi in model.segment_bounds]
        cols += model.base_column_list(sig)
        for term in model.effect_terms:
            block = term.columns(sig, torque)
            cols += [block[:, j] for j in range(block.shape[1])]
        return cols, model.segment_index(torque)

    rec = sim_recording(400)
    model = ComplianceModel.paper(JOINT).with_effects(
        Harmonics(signal="theta_m", orders=(2.0, 3.0)),
        Coulomb(signal="omega_l", omega_s=0.05),
        ColumnTimesTorque(name="current", center=0.0, scale=5.0, torque_scale=100.0),
        Backlash(width=5.0),
        Hysteresis(torque_scale=20.0),
    )
    sig = hdjax.compliance.signals_from_recording(rec, model.ratio, model.twist_sign)
    torque = jnp.asarray(rec.torque)
    sig = eqx.tree_at(lambda s: s.extras, sig, {**sig.extras, TORQUE_PATH: 0.9 * torque})
    cols, seg = compact_column_list(model, sig, torque)
    ref_cols, ref_seg = single(model, sig, torque)
    assert len(cols) == len(ref_cols) == model.n_segments + model.n_base + model.n_effect
    for got, ref in zip(cols, ref_cols):
        np.testing.assert_array_equal(got, np.asarray(ref))
    np.testing.assert_array_equal(seg, np.asarray(ref_seg))
