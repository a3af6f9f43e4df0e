"""Segment framing and the recording reader: truncated tails, corrupt middles, replay."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan.feed import AllanFeed
from avard.core.errors import FormatError
from avard.core.io import frames
from avard.core.io.recording import (
    FRAME_HEADER,
    RecordingReader,
    frame,
    scan_frames,
    segment_files,
)
from hypothesis import given, settings
from hypothesis import strategies as st


def _payloads(k: int) -> list[bytes]:
    return [bytes([i % 251]) * (10 + 7 * i) for i in range(k)]


def test_frame_layout_is_length_crc_payload() -> None:
    f = frame(b"hello")
    n, crc = FRAME_HEADER.unpack(f[:8])
    assert n == 5 and crc == zlib.crc32(b"hello") and f[8:] == b"hello"


def test_truncated_tail_is_dropped_and_reported() -> None:
    data = b"".join(frame(p) for p in _payloads(5))
    cut = data[:-7]
    probs: list = []
    got = [f.payload for f in scan_frames(cut, "seg", problems=probs)]
    assert got == _payloads(4)
    assert len(probs) == 1 and probs[0].kind == "truncated"
    last = len(frame(_payloads(5)[4]))
    assert probs[0].dropped_bytes == last - 7
    assert probs[0].offset == len(cut) - (last - 7)


def test_corrupt_middle_record_is_reported_by_position_and_rest_is_kept() -> None:
    pay = _payloads(6)
    frs = [frame(p) for p in pay]
    data = bytearray(b"".join(frs))
    bad_at = sum(len(f) for f in frs[:2])
    data[bad_at + 12] ^= 0xFF            # flip a payload byte of record 2
    probs: list = []
    got = [f.payload for f in scan_frames(bytes(data), "seg", problems=probs)]
    assert got == pay[:2] + pay[3:]
    assert [(p.kind, p.offset, p.dropped_bytes) for p in probs] == [
        ("corrupt", bad_at, len(frs[2]))]


def test_corrupt_length_field_resyncs_on_next_frame() -> None:
    pay = _payloads(4)
    frs = [frame(p) for p in pay]
    data = bytearray(b"".join(frs))
    at = len(frs[0])
    data[at:at + 4] = (10**9).to_bytes(4, "little")
    probs: list = []
    got = [f.payload for f in scan_frames(bytes(data), "seg", problems=probs)]
    assert got == [pay[0], pay[2], pay[3]]
    assert probs[0].kind == "corrupt" and probs[0].offset == at


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(min_size=1, max_size=40), min_size=1, max_size=8),
       st.integers(min_value=0, max_value=10_000))
def test_any_truncation_keeps_every_complete_frame(payloads: list[bytes], cut_seed: int) -> None:
    data = b"".join(frame(p) for p in payloads)
    cut = cut_seed % (len(data) + 1)
    probs: list = []
    got = [f.payload for f in scan_frames(data[:cut], problems=probs)]
    ends = np.cumsum([len(frame(p)) for p in payloads])
    complete = int(np.searchsorted(ends, cut, side="right"))
    # Every frame that is complete before the cut survives; nothing is invented.
    assert got[:complete] == payloads[:complete]
    kept = sum(len(frame(p)) for p in got)
    assert kept + sum(p.dropped_bytes for p in probs) == cut


def _write_segment(path: Path, records: list[dict]) -> None:
    path.write_bytes(b"".join(frame(frames.encode(r)) for r in records))


def _header(run: str = "r1", temps: tuple[str, ...] = ()) -> dict:
    return frames.header_record(run, rate_hz=125.0, t_mono=0.0, t_real=0.0,
                                scale_m_s2_per_count=9.80665 / 256000,
                                temperature_channels=list(temps))


def test_reader_strict_raises_with_position(tmp_path: Path) -> None:
    recs = [_header(), frames.raw_record("r1", 1, 0, np.ones((4, 3), np.int32), 0.0, 0.0)]
    seg = tmp_path / "20260101T000000Z_r1_0000.avr"
    _write_segment(seg, recs)
    data = bytearray(seg.read_bytes())
    data[-3] ^= 0x01
    data += frame(frames.encode(recs[1]))
    seg.write_bytes(bytes(data))
    with pytest.raises(FormatError, match=r"corrupt record at byte \d+"):
        list(RecordingReader(seg, strict=True))
    lenient = RecordingReader(tmp_path)
    assert [r["kind"] for r in lenient] == ["header", "raw"]
    assert lenient.problems[0].kind == "corrupt"


def test_directory_without_segments_is_a_format_error(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"no \.avr segment files"):
        segment_files(tmp_path)


class _Sink:
    def __init__(self) -> None:
        self.blocks: list[np.ndarray] = []
        self.gaps = 0

    def update(self, block: np.ndarray) -> None:
        self.blocks.append(block.copy())

    def gap(self) -> None:
        self.blocks.append(np.zeros((0, 0)))
        self.gaps += 1


def test_allan_feed_holds_temperatures_from_their_index_and_waits_for_all() -> None:
    sink = _Sink()
    feed = AllanFeed(sink, 2.0, ["chip", "t1"])
    feed.temp(0, ["chip"], [30.0])
    feed.raw(0, np.ones((4, 3), np.int32))           # t1 unknown: nothing fed yet
    assert feed.fed == 0 and feed.skipped == 4
    feed.temp(6, ["t1"], [20.0])
    feed.temp(8, ["chip", "t1"], [31.0, None])        # None: a failed read keeps the hold
    feed.raw(4, np.ones((8, 3), np.int32))
    block = np.concatenate(sink.blocks)
    assert feed.fed == 6 and feed.skipped == 6
    np.testing.assert_array_equal(block[:, 0], 2.0)
    np.testing.assert_array_equal(block[:, 3], [30, 30, 31, 31, 31, 31])
    np.testing.assert_array_equal(block[:, 4], 20.0)
    feed.raw(20, np.ones((2, 3), np.int32))           # index jump → segment break
    assert sink.gaps == 1


def test_last_record_reads_from_the_end_and_survives_damage(tmp_path: Path) -> None:
    from avard.core.io.recording import first_record, frame_offsets, last_record

    recs = [_header()] + [frames.raw_record("r1", k, 10 * k, np.full((10, 3), k, np.int32),
                                            0.0, 0.0) for k in range(5)]
    recs.append(frames.event_record("r1", 0, "start", 0.0, 0.0))
    seg = tmp_path / "s.avr"
    _write_segment(seg, recs)
    seg.write_bytes(seg.read_bytes() + b"\x10\x00\x00\x00trunc")    # a power cut mid-frame
    assert len(frame_offsets(seg) or []) == len(recs)
    assert last_record(seg, "raw")["i0"] == 40
    assert first_record(seg)["kind"] == "header"
    data = bytearray(seg.read_bytes())
    off = frame_offsets(seg)[2]
    data[off:off + 4] = (1 << 30).to_bytes(4, "little")             # damaged length field
    seg.write_bytes(bytes(data))
    assert frame_offsets(seg) is None
    assert last_record(seg, "raw")["i0"] == 40                      # falls back to a full scan


def _raw_segment(path: Path, k: int) -> list[int]:
    """A segment of a header and ``k`` raw blocks of 10 samples; the blocks' byte offsets."""
    recs = [_header()] + [frames.raw_record("r1", j, 10 * j, np.full((10, 3), j, np.int32),
                                            0.0, 0.0) for j in range(k)]
    _write_segment(path, recs)
    return [f.offset for f in scan_frames(path.read_bytes())][1:]


@pytest.mark.parametrize("bit", [10, 20])            # a length inside the file; one past EOF
def test_one_flipped_length_bit_never_hides_the_records_after_it(
        tmp_path: Path, bit: int, caplog: pytest.LogCaptureFixture) -> None:
    """A flipped bit in a frame's length field is damage, not a torn tail: the records after
    it are still read, from the end, and the last raw block is the true one."""
    from avard.core.io.recording import last_record, records_backwards

    seg = tmp_path / "s.avr"
    offs = _raw_segment(seg, 40)
    data = bytearray(seg.read_bytes())
    n = int.from_bytes(data[offs[5]:offs[5] + 4], "little") ^ (1 << bit)
    assert n < 1 << 24                                 # plausible (under MAX_FRAME_BYTES)
    data[offs[5]:offs[5] + 4] = n.to_bytes(4, "little")
    seg.write_bytes(bytes(data))
    assert last_record(seg, "raw")["i0"] == 390
    got = [r["seq"] for r in records_backwards(seg) if r["kind"] == "raw"]
    assert got == [j for j in reversed(range(40)) if j != 5]
    # and the damage is said, at its byte offset, as the forward reader says it
    assert any(f"corrupt record at byte {offs[5]} " in r.getMessage() for r in caplog.records)


def test_a_torn_tail_is_still_dropped_from_the_end(tmp_path: Path) -> None:
    from avard.core.io.recording import last_record, records_backwards

    seg = tmp_path / "s.avr"
    _raw_segment(seg, 6)
    whole = seg.read_bytes()
    seg.write_bytes(whole + frame(frames.encode(frames.raw_record(
        "r1", 6, 60, np.ones((10, 3), np.int32), 0.0, 0.0)))[:-9])
    assert last_record(seg, "raw")["i0"] == 50
    assert [r["seq"] for r in records_backwards(seg) if r["kind"] == "raw"] == [5, 4, 3, 2, 1, 0]


def test_reading_a_damaged_segment_from_the_end_holds_no_copy_of_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A damaged segment is read forwards to find its frames, but neither its bytes nor its
    decoded records are held: the last raw block costs a couple of decodes, and while the
    caller looks at it the reader holds far less than the file's size (an hour at 4 kHz is
    ~170 MB). The resync's own working memory is bounded by its window, not the file."""
    import tracemalloc

    from avard.core.io import recording

    seg = tmp_path / "s.avr"
    recs = [_header()] + [frames.raw_record("r1", j, 500 * j, np.full((500, 3), j, np.int32),
                                            0.0, 0.0) for j in range(300)]
    _write_segment(seg, recs)
    data = bytearray(seg.read_bytes())
    off = [f.offset for f in scan_frames(bytes(data))][3]
    data[off:off + 4] = (1 << 30).to_bytes(4, "little")       # implausible: read forwards
    seg.write_bytes(bytes(data))
    decoded = 0
    real = frames.decode

    def counting(payload: bytes, **kw: object) -> dict:
        nonlocal decoded
        decoded += 1
        return real(payload, **kw)

    monkeypatch.setattr(frames, "decode", counting)
    tracemalloc.start()
    try:
        newest = recording.records_backwards(seg)
        last = next(r for r in newest if r["kind"] == "raw")
        held = tracemalloc.get_traced_memory()[0]     # while the reader waits at its record
    finally:
        tracemalloc.stop()
    assert last["i0"] == 500 * 299
    assert decoded <= 2
    assert held < len(data) // 8, (held, len(data))
    assert [r["seq"] for r in newest][-1] == 0     # and it still goes on to the start


def test_a_zero_filled_tail_is_read_from_the_end_not_by_scanning_the_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """ext4 can leave a block of zeros after a power cut. Eight zero bytes read as a frame of
    length 0 (never a record): the listing ends there and only the zeros are scanned, not the
    hour of recording before them."""
    from avard.core.io import recording

    seg = tmp_path / "s.avr"
    _raw_segment(seg, 20)
    seg.write_bytes(seg.read_bytes() + bytes(4096))
    starts: list[int] = []
    real = recording._scanned_offsets

    def scanned(path: str | Path, start: int = 0) -> list[int]:
        starts.append(start)
        return real(path, start)

    monkeypatch.setattr(recording, "_scanned_offsets", scanned)
    assert recording.last_record(seg, "raw")["i0"] == 190
    assert starts and min(starts) == seg.stat().st_size - 4096
