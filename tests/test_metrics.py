"""Error metrics: RMS, maximum, error rate in % of rated torque (Song et al. Fig. 17)."""

import numpy as np
import pytest

import hdjax


def test_known_values():
    ref = np.zeros(4)
    est = np.array([1.0, -1.0, 3.0, -3.0])
    m = hdjax.error_metrics(est, ref, rated_torque=50.0)
    assert m.rms == pytest.approx(np.sqrt(5.0)) and m.max == 3.0 and m.bias == 0.0
    assert m.rms_pct == pytest.approx(100 * np.sqrt(5.0) / 50) and m.max_pct == pytest.approx(6.0)
    assert m.n == 4 and m.as_dict()["n"] == 4
    masked = hdjax.error_metrics(est, ref, 50.0, mask=[True, True, False, False])
    assert masked.rms == 1.0 and masked.n == 2


@pytest.mark.parametrize(
    "args, match",
    [
        ((np.zeros(3), np.zeros(4), 1.0), "shape"),
        ((np.zeros(3), np.zeros(3), 0.0), "rated_torque must be positive"),
        ((np.array([np.nan, 0.0]), np.zeros(2), 1.0), "NaN or inf"),
    ],
)
def test_bad_input(args, match):
    with pytest.raises(hdjax.DataError, match=match):
        hdjax.error_metrics(*args)
    with pytest.raises(hdjax.DataError, match="no samples"):
        hdjax.error_metrics(np.zeros(2), np.zeros(2), 1.0, mask=[False, False])
