"""Recursive least squares by the SMW update, Song et al. eqs. (18)-(25), against batch LS."""

import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax.compliance import calibrate_lstsq, calibrate_rls, rls_init, rls_scan, rls_solve
from tests.helpers import simulate


@pytest.fixture(scope="session")
def case():
    # well-conditioned float64 data (scaled condition ~60), 0.1 arcsec noise
    return simulate("rls", 2000, per_segment=False, noise=5e-7, seed=21)


@pytest.fixture(scope="session")
def batch(case):
    return np.asarray(calibrate_lstsq(case.model, (case.sig, case.torque)).value.coef)


def rel_err(x, ref):
    return np.max(np.abs(np.asarray(x) - ref)) / np.max(np.abs(ref))


@pytest.mark.parametrize("block_size", [1, 32, 7])  # rank-one (eqs. 24-25), block, with a tail
def test_matches_batch_least_squares(case, batch, block_size):
    print("seed", case.seed)
    res = calibrate_rls(case.model, (case.sig, case.torque), block_size=block_size)
    # the bar: 1e-8 relative on well-conditioned float64 data
    assert rel_err(res.value.coef, batch) < 1e-8
    assert res.stats["rank"] == res.stats["n_terms"] == case.model.n_coef


def test_per_segment_block_matches_batch():
    c = simulate(
        "rls-seg", 1500, per_segment=True, noise=5e-7, seed=22, poly_order=2, fourier_order=1
    )
    ref = np.asarray(calibrate_lstsq(c.model, (c.sig, c.torque)).value.coef)
    # init block must reach every segment (the data are shuffled in torque, so 2p rows do)
    res = calibrate_rls(c.model, (c.sig, c.torque), block_size=32)
    assert rel_err(res.value.coef, ref) < 1e-8


def _random_problem(n=600, p=6, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, p))
    b = a @ rng.standard_normal(p) + 0.1 * rng.standard_normal(n)
    return a, b


@pytest.mark.parametrize("block_size", [1, 10])
def test_forgetting_matches_weighted_batch(block_size):
    a, b = _random_problem(seed=3)
    lam, n0 = 0.98, 60
    state, _ = rls_solve(
        jnp.asarray(a), jnp.asarray(b), block_size=block_size, forgetting=lam, init_samples=n0
    )
    # after k more blocks a row of block j carries weight lam**(k - 1 - j); the initial batch
    # lam**k: exactly the exponentially weighted least-squares problem
    n_blocks = (len(b) - n0) // block_size
    w = np.empty(len(b))
    w[:n0] = lam**n_blocks
    for j in range(n_blocks):
        w[n0 + j * block_size : n0 + (j + 1) * block_size] = lam ** (n_blocks - 1 - j)
    sw = np.sqrt(w)
    ref, *_ = np.linalg.lstsq(a * sw[:, None], b * sw, rcond=None)
    assert rel_err(state.x, ref) < 1e-8
    # and P is the inverse of the weighted information matrix
    g = (a * w[:, None]).T @ a
    np.testing.assert_allclose(np.asarray(state.p), np.linalg.inv(g), rtol=1e-8, atol=1e-12)


def test_covariance_is_symmetric_and_the_inverse_gram():
    a, b = _random_problem(n=2000, p=8, seed=4)
    state, hist = rls_solve(jnp.asarray(a), jnp.asarray(b), block_size=16)
    p = np.asarray(state.p)
    assert np.array_equal(p, p.T)  # kept exactly symmetric by construction
    assert np.linalg.eigvalsh(p).min() > 0
    np.testing.assert_allclose(p, np.linalg.inv(a.T @ a), rtol=1e-9)
    assert hist.shape == ((2000 - 16) // 16, 8)  # one estimate per block after eq. (18)


def test_init_is_eq18():
    a, b = _random_problem(n=40, p=5, seed=5)
    st = rls_init(jnp.asarray(a), jnp.asarray(b))
    ref, *_ = np.linalg.lstsq(a, b, rcond=None)
    assert rel_err(st.x, ref) < 1e-12


def test_scan_does_not_recompile():
    a, b = _random_problem(n=200, p=4, seed=6)
    st = rls_init(jnp.asarray(a[:20]), jnp.asarray(b[:20]))
    blocks = jnp.asarray(a[20:].reshape(18, 10, 4)), jnp.asarray(b[20:].reshape(18, 10))
    rls_scan(st, *blocks, 1.0)
    size = rls_scan._cached._cache_size()
    rls_scan(st, blocks[0] * 2.0, blocks[1], 1.0)
    assert rls_scan._cached._cache_size() == size


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(forgetting=0.0), "forgetting factor must lie in"),
        (dict(forgetting=1.5), "forgetting factor must lie in"),
        (dict(block_size=0), "block_size must be a positive integer"),
        (dict(init_samples=3), "init_samples must lie in"),
    ],
)
def test_bad_options(kwargs, match):
    a, b = _random_problem(n=50, p=5)
    with pytest.raises(hdjax.ConfigError, match=match):
        rls_solve(jnp.asarray(a), jnp.asarray(b), **kwargs)


def test_rank_deficient_initial_block():
    a, b = _random_problem(n=50, p=5)
    a[:, 4] = a[:, 3]  # two identical columns
    with pytest.raises(hdjax.CalibrationError, match="rank-deficient initial block"):
        rls_solve(jnp.asarray(a), jnp.asarray(b))
