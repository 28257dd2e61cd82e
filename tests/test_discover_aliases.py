"""Aliases: candidates a record cannot tell apart (hdjax.discover._aliases).

The principal-angle cosine against spans built to be equal, orthogonal or of different widths,
and on LARA8 joint 3 (one sweep of a stiff joint): Coulomb friction at the motor and at the
output are one column there, a harmonic of the motor angle and one of the output angle are not.
"""

import numpy as np
import pytest

import hdjax
from hdjax.discover._aliases import find_aliases, span_cosine
from hdjax.effects import Coulomb, Harmonics

from .conftest import REPO


def test_span_cosine_of_equal_orthogonal_and_unequal_spans():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((500, 2))
    mix = np.array([[2.0, -1.0], [0.5, 3.0]])  # invertible: the same span
    assert span_cosine(a, a @ mix + 7.0) == pytest.approx(1.0, abs=1e-12)
    # a direction orthogonal to both of a's (after centring): cosine 0
    q, _ = np.linalg.qr(np.column_stack([a - a.mean(0), rng.standard_normal(500)]))
    b = np.column_stack([a[:, 0], q[:, 2]])
    assert span_cosine(a, b) == pytest.approx(0.0, abs=1e-12)
    assert span_cosine(a, a[:, :1]) == 0.0  # widths differ: not compared
    assert span_cosine(a, np.column_stack([a[:, 0], np.ones(500)])) == 0.0  # a constant column


def test_motor_and_output_coulomb_are_aliases_on_lara8(lara8_dir):
    from hdjax._formats import load_recording
    from hdjax._io import ColumnMap, read_toml

    cfg = read_toml(REPO / "experiments" / "lara8_discover.toml")
    joint = hdjax.Joint(**{k: cfg["joint"][k] for k in ("ratio", "rated_torque", "twist_sign")})
    columns = ColumnMap.from_dict({"columns": cfg["data"]["columns"]})
    rec = load_recording(lara8_dir / "validate.csv", columns)
    sig = hdjax.signals(rec, joint)
    torque = np.asarray(rec.torque)
    wm = float(np.sqrt(np.mean(np.asarray(sig.omega_m) ** 2)))
    motor = Coulomb("omega_m", 0.05 * wm)
    others = [
        ("coulomb:omega_l", Coulomb("omega_l", 0.05 * wm / joint.ratio)),
        ("harmonic:theta_l:2", Harmonics("theta_l", (2.0,))),
    ]
    found = find_aliases(motor, others, sig, torque)
    assert [a["key"] for a in found] == ["coulomb:omega_l"], found
    assert found[0]["cosine"] >= 0.99
    # two harmonics of the two angles: the sweep turns the motor 101 times as far
    assert find_aliases(Harmonics("theta_m", (2.0,)), others[1:], sig, torque) == []
