"""The [joint] table."""

import pytest

import hdjax


def write(tmp_path, text):
    p = tmp_path / "exp.toml"
    p.write_text(text)
    return p


def test_load_joint(tmp_path):
    p = write(
        tmp_path,
        "[joint]\nratio = 101\nrated_torque = 150.0\ntwist_sign = -1\n"
        'encoder_bits_motor = 24\nname = "j3"\n',
    )
    j = hdjax.load_joint(p)
    assert (j.ratio, j.rated_torque, j.twist_sign, j.encoder_bits_motor, j.name) == (
        101,
        150.0,
        -1,
        24,
        "j3",
    )
    assert hdjax.Joint.from_dict(j.to_dict()) == j
    assert "current_limit" not in j.to_dict()


@pytest.mark.parametrize(
    "body, match",
    [
        ("rated_torque = 10\n", r"\[joint\]: missing required key 'ratio'"),
        ("ratio = 0\nrated_torque = 10\n", "ratio must be a positive finite number, got 0"),
        ("ratio = -101\nrated_torque = 10\n", "ratio must be a positive finite number, got -101"),
        ('ratio = "101"\nrated_torque = 10\n', "ratio must be a number"),
        (
            "ratio = 101\nrated_torque = 10\nratoi = 3\n",
            r"unknown key 'ratoi' \(did you mean 'ratio'\?\)",
        ),
        ("ratio = 101\nrated_torque = 10\ntwist_sign = 2\n", "twist_sign must be 1 or -1"),
        (
            "ratio = 101\nrated_torque = 10\nencoder_bits_load = 64\n",
            "encoder_bits_load must be an integer in 1..40",
        ),
    ],
)
def test_bad_joint_table(tmp_path, body, match):
    p = write(tmp_path, "[joint]\n" + body)
    with pytest.raises(hdjax.ConfigError, match=match) as err:
        hdjax.load_joint(p)
    if "missing" in match or "unknown" in match:
        assert str(p) in str(err.value)  # names the file


def test_bad_files(tmp_path):
    with pytest.raises(hdjax.ConfigError, match="no such file"):
        hdjax.load_joint(tmp_path / "none.toml")
    with pytest.raises(hdjax.ConfigError, match=r"no \[joint\] table"):
        hdjax.load_joint(write(tmp_path, "[data]\npath = 'x'\n"))
    with pytest.raises(hdjax.ConfigError, match="not valid TOML"):
        hdjax.load_joint(write(tmp_path, "[joint\nratio = 1\n"))
