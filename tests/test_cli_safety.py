"""The user's files survive every command: outputs never replace inputs, the current directory
or a folder hdjax did not write, whatever the flags (checked before any work)."""

import hashlib
import os

import pytest

from hdjax import Joint, save_csv
from hdjax.cli import main
from hdjax.pipelines import synthetic_recording

from .helpers import tiny_config

CONFIG = tiny_config("tiny", 'kind = "files"\ntrain = ["data.csv"]\nsplit = 0.3\n')


@pytest.fixture
def proj(tmp_path, monkeypatch):
    """A user's project folder: a config and its data, and the current directory above it."""
    d = tmp_path / "proj"
    d.mkdir()
    (d / "cfg.toml").write_text(CONFIG)
    rec = synthetic_recording(Joint(ratio=160.0, rated_torque=400.0), 600, seed=1)
    save_csv(rec, d / "data.csv")
    monkeypatch.chdir(tmp_path)
    return d


def _digest(root):
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("command", ["run", "sweep"])
@pytest.mark.parametrize("out", ["proj", ".", "proj/data.csv", "proj/cfg.toml", "proj/data.csv/x"])
def test_run_and_sweep_never_replace_their_inputs(proj, capsys, command, out):
    before = _digest(proj.parent)
    argv = [command, "proj/cfg.toml", "--out", out, "--overwrite", "-q"]
    if command == "sweep":
        argv += ["--values", "1,2"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hdjax: error: ")
    assert _digest(proj.parent) == before
    assert sorted(os.listdir(proj.parent)) == ["proj"]


def test_estimate_never_replaces_its_inputs(proj, capsys):
    assert main(["run", "proj/cfg.toml", "--out", "res", "-q"]) == 0
    capsys.readouterr()
    before = _digest(proj.parent)
    base = ["estimate", "--model", "res", "--data", "proj/data.csv", "-q", "--overwrite"]
    for out in ("proj/data.csv", "res/model.json", "res", "proj", "proj/cfg.toml"):
        assert main(base + ["--out", out]) == 2, out
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"hdjax: error: {out}: "), err
    # a file hdjax did not write is not replaced either
    (proj.parent / "notes.csv").write_text("my notes\n")
    before["notes.csv"] = hashlib.sha256(b"my notes\n").hexdigest()
    assert main(base + ["--out", "notes.csv"]) == 2
    assert "not a file hdjax wrote" in capsys.readouterr().err
    assert _digest(proj.parent) == before
    # --model DIR reads DIR/model.json; an earlier estimate is replaced under --overwrite
    assert main(base + ["--out", "est.csv"]) == 0
    assert main(base + ["--out", "est.csv"]) == 0
    assert (proj.parent / "est.csv").read_text().startswith("t,torque_estimate")


def test_overwrite_replaces_only_an_hdjax_result(proj, capsys):
    mine = proj.parent / "mine"
    mine.mkdir()
    (mine / "paper.tex").write_text("x")
    assert main(["run", "proj/cfg.toml", "--out", "mine", "--overwrite", "-q"]) == 2
    err = capsys.readouterr().err
    assert "not an hdjax result folder (it holds paper.tex)" in err
    assert main(["run", "proj/cfg.toml", "--out", "res", "-q"]) == 0
    assert main(["run", "proj/cfg.toml", "--out", "res", "-q"]) == 2
    assert main(["run", "proj/cfg.toml", "--out", "res", "-q", "--overwrite"]) == 0
    (proj.parent / "res" / "keep.txt").write_text("mine")
    assert main(["run", "proj/cfg.toml", "--out", "res", "-q", "--overwrite"]) == 2
    assert (proj.parent / "res" / "keep.txt").read_text() == "mine"
    assert sorted(os.listdir(proj.parent)) == ["mine", "proj", "res"]


def test_failed_sweep_leaves_no_partial_folder(proj, capsys):
    argv = ["sweep", "proj/cfg.toml", "--out", "sw", "-q", "--setting", "model.poly_order"]
    assert main(argv + ["--values", "1,2", "--set", "data.train=['missing.csv']"]) == 2
    assert sorted(os.listdir(proj.parent)) == ["proj"]
    assert main(argv + ["--values", ""]) == 2
    assert "no values" in capsys.readouterr().err


def test_a_full_disk_is_one_line_and_leaves_no_staging(proj, capsys, monkeypatch):
    import errno

    from hdjax import _io

    real = _io.atomic_write_bytes

    def full(path, data):
        if str(path).endswith("metrics.json"):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(_io, "atomic_write_bytes", full)
    assert main(["run", "proj/cfg.toml", "--out", "res", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no space left on device; the disk is full" in err, err
    assert sorted(os.listdir(proj.parent)) == ["proj"]


def test_a_folder_without_write_permission_is_refused_before_work(proj, capsys, monkeypatch):
    # (root may write anywhere, so the permission answer is simulated where it is asked)
    from hdjax.report import _outputs

    monkeypatch.setattr(_outputs.os, "access", lambda p, mode: False)
    assert main(["run", "proj/cfg.toml", "--out", "res", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hdjax: error: res: cannot write in ") and "permission" in err
    assert sorted(os.listdir(proj.parent)) == ["proj"]
