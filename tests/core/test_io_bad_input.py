"""Inputs the readers used to take wrongly, each now read right or refused in one line: a
CSV with a byte-order mark (spreadsheets' "CSV UTF-8"), and two columns under one name (the
second went unreported: channels are picked and reported by name)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from avard.core.errors import DataError
from avard.core.io.readers import load_record
from avard.core.io.source import open_record

N = 4000


def _csv(path: Path, header: str, *, bom: bool = False) -> Path:
    rng = np.random.default_rng(4)
    rows = np.column_stack([np.arange(N) / 100.0, rng.normal(0, 1e-3, (N, 3))])
    text = header + "\n" + "\n".join(",".join(f"{v:.9g}" for v in r) for r in rows) + "\n"
    path.write_text(text, encoding="utf-8-sig" if bom else "utf-8")
    return path


def test_a_byte_order_mark_does_not_hide_the_time_column(tmp_path) -> None:
    plain = _csv(tmp_path / "plain.csv", "t,x,y,z")
    marked = _csv(tmp_path / "marked.csv", "t,x,y,z", bom=True)
    assert marked.read_bytes()[:3] == b"\xef\xbb\xbf"
    for read in (load_record, lambda p: open_record(p).info):
        a, b = read(plain), read(marked)
        assert (b.rate_hz, list(b.names)) == (a.rate_hz, list(a.names))
        assert list(b.names) == ["x", "y", "z"] and b.rate_hz == pytest.approx(100.0)
    np.testing.assert_array_equal(load_record(marked).accel, load_record(plain).accel)


def test_two_csv_columns_under_one_name_are_refused(tmp_path) -> None:
    p = _csv(tmp_path / "dup.csv", "t,x,x,z")
    for read in (load_record, lambda p: open_record(p).info):
        with pytest.raises(DataError, match=r"'x' is given to two columns.*name every column"):
            read(p)


@pytest.mark.parametrize("key", ["axes", "temperature_names"])
def test_two_npz_channels_under_one_name_are_refused(tmp_path, key) -> None:
    rng = np.random.default_rng(5)
    extra = ({"axes": np.array(["x", "x", "z"])} if key == "axes" else
             {"temperature_c": np.ones((N, 2)), "temperature_names": np.array(["a", "a"])})
    p = tmp_path / "dup.npz"
    np.savez(p, accel=rng.normal(0, 1e-3, (N, 3)), rate_hz=100.0, **extra)
    for read in (load_record, lambda p: open_record(p).info):
        with pytest.raises(DataError, match=rf"is given to two columns.*fix '{key}'"):
            read(p)


@pytest.mark.parametrize("extra, said", [
    ({"accel": np.zeros((N, 0))}, r"accel has shape \(4000, 0\).*C > 0"),
    ({"temperature_c": np.array(["a"] * N)}, r"temperature_c has dtype <U1; it must be numbers"),
    ({"temperature_c": np.float64(20.0)}, r"temperature_c has shape \(\)"),
])
def test_an_npz_whose_arrays_cannot_be_its_samples_is_refused(tmp_path, extra, said) -> None:
    """Zero accel columns ended analyze in a ValueError traceback; temperatures as strings
    went through analyze unread and ended explain in one; a 0-d temperature_c in an
    IndexError."""
    rng = np.random.default_rng(6)
    arrays = {"accel": rng.normal(0, 1e-3, (N, 3)), "rate_hz": 100.0, **extra}
    p = tmp_path / "bad.npz"
    np.savez(p, **arrays)
    for read in (load_record, lambda p: open_record(p).info):
        with pytest.raises(DataError, match=said):
            read(p)
