"""Experiment files: parsing (line and column), validation, did-you-mean, resolved dumps."""

import tomllib

import pytest

from hdjax import ConfigError
from hdjax.cli import main
from hdjax.config import apply_setting, dumps_toml, load_experiment, parse_value, resolve

MINIMAL = "[joint]\nratio = 160\nrated_torque = 400\n"


def _write(tmp_path, text, name="exp.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_defaults_filled_and_joint_resolved(tmp_path):
    exp = load_experiment(_write(tmp_path, MINIMAL))
    assert exp["model"]["poly_order"] == 6  # the paper's eq. (8)
    assert exp["model"]["n_segments"] == 5  # the paper's eq. (7)
    assert exp["model"]["fourier_order"] == 3  # the paper's eq. (9)
    assert exp["joint"] == {"ratio": 160, "rated_torque": 400, "twist_sign": 1.0, "name": "joint"}
    assert exp.base_dir == tmp_path.resolve()


def test_parse_error_names_line_and_column(tmp_path, capsys):
    p = _write(tmp_path, MINIMAL + "[model]\npoly_order = = 4\n")
    assert main(["run", str(p), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    # line 5, column 14 of the file: the second '='
    assert f"{p}:5:14:" in err and "TOML syntax error" in err
    assert not (tmp_path / "o").exists()


def test_unknown_key_did_you_mean(tmp_path, capsys):
    p = _write(tmp_path, MINIMAL + "[model]\npoly_ordr = 4\n")
    assert main(["run", str(p)]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'poly_ordr' in [model]" in err and "did you mean 'poly_order'" in err


def test_unknown_table_did_you_mean(tmp_path):
    with pytest.raises(ConfigError, match=r"unknown table \[modle\].*did you mean 'model'"):
        load_experiment(_write(tmp_path, MINIMAL + "[modle]\npoly_order = 4\n"))


def test_bad_values_are_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"poly_order must be an integer"):
        load_experiment(_write(tmp_path, MINIMAL + "[model]\npoly_order = 2.5\n"))
    with pytest.raises(ConfigError, match=r"kinematic must be one of .*did you mean 'paper'"):
        load_experiment(_write(tmp_path, MINIMAL + '[model]\nkinematic = "papr"\n'))
    with pytest.raises(ConfigError, match=r"missing required key 'rated_torque'"):
        load_experiment(_write(tmp_path, "[joint]\nratio = 160\n"))
    with pytest.raises(ConfigError, match=r"no \[joint\] table"):
        load_experiment(_write(tmp_path, "[model]\npoly_order = 3\n"))
    with pytest.raises(ConfigError, match=r"kind = \"files\" needs train"):
        load_experiment(_write(tmp_path, MINIMAL + '[data]\nkind = "files"\n'))


def test_missing_config_file(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.toml")]) == 2
    assert "nope.toml: no such experiment file" in capsys.readouterr().err


def test_overrides_and_values():
    cfg = resolve(tomllib.loads(MINIMAL))
    assert apply_setting(cfg, "model.poly_order", 3)["model"]["poly_order"] == 3
    assert apply_setting(cfg, "network.width", 7)["network"]["hidden"] == [7]
    assert apply_setting(cfg, "network.depth", 3)["network"]["hidden"] == [20, 20, 20]
    with pytest.raises(ConfigError, match=r"unknown setting 'model.poly_oder'.*'model.poly_order'"):
        apply_setting(cfg, "model.poly_oder", 3)
    assert parse_value("4") == 4 and parse_value("[1, 2]") == [1, 2]
    assert parse_value("true") is True and parse_value("adam") == "adam"


def test_set_option_through_cli(tmp_path, capsys):
    p = _write(tmp_path, MINIMAL)
    assert main(["run", str(p), "--set", "model.poly_ordr=3"]) == 2
    assert "did you mean 'model.poly_order'" in capsys.readouterr().err


def test_resolved_dump_round_trips(tmp_path):
    exp = load_experiment(_write(tmp_path, MINIMAL + '[data]\ntest = {a = "x.csv"}\n'))
    text = dumps_toml(dict(exp), header="resolved\nsecond line")
    again = resolve(tomllib.loads(text))
    assert again == dict(exp)


def test_a_model_key_the_kinematic_form_ignores_is_refused_naming_the_form():
    # `harmonic_orders_m = [2]` under the default kinematic = "paper" was silently ignored
    doc = {"joint": {"ratio": 160, "rated_torque": 400}, "model": {"harmonic_orders_m": [2.0]}}
    with pytest.raises(
        ConfigError, match='harmonic_orders_m: read only with kinematic = "harmonic"'
    ):
        resolve(doc)
    doc["model"]["kinematic"] = "harmonic"
    assert resolve(doc)["model"]["harmonic_orders_m"] == [2.0]
    doc = {"joint": {"ratio": 160, "rated_torque": 400}, "model": {"kinematic": "none"}}
    doc["model"]["fourier_order"] = 1
    with pytest.raises(ConfigError, match='set kinematic = "paper" to use it, or remove'):
        resolve(doc)
    # a resolved config lists every key at its default: it is accepted as it is
    doc["model"]["fourier_order"] = resolve({"joint": doc["joint"]})["model"]["fourier_order"]
    again = resolve(resolve(doc))
    assert again["model"]["kinematic"] == "none"
