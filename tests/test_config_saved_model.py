"""Saved models: round trip, corrupt files, incompatible versions, data that does not fit."""

import json

import jax
import numpy as np
import pytest

from hdjax import DataError, Joint, ModelMismatchError
from hdjax.compliance import ComplianceModel, calibrate_lstsq, estimate_torque
from hdjax.modelfile import check_compatible, load_model, save_model
from hdjax.pipelines import synthetic_recording

JOINT = Joint(ratio=160.0, rated_torque=400.0)


@pytest.fixture(scope="module")
def fitted():
    rec = synthetic_recording(JOINT, 3000, seed=1)
    model = ComplianceModel.paper(
        JOINT, poly_order=3, kinematic="none", per_segment=False, current_scale=10.0
    )
    return rec, calibrate_lstsq(model, rec).value


def test_round_trip_compliance_and_network(tmp_path, fitted):
    from hdjax.network import Network, make_layout

    rec, model = fitted
    net = Network(make_layout(kalman=True), (4, 3), key=jax.random.PRNGKey(2))
    path = save_model(tmp_path / "m.json", JOINT, compliance=model, network=net, meta={"seed": 5})
    saved = load_model(path)
    assert saved.joint == JOINT and saved.meta == {"seed": 5}
    np.testing.assert_array_equal(np.asarray(saved.compliance.coef), np.asarray(model.coef))
    a = np.asarray(estimate_torque(model, rec).torque)
    b = np.asarray(estimate_torque(saved.compliance, rec).torque)
    np.testing.assert_array_equal(a, b)  # float64 written with repr: exact
    for w0, w1 in zip(net.weights, saved.network.weights):
        np.testing.assert_array_equal(np.asarray(w0), np.asarray(w1))
    assert saved.network.layout == net.layout
    x = np.ones((2, 6))
    np.testing.assert_array_equal(np.asarray(net(x)), np.asarray(saved.network(x)))


def test_truncated_file_is_refused(tmp_path, fitted):
    path = save_model(tmp_path / "m.json", JOINT, compliance=fitted[1])
    path.write_text(path.read_text()[:-40])
    with pytest.raises(DataError, match="corrupt model file, not valid JSON"):
        load_model(path)


def test_edited_file_is_refused(tmp_path, fitted):
    path = save_model(tmp_path / "m.json", JOINT, compliance=fitted[1])
    d = json.loads(path.read_text())
    d["compliance"]["coef"][0] *= 2
    path.write_text(json.dumps(d))
    with pytest.raises(DataError, match="checksum mismatch"):
        load_model(path)


def test_incompatible_version_is_refused(tmp_path, fitted):
    path = save_model(tmp_path / "m.json", JOINT, compliance=fitted[1])
    d = json.loads(path.read_text())
    d["format_version"] = 99
    path.write_text(json.dumps(d))
    with pytest.raises(ModelMismatchError, match="format version 99 is incompatible"):
        load_model(path)


def test_other_ratio_is_refused(tmp_path, fitted):
    rec, model = fitted
    saved = load_model(save_model(tmp_path / "m.json", JOINT, compliance=model))
    with pytest.raises(ModelMismatchError, match="calibrated for ratio 160 but the data's joint"):
        check_compatible(saved, rec, Joint(ratio=100.0, rated_torque=400.0))
    other = synthetic_recording(Joint(ratio=100.0, rated_torque=400.0), 3000, seed=1)
    with pytest.raises(ModelMismatchError, match="moves 100 times the output angle"):
        check_compatible(saved, other)
    check_compatible(saved, rec, JOINT)  # the right data passes


def test_missing_feature_column_is_refused(tmp_path, fitted):
    from hdjax.compliance import ColumnTimesTorque

    rec, model = fitted
    warm = model.with_effects(ColumnTimesTorque(name="temperature", scale=100.0))
    saved = load_model(save_model(tmp_path / "m.json", JOINT, compliance=warm))
    with pytest.raises(ModelMismatchError, match="reads column\\(s\\) temperature"):
        check_compatible(saved, rec)
