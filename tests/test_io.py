"""CSV / npz loading and saving, column maps, and every bad-file case of issue 2."""

import math

import numpy as np
import pytest

import hdjax
from hdjax._io import ColumnSpec, did_you_mean
from tests.helpers import sim_recording

HEADER = "t,theta_m,theta_l,current,torque"


def write(tmp_path, text, name="log.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def good_rows(n=5):
    return "\n".join(f"{0.01 * i},{0.5 * i},{0.005 * i},{0.1 * i},{i}" for i in range(n))


@pytest.mark.parametrize("fmt", ["csv", "npz"])
def test_round_trip(tmp_path, fmt):
    rec = sim_recording(60)
    path = tmp_path / f"rec.{fmt}"
    (hdjax.save_csv if fmt == "csv" else hdjax.save_npz)(rec, path)
    back = hdjax.load_recording(path)
    assert back.column_names == rec.column_names and back.source == str(path)
    for name in rec.column_names:  # the CSV's shortest exact digits and npz are both exact
        np.testing.assert_array_equal(np.asarray(back.column(name)), np.asarray(rec.column(name)))
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary behind


def test_csv_values_in_their_shortest_exact_digits():
    # 0.004 reads as 0.004, not %.17g's 0.0040000000000000001; every value reads back exactly
    from hdjax._io import csv_bytes

    rng = np.random.default_rng(3)
    cols = {
        "t": np.arange(1000) * 0.004,
        "x": rng.normal(size=1000) * 1e3,
        "odd": np.r_[np.nan, np.inf, -np.inf, 5e-324, 0.1 + 0.2, -0.0, np.zeros(994)],
    }
    text = csv_bytes(cols).decode()
    lines = text.splitlines()
    assert lines[0] == "t,x,odd" and lines[2].split(",")[0] == "0.004" and len(lines) == 1001
    assert lines[5].split(",")[2] == "0.30000000000000004"
    back = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    for j, values in enumerate(cols.values()):
        np.testing.assert_array_equal(back[:, j], values)
    assert lines[6].split(",")[2] == "-0" and np.signbit(back[5, 2])  # -0.0 stays negative
    with pytest.raises(ValueError, match="differ in length"):
        csv_bytes({"a": np.zeros(3), "b": np.zeros(2)})


def test_plain_csv_without_torque_keeps_extras(tmp_path):
    p = write(tmp_path, "t,theta_m,theta_l,current,temp\n0,0,0,0,20\n0.1,1,0.01,0.2,21\n")
    rec = hdjax.load_csv(p)
    assert not rec.has_torque and list(rec.extras) == ["temp"]


def test_column_map_counts_offset_and_wrap(tmp_path):
    cpr = 2**24
    t = np.arange(6) * 0.004
    counts_m = np.array([0, 1, 2, 3, 4, 5]) * cpr // 4 + 7  # quarter turns, offset by 7 counts
    # an 16-bit wrapping load counter: 65530, 65535 -> 4, 9, ...
    load = (65530 + 5 * np.arange(6)) % 65536
    lines = ["stamp,mot,load,cur_mA,Tq"] + [
        f"{t[i]},{counts_m[i]},{load[i]},{100 * i},{i}" for i in range(6)
    ]
    p = write(tmp_path, "\n".join(lines))
    cmap = hdjax.ColumnMap.from_dict(
        {
            "columns": {
                "t": "stamp",
                "theta_m": {"source": "mot", "counts_per_rev": cpr, "offset": "first"},
                "theta_l": {"source": "load", "scale": 1e-3, "modulus": 65536},
                "current": {"source": "cur_mA", "scale": 1e-3},
                "torque": "Tq",
            },
            "extras": {},
        }
    )
    rec = hdjax.load_csv(p, cmap)
    np.testing.assert_allclose(np.asarray(rec.theta_m), np.arange(6) * math.pi / 2, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(rec.theta_l), (65530 + 5 * np.arange(6)) * 1e-3)
    np.testing.assert_allclose(np.asarray(rec.current), 0.1 * np.arange(6))
    assert rec.extras == {}


def test_counter_values_are_exact_in_float64():
    spec = ColumnSpec(source="x", scale=2 * math.pi / 2**24)
    big = np.array([1_401_537_495.0, 1_401_537_496.0])  # LARA8 motor counts, 84 turns
    out = spec.apply(big)
    assert out[1] - out[0] == pytest.approx(2 * math.pi / 2**24, rel=1e-6)


# ------------------------------------------------------------------------------------------
# Bad files


def test_missing_column_names_the_file_and_suggests(tmp_path):
    p = write(tmp_path, "t,theta_m,theta_L,current\n0,0,0,0\n0.1,1,1,1\n")
    with pytest.raises(hdjax.DataError) as err:
        hdjax.load_csv(p)
    msg = str(err.value)
    assert str(p) in msg and "missing column 'theta_l'" in msg and "did you mean 'theta_L'" in msg
    assert "[data.columns]" in msg


def test_misspelt_mapped_column(tmp_path):
    p = write(tmp_path, "stamp,theta_m,theta_l,current\n0,0,0,0\n0.1,1,1,1\n")
    cmap = hdjax.ColumnMap.from_dict({"columns": {"t": "stmp"}})
    with pytest.raises(
        hdjax.DataError, match=r"no column 'stmp' \(for 't'\) \(did you mean 'stamp'\?\)"
    ):
        hdjax.load_csv(p, cmap)


def test_non_numeric_cell(tmp_path):
    p = write(tmp_path, f"{HEADER}\n0,0,0,0,0\n0.1,1,abc,1,1\n")
    with pytest.raises(
        hdjax.DataError, match=r"non-numeric cell 'abc' in column 'theta_l' at line 3"
    ):
        hdjax.load_csv(p)


def test_nan_cell_and_empty_cell(tmp_path):
    p = write(tmp_path, f"{HEADER}\n0,0,0,0,0\n0.1,1,nan,1,1\n")
    with pytest.raises(hdjax.DataError, match=r"log.csv: column 'theta_l' has 1 NaN/inf"):
        hdjax.load_csv(p)
    p = write(tmp_path, f"{HEADER}\n0,0,0,0,0\n0.1,1,1,,1\n", "e.csv")
    with pytest.raises(
        hdjax.DataError, match=r"e.csv: column 'current' has 1 NaN/inf value\(s\), first at row 1"
    ):
        hdjax.load_csv(p)


def test_ragged_rows(tmp_path):
    p = write(tmp_path, f"{HEADER}\n0,0,0,0,0\n0.1,1,1,1\n")
    with pytest.raises(hdjax.DataError, match="line 3 has 4 cells but the header has 5"):
        hdjax.load_csv(p)


def test_empty_file_and_header_only(tmp_path):
    with pytest.raises(hdjax.DataError, match="empty.csv: the file is empty"):
        hdjax.load_csv(write(tmp_path, "", "empty.csv"))
    with pytest.raises(hdjax.DataError, match="h.csv: the file has a header but no data rows"):
        hdjax.load_csv(write(tmp_path, HEADER + "\n", "h.csv"))
    with pytest.raises(hdjax.DataError, match="nope.csv: no such file"):
        hdjax.load_csv(tmp_path / "nope.csv")


def test_duplicated_time_in_file(tmp_path):
    p = write(tmp_path, f"{HEADER}\n0,0,0,0,0\n0.1,1,1,1,1\n0.1,2,2,2,2\n")
    with pytest.raises(
        hdjax.DataError,
        match=r"log.csv: time column 't' must be strictly increasing, but it is duplicated",
    ):
        hdjax.load_csv(p)


def test_bad_npz_and_format(tmp_path):
    p = tmp_path / "x.npz"
    p.write_bytes(b"not a zip")
    with pytest.raises(hdjax.DataError, match="x.npz: not a readable .npz archive"):
        hdjax.load_npz(p)
    np.savez(
        tmp_path / "y.npz",
        t=np.arange(3.0),
        theta_m=np.zeros(3),
        theta_l=np.zeros(2),
        current=np.zeros(3),
    )
    with pytest.raises(hdjax.DataError, match=r"y.npz: columns have different lengths"):
        hdjax.load_npz(tmp_path / "y.npz")
    with pytest.raises(hdjax.DataError, match="unknown recording format '.txt'"):
        hdjax.load_recording(tmp_path / "z.txt")


@pytest.mark.parametrize(
    "table, match",
    [
        ({"colums": {}}, r"\[data\]: unknown key 'colums' \(did you mean 'columns'\?\)"),
        (
            {"columns": {"theta": "x"}},
            r"'theta' is not a schema column \(did you mean 'theta_m'\?\)",
        ),
        (
            {"columns": {"t": {"sorce": "x"}}},
            r"\[data\].columns.t: unknown key 'sorce' \(did you mean 'source'\?\)",
        ),
        ({"columns": {"t": {"scale": 2.0}}}, r"\[data\].columns.t: missing 'source'"),
        ({"columns": {"t": {"source": "x", "scale": 1.0, "counts_per_rev": 4}}}, "not both"),
        (
            {"columns": {"t": {"source": "x", "counts_per_rev": -4}}},
            "'counts_per_rev' must be a positive",
        ),
        ({"columns": {"t": {"source": "x", "scale": 0}}}, "'scale' must be a finite non-zero"),
        ({"columns": {"t": {"source": "x", "offset": "last"}}}, "'offset' must be a number or"),
        ({"columns": {"t": 3}}, "expected a column name or a table"),
    ],
)
def test_bad_column_map(table, match):
    with pytest.raises(hdjax.ConfigError, match=match):
        hdjax.ColumnMap.from_dict(table)


def test_did_you_mean():
    assert did_you_mean("curent", ["current", "torque"]) == " (did you mean 'current'?)"
    assert did_you_mean("zzz", ["current"]) == ""
