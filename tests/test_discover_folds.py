"""Segments, folds, gap-safe signals, block-Gram scoring and the implicit hysteresis inversion.

Each has a closed-form reference: an AR(1) residual's correlation length, a backward difference
that must not span a gap, the exact cross-validated gains of `cv_gains` (per-fold QR) for the
block-Gram shortcut, and a forward model (twist from a known torque path) for the inversion.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

import hdjax
from hdjax.compliance import ComplianceModel, Hysteresis, Signals, dahl_state, estimate_torque
from hdjax.discover import pipeline_signals
from hdjax.discover._folds import (
    contiguous_blocks,
    correlation_length,
    fold_assignment,
    segment_starts,
)
from hdjax.discover._gram import block_statistics, fold_gains
from hdjax.discover._pipeline import PipelineData, cross_validate
from hdjax.discover._select import cv_gains, fold_basis
from hdjax.effects import SEGMENT_START

JOINT = hdjax.Joint(ratio=160, rated_torque=400)


def _gappy_time():
    # 3 segments: a jump of 10 periods, then the join of a block split (one block missing)
    t = np.r_[np.arange(300), 310 + np.arange(200), 610 + np.arange(250)] * 4e-3
    return t


def test_segments_blocks_and_folds_never_cross_a_gap():
    t = _gappy_time()
    starts = segment_starts(t)
    assert np.flatnonzero(starts).tolist() == [0, 300, 500]
    seg = np.cumsum(starts) - 1
    blocks = contiguous_blocks(starts, 100)
    for b in np.unique(blocks):
        idx = np.flatnonzero(blocks == b)
        assert np.all(np.diff(idx) == 1), "a block is contiguous"
        assert np.unique(seg[idx]).size == 1, "a block never straddles a gap"
    folds = fold_assignment(blocks, 5)
    assert sorted(np.concatenate(folds).tolist()) == list(range(t.size))
    rng = np.random.default_rng(0)
    deal = fold_assignment(blocks, 5, rng=rng)
    sizes = [np.unique(blocks[f]).size for f in deal]
    assert max(sizes) - min(sizes) <= 1, "a random deal stays balanced"


@pytest.mark.parametrize("phi", [0.5, 0.9, 0.98])
def test_correlation_length_of_an_ar1_residual(phi):
    # autocorrelation phi^lag falls below 1/e at lag ceil(-1/ln phi) (closed form)
    rng = np.random.default_rng(1)
    n = 200000
    e = rng.standard_normal(n)
    r = scipy.signal.lfilter([1.0], [1.0, -phi], e)
    expect = math.ceil(-1.0 / math.log(phi))
    got = correlation_length(r)
    assert abs(got - expect) <= max(1, 0.1 * expect), (got, expect)


def test_pipeline_signals_do_not_differentiate_across_gaps():
    t = _gappy_time()
    theta_l = 0.3 * np.sin(2 * np.pi * 0.5 * t)
    theta_m = 160 * theta_l
    rec = hdjax.make_recording(t, theta_m, theta_l, 0 * t, 0 * t, {}, source="gappy")
    data = pipeline_signals(rec, 160.0, 1.0, "difference")
    w = np.asarray(data.sig.omega_l)
    exact = 0.3 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t)
    # every backward difference inside a segment is within one step of the derivative; the
    # first sample after a gap takes the next one's (without the fix it averages over the gap)
    err = np.abs(w - exact)
    assert err.max() < 0.02 * np.abs(exact).max(), err.max()
    # memory states carry across the 40 ms of dropped samples and restart at the 0.4 s join
    start = np.asarray(data.sig.extras[SEGMENT_START])
    assert np.flatnonzero(start).tolist() == [0, 500]


def test_block_gram_gains_equal_the_exact_cross_validated_gains():
    rng = np.random.default_rng(2)
    n = 3000
    a = np.column_stack([np.ones(n), rng.standard_normal((n, 3))])
    c1 = rng.standard_normal((n, 2))
    c2 = rng.standard_normal((n, 1))
    y = a @ [0.1, 1.0, -2.0, 0.5] + c1 @ [0.3, 0.0] + 0.1 * rng.standard_normal(n)
    starts = np.zeros(n, bool)
    starts[0] = True
    blocks = contiguous_blocks(starts, 150)
    folds = fold_assignment(blocks, 5)
    exact = [g for g, _ in cv_gains(fold_basis(a, y, tests=folds), [c1, c2])]
    fold_of_block = np.arange(blocks.max() + 1) % 5
    fast, _ = fold_gains(block_statistics(a, [c1, c2], y, blocks), fold_of_block, 5)
    # normal equations on well-conditioned columns: agreement to ~1e-10
    np.testing.assert_allclose(fast, exact, atol=1e-9)
    assert exact[0] > 0.5 and exact[1] < 0.01


def _hysteresis_model(c, scale):
    base = ComplianceModel.paper(JOINT, poly_order=0, kinematic="none", per_segment=False)
    model = base.with_effects(Hysteresis(torque_scale=scale))
    k = np.array([1.2, 1.1, 1.0, 1.1, 1.2]) / 6.7e4
    coef = np.zeros(model.n_coef)
    coef[:5] = k
    coef[-1] = c
    return eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef))


@pytest.mark.parametrize("loop_gain", [0.3, 0.9])
def test_path_inversion_recovers_the_torque_of_a_sharp_hysteresis(loop_gain):
    # twist = k T + c z(T) with the Dahl state of the true torque; the slope right after a
    # reversal is k (1 - loop_gain). Inside the central segment the implicit step is exact.
    scale = 10.0
    k = 1.0 / 6.7e4
    c = -loop_gain * k * scale / 2.0
    model = _hysteresis_model(c, scale)
    n = 4000
    t = np.arange(n) * 2e-3
    torque = 100 * np.sin(2 * np.pi * 0.7 * t) * np.sin(2 * np.pi * 0.11 * t)
    reset = np.zeros(n)
    reset[[0, 2000]] = 1.0
    z = np.asarray(dahl_state(jnp.asarray(torque), scale, jnp.asarray(reset)))
    twist = k * torque + c * z
    zeros = jnp.zeros(n)
    sig = Signals(
        twist=jnp.asarray(twist),
        current=zeros,
        theta_m=zeros,
        theta_l=zeros,
        omega_m=zeros,
        omega_l=zeros,
        extras={SEGMENT_START: jnp.asarray(reset)},
    )
    est = np.asarray(estimate_torque(model, sig).torque)
    err = np.abs(est - torque).max()
    assert err < 1e-6, err
    # the one-pass estimate (state driven by the estimate without hysteresis) is far off
    naive_z = np.asarray(dahl_state(jnp.asarray(twist / k), scale, jnp.asarray(reset)))
    naive = (twist - c * naive_z) / k
    assert np.abs(naive - torque).max() > 100 * err + 0.1


def test_a_cross_validation_that_scores_no_sample_is_unknown_not_zero():
    # a one-way torque sweep split in two halves: each fold holds out torques outside the range
    # its training part calibrates, so nothing is scored; a zero error would accept any step
    n = 2000
    torque = np.linspace(-200.0, 200.0, n)
    model = ComplianceModel.paper(JOINT, poly_order=0, kinematic="none", per_segment=False)
    zeros = jnp.zeros(n)
    sig = Signals(
        twist=jnp.asarray(torque / 6.7e4),
        current=zeros,
        theta_m=zeros,
        theta_l=zeros,
        omega_m=zeros,
        omega_l=zeros,
        extras={SEGMENT_START: jnp.asarray(np.r_[1.0, np.zeros(n - 1)])},
    )
    data = PipelineData(sig, torque, np.r_[True, np.zeros(n - 1, bool)])
    halves = [np.arange(n // 2), np.arange(n // 2, n)]
    cv = cross_validate(model, data, halves)
    assert np.isnan(cv.torque_rms) and np.isnan(cv.twist_rms_arcsec)
    inner = [np.arange(800, 1000), np.arange(1000, 1200)]
    assert np.isfinite(cross_validate(model, data, inner).torque_rms)


def test_a_held_out_sample_outside_its_folds_range_of_an_extrapolating_signal_is_not_scored():
    """The paper's kinematic columns are smooth functions of the output's angle times speed
    and the wave-generator polynomial one of the current: a held-out sample beyond the
    training part's range of either is extrapolation, which TEST never asks for. The rows are
    checked against a direct count, and cross-validation of the paper's model scores exactly
    those (and more without the kinematic columns)."""
    from hdjax.discover._pipeline import coverage_arguments, motion_regime, scored_rows

    from .discover_data import synthetic_recording

    data = pipeline_signals(synthetic_recording(0, n=6000), JOINT.ratio, 1.0, "difference")
    sig = data.sig
    model = ComplianceModel.paper(JOINT, poly_order=2, kinematic="paper", fourier_order=2)
    product = np.asarray(sig.theta_l) * np.asarray(sig.omega_l)
    args = coverage_arguments(model, data)
    assert len(args) == 2
    assert np.array_equal(args[0], np.asarray(sig.current)) or np.array_equal(args[1], product)
    assert {a.tobytes() for a in args} == {np.asarray(sig.current).tobytes(), product.tobytes()}
    assert (
        coverage_arguments(ComplianceModel.paper(JOINT, poly_order=0, kinematic="none"), data) == []
    )
    folds = fold_assignment(contiguous_blocks(data.starts, 600), 5)
    regime = motion_regime(np.asarray(sig.omega_l))
    scored = 0
    for te, rows in zip(folds, scored_rows(data, folds, args)):
        train = np.setdiff1d(np.arange(data.n), te)
        keep = []
        for i in te:  # one sample at a time, from the definition
            same = train[regime[train] == regime[i]]
            ok = same.size and data.torque[same].min() <= data.torque[i] <= data.torque[same].max()
            for x in args:
                ok = ok and x[train].min() <= x[i] <= x[train].max()
            keep.append(bool(ok))
        assert np.array_equal(rows, te[np.asarray(keep)])
        scored += rows.size
    # the extrapolating signals leave rows out that the torque alone keeps
    assert sum(r.size for r in scored_rows(data, folds)) > scored
    cv = cross_validate(model, data, folds)
    assert np.isfinite(cv.squared_errors).sum() == scored
