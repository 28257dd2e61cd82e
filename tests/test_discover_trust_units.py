"""Units of the trustworthy residual loop, each against a reference known independently.

- `unexplained`: a residual built from a known out-of-vocabulary order and a known shape
  against torque is listed with that signal, order or shape and amplitude (closed form);
  white noise lists nothing.
- Stability selection: a candidate whose columns help only when two of its blocks share a fold
  (true of the standard deal, rarely of a random one: counted from the deals alone) is not
  eligible, while a genuine one is.
- Fold blocks: no shorter than an AR(1) residual's correlation time (closed form), never across
  a gap (a time jump over 3 sample periods), and a loud warning when the record is too short.
- The 1/3-period rule for a named order of the output angle, at the library level.
- TEST never chooses: the loop's choices and cross-validated errors do not depend on TEST.
"""

import json
import math
import types

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

from hdjax.compliance import ComplianceModel, Signals
from hdjax.discover import DiscoverOptions, build_library, discover
from hdjax.discover._decision import Scored, eligible, rank
from hdjax.discover._folds import (
    GAP_FACTOR,
    MAX_BLOCKS,
    contiguous_blocks,
    correlation_length,
    cv_block_length,
    resampled_assignments,
    segment_starts,
)
from hdjax.discover._gram import block_statistics, fold_gains
from hdjax.discover._library import LibraryOptions
from hdjax.discover._report import write_report
from hdjax.discover._spectrum import order_spectrum
from hdjax.discover._unexplained import unexplained_structure

from .discover_data import JOINT, synthetic_recording

ARCSEC = math.pi / (180 * 3600)


# -- unexplained structure ---------------------------------------------------------------------


def _angles_and_torque(n, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 2e-3
    theta_m = 25.0 * t + 3.0 * np.sin(0.7 * t)  # about 40 motor revolutions
    torque = 300.0 * np.sin(2 * np.pi * 0.37 * t + 0.2) * np.cos(2 * np.pi * 0.05 * t)
    return rng, theta_m, torque


def _unexplained(residual, theta_m, torque):
    spectra = {"theta_m": order_spectrum(theta_m, residual, min_order=0.5, max_order=8.0)}
    return unexplained_structure(
        residual,
        spectra,
        {"torque": torque},
        correlation_length=correlation_length(residual),
        angles={"theta_m": theta_m},
    )


def test_an_out_of_vocabulary_order_and_a_torque_shape_are_listed_and_noise_is_not():
    n = 5000
    rng, theta_m, torque = _angles_and_torque(n, 0)
    noise = 1.0 * ARCSEC * rng.standard_normal(n)
    a_order, order = 3.0 * ARCSEC, 5.37  # no integer, no 2 +- 2/N: no family names it
    wave = a_order * np.sin(order * theta_m + 0.3)
    a_shape = 6.0 * ARCSEC
    shape = a_shape * (np.abs(torque) / 300.0) ** 2  # even in the torque: no odd term has it
    listed = _unexplained(noise + wave + shape, theta_m, torque)
    orders = [u for u in listed if u["kind"] == "order"]
    shapes = [u for u in listed if u["kind"] == "shape"]
    assert len(orders) == 1 and orders[0]["signal"] == "theta_m", listed
    assert abs(orders[0]["order"] - order) < 2 * np.pi / np.ptp(theta_m), orders[0]
    # sqrt(2 p var) is the sinusoid's amplitude: within the noise's share of the estimate
    np.testing.assert_allclose(orders[0]["amplitude_arcsec"], a_order / ARCSEC, rtol=0.15)
    assert len(shapes) == 1 and shapes[0]["signal"] == "torque", listed
    # half the range of the bin means: half of a_shape (the bins' centres reach ~|T| = 300)
    np.testing.assert_allclose(shapes[0]["amplitude_arcsec"], 0.5 * a_shape / ARCSEC, rtol=0.15)
    bins, means = np.asarray(shapes[0]["bins"]), np.asarray(shapes[0]["bin_means_arcsec"])
    assert means[np.argmin(np.abs(bins))] < means[0] and means[np.argmin(np.abs(bins))] < means[-1]
    # the order alone, then the shape alone, each listed without the other
    assert [u["kind"] for u in _unexplained(noise + wave, theta_m, torque)] == ["order"]
    assert [u["kind"] for u in _unexplained(noise + shape, theta_m, torque)] == ["shape"]
    # white noise: nothing (several draws)
    for seed in (1, 2):
        r = ARCSEC * np.random.default_rng(seed).standard_normal(n)
        assert _unexplained(r, theta_m, torque) == []


# -- stability selection -----------------------------------------------------------------------

BLOCK, N_BLOCKS, N_FOLDS = 200, 10, 5
# one candidate group of three columns, each on a pair of blocks (slopes on the pair): a pair
# with equal slopes helps when its blocks are in different folds (each predicts the other), one
# with opposite slopes hurts three times as much then; a pair in one fold does nothing (no
# training sample). The standard deal (block b to fold b mod 5) splits both equal pairs and
# keeps the opposite pair (2, 7) together.
PAIRS = [((0, 1), (1.0, 1.0)), ((3, 4), (1.0, 1.0)), ((2, 7), (1.0, -1.0))]


def _helps(fold_of_block) -> bool:
    """The combinatorial rule: the opposite pair shares a fold and an equal pair does not."""
    same = [fold_of_block[p] == fold_of_block[q] for (p, q), _ in PAIRS]
    return bool(same[2] and not (same[0] and same[1]))


def test_a_candidate_that_helps_only_under_one_fold_deal_is_not_eligible():
    rng = np.random.default_rng(5)
    n = BLOCK * N_BLOCKS
    blocks = np.repeat(np.arange(N_BLOCKS), BLOCK)
    a = np.ones((n, 1))
    genuine = rng.standard_normal((n, 1))
    spurious = np.zeros((n, len(PAIRS)))
    y = 0.5 * genuine[:, 0] + rng.standard_normal(n)
    for j, (pair, slopes) in enumerate(PAIRS):
        for b, s in zip(pair, slopes):
            u = rng.standard_normal(BLOCK)
            spurious[blocks == b, j] = u
            y[blocks == b] += s * u
    stats = block_statistics(a, [genuine, spurious], y, blocks)
    standard = np.arange(N_BLOCKS) % N_FOLDS
    total, per_fold = fold_gains(stats, standard, N_FOLDS)
    deals = resampled_assignments(N_BLOCKS, N_FOLDS, 20, seed=0)
    resampled = [fold_gains(stats, d, N_FOLDS)[0] for d in deals]
    options = DiscoverOptions()
    scored = [
        Scored(
            types.SimpleNamespace(key=key),
            float(total[i]),
            per_fold[i],
            True,
            np.asarray([r[i] for r in resampled]),
        )
        for i, key in enumerate(["genuine", "spurious"])
    ]
    ranked = rank(scored, options.min_gain)
    stability = {r.candidate.key: r.stability for r in ranked}
    # the spurious group's standard gain passes min_gain: only stability can reject it
    assert _helps(standard) and total[1] >= 2 * options.min_gain, total
    expected = np.mean([_helps(d) for d in deals])
    assert stability["spurious"] == pytest.approx(expected, abs=0.051), (stability, expected)
    assert stability["spurious"] < options.min_stability
    assert stability["genuine"] == 1.0 and total[0] >= 2 * options.min_gain
    assert [r.candidate.key for r in eligible(ranked, options)] == ["genuine"]


# -- fold blocks -------------------------------------------------------------------------------


def _ar1(n, phi, seed):
    e = np.random.default_rng(seed).standard_normal(n)
    return scipy.signal.lfilter([1.0], [1.0, -phi], e)


def test_fold_blocks_are_no_shorter_than_the_correlation_time_and_never_cross_a_gap():
    phi = 0.97  # correlation length ceil(-1/ln phi) = 33 samples
    corr_true = math.ceil(-1.0 / math.log(phi))
    dt = 4e-3
    # segment lengths that are not multiples of the block (1.6 blocks round up to 2 shorter
    # ones, which must still be no shorter than the correlation time); the jumps: 3.5
    # periods is a gap, 2.5 periods is not
    lengths = [8000, 53, 6100, 4020]
    jumps = [3.5, 2.5, 10.0]
    t = [np.arange(lengths[0]) * dt]
    for m, jump in zip(lengths[1:], jumps):
        t.append(t[-1][-1] + jump * dt + np.arange(m) * dt)
    t = np.concatenate(t)
    starts = segment_starts(t)
    edges = np.cumsum(lengths)[:-1]
    assert np.flatnonzero(starts).tolist() == [0, edges[0], edges[2]], "gap over 3 periods"
    assert GAP_FACTOR == 3.0
    r = _ar1(t.size, phi, 3)
    length, note = cv_block_length(r, starts, 5, 10)
    assert note is None
    corr = correlation_length(r, starts)
    assert abs(corr - corr_true) <= 0.1 * corr_true and length >= corr
    blocks = contiguous_blocks(starts, length)
    seg = np.cumsum(starts) - 1
    for b in np.unique(blocks):
        idx = np.flatnonzero(blocks == b)
        assert np.all(np.diff(idx) == 1)
        assert np.unique(seg[idx]).size == 1, "a block straddles a gap"
        whole = idx.size == np.sum(seg == seg[idx[0]])
        # no shorter than the correlation time (and 3/4 of the length asked for), unless the
        # block is its whole segment
        assert (idx.size >= corr and idx.size >= 0.75 * length) or whole, (b, idx.size)
    # a shorter record (under MAX_BLOCKS correlation lengths), where the correlation length
    # sets the blocks; its 120-sample segment is 1.8 correlation lengths
    starts = np.zeros(6000, bool)
    starts[[0, 3000, 3120]] = True
    r = _ar1(starts.size, phi, 5)
    length, _ = cv_block_length(r, starts, 5, 10)
    corr = correlation_length(r, starts)
    assert -(-starts.size // MAX_BLOCKS) < corr < 120 / 1.5, corr
    blocks = contiguous_blocks(starts, length)
    seg = np.cumsum(starts) - 1
    for b in np.unique(blocks):
        idx = np.flatnonzero(blocks == b)
        assert idx.size >= corr or idx.size == np.sum(seg == seg[idx[0]]), (b, idx.size, corr)


def test_a_record_too_short_for_its_correlation_time_is_said_loudly():
    # 600 samples, 5 folds: two blocks per fold leave 60-sample blocks, the residual's
    # correlation length is ~100 (phi = 0.99)
    r = _ar1(600, 0.99, 4)
    starts = np.r_[True, np.zeros(599, bool)]
    corr = correlation_length(r, starts)
    assert corr > 60
    length, note = cv_block_length(r, starts, 5, 10)
    assert length == 60
    assert note is not None and note.startswith("warning:") and "shorter than the correl" in note
    # only the requested minimum capped, blocks still longer than the correlation: no warning
    white = np.random.default_rng(4).standard_normal(600)
    length, note = cv_block_length(white, starts, 5, 200)
    assert length == 60 and note is not None and not note.startswith("warning")


# -- the 1/3-period rule -----------------------------------------------------------------------


def _library_orders(period_fraction: float) -> list[str]:
    n = 4000
    rng = np.random.default_rng(6)
    t = np.linspace(0.0, 1.0, n)
    span = 2 * np.pi * period_fraction
    theta_l = span * (t - 0.5)  # one slow sweep, no angle gap
    ratio = JOINT.ratio
    z = np.zeros(n)
    sig = Signals(
        twist=jnp.asarray(z),
        current=jnp.asarray(z),
        theta_m=jnp.asarray(ratio * theta_l),
        theta_l=jnp.asarray(theta_l),
        omega_m=jnp.asarray(z + ratio * span),
        omega_l=jnp.asarray(z + span),
        extras={},
    )
    options = LibraryOptions(families=("harmonic:theta_l",))
    cands, _ = build_library(
        sig,
        300.0 * np.sin(2 * np.pi * 3 * t),
        rng.standard_normal(n),
        ComplianceModel.paper(JOINT),
        options=options,
    )
    return sorted({c.key for c in cands})


def test_order_one_of_the_output_angle_is_offered_from_a_third_of_a_period():
    covered = _library_orders(0.36)
    assert "harmonic:theta_l:1" in covered, covered
    short = _library_orders(0.30)
    assert "harmonic:theta_l:1" not in short, short
    assert "harmonic:theta_l:2" in short  # 0.6 of order 2's period


# -- the loop: TEST never chooses, `unexplained` in report.json, the cap note ------------------

EFFECTS = [("coulomb_l", 8 * ARCSEC, 0.05), ("harmonic_m", 3.3, 4 * ARCSEC)]
# the motor-angle harmonic has no name in this vocabulary: what the loop leaves unexplained
OPTIONS = DiscoverOptions(
    max_effects=2,
    library=LibraryOptions(
        families=tuple(f for f in LibraryOptions().families if f != "harmonic:theta_m")
    ),
)


@pytest.fixture(scope="module")
def train():
    return synthetic_recording(11, EFFECTS, n=8000)


@pytest.fixture(scope="module")
def first(train):
    test = synthetic_recording(12, EFFECTS, n=3000)
    return test, discover(train, test, JOINT, OPTIONS)


def _choices(res):
    rec = res.aux
    return dict(
        effects=rec.effects,
        cv=[rec.baseline_cv_torque_rms, rec.baseline_cv_twist_rms_arcsec]
        + [x for s in rec.steps for x in (s.cv_torque_rms, s.cv_twist_rms_arcsec)],
        gains=[(s.cv_gain, s.fold_gains, s.stability) for s in rec.steps],
        coef=np.asarray(res.value.coef).tolist(),
        block=rec.cv_block_samples,
        ranking=rec.final_ranking,
        unexplained=rec.unexplained,
    )


def test_test_is_never_used_to_choose(train, first):
    test, res = first
    assert res.aux.effects and res.aux.effects[0] == "coulomb:omega_l", res.aux.final_ranking
    # another draw and length, whose Coulomb friction has the opposite sign: on it the step
    # TRAIN chose makes the error worse, so any use of TEST to choose would drop it
    flipped = [("coulomb_l", -8 * ARCSEC, 0.05)] + EFFECTS[1:]
    other = synthetic_recording(13, flipped, n=2500)
    noise = np.random.default_rng(14).normal(0.0, 100.0, test.t.size)
    garbage = eqx.tree_at(lambda r: r.torque, test, test.torque * 0 + noise)
    for new_test in (other, garbage):
        res2 = discover(train, new_test, JOINT, OPTIONS)
        assert _choices(res2) == _choices(res)
        assert res2.aux.baseline.rms != res.aux.baseline.rms
        assert res2.aux.final.rms != res.aux.final.rms
        if new_test is other:
            assert res2.aux.steps[0].test.rms > res2.aux.baseline.rms


def test_report_json_lists_what_the_loop_leaves_unexplained(first, tmp_path):
    _, res = first
    write_report(res, tmp_path / "out", figures=False)
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    orders = [u for u in rep["unexplained"] if u["kind"] == "order"]
    assert [u["signal"] for u in orders] == ["theta_m"], rep["unexplained"]
    assert abs(orders[0]["order"] - 3.3) < 0.05
    np.testing.assert_allclose(orders[0]["amplitude_arcsec"], 4.0, rtol=0.25)
    assert "harmonic:theta_m" not in " ".join(rep["effects"])


def test_the_loop_reports_capped_fold_blocks_in_its_notes():
    # 1000 TRAIN samples, 5 folds: the 200-sample default blocks would leave fewer than two
    # per fold; the loop caps them at 100 and says so (a white residual: no warning)
    train = synthetic_recording(21, [], n=1000)
    res = discover(train, train, JOINT, DiscoverOptions(max_effects=0))
    assert res.aux.cv_block_samples == 100
    capped = [n for n in res.aux.notes if "cross-validation blocks of 100 samples" in n]
    assert len(capped) == 1 and "no shorter than the residual's correlation length" in capped[0]
    corr = correlation_length(res.aux.train_residual_final)
    assert corr <= 100


def test_the_speed_instrument_leaves_out_the_samples_the_backward_difference_reads():
    # instrument_speed at k is free of the angle's noise at k and k-1 (the two samples of the
    # backward difference at k), exact for a line, and never reads across a segment's start
    from hdjax.discover._uncertainty import instrument_speed

    rng = np.random.default_rng(4)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.8e-3, 1.2e-3, 199)])  # jittered time stamps
    starts = np.zeros(200, bool)
    starts[[0, 120]] = True
    theta = 3.0 + 2.5 * t
    speed = instrument_speed(t, theta, starts)
    np.testing.assert_allclose(speed, 2.5, rtol=1e-9)
    for k in (1, 30, 119, 121, 199):
        bumped = theta.copy()
        bumped[k] += 1e-3
        moved = np.flatnonzero(np.abs(instrument_speed(t, bumped, starts) - speed) > 1e-9)
        assert k not in moved and k + 1 not in moved, (k, moved)
        assert np.all(np.isin(moved, np.arange(200)[starts.cumsum() == starts.cumsum()[k]]))
        assert moved.size, k  # the neighbours do read it
