"""The Recording pytree and make_recording's validation (issue 2, bad input)."""

import jax
import numpy as np
import pytest

import hdjax
from tests.helpers import sim_recording


def _cols(n=20):
    t = np.arange(n) * 0.004
    return dict(t=t, theta_m=101 * 0.1 * np.sin(t), theta_l=0.1 * np.sin(t), current=np.cos(t))


def test_fields_dtypes_and_pytree():
    rec = sim_recording(50)
    assert rec.n_samples == 50 and rec.has_torque
    assert rec.column_names == ("t", "theta_m", "theta_l", "current", "torque", "temperature")
    for name in rec.column_names:
        assert rec.column(name).dtype == np.float64
    leaves = jax.tree_util.tree_leaves(rec)
    assert len(leaves) == 6
    doubled = jax.tree_util.tree_map(lambda x: 2 * x, rec)
    np.testing.assert_allclose(np.asarray(doubled.t), 2 * np.asarray(rec.t))
    assert jax.jit(lambda r: r.theta_l.sum())(rec) == pytest.approx(float(rec.theta_l.sum()))


def test_select_split_with_torque_and_extras():
    rec = sim_recording(100)
    a, b = rec.split(0.25)
    assert (a.n_samples, b.n_samples) == (25, 75) and float(b.t[0]) == float(rec.t[25])
    r2 = rec.with_torque(np.zeros(100)).with_extras(pressure=np.ones(100))
    assert float(r2.torque.sum()) == 0.0 and "pressure" in r2.extras
    assert rec.to_numpy()["temperature"].shape == (100,)
    no_torque = sim_recording(10, with_torque=False)
    assert not no_torque.has_torque and "torque" not in no_torque.column_names
    with pytest.raises(hdjax.DataError, match="has no 'torque' column"):
        no_torque.column("torque")
    with pytest.raises(hdjax.DataError, match="no column 'temp'"):
        rec.column("temp")
    with pytest.raises(hdjax.DataError, match="split fraction"):
        rec.split(1.5)


def test_non_numeric_column():
    c = _cols()
    c["current"] = ["a"] * 20
    with pytest.raises(hdjax.DataError, match="src: column 'current' is not numeric"):
        hdjax.make_recording(**c, source="src")


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf(bad):
    c = _cols()
    c["theta_l"] = c["theta_l"].copy()
    c["theta_l"][7] = bad
    with pytest.raises(
        hdjax.DataError, match=r"column 'theta_l' has 1 NaN/inf value\(s\), first at row 7"
    ):
        hdjax.make_recording(**c, source="x.csv")


def test_columns_of_different_lengths():
    c = _cols()
    c["current"] = c["current"][:-1]
    with pytest.raises(hdjax.DataError, match=r"different lengths \(.*current=19"):
        hdjax.make_recording(**c)


@pytest.mark.parametrize(
    "t, what, row",
    [([0.0, 0.1, 0.1, 0.2], "duplicated", 2), ([0.0, 0.2, 0.1, 0.3], "decreasing", 2)],
)
def test_time_not_strictly_increasing(t, what, row):
    n = len(t)
    with pytest.raises(
        hdjax.DataError, match=f"'t' must be strictly increasing, but it is {what} at row {row}"
    ):
        hdjax.make_recording(t, np.zeros(n), np.zeros(n), np.zeros(n), source="log.csv")


def test_too_few_samples_and_shadowing_extras():
    with pytest.raises(hdjax.DataError, match="at least 2 samples"):
        hdjax.make_recording([0.0], [0.0], [0.0], [0.0])
    c = _cols()
    with pytest.raises(hdjax.DataError, match="extra column 'torque' shadows a core column"):
        hdjax.make_recording(**c, extras={"torque": np.zeros(20)})


def test_degrees_warn():
    t = np.arange(200) * 0.01
    theta_l_deg = 90.0 * np.sin(t)  # degrees: a span of ~150 "rad"
    with pytest.warns(hdjax.UnitWarning, match="theta_l spans .* looks like degrees"):
        hdjax.make_recording(t, 101 * theta_l_deg, theta_l_deg, np.zeros(200), source="deg.csv")
    # the same motion in radians does not warn (warnings are errors in this suite)
    hdjax.make_recording(t, 101 * np.radians(theta_l_deg), np.radians(theta_l_deg), np.zeros(200))
    # and the check can be turned off
    hdjax.make_recording(t, theta_l_deg, theta_l_deg, np.zeros(200), check_units=False)
