"""Resynchronisation after damage: the vectorised search equals the definition (try every
offset with ``_valid_at``) and its CRC arithmetic equals zlib on every range."""

from __future__ import annotations

import zlib

import numpy as np
from avard.core.io.recording import (
    MAX_FRAME_BYTES,
    _crc_of_ranges,
    _PrefixCrc,
    _resync,
    _valid_at,
    frame,
    scan_frames,
)
from hypothesis import given, settings
from hypothesis import strategies as st


def _resync_by_definition(buf: memoryview, start: int, max_bytes: int) -> int | None:
    pos = start
    while pos + 8 <= len(buf):
        if _valid_at(buf, pos, max_bytes) is not None:
            return pos
        pos += 1
    return None


def test_crc_of_any_range_from_prefix_crcs_equals_zlib() -> None:
    rng = np.random.default_rng(7)
    data = rng.bytes(5000)
    starts = np.sort(rng.integers(0, 2500, 400))
    ends = starts + rng.integers(1, 2500, 400)
    got = _crc_of_ranges(_PrefixCrc(memoryview(data)), starts, ends)
    want = [zlib.crc32(data[s:e]) for s, e in zip(starts.tolist(), ends.tolist(), strict=True)]
    assert got.tolist() == want


@settings(max_examples=150, deadline=None)
@given(sizes=st.lists(st.integers(1, 300), min_size=1, max_size=12),
       flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 7)),
                      max_size=4),
       start=st.floats(0, 1, exclude_max=True), small_cap=st.booleans(), seed=st.integers(0, 99))
def test_resync_finds_the_same_offset_as_trying_every_byte(sizes, flips, start, small_cap,
                                                           seed) -> None:
    rng = np.random.default_rng(seed)
    buf = bytearray(b"".join(frame(rng.bytes(n)) for n in sizes))
    for where, bit in flips:
        buf[int(where * len(buf))] ^= 1 << bit
    view = memoryview(bytes(buf))
    cap = 100 if small_cap else MAX_FRAME_BYTES
    at = int(start * len(buf))
    assert _resync(view, at, cap) == _resync_by_definition(view, at, cap)


def test_a_crafted_segment_where_every_offset_claims_the_rest_of_the_file_reads_whole() -> None:
    """Every 4-byte-aligned offset claims a frame to the end (the issue's crafted file): no
    frame is valid, so the whole of it is one truncated tail, found without trying each."""
    size = 1 << 18
    claims = size - np.arange(0, size, 4, dtype=np.int64) - 8
    data = np.clip(claims, 0, None).astype("<u4").tobytes()
    problems: list = []
    assert list(scan_frames(data, "crafted", problems=problems)) == []
    assert [(p.kind, p.offset, p.dropped_bytes) for p in problems] == [("truncated", 0, size)]
    # and a real frame after 200 kB of such garbage is still found
    good = frame(b"\x81\xa4kind\xa3raw")
    got = list(scan_frames(data[:200_000] + good, "crafted", problems=problems))
    assert [f.offset for f in got] == [200_000]


def _densely_damaged(n_frames: int) -> bytes:
    """The campaign's file: valid 13-byte frames (5-byte payloads), each followed by a junk
    byte."""
    rng = np.random.default_rng(3)
    out = bytearray()
    for k in range(n_frames):
        out += frame(bytes(rng.integers(0, 256, 5, dtype=np.uint8))) + bytes([k % 251 + 1])
    return bytes(out)


def test_resync_work_on_a_densely_damaged_segment_grows_with_its_size_not_a_window(
        monkeypatch) -> None:
    """#26 item 10: every resync evaluated a fixed window of 16 384 candidate offsets, about
    1 200 candidate evaluations per byte of such a file (140 CPU-s per MB). Counted here, not
    timed: candidate offsets evaluated (one at a time, or in vectorised windows) per byte."""
    import avard.core.io.recording as rec

    data = _densely_damaged(3000)
    evaluated = [0]
    one, window = rec._valid_at, rec._valid_in

    def count_one(buf, pos, max_bytes):  # type: ignore[no-untyped-def]
        evaluated[0] += 1
        return one(buf, pos, max_bytes)

    def count_window(buf, lo, hi, max_bytes, prefix):  # type: ignore[no-untyped-def]
        evaluated[0] += max(0, min(hi, len(buf) - 7) - lo)
        return window(buf, lo, hi, max_bytes, prefix)

    monkeypatch.setattr(rec, "_valid_at", count_one)
    monkeypatch.setattr(rec, "_valid_in", count_window)
    problems: list = []
    frames_read = list(scan_frames(data, problems=problems))
    assert len(frames_read) == 3000
    assert len(problems) == 3000 and all(p.dropped_bytes == 1 for p in problems)
    assert evaluated[0] / len(data) < 2.0, evaluated[0] / len(data)


@settings(max_examples=60, deadline=None)
@given(junk=st.lists(st.binary(min_size=0, max_size=40), min_size=1, max_size=12),
       long_claims=st.booleans())
def test_the_near_search_equals_the_definition_between_short_and_long_claims(junk,
                                                                             long_claims):
    """Frames separated by junk, some of whose offsets claim long payloads (deferred to the
    windowed search) before a short valid frame: the same offset as trying every byte."""
    parts = []
    for k, j in enumerate(junk):
        if long_claims and len(j) >= 4:
            j = (5000 + k).to_bytes(4, "little") + j[4:]
        parts.append(frame(bytes([k]) * (1 + k % 7)) + j)
    buf = memoryview(b"".join(parts) + b"\x00" * 5100)   # room for the long claims
    for start in range(0, len(buf) - 5100, 3):
        assert _resync(buf, start, MAX_FRAME_BYTES) == _resync_by_definition(
            buf, start, MAX_FRAME_BYTES)
