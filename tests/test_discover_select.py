"""Candidate scoring: FWL cross-validation against explicit refits, and pysindy selection."""

import numpy as np

from hdjax.discover import cv_gain, fold_basis, sindy_select
from hdjax.discover._select import fold_indices


def _problem(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    a = np.column_stack([np.ones(n), rng.standard_normal((n, 3))])
    extra = rng.standard_normal((n, 2))
    y = a @ np.array([1.0, 2.0, -1.0, 0.5]) + extra @ np.array([0.4, -0.3])
    y += 0.1 * rng.standard_normal(n)
    return a, extra, y


def test_cv_gain_matches_explicit_refit_per_fold():
    a, extra, y = _problem()
    basis = fold_basis(a, y, n_folds=5, block=50)
    gain, per_fold = cv_gain(basis, extra)
    sse0, sse1 = [], []
    for te in fold_indices(len(y), 5, 50):
        tr = np.setdiff1d(np.arange(len(y)), te)
        b0 = np.linalg.lstsq(a[tr], y[tr], rcond=None)[0]
        full = np.column_stack([a, extra])
        b1 = np.linalg.lstsq(full[tr], y[tr], rcond=None)[0]
        sse0.append(np.sum((y[te] - a[te] @ b0) ** 2))
        sse1.append(np.sum((y[te] - full[te] @ b1) ** 2))
    sse0, sse1 = np.array(sse0), np.array(sse1)
    np.testing.assert_allclose(per_fold, 1 - sse1 / sse0, rtol=1e-9)
    np.testing.assert_allclose(gain, 1 - sse1.sum() / sse0.sum(), rtol=1e-9)
    assert gain > 0.9


def test_useless_column_has_no_gain():
    a, _, y = _problem()
    noise = np.random.default_rng(5).standard_normal((len(y), 1))
    gain, per_fold = cv_gain(fold_basis(a, y), noise)
    assert gain < 0.005


def test_sindy_selects_the_true_columns_only():
    a, extra, y = _problem()
    rng = np.random.default_rng(7)
    decoys = [rng.standard_normal(len(y)) for _ in range(6)]
    cols = [extra[:, 0], extra[:, 1]] + decoys
    resid = y - a @ np.linalg.lstsq(a, y, rcond=None)[0]
    chosen = sindy_select(a, resid, cols, [f"c{i}" for i in range(len(cols))], threshold=0.05)
    assert chosen.tolist() == [True, True] + [False] * 6


def test_column_absorbed_by_the_base_design_is_not_selected():
    a, extra, y = _problem()
    resid = y - a @ np.linalg.lstsq(a, y, rcond=None)[0]
    # a copy of a base column can explain nothing once made orthogonal to the base
    chosen = sindy_select(a, resid, [a[:, 1], extra[:, 0]], ["dup", "x0"], threshold=0.05)
    assert chosen.tolist() == [False, True]


def test_numpy_candidate_columns_equal_the_model_terms():
    from hdjax.compliance import (
        Backlash,
        Column,
        Coulomb,
        Harmonics,
        Hysteresis,
        Stiffening,
        Viscous,
        signals_from_recording,
    )
    from hdjax.discover._library import candidate_columns

    from .discover_data import synthetic_recording

    rec = synthetic_recording(1, [("temperature", 0.02)], n=2000)
    sig = signals_from_recording(rec, 160.0)
    terms = [
        Harmonics("theta_m", (2.0, 2 - 2 / 160)),
        Coulomb("omega_l", 0.05),
        Viscous("omega_m", 3.0),
        Column("temperature", 25.0, 3.0),
        Backlash(8.0),
        Stiffening(400.0),
        Hysteresis(20.0),
    ]
    for term in terms:
        # same formulas in NumPy and JAX: agreement to rounding of a few ulps of O(1) values
        np.testing.assert_allclose(
            candidate_columns(term, sig, rec.torque),
            np.asarray(term.columns(sig, rec.torque)),
            rtol=0,
            atol=1e-13,
        )
    # the Hysteresis column has no NumPy shortcut in the library (it is the model's own scan),
    # so it is checked against the Dahl recursion written out here, sample by sample
    dT = np.diff(np.asarray(rec.torque), prepend=float(rec.torque[0])) / 20.0
    z, ref = 0.0, np.empty(dT.size)
    for i, d in enumerate(dT):
        z = min(1.0, max(-1.0, z + d * (1.0 - z * np.sign(d))))
        ref[i] = z
    assert np.ptp(ref) > 1.0  # the torque path drives the state through a loop
    got = np.asarray(Hysteresis(20.0).columns(sig, rec.torque))[:, 0]
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        candidate_columns(Hysteresis(20.0), sig, rec.torque)[:, 0], ref, rtol=0, atol=1e-12
    )
