"""`hdjax estimate` and `hdjax discover` refuse, in one line, logs too large for the free
memory, before reading them (the free memory is patched small; the logs are real)."""

import pytest

import hdjax._memory as preflight
from hdjax import Joint, save_csv
from hdjax.cli import main
from hdjax.pipelines import synthetic_recording


@pytest.fixture
def logs(tmp_path, monkeypatch):
    rec = synthetic_recording(Joint(ratio=160, rated_torque=400), 2000, seed=0)
    save_csv(rec, tmp_path / "log.csv")
    (tmp_path / "joint.toml").write_text("[joint]\nratio = 160\nrated_torque = 400\n")
    size = (tmp_path / "log.csv").stat().st_size
    # reading a CSV whole takes about 15 times its size; 5 times is free
    monkeypatch.setattr(preflight, "available_memory", lambda: 5 * size)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize(
    "argv",
    [
        ["estimate", "--model", "model.json", "--data", "log.csv", "--out", "e.csv"],
        ["discover", "--train", "log.csv", "--test", "log.csv", "--joint", "joint.toml"]
        + ["--out", "d"],
    ],
    ids=["estimate", "discover"],
)
def test_log_larger_than_free_memory_refused_before_reading(logs, argv, capsys):
    before = sorted(p.name for p in logs.iterdir())
    assert main([*argv, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "reading log.csv" in err and "of memory but only" in err, err
    assert sorted(p.name for p in logs.iterdir()) == before


def test_the_estimate_covers_what_reading_takes(tmp_path):
    """The check's estimate is at least the peak that reading the CSV whole allocates
    (measured with tracemalloc: about 10.4 times the file), and not above twice it."""
    import tracemalloc

    from hdjax import load_csv

    rec = synthetic_recording(Joint(ratio=160, rated_torque=400), 2000, seed=0)
    path = tmp_path / "log.csv"
    save_csv(rec, path)
    load_csv(path)  # imports and caches outside the measurement
    tracemalloc.start()
    try:
        load_csv(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    with pytest.raises(preflight.ConfigError, match="of memory"):
        preflight.check_read_memory([path], fix="-", free=peak)
    preflight.check_read_memory([path], fix="-", free=2 * peak)
