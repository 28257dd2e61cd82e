"""Log formats: chunked CSV, Parquet, HDF5, MATLAB v7.3 and MCAP, each read through a column map
from a file the test writes, whole and in chunks, against the same log read from CSV."""

import json

import numpy as np
import pytest

import hdjax
from hdjax._formats import iter_recordings, load
from hdjax._io import csv_bytes
from hdjax.cli import main

N = 257  # odd, so chunks of 64 leave a one-row tail (folded into the last chunk)
CPR = 2**16  # a 16-bit load counter that wraps during the log


def raw_log(n=N, seed=3):
    """Raw columns as a logger writes them: counts, mA, a wrapping counter, a temperature."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    theta_l = 1.5 * np.sin(2 * np.pi * 2.0 * t)
    mot = np.round(theta_l * 100 / (2 * np.pi) * 2**20) + 12345  # motor counts, 20-bit, offset
    load = np.round(theta_l / (2 * np.pi) * CPR * 4) % CPR  # wraps (4 counts per CPR/4)
    return {
        "stamp": t,
        "mot": mot,
        "load": load,
        "cur_mA": 1e3 * (0.3 * np.cos(2 * np.pi * 2.0 * t) + 0.01 * rng.standard_normal(n)),
        "Tq": 40 * np.cos(2 * np.pi * 2.0 * t),
        "temp": 30 + 0.001 * np.arange(n),
    }


CMAP = hdjax.ColumnMap.from_dict(
    {
        "columns": {
            "t": "stamp",
            "theta_m": {"source": "mot", "counts_per_rev": 2**20, "offset": "first"},
            "theta_l": {"source": "load", "counts_per_rev": 4 * CPR, "modulus": CPR},
            "current": {"source": "cur_mA", "scale": 1e-3},
            "torque": "Tq",
        },
        "extras": {"temp": "temp"},
    }
)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    d = tmp_path_factory.mktemp("formats")
    raw = raw_log()
    path = d / "log.csv"
    path.write_bytes(csv_bytes(raw))
    return d, raw, path, hdjax.load_csv(path, CMAP)


def same(a, b, rtol=0.0):
    assert a.column_names == b.column_names
    for name in a.column_names:
        np.testing.assert_allclose(
            np.asarray(a.column(name)), np.asarray(b.column(name)), rtol=rtol, atol=0
        )


def concat(chunks):
    cols = [c.to_numpy() for c in chunks]
    t = {k: np.concatenate([c[k] for c in cols]) for k in cols[0]}
    return hdjax.make_recording(
        t["t"],
        t["theta_m"],
        t["theta_l"],
        t["current"],
        t["torque"],
        {k: v for k, v in t.items() if k not in ("t", "theta_m", "theta_l", "current", "torque")},
        check_units=False,
    )


def write_parquet(path, raw):
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table(raw), path, row_group_size=100)


def write_hdf5(path, raw):
    import h5py

    with h5py.File(path, "w") as f:
        g = f.create_group("log")
        for k, v in raw.items():
            g.create_dataset(k, data=v)


def write_mat73(path, raw):
    """What MATLAB's save(..., '-v7.3') writes: a 512-byte user block and (1, n) variables."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for k, v in raw.items():
            f.create_dataset(k, data=np.asarray(v)[None, :])
        f.create_group("#refs#")


def write_mcap_json(path, raw):
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        schema = w.register_schema("joint", "jsonschema", json.dumps({"type": "object"}).encode())
        ch = w.register_channel("/joint1/state", "json", schema)
        env = w.register_channel("/joint1/env", "json", schema)
        for i in range(len(raw["stamp"])):
            ns = int(round(raw["stamp"][i] * 1e9))
            msg = {
                "stamp": raw["stamp"][i],
                "enc": [raw["mot"][i], raw["load"][i]],
                "drive": {"cur_mA": raw["cur_mA"][i], "Tq": raw["Tq"][i]},
            }
            w.add_message(ch, log_time=ns, data=json.dumps(msg).encode(), publish_time=ns)
            w.add_message(
                env,
                log_time=ns,
                data=json.dumps({"temp": raw["temp"][i]}).encode(),
                publish_time=ns,
            )
        w.finish()


MCAP_MAP = hdjax.ColumnMap.from_dict(
    {
        "columns": {
            "t": "/joint1/state:stamp",
            "theta_m": {
                "source": "/joint1/state:enc[0]",
                "counts_per_rev": 2**20,
                "offset": "first",
            },
            "theta_l": {"source": "enc[1]", "counts_per_rev": 4 * CPR, "modulus": CPR},
            "current": {"source": "drive.cur_mA", "scale": 1e-3},
            "torque": "/joint1/state:drive.Tq",
        },
        "extras": {"temp": "/joint1/env:temp"},
    }
)


def write_mcap_ros2(path, raw):
    from mcap_ros2.writer import Writer

    msgdef = "float64 stamp\nfloat64[] position\nfloat64 current\nfloat64 effort\nfloat64 temp"
    with open(path, "wb") as fh:
        w = Writer(fh)
        schema = w.register_msgdef("hdjax_test/JointLog", msgdef)
        for i in range(len(raw["stamp"])):
            ns = int(round(raw["stamp"][i] * 1e9))
            w.write_message(
                "/joint_log",
                schema,
                {
                    "stamp": float(raw["stamp"][i]),
                    "position": [raw["mot"][i], raw["load"][i]],
                    "current": float(raw["cur_mA"][i]),
                    "effort": float(raw["Tq"][i]),
                    "temp": float(raw["temp"][i]),
                },
                log_time=ns,
                publish_time=ns,
            )
        w.finish()


ROS2_MAP = hdjax.ColumnMap.from_dict(
    {
        "columns": {
            "t": "stamp",
            "theta_m": {"source": "position[0]", "counts_per_rev": 2**20, "offset": "first"},
            "theta_l": {
                "source": "/joint_log:position[1]",
                "counts_per_rev": 4 * CPR,
                "modulus": CPR,
            },
            "current": {"source": "current", "scale": 1e-3},
            "torque": "effort",
        },
        "extras": {"temp": "temp"},
    }
)

FORMATS = {
    "parquet": (".parquet", write_parquet, CMAP),
    "hdf5": (
        ".h5",
        write_hdf5,
        hdjax.ColumnMap.from_dict(
            {
                "columns": {
                    k: (
                        {**v, "source": "log/" + v["source"]} if isinstance(v, dict) else "log/" + v
                    )
                    for k, v in {
                        "t": "stamp",
                        "theta_m": {"source": "mot", "counts_per_rev": 2**20, "offset": "first"},
                        "theta_l": {"source": "load", "counts_per_rev": 4 * CPR, "modulus": CPR},
                        "current": {"source": "cur_mA", "scale": 1e-3},
                        "torque": "Tq",
                    }.items()
                },
                "extras": {"temp": "log/temp"},
            }
        ),
    ),
    "mat73": (".mat", write_mat73, CMAP),
    "mcap-json": (".mcap", write_mcap_json, MCAP_MAP),
    "mcap-ros2": (".mcap", write_mcap_ros2, ROS2_MAP),
}


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_format_matches_csv_whole_and_chunked(reference, fmt):
    d, raw, _, ref = reference
    suffix, write, cmap = FORMATS[fmt]
    path = d / f"log-{fmt}{suffix}"
    write(path, raw)
    whole = hdjax.load_recording(path, cmap)
    same(whole, ref)  # every format stores float64 exactly
    chunks = list(iter_recordings(path, cmap, chunk=64))
    assert [c.n_samples for c in chunks] == [64, 64, 64, 65]
    same(concat(chunks), ref, rtol=1e-15)  # unwrapping continued across chunk boundaries


def test_chunked_csv_equals_whole_csv(reference):
    _, raw, path, ref = reference
    assert int(np.ptp(raw["load"])) > CPR // 2  # the counter really wraps in this log
    chunks = list(iter_recordings(path, CMAP, chunk=50))
    assert [c.n_samples for c in chunks] == [50] * 5 + [7]
    same(concat(chunks), ref, rtol=1e-15)


@pytest.mark.parametrize("chunk", [2, 50, 10_000])
def test_load_recording_in_chunks_equals_whole(reference, chunk):
    # the chunks joined are the whole file's recording (the parser holds one chunk at a time)
    d, raw, path, ref = reference
    rec = hdjax.load_recording(path, CMAP, chunk=chunk)
    same(rec, ref, rtol=1e-15)
    assert rec.source == ref.source
    pq = d / "log-joined.parquet"
    write_parquet(pq, raw)
    same(hdjax.load_recording(pq, CMAP, chunk=chunk), ref, rtol=1e-15)
    with pytest.raises(hdjax.DataError, match="chunk must be an integer >= 2"):
        hdjax.load_recording(path, CMAP, chunk=1)


def test_plain_mcap_topic_needs_no_map(tmp_path):
    from mcap.writer import Writer

    rec = hdjax.make_recording(
        np.arange(5) * 0.01, np.arange(5) * 0.1, np.arange(5) * 1e-3, np.ones(5), np.arange(5.0)
    )
    path = tmp_path / "plain.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sch = w.register_schema("j", "jsonschema", b"{}")
        ch = w.register_channel("/j", "json", sch)
        for i in range(5):
            row = {k: float(v[i]) for k, v in rec.to_numpy().items()} | {"temp": 20.0 + i}
            w.add_message(ch, log_time=i, data=json.dumps(row).encode(), publish_time=i)
        w.finish()
    back = load(path)
    assert back.column_names == ("t", "theta_m", "theta_l", "current", "torque", "temp")
    np.testing.assert_array_equal(np.asarray(back.theta_m), np.asarray(rec.theta_m))


def test_unknown_suffix_and_missing_column_are_one_line_errors(reference, tmp_path):
    d, raw, _, _ = reference
    bad = tmp_path / "log.xlsx"
    bad.write_text("x")
    with pytest.raises(hdjax.DataError, match="unknown recording format '.xlsx'.*parquet"):
        hdjax.load_recording(bad)
    path = d / "log-missing.parquet"
    write_parquet(path, {k: v for k, v in raw.items() if k != "Tq"})
    with pytest.raises(hdjax.DataError, match="no column 'Tq'.*the file has: stamp"):
        hdjax.load_recording(path, CMAP)
    v5 = tmp_path / "old.mat"
    v5.write_bytes(b"MATLAB 5.0 MAT-file" + bytes(200))
    with pytest.raises(hdjax.DataError, match="saved as v7.3"):
        hdjax.load_recording(v5)


def test_missing_extra_names_the_install(monkeypatch, tmp_path):
    monkeypatch.setitem(__import__("sys").modules, "h5py", None)  # import h5py now fails
    p = tmp_path / "x.h5"
    p.write_bytes(b"\x89HDF")
    with pytest.raises(hdjax.DataError, match=r"pip install 'hdjax\[hdf5\]'"):
        hdjax.load_recording(p)


def test_convert_cli(reference, tmp_path, capsys):
    d, raw, path, ref = reference
    cmap_toml = tmp_path / "map.toml"
    cmap_toml.write_text(
        '[data.columns]\nt = "stamp"\ntorque = "Tq"\n'
        'theta_m = { source = "mot", counts_per_rev = 1048576, offset = "first" }\n'
        'theta_l = { source = "load", counts_per_rev = 262144, modulus = 65536 }\n'
        'current = { source = "cur_mA", scale = 1e-3 }\n[data.extras]\ntemp = "temp"\n'
    )
    mapped, rawpq = tmp_path / "mapped.parquet", tmp_path / "raw.parquet"
    assert (
        main(
            ["convert", str(path), str(mapped), "--columns", str(cmap_toml), "--chunk", "100", "-q"]
        )
        == 0
    )
    same(hdjax.load_recording(mapped), ref, rtol=1e-15)
    assert main(["convert", str(path), str(rawpq), "--chunk", "100", "-q"]) == 0
    same(hdjax.load_recording(rawpq, CMAP), ref)
    # refused without --overwrite, and nothing half-written on a bad input
    assert main(["convert", str(path), str(rawpq), "-q"]) == 2
    assert "already exists" in capsys.readouterr().err
    broken = tmp_path / "broken.csv"
    broken.write_text(path.read_text() + "1.0,oops,3,4,5,6\n")
    assert main(["convert", str(broken), str(tmp_path / "b.parquet"), "--chunk", "64", "-q"]) == 2
    assert "non-numeric cell 'oops'" in capsys.readouterr().err
    assert not list(tmp_path.glob("*b.parquet*"))


def test_estimate_help_names_every_format(capsys):
    from hdjax._formats import SUFFIXES

    assert main(["estimate", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    data = text.split("options:", 1)[1].split("--data DATA", 1)[1].split("--out", 1)[0]
    for suffix in SUFFIXES:
        assert suffix in data, (suffix, data)
