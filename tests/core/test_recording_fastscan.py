"""The recording scan's fast path (issue #25 item 2): frames checked and raw blocks read by the
C loop (core/io/_framescan.c through core/io/rawscan.py), the walk taking a stretch of raw
blocks as one, and the read plan's reads of many blocks at once. Held equal to the general
reader (every frame decoded by frames.decode and walked one by one): the same samples, the
same losses, duplicates, gaps and problems, the same summary, the same read plan, on clean
recordings and on every kind of damage the reader survives."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from avard.core.errors import DataError, FormatError
from avard.core.io import frames, rawscan
from avard.core.io.recording import frame
from avard.core.io.source import RecordingSource, open_record
from avard.daemon.service.recorder import Recorder
from hypothesis import given, settings
from hypothesis import strategies as st

pytestmark = pytest.mark.skipif(not rawscan.available(),
                                reason="the compiled frame loop is not built (setup.py)")

RATE = 125.0
SCALE = 3.9e-5


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _write_run(directory: Path, run: str, i0: int, seconds: float, *, seed: int,
               segment_s: float = 20.0, block: int = 62, gap_at: int | None = None,
               restart_from: int | None = None) -> int:
    """One run through the recorder's segment writer, laid out as the service lays it out:
    header copies every 5 s, temperature and Allan records between the raw blocks."""
    clock = Clock()

    def header() -> dict[str, Any]:
        return frames.header_record(run, rate_hz=RATE, t_mono=clock.t, t_real=clock.t,
                                    i0=i0, scale_m_s2_per_count=SCALE,
                                    temperature_channels=["board"],
                                    timebase={"odr_hz": RATE, "odr_u_hz": 1e-4},
                                    nominal_odr_hz=RATE)

    rec = Recorder(directory, run, header, segment_s=segment_s, header_every_s=5.0,
                   clock=clock, wall=clock, realtime=lambda: 1.7e9 + clock.t)
    rng = np.random.default_rng(seed)
    if restart_from is not None:        # the previous run ended there
        rec.write(frames.gap_record(run, 0, restart_from, i0 - restart_from, 0.0, 0.0,
                                    "restart"))
    at = i0
    for k in range(int(seconds * RATE) // block):
        clock.t = (at - i0) / RATE
        if gap_at is not None and k == gap_at:
            rec.write(frames.gap_record(run, 0, at, 40, clock.t, clock.t, "overrun"))
            at += 40
        counts = rng.integers(-50_000, 50_000, (block, 3)).astype(np.int32)
        rec.write(frames.raw_record(run, 0, at, counts, clock.t, clock.t, rate_hz=RATE,
                                    chip_temp_c=None if k % 3 else 24.5))
        rec.write(frames.temp_record(run, 0, at, ["board"], [20.0 + k * 1e-3], clock.t,
                                     clock.t))
        if k % 10 == 0:
            rec.write(frames.status_record(run, 0, {"k": k}, clock.t, clock.t))
        at += block
    rec.close()
    return at


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two runs (the second a restart) in segments of 20 s, with a recorded gap."""
    d = tmp_path_factory.mktemp("fastscan") / "rec"
    end = _write_run(d, "n00000001-20260101T000000Z-a", 0, 70.0, seed=1, gap_at=60)
    _write_run(d, "n00000002-20260101T000200Z-b", end + 300, 45.0, seed=2, restart_from=end)
    return d


def _segments(rec: Path) -> list[Path]:
    return sorted(p for p in rec.glob("*.avr"))


def _flip(path: Path, at: int) -> None:
    data = bytearray(path.read_bytes())
    data[at] ^= 0x10
    path.write_bytes(bytes(data))


def _raw_offsets(seg: Path) -> list[int]:
    from avard.core.io.recording import RecordingReader

    return [fr.offset for fr in RecordingReader(seg).frames()
            if frames.decode(fr.payload)["kind"] == "raw"]


def _both(path: Path, monkeypatch: pytest.MonkeyPatch, **kw: Any
          ) -> tuple[RecordingSource | Exception, RecordingSource | Exception]:
    """The record opened by the fast path and by the general one (the C loop switched off)."""
    def opened() -> Any:
        try:
            return open_record(path, **kw)
        except (DataError, FormatError) as exc:
            return exc

    fast = opened()
    with monkeypatch.context() as m:
        m.setattr(rawscan, "_framescan", None)
        assert not rawscan.available()
        slow = opened()
    return fast, slow


def _stretches_counted(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The blocks of each stretch the scan hands the walk from now on."""
    taken: list[int] = []
    real = rawscan.stretch_record

    def counted(run, stretch):  # type: ignore[no-untyped-def]
        taken.append(len(stretch.i0))
        return real(run, stretch)

    monkeypatch.setattr(rawscan, "stretch_record", counted)
    return taken


def _assert_same(fast: Any, slow: Any) -> None:
    if isinstance(slow, Exception):
        assert type(fast) is type(slow) and str(fast) == str(slow)
        return
    assert fast.info == slow.info               # runs, losses, duplicates, gaps, problems
    assert (fast._plan is None) == (slow._plan is None)
    if fast._plan is not None:
        for name in ("fidx", "off", "i0", "n", "sidx", "cut"):
            assert getattr(fast._plan, name) == getattr(slow._plan, name), name
        assert fast._plan.scales == slow._plan.scales
    # the samples: the fast read plan against the general walk of every record
    for kw in ({}, {"columns": [2, 0], "temperature": False}):
        got = list(fast.blocks(500, **kw))
        plan, slow._plan = slow._plan, None
        want = list(slow.blocks(500, **kw))
        slow._plan = plan
        assert len(got) == len(want)
        for (a, t, e), (b, u, f) in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)
            assert e == f
            assert (t is None) == (u is None)
            if t is not None:
                np.testing.assert_array_equal(t, u)


def _copy(recording: Path, tmp_path: Path) -> Path:
    out = tmp_path / "rec"
    shutil.copytree(recording, out)
    return out


def test_the_fast_scan_is_the_general_one_on_a_clean_recording(recording: Path,
                                                                monkeypatch) -> None:
    taken = _stretches_counted(monkeypatch)
    fast, slow = _both(recording, monkeypatch)
    # the fast path was taken: every raw block read in C, in a few stretches
    assert isinstance(fast, RecordingSource) and sum(taken) == len(fast._plan.i0)
    assert len(taken) < sum(taken) / 5
    # header copies (every 5 s) cut no stretch: segment ends and gap records do
    assert len(taken) <= len(_segments(recording)) + len(fast.info.recording.gaps)
    _assert_same(fast, slow)
    assert not isinstance(fast, Exception)
    summary = fast.info.recording
    assert summary is not None and len(summary.runs) == 2 and len(summary.gaps) == 2
    assert summary.samples_lost == 0 and fast.info.n_samples == sum(
        r.n_samples for r in summary.runs)


@pytest.mark.parametrize("damage", [
    "flipped raw", "flipped header", "flipped length", "torn tail", "zero tail",
    "deleted", "emptied", "directory", "copied", "copied renamed", "first header gone",
    "garbage between", "other layout", "undecodable"])
def test_the_fast_scan_is_the_general_one_on_damage(recording: Path, tmp_path: Path,
                                                    monkeypatch, damage: str) -> None:
    rec = _copy(recording, tmp_path)
    segs = _segments(rec)
    mid = segs[1]
    raws = _raw_offsets(mid)
    if damage == "flipped raw":
        for at in raws[3:12:4]:                   # three raw frames apart
            _flip(mid, at + 60)
    elif damage == "flipped header":
        _flip(mid, 30)                            # the segment's first header
    elif damage == "flipped length":
        _flip(mid, raws[5] + 2)                   # a length far past the end
    elif damage == "torn tail":
        with open(segs[-1], "r+b") as f:
            f.truncate(f.seek(0, 2) - 100)
    elif damage == "zero tail":
        with open(segs[-1], "ab") as f:
            f.write(bytes(5000))
    elif damage == "deleted":
        mid.unlink()
    elif damage == "emptied":
        mid.write_bytes(b"")
    elif damage == "directory":
        mid.unlink()
        mid.mkdir()
    elif damage == "copied":
        shutil.copy(segs[0], rec / (segs[-1].stem + "_copy.avr"))
    elif damage == "copied renamed":
        shutil.copy(mid, rec / "zzz_00000099_x.avr")
    elif damage == "first header gone":
        _flip(segs[0], 30)                        # no copy of it before the raw blocks
    elif damage == "garbage between":
        data = mid.read_bytes()
        at = raws[7]
        mid.write_bytes(data[:at] + os.urandom(333) + data[at:])
    elif damage == "other layout":
        # raw records the C loop leaves to the general decoder: an extra key, int16 counts,
        # a signed-int index: read all the same
        data = bytearray(mid.read_bytes())
        out = bytearray()
        pos = 0
        from avard.core.io.recording import scan_frames
        for k, fr in enumerate(scan_frames(bytes(data))):
            rec_ = frames.decode(fr.payload)
            if rec_["kind"] == "raw" and k % 5 == 1:
                rec_["extra"] = 1
            elif rec_["kind"] == "raw" and k % 5 == 3:
                rec_["counts"] = np.asarray(rec_["counts"]).astype(np.int16)
            out += frame(frames.encode(rec_)) if rec_["kind"] == "raw" else data[
                fr.offset:fr.offset + 8 + len(fr.payload)]
            pos = fr.offset + 8 + len(fr.payload)
        mid.write_bytes(bytes(out + data[pos:]))
    elif damage == "undecodable":
        # raw frames whose CRC checks but whose record does not (format version 2, a count
        # of the wrong sign): reported, their samples lost
        data = bytearray(mid.read_bytes())
        out = bytearray()
        from avard.core.io.recording import scan_frames
        for fr in scan_frames(bytes(data)):
            payload = fr.payload
            if fr.offset in (raws[4], raws[9]):
                bad = msgpack.unpackb(payload)
                bad["v" if fr.offset == raws[4] else "i0"] = 2 if fr.offset == raws[4] else -1
                payload = msgpack.packb(bad)
            out += frame(payload)
        mid.write_bytes(bytes(out))
    fast, slow = _both(rec, monkeypatch)
    _assert_same(fast, slow)
    if damage == "undecodable":
        assert not isinstance(fast, Exception) and fast.info.recording is not None
        assert sum("undecodable" in p for p in fast.info.recording.problems) == 2
        assert fast.info.recording.samples_lost > 0
    if damage in ("flipped raw", "deleted", "emptied", "directory"):
        assert not isinstance(fast, Exception)
        assert fast.info.recording is not None and fast.info.recording.samples_lost > 0


def test_a_run_picked_by_runs_reads_the_same(recording: Path, monkeypatch) -> None:
    fast, slow = _both(recording, monkeypatch, runs=["n00000002-20260101T000200Z-b"])
    _assert_same(fast, slow)


def test_a_small_chunk_splits_frames_across_reads(recording: Path, monkeypatch) -> None:
    """Frames cut by the chunk's end are read whole on the next read (and a frame longer
    than a chunk too)."""
    monkeypatch.setattr(rawscan, "CHUNK", 777)
    fast, slow = _both(recording, monkeypatch)
    _assert_same(fast, slow)


def test_a_segment_deleted_during_the_scan_is_one_line(recording: Path, tmp_path: Path,
                                                       monkeypatch) -> None:
    rec = _copy(recording, tmp_path)
    src = RecordingSource(rec)
    seg = _segments(rec)[1]
    real = rawscan.scan_file

    def vanishing(fh, name, *a):  # type: ignore[no-untyped-def]
        if name == str(_segments(rec)[0]):
            seg.unlink()
        return real(fh, name, *a)

    monkeypatch.setattr(rawscan, "scan_file", vanishing)
    with pytest.raises(DataError, match="removed while the recording was read"):
        _ = src.info


# --------------------------------------------------------------------------------------------
# the C record reader accepts only what frames.decode accepts, with the same values


def _raw_payload(**over: Any) -> bytes:
    rec = frames.raw_record("n00000001-x", 7, 1000, np.arange(12, dtype=np.int32).reshape(4, 3),
                            1.0, 2.0, rate_hz=RATE, chip_temp_c=25.0)
    rec.update(over)
    return frames.encode(rec, check=False)


def _c_entries(payload: bytes) -> np.ndarray:
    from avard.core.io import _framescan  # type: ignore[attr-defined]

    consumed, status, raw = _framescan.scan(frame(payload), 0, 1 << 24)
    assert status == 0 and consumed == len(payload) + 8
    return np.frombuffer(raw, dtype=np.int64).reshape(-1, _framescan.ENTRY_FIELDS)


def _agrees(payload: bytes) -> None:
    """Whatever the C loop reads as a raw record, frames.decode reads the same; what it skips
    by its kind is a kind the scan skips."""
    e = _c_entries(payload)
    if not len(e):
        from avard.core.io.recording_source import _NO_SAMPLES, _peek_kind

        assert _peek_kind(payload) in _NO_SAMPLES
        return
    (off, size, code, i0, n, counts, run_at, run_len, _same), = e.tolist()
    assert off == 0 and size == len(payload)
    if code == 2:
        return                                     # left to the general decoder
    rec = frames.decode(payload)                   # must not raise
    assert rec["kind"] == "raw" and (rec["i0"], rec["n"]) == (i0, n)
    assert rec["run"] == payload[run_at - 8:run_at - 8 + run_len].decode()
    c = np.frombuffer(payload[counts - 8:counts - 8 + 12 * n], dtype="<i4").reshape(n, 3)
    np.testing.assert_array_equal(c, rec["counts"])


def test_the_c_reader_reads_the_records_the_service_writes() -> None:
    for payload in (_raw_payload(), _raw_payload(chip_temp_c=None), _raw_payload(i0=2**40)):
        e = _c_entries(payload)
        assert e[0, 2] == 1
        _agrees(payload)
    rec = frames.raw_record("r", 0, 5, np.zeros((2, 3), np.int32), 1.0, 2.0)  # no extras
    assert _c_entries(frames.encode(rec))[0, 2] == 1


@pytest.mark.parametrize("change", [
    {"v": 2}, {"v": True}, {"seq": -1}, {"i0": -5}, {"n": 5}, {"t_mono": "x"},
    {"rate_hz": None}, {"chip_temp_c": "hot"}, {"run": "caf\u00e9"}, {"extra": 1},
    {"kind": "temp"}])
def test_the_c_reader_leaves_every_other_layout_to_the_general_decoder(change) -> None:
    payload = _raw_payload(**change)
    assert change == {"kind": "temp"} or _c_entries(payload)[0, 2] == 2
    _agrees(payload)


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_the_c_reader_never_accepts_what_decode_refuses(data: st.DataObject) -> None:
    """Hostile payloads (a valid record with bytes changed, cut or added) under a valid CRC:
    the C reader reads a raw record only where frames.decode reads the same one."""
    payload = bytearray(_raw_payload(chip_temp_c=data.draw(st.sampled_from([None, 25.0]))))
    for _ in range(data.draw(st.integers(1, 4))):
        how = data.draw(st.sampled_from(["set", "cut", "add"]))
        at = data.draw(st.integers(0, len(payload) - 1))
        if how == "set":
            payload[at] = data.draw(st.integers(0, 255))
        elif how == "cut":
            del payload[at:at + data.draw(st.integers(1, 8))]
        else:
            payload[at:at] = data.draw(st.binary(min_size=1, max_size=8))
        if not payload:
            return
    _agrees(bytes(payload))


def test_the_c_reader_agrees_on_msgpack_variants() -> None:
    """The same record with its integers and floats in other msgpack widths."""
    base = msgpack.unpackb(_raw_payload())
    for packed in (msgpack.packb(base, use_single_float=True),
                   msgpack.packb(dict(base, i0=70000, seq=300))):
        _agrees(packed)


def test_runs_interleaved_in_one_file_read_the_same(tmp_path: Path, monkeypatch) -> None:
    """Blocks of two runs alternating in one segment, one run's header late, an index that
    jumps back (met before), a zero-sample block: each where the walk must take the blocks one
    by one, read alike by both paths."""
    a, b = "n00000001-x-a", "n00000002-x-b"

    def head(run: str, i0: int) -> bytes:
        return frame(frames.encode(frames.header_record(
            run, rate_hz=RATE, t_mono=0.0, t_real=0.0, i0=i0, scale_m_s2_per_count=SCALE)))

    def raw(run: str, i0: int, n: int) -> bytes:
        counts = np.arange(3 * n, dtype=np.int32).reshape(n, 3) + i0
        return frame(frames.encode(frames.raw_record(run, 0, i0, counts, 0.0, 0.0)))

    parts = [head(a, 0), raw(a, 0, 10), raw(a, 10, 10), raw(b, 1000, 10), raw(b, 1010, 10),
             raw(a, 20, 10), head(b, 1000), raw(b, 1020, 10), raw(a, 15, 10),
             raw(a, 30, 0), raw(a, 30, 10), raw(b, 1030, 5)]
    rec = tmp_path / "rec"
    rec.mkdir()
    (rec / f"{a}_00000000_x.avr").write_bytes(b"".join(parts))
    fast, slow = _both(rec, monkeypatch)
    _assert_same(fast, slow)
    assert not isinstance(fast, Exception)
    assert fast.info.recording is not None and fast.info.recording.samples_duplicated == 10


def test_the_one_switch_turns_the_frame_loop_off_too(monkeypatch: pytest.MonkeyPatch) -> None:
    """``AVARD_NO_C_KERNELS`` (anything but 0) switches off every compiled path: the Allan
    kernels and the recording scan's frame loop alike, so the general reader scans."""
    from avard.core.allan import kernels

    monkeypatch.setenv("AVARD_NO_C_KERNELS", "0")
    assert rawscan._load() is not None and kernels._load() is not None
    monkeypatch.setenv("AVARD_NO_C_KERNELS", "1")
    assert rawscan._load() is None and kernels._load() is None


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=0, max_size=700), st.integers(0, 15),
       st.integers(0, 2**32 - 1))
def test_the_frame_loops_crc_is_zlibs(data: bytes, cut: int, start: int) -> None:
    """The C loop's CRC-32 (folded by carry-less multiplication where the CPU has it, zlib's
    for the tail and short frames) is zlib's, whatever the length, alignment and start."""
    import zlib

    from avard.core.io import _framescan

    view = memoryview(data)[cut:]
    assert _framescan.crc32(view, start) == zlib.crc32(view, start)


@pytest.mark.parametrize("size", [63, 64, 65, 79, 80, 127, 128, 129, 1 << 20, (1 << 20) + 37])
def test_the_frame_loops_crc_at_the_folds_boundaries(size: int) -> None:
    """Around the fold's 64-byte start and 16-byte steps, and a chunk's length."""
    import zlib

    from avard.core.io import _framescan

    data = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8).tobytes()
    for cut in (0, 1, 7, 15):
        assert _framescan.crc32(data[cut:]) == zlib.crc32(data[cut:])
        assert _framescan.crc32(data[cut:], 0xFFFFFFFF) == zlib.crc32(data[cut:], 0xFFFFFFFF)
    # a frame whose payload is long enough to fold still checks, and one flipped bit fails
    payload = frames.encode(frames.raw_record(
        "r", 0, 0, np.arange(3 * 1000, dtype=np.int32).reshape(-1, 3), 0.0, 0.0))
    good = frame(payload)
    consumed, status, _ = _framescan.scan(good, 0, 1 << 24)
    assert (consumed, status) == (len(good), 0)
    bad = bytearray(good)
    bad[len(bad) // 2] ^= 1
    consumed, status, _ = _framescan.scan(bytes(bad), 0, 1 << 24)
    assert (consumed, status) == (0, 1)


def test_header_copies_between_blocks_read_the_same(tmp_path: Path, monkeypatch) -> None:
    """Header records between one run's raw blocks: copies with a newer rate fit (the newest
    one is the run's rate), a copy whose CRC checks but whose record does not decode, a
    header of another run, a run whose first header comes after its first blocks, and
    blocks met before with a copy between them: the stretch goes on across a readable copy
    and is taken in place otherwise, read alike by both paths."""
    a, b, c = "n00000001-x-a", "n00000002-x-b", "n00000003-x-c"

    def head(run: str, i0: int, rate: float = RATE, *, v: int = 1) -> bytes:
        rec = frames.header_record(run, rate_hz=rate, t_mono=0.0, t_real=0.0, i0=i0,
                                   scale_m_s2_per_count=SCALE,
                                   timebase={"odr_hz": rate, "odr_u_hz": 1e-4},
                                   nominal_odr_hz=RATE)
        payload = frames.encode(rec)
        if v != 1:                               # checks by CRC, refused by decode
            bad = msgpack.unpackb(payload)
            bad["v"] = v
            payload = msgpack.packb(bad)
        return frame(payload)

    def raw(run: str, i0: int, n: int = 10) -> bytes:
        counts = np.arange(3 * n, dtype=np.int32).reshape(n, 3) + i0
        return frame(frames.encode(frames.raw_record(run, 0, i0, counts, 0.0, 0.0)))

    parts = [head(a, 0), raw(a, 0), head(a, 10, 125.01), raw(a, 10), head(a, 20, 125.02),
             head(a, 20, 125.03), raw(a, 20),                # copies read: taken whole
             raw(c, 9000), head(c, 9010), raw(c, 9010), raw(c, 9020), head(c, 9030),
             raw(c, 9030),                                    # the run's first header within
             raw(a, 30), head(a, 40, v=2), raw(a, 40), head(b, 5000),
             raw(a, 50),                                      # undecodable, another run's
             head(a, 60, 125.04), raw(a, 30), head(a, 40, 125.05), raw(a, 40),  # met before
             raw(a, 60)]
    rec = tmp_path / "rec"
    rec.mkdir()
    (rec / f"{a}_00000000_x.avr").write_bytes(b"".join(parts))
    fast, slow = _both(rec, monkeypatch, runs=[a])
    _assert_same(fast, slow)
    assert isinstance(fast, RecordingSource) and fast.info.recording is not None
    summary = fast.info.recording
    assert sum("undecodable" in p for p in summary.problems) == 1
    assert summary.samples_duplicated == 20
    assert [r.rate_hz for r in summary.runs] == [125.05]
    n_full = fast.info.n_samples
    # the copies of a stretch taken whole are the run's newest header when they are the last
    (rec / f"{a}_00000000_x.avr").write_bytes(b"".join(parts[:7]))
    fast, slow = _both(rec, monkeypatch, runs=[a])
    _assert_same(fast, slow)
    assert isinstance(fast, RecordingSource) and fast.info.recording is not None
    assert [r.rate_hz for r in fast.info.recording.runs] == [125.03]
    (rec / f"{a}_00000000_x.avr").write_bytes(b"".join(parts))
    # and header records cut no stretch
    taken = _stretches_counted(monkeypatch)
    assert open_record(rec, runs=[a]).info.n_samples == n_full
    assert taken == [3, 4, 3, 2, 1]


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["raw", "raw", "raw", "head", "head", "bad head",
                                           "jump"]),
                          st.sampled_from(["a", "b"]), st.integers(0, 3)),
                min_size=1, max_size=30))
def test_header_records_anywhere_read_the_same(steps: list[tuple[str, str, int]]) -> None:
    """Fuzz: raw blocks, header records (readable with a new rate, or undecodable) and index
    jumps back of two runs in any order in one segment: the fast path reads what the general
    one reads, headers in stretches or not, in chunks of any size."""
    import tempfile

    runs = {"a": "n00000001-x-a", "b": "n00000002-x-b"}
    at = {"a": 0, "b": 100_000}
    parts = []
    for what, r, k in steps:
        run = runs[r]
        if what == "raw":
            counts = np.full((5 + k, 3), at[r], dtype=np.int32)
            parts.append(frame(frames.encode(frames.raw_record(run, 0, at[r], counts, 0.0,
                                                               0.0))))
            at[r] += 5 + k
        elif what == "jump":
            at[r] = max(at[r] - 7 * k, 0 if r == "a" else 100_000)
        else:
            rate = RATE + 0.01 * k
            payload = frames.encode(frames.header_record(
                run, rate_hz=rate, t_mono=0.0, t_real=0.0, i0=at[r],
                # compatible rates (as wide as the fit's uncertainty): the record's rate is
                # their mean, so it shows each run's newest header
                scale_m_s2_per_count=SCALE, timebase={"odr_hz": rate, "odr_u_hz": 0.5},
                nominal_odr_hz=RATE))
            if what == "bad head":
                bad = msgpack.unpackb(payload)
                bad["v"] = 2
                payload = msgpack.packb(bad)
            parts.append(frame(payload))
    with tempfile.TemporaryDirectory() as tmp, pytest.MonkeyPatch.context() as mp:
        rec = Path(tmp) / "rec"
        rec.mkdir()
        (rec / f"{runs['a']}_00000000_x.avr").write_bytes(b"".join(parts))
        for pick, chunk in ((None, rawscan.CHUNK), ([runs["a"]], rawscan.CHUNK),
                            ([runs["a"]], 257)):      # a chunk ends within most stretches
            mp.setattr(rawscan, "CHUNK", chunk)
            fast, slow = _both(rec, mp, runs=pick)
            _assert_same(fast, slow)
