"""Every command against a table of broken inputs, and against randomly corrupted files.

Per case: exit code 0 or 2, at most one line on stderr and no traceback, no file left that was
not there before (beside the declared output of a case that succeeds), and every input
byte-identical (compared by SHA-256). The cases run in-process and almost all are refused before
any JAX work; the few that succeed use a 600-sample recording.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from hdjax import Joint, save_csv
from hdjax.cli import main
from hdjax.pipelines import synthetic_recording

from .discover_data import synthetic_recording as discover_recording
from .helpers import tiny_config

CONFIG = tiny_config("tiny", 'kind = "files"\ntrain = ["data.csv"]\nsplit = 0.3\n')

SYNTHETIC = tiny_config("synth", 'kind = "synthetic"\nn_samples = 600\n')

JOINT = "[joint]\nratio = 160\nrated_torque = 400\n"
COLUMNS = '[data]\ncolumns = { t = "t" }\n'
LATIN1 = "temp_°C"


def _csv_text(cols: dict) -> str:
    names = list(cols)
    buf = io.StringIO()
    body = np.column_stack([cols[k] for k in names])
    np.savetxt(buf, body, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return buf.getvalue()


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    """A user's folder: proj/ (configs, data, joint, column map, discover logs) and res/ (a
    result of 'hdjax run' holding model.json)."""
    root = tmp_path_factory.mktemp("world")
    proj = root / "proj"
    proj.mkdir()
    joint = Joint(ratio=160.0, rated_torque=400.0)
    rec = synthetic_recording(joint, 600, seed=1)
    (proj / "cfg.toml").write_text(CONFIG)
    (proj / "synth.toml").write_text(SYNTHETIC)
    save_csv(rec, proj / "data.csv")
    save_csv(synthetic_recording(joint, 600, seed=2), proj / "new.csv")
    deg = rec.to_numpy()
    deg["theta_m"], deg["theta_l"] = np.degrees(deg["theta_m"]), np.degrees(deg["theta_l"])
    (proj / "deg.csv").write_text(_csv_text(deg))
    (proj / "joint.toml").write_text(JOINT)
    (proj / "columns.toml").write_text(COLUMNS)
    (proj / "sub").mkdir()
    (proj / "sub" / "keep.txt").write_text("the user's notes\n")
    train = discover_recording(1, [("harmonic_m", 2.0, 30 * 4.85e-6)], n=2000)
    test = discover_recording(2, [("harmonic_m", 2.0, 30 * 4.85e-6)], n=1000)
    save_csv(train, proj / "train.csv")
    save_csv(test, proj / "test.csv")
    (proj / "disc.toml").write_text(
        JOINT + '[data]\ntrain = "train.csv"\ntest = "test.csv"\n[discover]\nmax_effects = 1\n'
    )
    cwd = os.getcwd()
    os.chdir(root)
    try:
        assert main(["run", "proj/cfg.toml", "--out", "res", "-q"]) == 0
    finally:
        os.chdir(cwd)
    return root


def _digest(root: Path) -> dict[str, str]:
    out = {}
    for dirpath, dirnames, files in os.walk(root):
        for d in dirnames:
            out[Path(dirpath, d).relative_to(root).as_posix() + "/"] = "dir"
        for f in files:
            p = Path(dirpath, f)
            rel = p.relative_to(root).as_posix()
            if p.is_symlink():
                out[rel] = "-> " + os.readlink(p)
            else:
                out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@contextlib.contextmanager
def _inside(folder: Path):
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(cwd)


def _latin1(text: str) -> bytes:
    return text.encode("latin-1")


def _with_extra_latin1(path: Path) -> bytes:
    lines = path.read_text().splitlines()
    lines[0] += f",{LATIN1}"
    lines[1:] = [line + ",25" for line in lines[1:]]
    return _latin1("\n".join(lines) + "\n")


# A case: (id, argv, setup(root) -> None, expected exit code, output that may appear, words
# that must be in the one stderr line). Paths are relative to the case's copy of the world.


def _set(rel: str, data: bytes | str):
    def setup(root: Path):
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data if isinstance(data, bytes) else data.encode())

    return setup


def _edit(rel: str, fn):
    def setup(root: Path):
        p = root / rel
        p.write_bytes(fn(p))

    return setup


def _mkdir(rel: str, *files: str):
    def setup(root: Path):
        (root / rel).mkdir(parents=True, exist_ok=True)
        for f in files:
            (root / rel / f).write_text("mine\n")

    return setup


def _chain(*fns):
    def setup(root: Path):
        for f in fns:
            f(root)

    return setup


def _nothing(root: Path):
    pass


def _outside(name: str, text: str):
    """A file beside the case's world (outside the current directory of the command)."""

    def setup(root: Path):
        (root.parent / "outside").mkdir(exist_ok=True)
        (root.parent / "outside" / name).write_text(text)

    return setup


FLEET_MANIFEST = (
    '[fleet]\nname = "cell"\ntask = "calibrate"\n[[joints]]\nname = "j"\nratio = 160\n'
    'rated_torque = 400\nlogs = [{ path = "data.csv", date = 2026-01-05 }]\n'
)


RUN = ["run", "proj/cfg.toml", "-q"]
SWEEP = ["sweep", "proj/cfg.toml", "-q", "--setting", "model.poly_order", "--values", "1,2"]
EST = ["estimate", "--model", "res/model.json", "--data", "proj/new.csv", "-q"]
DISC = [
    "discover",
    "--train",
    "proj/train.csv",
    "--test",
    "proj/test.csv",
    "--joint",
    "proj/joint.toml",
    "--quiet",
    "--no-figures",
]

CASES = [
    # -- data loss: an output that is, holds or lies in an input; the current directory -----
    (
        "run-out-holds-config",
        RUN + ["--out", "proj", "--overwrite"],
        _nothing,
        2,
        None,
        ["holds the input"],
    ),
    (
        "sweep-out-holds-config",
        SWEEP + ["--out", "proj", "--overwrite"],
        _nothing,
        2,
        None,
        ["holds the input"],
    ),
    (
        "estimate-out-is-data",
        EST + ["--out", "proj/new.csv", "--overwrite"],
        _nothing,
        2,
        None,
        ["is also an input"],
    ),
    (
        "estimate-out-is-model",
        EST + ["--out", "res/model.json", "--overwrite"],
        _nothing,
        2,
        None,
        ["is also an input"],
    ),
    ("run-out-dot", RUN + ["--out", ".", "--overwrite"], _nothing, 2, None, ["holds the input"]),
    (
        "run-out-cwd-no-input",
        ["run", "../outside/synth.toml", "-q", "--out", ".", "--overwrite"],
        _outside("synth.toml", SYNTHETIC),
        2,
        None,
        [".: --out is the current directory", "never replaces"],
    ),
    (
        "sweep-out-dot",
        SWEEP + ["--out", ".", "--overwrite"],
        _nothing,
        2,
        None,
        [".: --out holds the input", "cfg.toml"],
    ),
    (
        "discover-out-holds-data",
        DISC + ["--out", "proj", "--overwrite"],
        _nothing,
        2,
        None,
        ["holds the input"],
    ),
    (
        "discover-out-dot",
        DISC + ["--out", ".", "--overwrite"],
        _nothing,
        2,
        None,
        [".: --out holds the input proj/train.csv"],
    ),
    (
        "run-out-inside-input-dir",
        ["estimate", "--model", "res", "--data", "proj/new.csv", "--out", "res/e.csv", "-q"],
        _nothing,
        2,
        None,
        ["lies inside the input"],
    ),
    (
        "run-out-foreign-dir",
        RUN + ["--out", "proj/sub", "--overwrite"],
        _nothing,
        2,
        None,
        ["not an hdjax result folder", "keep.txt"],
    ),
    (
        "discover-out-foreign-dir",
        DISC + ["--out", "proj/sub", "--overwrite"],
        _nothing,
        2,
        None,
        ["not an hdjax result folder"],
    ),
    (
        "run-out-result-no-overwrite",
        RUN + ["--out", "res"],
        _nothing,
        2,
        None,
        ["already exists", "--overwrite"],
    ),
    (
        "run-out-result-with-user-file",
        RUN + ["--out", "res", "--overwrite"],
        _set("res/notes.txt", "mine\n"),
        2,
        None,
        ["did not write", "notes.txt"],
    ),
    (
        "estimate-out-foreign-file",
        EST + ["--out", "proj/sub/keep.txt", "--overwrite"],
        _nothing,
        2,
        None,
        ["not a file hdjax wrote"],
    ),
    # -- tracebacks before: --model DIR, --out under a file, a folder for a file --------------
    (
        "estimate-model-dir",
        ["estimate", "--model", "res", "--data", "proj/new.csv", "--out", "e.csv", "-q"],
        _nothing,
        0,
        "e.csv",
        [],
    ),
    (
        "estimate-model-dir-without-model",
        ["estimate", "--model", "proj/sub", "--data", "proj/new.csv", "--out", "e.csv", "-q"],
        _nothing,
        2,
        None,
        ["without model.json"],
    ),
    (
        "run-out-under-a-file",
        RUN + ["--out", "proj/sub/keep.txt/x"],
        _nothing,
        2,
        None,
        ["is a file, not a folder"],
    ),
    (
        "estimate-out-under-a-file",
        EST + ["--out", "proj/sub/keep.txt/e.csv"],
        _nothing,
        2,
        None,
        ["is a file, not a folder"],
    ),
    (
        "discover-out-under-a-file",
        DISC + ["--out", "proj/sub/keep.txt/d"],
        _nothing,
        2,
        None,
        ["is a file, not a folder"],
    ),
    (
        "run-out-in-proc",
        RUN + ["--out", "/proc/hdjax-out"],
        _nothing,
        2,
        None,
        ["/proc/hdjax-out: cannot create the result folder"],
    ),
    (
        "estimate-out-dir-overwrite",
        EST + ["--out", "proj/sub", "--overwrite"],
        _nothing,
        2,
        None,
        ["is a folder"],
    ),
    (
        "run-train-is-a-dir",
        ["run", "proj/cfg.toml", "-q", "--out", "o", "--set", "data.train=['sub']"],
        _nothing,
        2,
        None,
        ["is a folder"],
    ),
    (
        "discover-train-is-a-dir",
        [
            "discover",
            "--train",
            "proj/sub",
            "--test",
            "proj/test.csv",
            "--joint",
            "proj/joint.toml",
            "--out",
            "d",
            "--quiet",
        ],
        _nothing,
        2,
        None,
        ["is a folder"],
    ),
    (
        "estimate-data-is-a-dir",
        ["estimate", "--model", "res", "--data", "proj/sub.csv", "--out", "e.csv", "-q"],
        _mkdir("proj/sub.csv"),
        2,
        None,
        ["is a folder"],
    ),
    (
        "run-config-is-a-dir",
        ["run", "proj", "-q", "--out", "o"],
        _nothing,
        2,
        None,
        ["is a directory"],
    ),
    # -- text that is not UTF-8 ----------------------------------------------------------------
    (
        "run-config-latin1",
        RUN + ["--out", "o"],
        _set("proj/cfg.toml", _latin1(f"# {LATIN1}\n" + CONFIG)),
        2,
        None,
        ["byte 0xb0 at byte position", "line 1", "UTF-8"],
    ),
    (
        "run-csv-latin1",
        RUN + ["--out", "o"],
        _edit("proj/data.csv", _with_extra_latin1),
        2,
        None,
        ["proj/data.csv", "byte position", 'encoding = "latin-1"'],
    ),
    (
        "run-csv-latin1-with-encoding",
        RUN + ["--out", "o", "--set", 'data.encoding="latin-1"'],
        _edit("proj/data.csv", _with_extra_latin1),
        0,
        "o",
        [],
    ),
    (
        "estimate-csv-latin1",
        EST + ["--out", "e.csv"],
        _edit("proj/new.csv", _with_extra_latin1),
        2,
        None,
        ["proj/new.csv", "byte position"],
    ),
    (
        "estimate-csv-latin1-column-map",
        EST + ["--out", "e.csv", "--columns", "proj/lat.toml"],
        _chain(
            _edit("proj/new.csv", _with_extra_latin1),
            _set("proj/lat.toml", '[data]\nencoding = "latin-1"\n'),
        ),
        0,
        "e.csv",
        [],
    ),
    (
        "estimate-joint-latin1",
        EST + ["--out", "e.csv", "--joint", "proj/joint.toml"],
        _set("proj/joint.toml", _latin1(f"# {LATIN1}\n" + JOINT)),
        2,
        None,
        ["joint.toml", "byte position"],
    ),
    (
        "estimate-columns-latin1",
        EST + ["--out", "e.csv", "--columns", "proj/columns.toml"],
        _set("proj/columns.toml", _latin1(f"# {LATIN1}\n" + COLUMNS)),
        2,
        None,
        ["columns.toml", "byte position"],
    ),
    (
        "discover-joint-latin1",
        DISC + ["--out", "d"],
        _set("proj/joint.toml", _latin1(f"# {LATIN1}\n" + JOINT)),
        2,
        None,
        ["byte position"],
    ),
    (
        "discover-train-latin1",
        DISC + ["--out", "d"],
        _edit("proj/train.csv", _with_extra_latin1),
        2,
        None,
        ["train.csv", "byte position"],
    ),
    (
        "run-csv-utf16",
        RUN + ["--out", "o"],
        _edit("proj/data.csv", lambda p: p.read_text().encode("utf-16")),
        2,
        None,
        ["UTF-16"],
    ),
    (
        "run-csv-nul",
        RUN + ["--out", "o"],
        _edit("proj/data.csv", lambda p: b"\x00" + p.read_bytes()),
        2,
        None,
        ["NUL byte"],
    ),
    (
        "run-csv-bom",
        RUN + ["--out", "o"],
        _edit("proj/data.csv", lambda p: b"\xef\xbb\xbf" + p.read_bytes()),
        0,
        "o",
        [],
    ),
    (
        "run-config-bom",
        RUN + ["--out", "o"],
        _edit("proj/cfg.toml", lambda p: b"\xef\xbb\xbf" + p.read_bytes()),
        0,
        "o",
        [],
    ),
    (
        "run-encoding-unknown",
        RUN + ["--out", "o", "--set", 'data.encoding="klingon"'],
        _nothing,
        2,
        None,
        ["unknown text encoding"],
    ),
    # -- --set and sweep members: the file's cross-table checks, before any work -------------
    (
        "run-set-kind-files",
        ["run", "proj/synth.toml", "-q", "--out", "o", "--set", 'data.kind="files"'],
        _nothing,
        2,
        None,
        ['kind = "files" needs'],
    ),
    (
        "sweep-set-kind-files",
        ["sweep", "proj/synth.toml", "-q", "--out", "o", "--set", 'data.kind="files"'],
        _nothing,
        2,
        None,
        ['kind = "files" needs'],
    ),
    (
        "sweep-member-kind-files",
        [
            "sweep",
            "proj/synth.toml",
            "-q",
            "--out",
            "o",
            "--setting",
            "data.kind",
            "--values",
            '"synthetic","files"',
        ],
        _nothing,
        2,
        None,
        ["sweep member", 'kind = "files" needs'],
    ),
    (
        "sweep-member-even-segments",
        [
            "sweep",
            "proj/synth.toml",
            "-q",
            "--out",
            "o",
            "--setting",
            "model.n_segments",
            "--values",
            "3,4",
        ],
        _nothing,
        2,
        None,
        ["n_segments = 4", "odd"],
    ),
    (
        "run-set-current-scale-tiny",
        RUN + ["--out", "o", "--set", "model.current_scale=1e-300"],
        _nothing,
        2,
        None,
        ["current_scale", "auto"],
    ),
    (
        "run-n-samples-huge",
        ["run", "proj/synth.toml", "-q", "--out", "o", "--set", "data.n_samples=2000000000000"],
        _nothing,
        2,
        None,
        ["n_samples", "of memory"],
    ),
    (
        "run-n-samples-float",
        ["run", "proj/synth.toml", "-q", "--out", "o", "--set", "data.n_samples=2e9"],
        _nothing,
        2,
        None,
        ["integer"],
    ),
    (
        "sweep-values-empty",
        SWEEP[:-2] + ["--values", "", "--out", "o"],
        _nothing,
        2,
        None,
        ["no values"],
    ),
    (
        "sweep-values-repeat",
        SWEEP[:-2] + ["--values", "2,2", "--out", "o"],
        _nothing,
        2,
        None,
        ["repeat"],
    ),
    (
        "run-set-syntax",
        RUN + ["--out", "o", "--set", "model.poly_order"],
        _nothing,
        2,
        None,
        ["KEY=VALUE"],
    ),
    (
        "run-set-unknown",
        RUN + ["--out", "o", "--set", "model.poly_ordr=3"],
        _nothing,
        2,
        None,
        ["did you mean"],
    ),
    (
        "run-rls-default",
        ["run", "proj/synth.toml", "-q", "--out", "o", "--set", 'fit.method="rls"'],
        _nothing,
        0,
        "o",
        [],
    ),
    # -- wrong answers: angles in degrees ----------------------------------------------------
    (
        "estimate-degrees",
        ["estimate", "--model", "res", "--data", "proj/deg.csv", "--out", "e.csv", "-q"],
        _nothing,
        2,
        None,
        ["degrees", "--force"],
    ),
    (
        "estimate-ratio",
        ["estimate", "--model", "res", "--data", "proj/ratio.csv", "--out", "e.csv", "-q"],
        None,
        2,
        None,
        ["ratio is 160", "--force"],
    ),
    # -- missing and malformed files ------------------------------------------------------
    (
        "run-config-missing",
        ["run", "proj/nope.toml", "-q", "--out", "o"],
        _nothing,
        2,
        None,
        ["no such"],
    ),
    (
        "run-config-syntax",
        RUN + ["--out", "o"],
        _set("proj/cfg.toml", "[joint\nratio = 1\n"),
        2,
        None,
        ["cfg.toml:1:"],
    ),
    (
        "run-config-unknown-key",
        RUN + ["--out", "o"],
        _set("proj/cfg.toml", CONFIG.replace("poly_order", "poly_ordr")),
        2,
        None,
        ["did you mean 'poly_order'"],
    ),
    (
        "run-data-missing",
        RUN + ["--out", "o"],
        lambda r: (r / "proj" / "data.csv").unlink(),
        2,
        None,
        ["no such file"],
    ),
    ("run-csv-empty", RUN + ["--out", "o"], _set("proj/data.csv", b""), 2, None, ["empty"]),
    (
        "run-csv-text-cell",
        RUN + ["--out", "o"],
        _edit("proj/data.csv", lambda p: p.read_bytes().replace(b"\n0,", b"\nx,", 1)),
        2,
        None,
        ["non-numeric"],
    ),
    (
        "run-csv-ragged",
        RUN + ["--out", "o"],
        _edit("proj/data.csv", lambda p: p.read_bytes() + b"1,2\n"),
        2,
        None,
        ["cells"],
    ),
    (
        "estimate-model-truncated",
        EST + ["--out", "e.csv"],
        _edit("res/model.json", lambda p: p.read_bytes()[:100]),
        2,
        None,
        ["corrupt model file"],
    ),
    (
        "estimate-model-missing",
        ["estimate", "--model", "nope.json", "--data", "proj/new.csv", "--out", "e.csv", "-q"],
        _nothing,
        2,
        None,
        ["no such"],
    ),
    (
        "estimate-model-latin1",
        EST + ["--out", "e.csv"],
        _set("res/model.json", _latin1('{"format": "°"}')),
        2,
        None,
        ["corrupt model file"],
    ),
    (
        "estimate-npz-corrupt",
        ["estimate", "--model", "res", "--data", "proj/x.npz", "--out", "e.csv", "-q"],
        _set("proj/x.npz", b"PK\x03\x04junk"),
        2,
        None,
        ["x.npz"],
    ),
    (
        "estimate-no-overwrite",
        EST + ["--out", "proj/sub/keep.txt"],
        _nothing,
        2,
        None,
        ["already exists"],
    ),
    ("unknown-command", ["rnu", "proj/cfg.toml"], _nothing, 2, None, ["did you mean 'run'"]),
    ("unknown-option", RUN + ["--overwite"], _nothing, 2, None, ["did you mean '--overwrite'"]),
    (
        "out-dangling-link",
        RUN + ["--out", "dangling"],
        lambda r: os.symlink(r / "nowhere", r / "dangling"),
        2,
        None,
        ["dangling"],
    ),
    # -- discover's own bad inputs ------------------------------------------------------------
    (
        "discover-missing-args",
        ["discover", "--train", "proj/train.csv", "--out", "d"],
        _nothing,
        2,
        None,
        ["missing --test, --joint"],
    ),
    (
        "discover-config-and-train",
        ["discover", "--config", "proj/disc.toml", "--train", "proj/train.csv", "--out", "d"],
        _nothing,
        2,
        None,
        ["either --config"],
    ),
    (
        "discover-max-effects",
        DISC + ["--out", "d", "--max-effects", "-1"],
        _nothing,
        2,
        None,
        ["--max-effects"],
    ),
    (
        "discover-min-gain",
        DISC + ["--out", "d", "--min-gain", "2"],
        _nothing,
        2,
        None,
        ["--min-gain"],
    ),
    (
        "discover-bad-int",
        DISC + ["--out", "d", "--max-effects", "x"],
        _nothing,
        2,
        None,
        ["invalid int"],
    ),
    ("discover-non-empty-out", DISC + ["--out", "proj/sub"], _nothing, 2, None, ["keep.txt"]),
    (
        "discover-test-lacks-core-column",
        DISC + ["--out", "d"],
        _edit("proj/test.csv", lambda p: _drop_column(p, "current")),
        2,
        None,
        ["current"],
    ),
    (
        "discover-ratio",
        DISC + ["--out", "d"],
        _set("proj/joint.toml", JOINT.replace("160", "100")),
        2,
        None,
        ["angles imply a reduction ratio of 16", "the joint file says 100"],
    ),
    (
        "discover-config-unknown-table",
        ["discover", "--config", "proj/disc.toml", "--out", "d"],
        _edit("proj/disc.toml", lambda p: p.read_bytes() + b"[nope]\n"),
        2,
        None,
        ["[nope]"],
    ),
    (
        "discover-config-latin1",
        ["discover", "--config", "proj/disc.toml", "--out", "d"],
        _edit("proj/disc.toml", lambda p: _latin1(f"# {LATIN1}\n") + p.read_bytes()),
        2,
        None,
        ["byte position"],
    ),
    (
        # a one-log split whose TEST part would be empty (2000 samples, TEST from row 3000)
        "discover-config-test-blocks-leave-test-empty",
        ["discover", "--config", "proj/disc.toml", "--out", "d"],
        _set(
            "proj/disc.toml",
            JOINT + '[data]\npath = "train.csv"\ntest_blocks = { block = 1000, every = 4 }\n',
        ),
        2,
        None,
        ["2000 samples", "TEST would start at row 3000", "at most 500"],
    ),
    (
        "discover-config-test-blocks-not-a-table",
        ["discover", "--config", "proj/disc.toml", "--out", "d"],
        _set("proj/disc.toml", JOINT + '[data]\npath = "train.csv"\ntest_blocks = 4\n'),
        2,
        None,
        ["test_blocks", "{ block = 100, every = 4 }"],
    ),
    (
        "discover-config-test-blocks-fractional",
        ["discover", "--config", "proj/disc.toml", "--out", "d"],
        _set(
            "proj/disc.toml",
            JOINT + '[data]\npath = "train.csv"\ntest_blocks = { block = 12.5 }\n',
        ),
        2,
        None,
        ["block must be a whole number >= 1", "12.5"],
    ),
    (
        "discover-unknown-option",
        DISC + ["--out", "d", "--ignore-collumn", "x"],
        _nothing,
        2,
        None,
        ["did you mean '--ignore-column'"],
    ),
]


def _drop_column(path: Path, name: str) -> bytes:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    keep = [i for i, h in enumerate(header) if h != name]
    return ("\n".join(",".join(line.split(",")[i] for i in keep) for line in lines) + "\n").encode()


def _ratio_csv(root: Path):
    text = (root / "proj" / "new.csv").read_text().splitlines()
    header = text[0].split(",")
    j = header.index("theta_m")
    rows = [text[0]]
    for line in text[1:]:
        cells = line.split(",")
        cells[j] = repr(float(cells[j]) * 100 / 160)
        rows.append(",".join(cells))
    (root / "proj" / "ratio.csv").write_text("\n".join(rows) + "\n")


CASES = [c if c[0] != "estimate-ratio" else (*c[:2], _ratio_csv, *c[3:]) for c in CASES]
CASES += [
    # -- the other commands: convert, fleet, bench ---------------------------------------------
    (
        "convert-out-is-input",
        ["convert", "proj/data.csv", "proj/data.csv", "--overwrite"],
        _nothing,
        2,
        None,
        ["is also an input"],
    ),
    (
        "convert-out-holds-input",
        ["convert", "proj/data.csv", "proj", "--overwrite"],
        _nothing,
        2,
        None,
        ["holds the input"],
    ),
    (
        "convert-out-foreign-file",
        ["convert", "proj/data.csv", "proj/sub/x.parquet", "--overwrite"],
        _set("proj/sub/x.parquet", "mine\n"),
        2,
        None,
        ["not a file hdjax wrote"],
    ),
    (
        "convert-csv-latin1",
        ["convert", "proj/data.csv", "d.parquet"],
        _edit("proj/data.csv", _with_extra_latin1),
        2,
        None,
        ["data.csv", "UTF-8", "byte 0xb0 at byte position", 'encoding = "latin-1"'],
    ),
    (
        "convert-csv-latin1-with-encoding",
        ["convert", "proj/data.csv", "d.parquet", "--columns", "proj/lat.toml", "-q"],
        _chain(
            _edit("proj/data.csv", _with_extra_latin1),
            _set("proj/lat.toml", '[data]\nencoding = "latin-1"\n'),
        ),
        0,
        "d.parquet",
        [],
    ),
    (
        "convert-csv-utf16",
        ["convert", "proj/data.csv", "d.parquet"],
        _edit("proj/data.csv", lambda p: p.read_text().encode("utf-16")),
        2,
        None,
        ["data.csv", "UTF-16"],
    ),
    (
        "convert-csv-nul",
        ["convert", "proj/data.csv", "d.parquet"],
        _edit("proj/data.csv", lambda p: p.read_bytes().replace(b"\n", b"\n\x00", 1)),
        2,
        None,
        ["data.csv", "NUL byte at byte position"],
    ),
    (
        "convert-csv-bom",
        ["convert", "proj/data.csv", "d.parquet", "-q"],
        _edit("proj/data.csv", lambda p: b"\xef\xbb\xbf" + p.read_bytes()),
        0,
        "d.parquet",
        [],
    ),
    (
        "convert-columns-latin1",
        ["convert", "proj/data.csv", "d.parquet", "--columns", "proj/columns.toml"],
        _set("proj/columns.toml", _latin1(f"# {LATIN1}\n" + COLUMNS)),
        2,
        None,
        ["byte position"],
    ),
    (
        "fleet-manifest-missing",
        ["fleet", "proj/nope.toml", "--out", "f"],
        _nothing,
        2,
        None,
        ["no such"],
    ),
    (
        "fleet-out-holds-manifest",
        ["fleet", "proj/cell.toml", "--out", "proj", "--overwrite"],
        _set("proj/cell.toml", FLEET_MANIFEST),
        2,
        None,
        ["proj: --out holds the input", "cell.toml"],
    ),
    (
        "bench-samples-huge",
        ["bench", "--samples", "100000000000000", "-q"],
        _nothing,
        2,
        None,
        ["of memory"],
    ),
    ("bench-samples-few", ["bench", "--samples", "10", "-q"], _nothing, 2, None, ["--samples"]),
]
CASES.append(
    (
        "estimate-degrees-force",
        ["estimate", "--model", "res", "--data", "proj/deg.csv", "--out", "e.csv", "-q", "--force"],
        _nothing,
        0,
        "e.csv",
        [],
    )
)
CASES.append(
    (
        "estimate-ratio-force",
        ["estimate", "--model", "res", "--data", "proj/ratio.csv", "--out", "e.csv", "-q"]
        + ["--force"],
        _ratio_csv,
        0,
        "e.csv",
        ["warning", "--force: estimating anyway"],
    )
)


def _train_on_ratio_csv(root: Path):
    _ratio_csv(root)
    cfg = root / "proj" / "cfg.toml"
    cfg.write_text(cfg.read_text().replace('"data.csv"', '"ratio.csv"'))


CASES += [
    ("run-ratio", RUN + ["--out", "o"], _train_on_ratio_csv, 2, None, ["ratio is 160", "--force"]),
    ("sweep-ratio", SWEEP + ["--out", "o"], _train_on_ratio_csv, 2, None, ["ratio is 160"]),
    (
        # least squares would not invert: the shape-constrained fit runs, and says so loudly
        "run-ratio-force",
        RUN + ["--out", "o", "--force"],
        _train_on_ratio_csv,
        0,
        "o",
        ["ratio is 160", "--force: running anyway", "not increasing with torque", "floor"],
    ),
]


def _chunked(extra: str = ""):
    """The run config with `[fit] chunk` (the files streamed) and `extra` lines in `[data]`."""

    def fn(path: Path) -> bytes:
        text = path.read_text().replace("[data]\n", f"[data]\n{extra}")
        return (text + "[fit]\nchunk = 64\n").encode()

    return _edit("proj/cfg.toml", fn)


CASES += [
    # streamed parts: the same refusals from the sums of the build pass, never a whole load
    (
        "run-chunk-ratio",
        RUN + ["--out", "o"],
        _chain(_train_on_ratio_csv, _chunked()),
        2,
        None,
        ["ratio is 160", "--force"],
    ),
    (
        "run-chunk-settle",
        RUN + ["--out", "o"],
        _chunked("settle = 100.0\n"),
        2,
        None,
        ["settle = 100 s leaves fewer than 2 samples"],
    ),
    (
        "run-chunk-format",
        RUN + ["--out", "o"],
        _chunked('format = "npz"\n'),
        2,
        None,
        ['format = "npz"', "suffix '.csv'"],
    ),
    (
        "sweep-chunk-missing-file",
        SWEEP + ["--out", "o"],
        _chain(_chunked(), lambda root: (root / "proj" / "data.csv").unlink()),
        2,
        None,
        ["data.csv", "no such file"],
    ),
]


def _encoding_in_discover_config(path: Path) -> bytes:
    return path.read_bytes().replace(b"[data]\n", b'[data]\nencoding = "latin-1"\n')


CASES.append(
    (
        "discover-config-encoding",
        ["discover", "--config", "proj/disc.toml", "--out", "d"],
        _chain(
            _edit("proj/train.csv", _with_extra_latin1),
            _edit("proj/test.csv", _with_extra_latin1),
            _edit("proj/disc.toml", _encoding_in_discover_config),
        ),
        2,
        None,
        [LATIN1, "constant"],  # read through the encoding, then refused for its constant value
    )
)


def _mcap_bytes(n: int = 200) -> bytes:
    """A valid MCAP log of the five core columns on one JSON topic."""
    from mcap.writer import Writer

    buf = io.BytesIO()
    w = Writer(buf)
    w.start()
    channel = w.register_channel("/j", "json", w.register_schema("j", "jsonschema", b"{}"))
    for i in range(n):
        row = {"t": i * 1e-3, "theta_m": 0.1 * i, "theta_l": 1e-3 * i, "current": 1.0}
        w.add_message(channel, log_time=i, data=json.dumps(row | {"torque": 0.0}).encode(),
                      publish_time=i)  # fmt: skip
    w.finish()
    return buf.getvalue()


def _mcap(rel: str, damage: str):
    """`rel` as a damaged MCAP file: cut at a fraction, its last 100 bytes cut, or no MCAP."""

    def setup(root: Path):
        data = _mcap_bytes()
        if damage == "junk":
            data = b"t,theta_m,theta_l,current,torque\n0,0,0,0,0\n"
        elif damage == "tail":
            data = data[:-100]
        else:
            data = data[: int(float(damage) * len(data))]
        (root / rel).write_bytes(data)

    return setup


CASES.append(
    (
        "estimate-missing-column-names-the-flag",
        EST + ["--out", "e.csv"],
        _edit("proj/new.csv", lambda p: _drop_column(p, "current")),
        2,
        None,
        ["missing column 'current'", "[data.columns]", "--columns FILE"],
    )
)

# a truncated or non-MCAP file: one line from every command that reads a log
for _damage in ("0.1", "0.5", "0.999", "tail", "junk"):
    CASES += [
        (
            f"convert-mcap-{_damage}",
            ["convert", "proj/log.mcap", "o.parquet", "-q"],
            _mcap("proj/log.mcap", _damage),
            2,
            None,
            ["proj/log.mcap", "not a readable MCAP file"],
        ),
        (
            f"discover-mcap-{_damage}",
            ["discover", "--train", "proj/log.mcap", "--test", "proj/test.csv"]
            + ["--joint", "proj/joint.toml", "--quiet", "--no-figures", "--out", "d"],
            _mcap("proj/log.mcap", _damage),
            2,
            None,
            ["proj/log.mcap", "not a readable MCAP file"],
        ),
        (
            f"estimate-mcap-{_damage}",
            ["estimate", "--model", "res/model.json", "--data", "proj/log.mcap", "-q"]
            + ["--out", "e.csv"],
            _mcap("proj/log.mcap", _damage),
            2,
            None,
            ["proj/log.mcap", "not a readable MCAP file"],
        ),
    ]


def _check(root: Path, argv, code_expected, output, words, capsys):
    before = _digest(root)
    with _inside(root):
        code = main(argv)
    cap = capsys.readouterr()
    err = cap.err
    assert code in (0, 2), (code, err)
    if code_expected is not None:
        assert code == code_expected, err
    assert "Traceback" not in err and "Traceback" not in cap.out, err
    # one line a problem; --force adds the warning of the check it overrides
    lines = err.splitlines()
    assert len(lines) <= (2 if "--force" in argv else 1), err
    assert all(line.startswith("hdjax") for line in lines), err
    if code == 2:
        assert err.startswith("hdjax"), err
    for w in words:
        assert w in err, err
    after = _digest(root)
    new = {k for k in after if k not in before}
    if output is not None and code == 0:
        new = {k for k in new if not (k == output or k.startswith(output.rstrip("/") + "/"))}
    assert not new, f"files left behind: {sorted(new)}"
    changed = sorted(k for k in before if after.get(k) != before[k])
    assert not changed, f"inputs changed or removed: {changed}"
    return code, err


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_broken_input(world, tmp_path, capsys, case):
    name, argv, setup, code, output, words = case
    if name == "run-out-in-proc" and not Path("/proc").is_dir():
        pytest.skip("needs /proc")
    root = tmp_path / "world"
    shutil.copytree(world, root, symlinks=True)
    setup(root)
    _check(root, argv, code, output, words, capsys)


def test_read_only_folder(world, tmp_path, capsys):
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    root = tmp_path / "world"
    shutil.copytree(world, root)
    (root / "ro").mkdir()
    (root / "ro").chmod(0o555)
    try:
        _, err = _check(root, RUN + ["--out", "ro/o"], 2, None, ["cannot write in"], capsys)
    finally:
        (root / "ro").chmod(0o755)


# ---------------------------------------------------------------------------------------------
# Random corruption: truncate, flip bytes, re-encode, reorder columns. Whatever the damage, the
# command answers in one line (exit 2) or accepts the file; the sentinel below stops an
# accepted input right before the numerical work, so every example stays cheap.


class ReachedWork(BaseException):
    """The input was accepted and the command got to its numerical work."""


@pytest.fixture
def stop_before_work(monkeypatch):
    import hdjax.cli._sweep
    import hdjax.compliance
    import hdjax.discover.internal
    import hdjax.pipelines.internal

    def stop(*a, **k):
        raise ReachedWork

    monkeypatch.setattr(hdjax.pipelines.internal, "calibrate", stop)
    monkeypatch.setattr(hdjax.compliance, "estimate_torque", stop)
    monkeypatch.setattr(hdjax.discover.internal, "discover", stop)
    monkeypatch.setattr(hdjax.cli._sweep, "_members_nested", stop)
    monkeypatch.setattr(hdjax.cli._sweep, "_member_loop", stop)


def _corrupt(data: bytes, how: str, pos: float, value: int) -> bytes:
    if not data:
        return data
    i = min(int(pos * len(data)), len(data) - 1)
    if how == "truncate":
        return data[:i]
    if how == "flip":
        return data[:i] + bytes([data[i] ^ (1 + value % 255)]) + data[i + 1 :]
    if how == "insert":
        return data[:i] + bytes([value % 256]) + data[i:]
    if how == "encode":
        codec = ["utf-16", "latin-1", "cp1252", "utf-8-sig", "utf-32"][value % 5]
        try:
            return data.decode("utf-8").replace("a", "ä", 1).encode(codec, errors="replace")
        except UnicodeDecodeError:
            return data
    if how == "reorder":
        lines = data.split(b"\n")
        rows = [line.split(b",") for line in lines if line]
        width = len(rows[0])
        perm = list(range(width))
        rnd = np.random.default_rng(value)
        rnd.shuffle(perm)
        out = [b",".join(r[k] for k in perm if k < len(r)) for r in rows]
        return b"\n".join(out) + b"\n"
    if how == "lines":
        lines = data.split(b"\n")
        j = value % max(len(lines), 1)
        return b"\n".join(lines[:j] + lines[j + 1 :])
    raise AssertionError(how)


HOW = st.sampled_from(["truncate", "flip", "insert", "encode", "reorder", "lines"])
FRACTION = st.floats(0.0, 1.0, allow_nan=False)
VALUE = st.integers(0, 1 << 16)
CORRUPTION = settings(
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    derandomize=True,
)


@pytest.fixture(scope="module")
def scratch(world, tmp_path_factory) -> Path:
    """One copy of the world for the corruption tests; each example restores what it broke."""
    root = tmp_path_factory.mktemp("scratch") / "world"
    shutil.copytree(world, root)
    return root


@contextlib.contextmanager
def _damaged(root: Path, rel: str, data: bytes):
    p = root / rel
    original = p.read_bytes()
    p.write_bytes(data)
    try:
        yield
    finally:
        p.write_bytes(original)


def _answer(root: Path, argv, capsys, output: str | None = None):
    """Run one command on a damaged world; check the contract; return the exit code. An
    accepted input may leave `output` (removed again for the next example)."""
    before = _digest(root)
    try:
        with _inside(root):
            code = main(argv)
    except ReachedWork:
        code = None
    cap = capsys.readouterr()
    assert code in ((None, 2) if output is None else (None, 0, 2)), (code, cap.err)
    assert "Traceback" not in cap.err and "Traceback" not in cap.out, cap.err
    assert cap.err.count("\n") <= 1, cap.err
    if code == 0:
        (root / output).unlink()
    assert _digest(root) == before  # nothing left behind, every input intact
    return code


def _fuzz(root, rel: str, argv, how, pos, value, capsys, output=None):
    data = (root / rel).read_bytes()
    if how == "reorder" and not rel.endswith(".csv"):
        how = "lines"
    with _damaged(root, rel, _corrupt(data, how, pos, value)):
        _answer(root, argv, capsys, output)


@CORRUPTION
@given(
    which=st.sampled_from(["proj/cfg.toml", "proj/data.csv"]), how=HOW, pos=FRACTION, value=VALUE
)
def test_run_survives_corrupt_files(scratch, capsys, stop_before_work, which, how, pos, value):
    _fuzz(scratch, which, RUN + ["--out", "o"], how, pos, value, capsys)


@CORRUPTION
@given(
    which=st.sampled_from(["proj/cfg.toml", "proj/data.csv"]), how=HOW, pos=FRACTION, value=VALUE
)
def test_sweep_survives_corrupt_files(scratch, capsys, stop_before_work, which, how, pos, value):
    _fuzz(scratch, which, SWEEP + ["--out", "o"], how, pos, value, capsys)


@CORRUPTION
@given(
    which=st.sampled_from(
        ["res/model.json", "proj/new.csv", "proj/joint.toml", "proj/columns.toml"]
    ),
    how=HOW,
    pos=FRACTION,
    value=VALUE,
)
def test_estimate_survives_corrupt_files(scratch, capsys, stop_before_work, which, how, pos, value):
    argv = EST + ["--out", "e.csv", "--joint", "proj/joint.toml", "--columns", "proj/columns.toml"]
    _fuzz(scratch, which, argv, how, pos, value, capsys)


@CORRUPTION
@given(
    which=st.sampled_from(["proj/train.csv", "proj/test.csv", "proj/joint.toml"]),
    how=HOW,
    pos=FRACTION,
    value=VALUE,
)
def test_discover_survives_corrupt_files(scratch, capsys, stop_before_work, which, how, pos, value):
    _fuzz(scratch, which, DISC + ["--out", "d"], how, pos, value, capsys)


@CORRUPTION
@given(
    path=st.lists(st.sampled_from(["compliance", "joint", "coef", "meta", "units"]), max_size=2),
    value=st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(10**30), 10**30),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=5),
        st.lists(st.floats(allow_nan=True), max_size=3),
        st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
    ),
)
def test_estimate_survives_edited_model_with_valid_checksum(
    scratch, capsys, stop_before_work, path, value
):
    """A model file edited by hand (or by another tool) with its checksum recomputed."""
    from hdjax.modelfile._saved_model import _checksum

    rel = "res/model.json"
    doc = json.loads((scratch / rel).read_text())
    doc.pop("checksum")
    node = doc
    for key in path[:-1]:
        node = node.get(key) if isinstance(node, dict) else None
    if not path:
        doc = value
    elif isinstance(node, dict):
        node[path[-1]] = value
    if isinstance(doc, dict):
        doc["checksum"] = _checksum(doc)
    with _damaged(scratch, rel, json.dumps(doc).encode()):
        _answer(scratch, EST + ["--out", "e.csv"], capsys)


@CORRUPTION
@given(
    which=st.sampled_from(["proj/data.csv", "proj/columns.toml"]),
    how=HOW,
    pos=FRACTION,
    value=VALUE,
)
def test_convert_survives_corrupt_files(scratch, capsys, which, how, pos, value):
    pytest.importorskip("pyarrow")
    argv = ["convert", "proj/data.csv", "d.parquet", "-q"]
    if which.endswith(".toml"):
        argv += ["--columns", which]
    _fuzz(scratch, which, argv, how, pos, value, capsys, output="d.parquet")
