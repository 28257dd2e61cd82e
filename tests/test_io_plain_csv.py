"""The fast reader of plain CSV bodies against the careful cell-by-cell parser.

`_read_csv_table` reads a plain body (numbers and commas only) with NumPy's C parser and
anything else cell by cell (`parse_cells`, which names a bad cell); both must give the same
float64 array, and every non-plain file must still reach the careful parser.
"""

import csv

import numpy as np
import pytest

from hdjax._errors import DataError
from hdjax._io import _plain_body, _read_csv_table, parse_cells


def _careful(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header = [h.strip() for h in rows[0]]
    rows = [r for r in rows[1:] if r and any(c.strip() for c in r)]
    return parse_cells(path, header, rows, 2)


def test_plain_body_equals_the_careful_parser(tmp_path):
    rng = np.random.default_rng(0)
    x = rng.standard_normal((3000, 4)) * 10.0 ** rng.integers(-300, 300, (3000, 4))
    x[0] = [0.0, -0.0, np.inf, -np.inf]
    path = tmp_path / "plain.csv"
    lines = ["t,a, b ,c"] + [",".join(repr(float(v)) for v in row) for row in x]
    lines[5] = lines[5].replace(",", " , ")  # spaces around cells
    lines.insert(9, "")  # a blank line
    lines.append("nan,NaN,1e5,+.5")
    path.write_text("\r\n".join(lines) + "\r\n")
    header, body = _read_csv_table(path)
    assert header == ["t", "a", "b", "c"]
    assert _plain_body(path.read_text(), 4) is not None  # the fast path was taken
    ref = _careful(path)
    # the same decimal strings parsed to the same doubles (NaN where NaN)
    np.testing.assert_array_equal(body, ref)
    np.testing.assert_array_equal(body[:-1], x)  # repr round-trips


@pytest.mark.parametrize(
    "text",
    [
        "a,b\n1,\n3,4\n",  # an empty cell: NaN
        'a,b\n"1",2\n',  # quoted cells
        "a,b\n1,2\n , \n3,4\n",  # a row of blank cells, dropped
        "a,b\n1,2\n  \n3,4\n",  # a whitespace-only line, dropped
    ],
)
def test_other_bodies_take_the_careful_parser(tmp_path, text):
    path = tmp_path / "x.csv"
    path.write_text(text)
    assert _plain_body(text, 2) is None
    header, body = _read_csv_table(path)
    np.testing.assert_array_equal(body, _careful(path))


@pytest.mark.parametrize(
    "text, message",
    [
        ("a,b\n1,2\n3,x\n", "non-numeric cell 'x' in column 'b' at line 3"),
        ("a,b\n1,2\n3,4,5\n", "line 3 has 3 cells but the header has 2"),
        ("a,a\n1,2\n", "duplicated column name"),
        ("a,b\n", "no data rows"),
    ],
)
def test_bad_files_are_refused_by_name(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=message):
        _read_csv_table(path)
