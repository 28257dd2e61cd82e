"""`config.resolved.toml` runs again from its result directory, whatever its file paths were."""

import json
import tomllib

from hdjax import Joint, save_csv
from hdjax.cli import main
from hdjax.config import load_experiment, with_absolute_paths
from hdjax.pipelines import synthetic_recording

CONFIG = """
[experiment]
name = "files"
seed = 2
[joint]
ratio = 160
rated_torque = 400
[data]
kind = "files"
train = ["logs/cal.csv"]
split = 0.3
[model]
poly_order = 3
kinematic = "none"
per_segment = false
[outputs]
timing = false
"""


def test_rerun_from_the_result_directory_repeats_the_metrics(tmp_path, monkeypatch):
    """The config names its data relative to its own folder; the resolved copy is run from
    inside the result directory, as its header says, and must give the same numbers."""
    proj = tmp_path / "proj"
    (proj / "logs").mkdir(parents=True)
    rec = synthetic_recording(Joint(ratio=160, rated_torque=400), 1200, seed=5)
    save_csv(rec, proj / "logs" / "cal.csv")
    (proj / "cfg.toml").write_text(CONFIG)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # neither the config's folder nor the result's
    flags = ["--quiet", "--no-figures", "--no-network"]
    assert main(["run", "../proj/cfg.toml", "--out", "first", *flags]) == 0
    first = elsewhere / "first"
    resolved = tomllib.loads((first / "config.resolved.toml").read_text())
    assert resolved["data"]["train"] == [str(proj / "logs" / "cal.csv")]
    monkeypatch.chdir(first)
    assert main(["run", "config.resolved.toml", "--out", "../second", *flags]) == 0
    a = json.loads((first / "metrics.json").read_text())
    b = json.loads((elsewhere / "second" / "metrics.json").read_text())
    assert a["model"]["scenarios"] == b["model"]["scenarios"]
    assert a["model"]["scenarios"]["cal"]["n"] == 360  # the split part, 30 % of 1200
    assert a["data"]["n_train"] == b["data"]["n_train"] == 840


def test_resolved_reference_and_test_files_are_absolute(tmp_path):
    """Every file setting ([data] test as list or table, [data.reference] dh or urdf) is
    written absolute; names and the other settings are untouched."""
    cfg = tmp_path / "sub" / "exp.toml"
    cfg.parent.mkdir()
    cfg.write_text(
        '[joint]\nratio = 160\nrated_torque = 400\n[data]\nkind = "files"\n'
        'train = ["a.csv", "/abs/b.csv"]\ntest = {held = "../c.csv"}\n'
        '[data.reference]\nkind = "wrench"\njoint = 1\ndh = "arm/dh.toml"\n'
        'angles = ["q1"]\nwrench = ["fx", "fy", "fz", "mx", "my", "mz"]\nmodel_torque = "none"\n'
    )
    exp = load_experiment(cfg)
    out = with_absolute_paths(exp)
    base = cfg.parent.resolve()
    assert out["data"]["train"] == [str(base / "a.csv"), "/abs/b.csv"]
    assert out["data"]["test"] == {"held": str(base.parent / "c.csv")}
    assert out["data"]["reference"]["dh"] == str(base / "arm" / "dh.toml")
    assert out["data"]["reference"]["angles"] == ["q1"]
    assert exp["data"]["train"] == ["a.csv", "/abs/b.csv"]  # the input is not changed
