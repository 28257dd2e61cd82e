"""`hdjax export`: the files it writes, and bad input answered with one line, exit code 2 and
nothing written (the output rules of every command, see docs/cli-safety.md)."""

import dataclasses
from typing import ClassVar

import numpy as np
import pytest

import hdjax
from hdjax import effects, export
from hdjax.cli import main
from hdjax.compliance import ComplianceModel
from hdjax.modelfile import save_model

from .helpers import JOINT, sim_recording
from .test_export import MODELS, NoCTerm, _network, _with_truth


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("export-models")
    save_model(
        d / "paper.json", JOINT, compliance=MODELS["paper_shared"](), network=_network(False)
    )
    save_model(d / "smoothed.json", JOINT, compliance=MODELS["smoothed_causal"]())
    (d / "run").mkdir()
    save_model(d / "run" / "model.json", JOINT, compliance=MODELS["every_effect"]())
    return d


def _one_error_line(capsys) -> str:
    # progress lines (`[  0.1s] ...`) may come first; the error is one line, and the last
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("[")]
    assert len(err) == 1 and err[0].startswith("hdjax: error: "), err
    return err[0]


def _nothing_written(out):
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")]


def test_export_writes_the_estimator_its_readme_vectors_and_check(models, tmp_path):
    out = tmp_path / "c"
    assert main(["export", "--model", str(models / "paper.json"), "--out", str(out), "-q"]) == 0
    names = {p.name for p in out.iterdir()}
    assert names == set(hdjax.export.FILES) | {".hdjax-result"}
    readme = (out / "README.md").read_text()
    assert "hdjax_init(&est);" in readme and "hdjax_step(&est, &x)" in readme
    assert "HDJAX_OUT_OF_RANGE" in readme and "backward difference" in readme
    assert "typedef double hdjax_real;" in (out / "hdjax_estimator.h").read_text()
    rows = (out / "test_vectors.csv").read_text().splitlines()
    assert rows[0] == "t,theta_m,theta_l,current,torque_expected,flags_expected"
    assert len(rows) == 2001
    # the network of the same file, in single precision; a result folder names its model.json
    out = tmp_path / "net"
    argv = ["export", "--model", str(models / "paper.json"), "--out", str(out), "-q"]
    assert main(argv + ["--method", "network", "--precision", "single"]) == 0
    assert "typedef float hdjax_real;" in (out / "hdjax_estimator.h").read_text()
    assert "HDJAX_INPUT_OUTSIDE" in (out / "README.md").read_text()
    out = tmp_path / "fx"
    assert main(["export", "--model", str(models / "run"), "--out", str(out), "-q"]) == 0
    header = (out / "hdjax_estimator.h").read_text()
    assert "double extra[HDJAX_N_EXTRA]" in header and "[0] temperature" in header


def test_test_vectors_from_a_log_equal_hdjax_estimate_causal(models, tmp_path):
    rec = sim_recording(600, seed=3)
    hdjax.save_csv(rec, tmp_path / "log.csv")
    out = tmp_path / "c"
    argv = ["export", "--model", str(models / "run"), "--out", str(out), "--data"]
    assert main(argv + [str(tmp_path / "log.csv"), "--vectors", "500", "-q"]) == 0
    vectors = np.genfromtxt(out / "test_vectors.csv", delimiter=",", names=True)
    assert vectors.shape == (500,)
    np.testing.assert_array_equal(vectors["theta_m"], np.asarray(rec.theta_m)[:500])
    est = tmp_path / "est.csv"
    argv = ["estimate", "--model", str(models / "run"), "--data", str(tmp_path / "log.csv")]
    assert main(argv + ["--out", str(est), "--causal", "-q"]) == 0
    torque = np.genfromtxt(est, delimiter=",", names=True)["torque_estimate"][:500]
    np.testing.assert_array_equal(vectors["torque_expected"], torque)


def test_a_velocity_that_reads_ahead_is_refused_unless_its_causal_form_is_asked(
    models, tmp_path, capsys
):
    out = tmp_path / "c"
    argv = ["export", "--model", str(models / "smoothed.json"), "--out", str(out)]
    assert main(argv) == 2
    line = _one_error_line(capsys)
    assert 'velocity = "smoothed"' in line and "reads 5 samples ahead" in line
    assert "--causal" in line
    _nothing_written(out)
    assert main(argv + ["--causal", "-q"]) == 0
    assert "causal form of velocity" in (out / "README.md").read_text()


class NoCFamily(effects.AbstractFamily):
    """A user's family whose term has no C code."""

    name: ClassVar[str] = "no_c"
    terms: ClassVar[tuple] = (NoCTerm,)

    def candidates(self, ctx):
        return []


def test_a_term_without_c_code_is_refused_in_one_line_and_nothing_is_written(tmp_path, capsys):
    family = effects.register(NoCFamily())
    try:
        model = _with_truth(
            ComplianceModel.paper(JOINT, per_segment=False).with_effects(NoCTerm()), 5
        )
        save_model(tmp_path / "m.json", JOINT, compliance=model)
        out = tmp_path / "c"
        assert main(["export", "--model", str(tmp_path / "m.json"), "--out", str(out)]) == 2
    finally:
        effects.unregister(family)
    line = _one_error_line(capsys)
    assert "NoCTerm (noc:omega_m, effect family 'no_c') has no C code" in line
    _nothing_written(out)


COUNTS_CASES = {
    "counts_per_rev_zero": ["--counts-per-rev-m", "0", "--counts-per-rev-l", "4096"],
    "counts_per_rev_negative": ["--counts-per-rev-m", "4096", "--counts-per-rev-l", "-4096"],
    "counts_per_rev_fraction": ["--counts-per-rev-m", "2.5", "--counts-per-rev-l", "4096"],
    "counts_per_rev_word": ["--counts-per-rev-m", "4096", "--counts-per-rev-l", "many"],
    "counts_per_rev_empty": ["--counts-per-rev-m", "", "--counts-per-rev-l", "4096"],
    "counts_per_rev_too_large": ["--counts-per-rev-m", str(2**53 + 1), "--counts-per-rev-l", "1"],
    # the model's joint gives no encoder_bits_load: one option alone is refused
    "counts_per_rev_one_encoder": ["--counts-per-rev-m", "4096"],
}


@pytest.mark.parametrize(
    "case, expect",
    [
        ("network_missing", "holds no network; use --method model"),
        ("inside_input", "lies inside the input"),
        ("foreign_folder", "not an hdjax result folder"),
        ("no_model", "no such model file"),
        ("not_a_model", "not an hdjax model file"),
        ("columns_without_data", "give --data too"),
        ("counts_per_rev_zero", "--counts-per-rev-m must be a whole number of encoder counts"),
        ("counts_per_rev_negative", "--counts-per-rev-l must be a whole number"),
        ("counts_per_rev_fraction", "per revolution, 1 to 2^53 (e.g. 2097152 for a 21-bit"),
        ("counts_per_rev_word", "got 'many'"),
        ("counts_per_rev_empty", "--counts-per-rev-m must be a whole number"),
        ("counts_per_rev_too_large", "got '9007199254740993'"),
        ("counts_per_rev_one_encoder", "the load encoder's resolution is unknown"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(case, expect, models, tmp_path, capsys):
    out = tmp_path / "c"
    model = models / "run"
    extra = []
    if case == "network_missing":
        extra = ["--method", "network"]
    elif case == "inside_input":
        out = models / "run" / "c"
    elif case == "foreign_folder":
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    elif case == "no_model":
        model = tmp_path / "absent.json"
    elif case == "not_a_model":
        model = tmp_path / "other.json"
        model.write_text('{"a": 1}')
    elif case == "columns_without_data":
        extra = ["--columns", str(tmp_path / "map.toml")]
    elif case.startswith("counts_per_rev"):
        extra = COUNTS_CASES[case]
    assert main(["export", "--model", str(model), "--out", str(out), *extra]) == 2
    assert expect in _one_error_line(capsys)
    if case == "foreign_folder":
        assert [p.name for p in out.iterdir()] == ["notes.txt"]
    else:
        _nothing_written(out)


def test_overwrite_replaces_only_an_export(models, tmp_path):
    out = tmp_path / "c"
    argv = ["export", "--model", str(models / "paper.json"), "--out", str(out), "-q"]
    assert main(argv + ["--vectors", "10"]) == 0
    assert main(argv + ["--vectors", "20", "--overwrite"]) == 0
    assert len((out / "test_vectors.csv").read_text().splitlines()) == 21


def test_the_counts_calling_sequence_of_the_readme_compiles(tmp_path):
    if export.find_compiler() is None:
        pytest.skip("no C compiler (cc, gcc or clang) on PATH")
    # a joint with encoder resolutions: the estimator takes counts, 2^bits per revolution
    joint = dataclasses.replace(JOINT, encoder_bits_motor=23, encoder_bits_load=19)
    save_model(tmp_path / "m.json", joint, compliance=MODELS["every_effect"]())
    out = tmp_path / "c"
    argv = ["export", "--model", str(tmp_path / "m.json"), "--out", str(out), "-q"]
    assert main(argv + ["--vectors", "10"]) == 0
    header = (out / "hdjax_estimator.h").read_text()
    assert "#define HDJAX_COUNTS_PER_REV_M 8388608LL" in header
    assert "#define HDJAX_COUNTS_PER_REV_L 524288LL" in header
    readme = (out / "README.md").read_text()
    block = readme.split("From encoder counts")[1].split("```c\n")[1].split("```")[0]
    assert "hdjax_sample_from_counts(&x, t, counts_m, counts_l, current, &zero);" in block
    (out / "use.c").write_text(
        '#include "hdjax_estimator.h"\n'
        "double use(double t, long long counts_m, long long counts_l, double current,\n"
        "           double temperature, int first_sample);\n"
        "static hdjax_state est;\n"
        "double use(double t, long long counts_m, long long counts_l, double current,\n"
        "           double temperature, int first_sample)\n{\n" + block + "    return torque;\n}\n"
    )
    export.compile_c(
        out, ["hdjax_estimator.c", "use.c"], "libuse.so", extra=("-pedantic", "-shared", "-fPIC")
    )
    # --counts-per-rev-m/-l override the joint
    out = tmp_path / "c2"
    argv = ["export", "--model", str(tmp_path / "m.json"), "--out", str(out), "-q"]
    assert (
        main(argv + ["--vectors", "10", "--counts-per-rev-m", "1000", "--counts-per-rev-l", "7"])
        == 0
    )
    header = (out / "hdjax_estimator.h").read_text()
    assert "HDJAX_COUNTS_PER_REV_M 1000LL" in header and "HDJAX_COUNTS_PER_REV_L 7LL" in header
