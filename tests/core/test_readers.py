"""One reader for .npz, .csv and recordings: values, streaming, and clear errors."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from avard.core.errors import DataError, FormatError
from avard.core.io.readers import Record, iter_blocks, load_record, record_info


def _npz(path: Path, compressed: bool = False, **arrays) -> Path:
    (np.savez_compressed if compressed else np.savez)(path, **arrays)
    return path


@pytest.mark.parametrize("compressed", [False, True])
@pytest.mark.parametrize("fortran", [False, True])
def test_npz_round_trip_and_streaming(tmp_path: Path, compressed: bool, fortran: bool) -> None:
    rng = np.random.default_rng(0)
    accel = rng.normal(size=(10_001, 3))
    temp = np.full((10_001, 2), np.nan)
    temp[::100] = 21.5
    if fortran:
        accel = np.asfortranarray(accel)
    p = _npz(tmp_path / "r.npz", compressed, accel=accel, rate_hz=125.0,
             axes=np.array(["X", "Y", "Z"]), temperature_c=temp,
             temperature_names=np.array(["plate", "air"]), gyro=accel * 0.1)
    rec = load_record(p)
    assert isinstance(rec, Record)
    assert np.array_equal(rec.accel, accel) and rec.rate_hz == 125.0
    assert rec.names == ["X", "Y", "Z"] and rec.temperature_names == ["plate", "air"]
    assert np.array_equal(rec.temperature_c, temp, equal_nan=True)
    assert np.array_equal(rec.gyro, accel * 0.1)
    assert rec.duration_s == pytest.approx(10_001 / 125.0)
    meta, blocks = iter_blocks(p, block=4096)
    parts = list(blocks)
    assert [len(a) for a, _ in parts] == [4096, 4096, 1809]
    assert np.array_equal(np.concatenate([a for a, _ in parts]), accel)
    assert meta["n_samples"] == 10_001 and meta["names"] == ["X", "Y", "Z"]


def test_npz_one_channel_integer_and_rate_override(tmp_path: Path) -> None:
    p = _npz(tmp_path / "one.npz", accel=np.arange(100, dtype=np.int32))
    with pytest.raises(DataError, match="--rate"):
        load_record(p)
    rec = load_record(p, rate_hz=10.0)
    assert rec.accel.shape == (100, 1) and rec.accel.dtype == np.float64
    assert rec.names == ["ch0"] and rec.rate_hz == 10.0


@pytest.mark.parametrize("rate", [0.0, -5.0, float("nan"), float("inf"), 1e9])
def test_impossible_rate_is_refused(tmp_path: Path, rate: float) -> None:
    p = _npz(tmp_path / "r.npz", accel=np.zeros((10, 3)), rate_hz=rate)
    with pytest.raises(DataError, match="Hz"):
        load_record(p)


def test_npz_errors_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="no 'accel'"):
        load_record(_npz(tmp_path / "a.npz", acc=np.zeros(3), rate_hz=1.0))
    bad = np.zeros((50, 3))
    bad[17, 1] = np.nan
    with pytest.raises(DataError, match="sample 17"):
        load_record(_npz(tmp_path / "b.npz", accel=bad, rate_hz=1.0))
    with pytest.raises(DataError, match="temperature_c"):
        load_record(_npz(tmp_path / "c.npz", accel=np.zeros((5, 3)), rate_hz=1.0,
                         temperature_c=np.zeros(4)))
    with pytest.raises(DataError, match="axis names"):
        load_record(_npz(tmp_path / "d.npz", accel=np.zeros((5, 3)), rate_hz=1.0,
                         axes=np.array(["x", "y"])))
    np.savez(tmp_path / "e.npz", accel=np.array([object(), 1], dtype=object), rate_hz=1.0)
    with pytest.raises(FormatError, match="objects"):
        load_record(tmp_path / "e.npz")
    (tmp_path / "f.npz").write_bytes(b"this is not a zip")
    with pytest.raises(FormatError, match=r"not a complete \.npz"):
        load_record(tmp_path / "f.npz")
    with pytest.raises(DataError, match="no such file"):
        load_record(tmp_path / "missing.npz")
    (tmp_path / "g.dat").write_text("x")
    with pytest.raises(FormatError, match="unknown data format"):
        load_record(tmp_path / "g.dat")


def test_truncated_npz_member_is_reported(tmp_path: Path) -> None:
    p = _npz(tmp_path / "t.npz", accel=np.zeros((1000, 3)), rate_hz=1.0)
    with zipfile.ZipFile(p) as zf:
        data = zf.read("accel.npy")
    with zipfile.ZipFile(tmp_path / "short.npz", "w") as zf:
        zf.writestr("accel.npy", data[:-240])
        zf.writestr("rate_hz.npy", _npy(1.0))
    with pytest.raises(FormatError, match="truncated"):
        load_record(tmp_path / "short.npz")


def _npy(v: float) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, np.float64(v))
    return buf.getvalue()


def test_csv_with_time_column_and_temperatures(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(3000, 2))
    t = np.arange(3000) / 62.5
    lines = ["t,ax,az,temp_plate,gyro_x"] + [
        f"{t[i]:.6f},{float(a[i, 0])!r},{float(a[i, 1])!r},{20 + i * 1e-3:.4f},0.0"
        for i in range(3000)]
    p = tmp_path / "r.csv"
    p.write_text("\n".join(lines) + "\n")
    rec = load_record(p)
    assert rec.rate_hz == pytest.approx(62.5, rel=1e-6)
    assert rec.names == ["ax", "az"] and rec.temperature_names == ["temp_plate"]
    assert np.allclose(rec.accel, a, rtol=0, atol=0)
    assert rec.temperature_c.shape == (3000, 1)
    meta, blocks = iter_blocks(p, block=1000)
    assert meta["n_samples"] is None and len(list(blocks)) == 3


def test_csv_without_time_needs_rate_and_semicolons_work(tmp_path: Path) -> None:
    p = tmp_path / "r.csv"
    p.write_text("x;y;z\n" + "".join(f"{i};{-i};0.5\n" for i in range(20)))
    with pytest.raises(DataError, match="--rate"):
        load_record(p)
    rec = load_record(p, rate_hz=4.0)
    assert rec.accel.shape == (20, 3) and rec.accel[3, 1] == -3.0
    assert record_info(p, rate_hz=4.0)["names"] == ["x", "y", "z"]


def test_csv_errors_name_the_problem(tmp_path: Path) -> None:
    p = tmp_path / "a.csv"
    p.write_text("1,2,3\n4,5,6\n")
    with pytest.raises(DataError, match="header"):
        load_record(p, rate_hz=1.0)
    p.write_text("t,temp_a\n0,1\n1,2\n")
    with pytest.raises(DataError, match="no acceleration column"):
        load_record(p)
    p.write_text("t,x\n0,1\n1,2\n0.5,3\n")
    with pytest.raises(DataError, match="increas"):
        load_record(p)
    p.write_text("t,x,y\n0,1,2\n1,2\n")
    with pytest.raises(DataError, match=r"fields|number"):
        load_record(p)
    p.write_text("x,y\n1,abc\n")
    with pytest.raises(DataError, match="number"):
        load_record(p, rate_hz=1.0)


def test_recording_dispatch_is_lazy_and_reads_avard_recordings(tmp_path: Path) -> None:
    """A directory or .avr goes to avard.core.io.recording; a directory without a recording
    says so."""
    empty = tmp_path / "rec"
    empty.mkdir()
    with pytest.raises((FormatError, DataError)):
        load_record(empty)


def test_real_imudata_reads(imudata_dir: Path) -> None:
    rec = load_record(imudata_dir / "adis16405_run1.npz")
    assert rec.accel.shape == (1_000_000, 3) and rec.rate_hz == 100.0
    assert rec.names == ["x", "y", "z"]
    assert rec.accel[:, 2].mean() == pytest.approx(-1.017 * 9.80665, rel=0.01)
    assert rec.gyro is not None and rec.gyro.shape == (1_000_000, 3)


@pytest.mark.parametrize("compressed", [False, True])
@pytest.mark.parametrize("dtype", [np.float64, np.int32])
def test_npz_columns_alone_and_without_temperatures(tmp_path: Path, compressed: bool,
                                                     dtype: type) -> None:
    """A pass over chosen accel columns gives exactly those columns as float64, in the order
    asked, for stored and deflated members of any numeric dtype."""
    rng = np.random.default_rng(4)
    accel = rng.integers(-1000, 1000, size=(9_000, 3)).astype(dtype)
    p = _npz(tmp_path / "c.npz", compressed, accel=accel, rate_hz=10.0,
             temperature_c=np.full(9_000, 20.0))
    meta, blocks = iter_blocks(p, block=4000, columns=[2, 0], temperature=False)
    parts = list(blocks)
    assert meta["names"] == ["x", "y", "z"] and meta["n_samples"] == 9_000
    assert all(t is None for _, t in parts)
    got = np.concatenate([a for a, _ in parts])
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, accel[:, [2, 0]].astype(np.float64))
    with pytest.raises(DataError, match="columns"):
        iter_blocks(p, columns=[3])


@pytest.mark.parametrize("compressed", [False, True])
def test_npz_columns_in_blocks_longer_than_one_read(tmp_path: Path, compressed: bool,
                                                    monkeypatch) -> None:
    """A block of chosen columns longer than ``READ_ROWS`` (a parallel chunk's) is read
    in pieces of at most that many rows: the same values and block lengths, its CRC still
    checked over the whole member, and a member that ends early still said to be
    truncated."""
    from avard.core.io import readers

    monkeypatch.setattr(readers, "READ_ROWS", 1000)
    accel = np.random.default_rng(6).normal(size=(9_500, 3))
    p = _npz(tmp_path / "c.npz", compressed, accel=accel, rate_hz=10.0)
    _meta, blocks = iter_blocks(p, block=4000, columns=[2, 0], temperature=False)
    parts = [a for a, _ in blocks]
    assert [len(a) for a in parts] == [4000, 4000, 1500]
    np.testing.assert_array_equal(np.concatenate(parts), accel[:, [2, 0]])
    if not compressed:  # a flipped bit in the last read block's rows: the CRC says so
        raw = bytearray(p.read_bytes())
        raw[raw.index(accel[9_000].tobytes())] ^= 0x01
        bad = tmp_path / "bad.npz"
        bad.write_bytes(bytes(raw))
        with pytest.raises(FormatError, match="CRC"):
            for _ in iter_blocks(bad, block=4000, columns=[1])[1]:
                pass
    with zipfile.ZipFile(p) as zf:
        data = zf.read("accel.npy")
    with zipfile.ZipFile(tmp_path / "short.npz", "w") as zf:
        zf.writestr("accel.npy", data[:-24 * 2000])
        zf.writestr("rate_hz.npy", _npy(10.0))
    with pytest.raises(FormatError, match=r"ends after 7500 of 9500 samples; the file is "
                                          "truncated"):
        for _ in iter_blocks(tmp_path / "short.npz", block=4000, columns=[0])[1]:
            pass
    # a short member followed by an entry larger than what it lacks: the rows stop at the
    # member's end, the next entry's bytes are never read as samples
    with zipfile.ZipFile(tmp_path / "short2.npz", "w") as zf:
        zf.writestr("accel.npy", data[:-24 * 2000])
        zf.writestr("rate_hz.npy", _npy(10.0))
        zf.writestr("notes.npy", _npy(np.ones(10_000)))
    for verify_columns in ([0], None):
        with pytest.raises(FormatError, match=r"ends after 7500 of 9500 samples"):
            for _ in iter_blocks(tmp_path / "short2.npz", block=4000,
                                 columns=verify_columns)[1]:
                pass


@pytest.mark.parametrize("loop", ["compiled", "zlib"])
def test_a_damaged_stored_npz_fails_its_crc_unless_told_not_to_check(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, loop: str) -> None:
    """By the compiled CRC loop (core/io/crc.py, when built) and by zlib's alike."""
    from avard.core.io import crc

    if loop == "zlib":
        monkeypatch.setattr(crc, "_compiled", None)
    elif crc._compiled is None:
        pytest.skip("the compiled frame loop is not built or switched off")
    accel = np.random.default_rng(5).normal(size=(5_000, 3))
    p = _npz(tmp_path / "d.npz", accel=accel, rate_hz=10.0)
    raw = bytearray(p.read_bytes())
    i = raw.index(accel[2_500].tobytes())  # a byte inside the accel data
    raw[i] ^= 0x01
    p.write_bytes(bytes(raw))
    with pytest.raises(FormatError, match="CRC"):
        for _ in iter_blocks(p, block=1000)[1]:
            pass
    # a later pass over a file its first pass checked: read as stored, no check
    n = sum(len(a) for a, _ in iter_blocks(p, block=1000, verify=False)[1])
    assert n == 5_000


def test_the_readers_crc_is_zlibs_on_the_buffers_the_reader_hands_it() -> None:
    """``crc.crc32`` on memoryviews of float64 blocks cut at any byte (the reader's
    ``readinto`` views and their tails), chained from any start, is zlib's."""
    import zlib

    from avard.core.io import crc

    rng = np.random.default_rng(11)
    block = rng.normal(size=(4_099, 3))
    view = block.data.cast("B")
    start = 0
    for cut in (0, 1, 63, 64, 65, 4_099 * 24 - 17, 4_099 * 24):
        part = view[:cut]
        assert crc.crc32(part, start) == zlib.crc32(part, start)
        start = zlib.crc32(part, start)
    assert crc.crc32(b"", 0xFFFFFFFF) == zlib.crc32(b"", 0xFFFFFFFF)


@pytest.mark.parametrize(("encoding", "kind"), [("latin-1", "not UTF-8 text;"),
                                                ("utf-16", "(it is UTF-16)")])
def test_a_csv_not_in_utf8_is_one_line(tmp_path: Path, encoding: str, kind: str) -> None:
    """Spreadsheets also write cp1252 and UTF-16: a UnicodeDecodeError traceback before."""
    from avard.core.io.source import open_record

    p = tmp_path / "lab.csv"
    rows = "".join(f"{i / 10},0.1,0.2,9.8,{21 + i / 100}\n" for i in range(50))
    p.write_bytes(("t,x,y,z,temp_°C\n" + rows).encode(encoding))
    with pytest.raises(DataError, match="save the CSV as UTF-8") as exc:
        list(open_record(str(p)).blocks(16))
    assert kind in str(exc.value)


def test_a_csv_turning_non_utf8_midway_is_one_line(tmp_path: Path) -> None:
    from avard.core.io.source import open_record

    p = tmp_path / "lab.csv"
    good = "".join(f"{i / 10},0.1,0.2,9.8\n" for i in range(5000))
    p.write_bytes(b"t,x,y,z\n" + good.encode() + "9999,0.1,0.2,9.8 °\n".encode("latin-1"))
    with pytest.raises(DataError, match="not UTF-8 text"):
        for _ in open_record(str(p)).blocks(256):
            pass


def _csv(p: Path, t: np.ndarray) -> Path:
    rng = np.random.default_rng(3)
    rows = "".join(f"{ti:.4f},{rng.normal():.6f},{rng.normal():.6f},{9.8 + rng.normal():.6f}\n"
                   for ti in t)
    p.write_text("t,x,y,z\n" + rows)
    return p


def test_a_hole_in_a_csvs_time_column_is_refused_in_one_line(tmp_path: Path) -> None:
    """Ten minutes missing from a 5 Hz log: read end to end, the hole became a bias step at
    its place and the record 10 minutes short, with nothing said (a CSV carries no gaps)."""
    from avard.core.io.source import open_record

    t = np.arange(0, 7200, 0.2)
    t = t[(t < 3000) | (t >= 3600)]
    p = _csv(tmp_path / "hole.csv", t)
    with pytest.raises(DataError, match=r"jumps by 600.2 s after t = 2999.8 s \(sample 15000\)"
                       r".*about 3000 samples are missing") as exc:
        for _ in open_record(str(p)).blocks(4096):
            pass
    assert "--rate" in str(exc.value)
    # the user may read it end to end on purpose: the rate given, t is not read
    n = sum(len(a) for a, _t, _e in open_record(str(p), rate_hz=5.0).blocks(4096))
    assert n == len(t)


def test_a_jittered_time_column_is_no_hole(tmp_path: Path) -> None:
    """A PC-stamped log's spacing wanders: up to 40 % either way is no missing sample."""
    from avard.core.io.source import open_record

    rng = np.random.default_rng(4)
    t = np.cumsum(0.2 * (1 + rng.uniform(-0.4, 0.4, 20000)))
    n = sum(len(a) for a, _t, _e in open_record(str(_csv(tmp_path / "j.csv", t))).blocks(4096))
    assert n == len(t)
