"""Angle orders that TRAIN's gaps leave undetermined are not offered (`_library.bridges_gaps`).

A one-way sweep like LARA8's (298° of the output in 7.35 s, 4-ms samples) split into long
time blocks leaves whole angle ranges without a TRAIN sample; short blocks interleave. The
reference is the rule's closed form: order $K$ is offered iff $K g \\le \\pi/2$ for the widest
gap $g$, or the span holds at least ten periods.
"""

import math

import numpy as np
import pytest

from hdjax.discover._library import bridges_gaps, spectrum_orders, widest_gap

N = 101
T = np.arange(0.0, 7.35, 4e-3)
THETA_L = np.radians(-149.0) + np.radians(298.0) * (T / T[-1])
NAMED = [1.0, 2.0, 3.0, 4.0, 6.73, 10.87]


def _offered(theta, keep, named=NAMED, seed=0):
    residual = np.random.default_rng(seed).standard_normal(theta.size)
    orders, _ = spectrum_orders(
        theta[keep],
        residual[keep],
        signal="theta_l",
        order_range=(0.5, 12.0),
        named=named,
        existing=[],
        n_peaks=0,
    )
    return sorted(k for k, _ in orders)


@pytest.mark.parametrize("block_s", [0.5, 2.0])
def test_output_orders_follow_the_widest_gap_of_train(block_s):
    keep = np.floor(T / block_s).astype(int) % 2 == 0
    gap = widest_gap(THETA_L[keep])
    # the gap is one TEST block of the sweep
    np.testing.assert_allclose(gap, np.radians(298.0) * block_s / T[-1], rtol=0.02)
    span = float(np.ptp(THETA_L[keep]))
    expected = [k for k in NAMED if k * gap <= math.pi / 2 or k * span >= 20 * math.pi]
    assert _offered(THETA_L, keep) == expected
    if block_s == 2.0:
        assert expected == [1.0]  # 81° gaps: only once per output revolution is determined
    else:
        assert expected == NAMED[:4]  # 20° gaps: orders 6.73 and 10.87 (53°, 33° periods) out


def test_the_whole_sweep_and_many_motor_revolutions_keep_their_orders():
    every = np.ones(T.size, bool)
    assert _offered(THETA_L, every) == NAMED
    # the motor angle turns 83 times: its gaps are bridged by periodicity
    keep = np.floor(T / 2.0).astype(int) % 2 == 0
    theta_m = N * THETA_L
    assert widest_gap(theta_m[keep]) > 10.0
    assert all(
        bridges_gaps(k, float(np.ptp(theta_m[keep])), widest_gap(theta_m[keep])) for k in NAMED
    )
