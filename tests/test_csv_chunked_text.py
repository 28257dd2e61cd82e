"""The chunked CSV reader decodes text by the rules of the whole-file reader: UTF-8 with or
without a byte-order mark, or the column map's `encoding`; a byte that does not decode (or a
NUL) is refused with the same line, naming the file and the byte position."""

import numpy as np
import pytest

import hdjax._formats._csv as chunked
from hdjax import ColumnMap, DataError, load_csv
from hdjax._formats import iter_recordings
from hdjax._io import _read_csv_table

HEADER = "t,theta_m,theta_l,current,temp_°C\n"


def _text(n: int = 40) -> str:
    rows = [
        f"{i * 1e-3:.3f},{0.1 * i:.4f},{0.1 * i / 160:.6f},{0.01 * i:.3f},2{i % 10}.5"
        for i in range(n)
    ]
    return HEADER + "\n".join(rows) + "\n"


def _error(fn) -> str:
    with pytest.raises(DataError) as info:
        fn()
    return str(info.value)


def _chunked(path, encoding=None):
    return list(chunked.iter_tables(path, 3, None, encoding))


@pytest.fixture
def small_blocks(monkeypatch):
    """Locate bad bytes in 7-byte blocks, so that characters and lines straddle blocks."""
    monkeypatch.setattr(chunked, "_BLOCK", 7)


@pytest.mark.parametrize("bad", [b"\xb0", b"\xe2\x82", b"\x00"], ids=["latin1", "cut", "nul"])
def test_bad_bytes_named_as_the_whole_file_reader_names_them(tmp_path, small_blocks, bad):
    """Every insertion point (header, cells, line ends, before and after the multi-byte °)
    gives the one line of the whole-file reader: same byte, same position, same line."""
    data = _text(12).encode()
    path = tmp_path / "log.csv"
    for bom in (b"", b"\xef\xbb\xbf"):
        for k in range(0, len(data), 5):
            path.write_bytes(bom + data[:k] + bad + data[k:])
            expected = _error(lambda: _read_csv_table(path))
            assert "byte position" in expected, expected
            assert _error(lambda: _chunked(path)) == expected, (bom, k)


def test_encoding_setting_reads_latin1_and_utf16(tmp_path):
    """With the map's encoding the chunks are the whole file; without it, the same refusal."""
    for encoding in ("latin-1", "utf-16"):
        path = tmp_path / f"{encoding}.csv"
        path.write_bytes(_text().encode(encoding))
        header, body = _read_csv_table(path, encoding)
        assert header[-1] == "temp_°C"
        parts = _chunked(path, encoding)
        assert list(parts[0]) == header
        np.testing.assert_array_equal(np.concatenate([p["temp_°C"] for p in parts]), body[:, -1])
        refusal = _error(lambda: _read_csv_table(path))
        assert _error(lambda: _chunked(path)) == refusal
        cmap = ColumnMap.from_dict({"encoding": encoding})
        chunks = list(iter_recordings(path, cmap, chunk=8))
        whole = load_csv(path, cmap)
        got = np.concatenate([np.asarray(r.column("temp_°C")) for r in chunks])
        np.testing.assert_array_equal(got, np.asarray(whole.column("temp_°C")))


def test_byte_order_mark_dropped(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + _text().encode())
    assert chunked.column_names(path)[0] == "t"
    assert list(_chunked(path)[0])[0] == "t"
