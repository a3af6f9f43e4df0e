"""Hostile input against the recording reader (avard.core.io.recording): hypothesis fuzzing.

Segment files are damaged the ways disks and power cuts damage them (truncation, bit flips,
zero-filled or garbage blocks, lengths claiming 4 GB) and built by a hostile writer (frames with
a valid CRC whose records are odd). For any file the reader must: never raise anything but
FormatError (and only in strict mode or when nothing at all is readable), keep every intact
record before the first damage, and account for every byte: what it returns plus what it
reports as dropped equals the file's size, so nothing is lost silently.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from avard.core.errors import AvardError, FormatError
from avard.core.io import frames, recording
from hypothesis import given
from hypothesis import strategies as st

from .test_fuzz_frames import (
    assert_bounded_allocation,
    fuzz_settings,
    make_counter,
    msgpack_values,
    mutated,
    save_counts,
    valid_records,
    wrong_type_records,
)

HDR = recording.FRAME_HEADER.size


@pytest.fixture(scope="module")
def counter(request):
    c = make_counter(request)
    yield c
    save_counts(request, c)


def _segment_records(n_raw: int = 4) -> list[dict[str, Any]]:
    recs: list[dict[str, Any]] = [frames.header_record(
        "run-1", rate_hz=125.0, t_mono=1.0, t_real=1.7e9, scale_m_s2_per_count=3.83e-5,
        temperature_channels=["plate"])]
    seq = 1
    for k in range(n_raw):
        counts = (np.arange(24, dtype=np.int32).reshape(8, 3) * (k + 1)) % 977 - 400
        recs.append(frames.raw_record("run-1", seq, 8 * k, counts, 1.0 + k, 1.7e9 + k))
        recs.append(frames.temp_record("run-1", seq + 1, 8 * k, ["plate"], [21.5 + k], 1.0, 2.0))
        seq += 2
    recs.append(frames.gap_record("run-1", seq, 8 * n_raw, 5, 9.0, 9.0, "overrun"))
    recs.append(frames.event_record("run-1", seq + 1, "clock_step", 9.0, 9.0,
                                    detail={"step_s": -3.0}))
    return recs


def _segment_bytes(recs: list[dict[str, Any]]) -> bytes:
    return b"".join(recording.frame(frames.encode(r)) for r in recs)


VALID_SEGMENT = _segment_bytes(_segment_records())


def _decodable_bytes(data: bytes) -> int:
    """Bytes of frames that have a valid CRC *and* decode to a valid record."""
    total = 0
    for fr in recording.scan_frames(data):
        try:
            frames.decode(fr.payload)
        except FormatError:
            continue
        total += HDR + len(fr.payload)
    return total


def _read_all(path: Path) -> tuple[list[dict[str, Any]], recording.RecordingReader]:
    reader = recording.RecordingReader(path)
    return list(reader), reader


def _check_reader(path: Path, data: bytes) -> list[dict[str, Any]]:
    """Non-strict reading never raises, keeps every valid record and accounts for every byte;
    strict reading raises nothing but FormatError."""
    recs, reader = _read_all(path)
    kept = _decodable_bytes(data)
    assert kept + reader.dropped_bytes == len(data), (
        f"{len(data)} bytes: {kept} kept + {reader.dropped_bytes} reported dropped; "
        f"problems: {[str(p) for p in reader.problems]}"
    )
    for prob in reader.problems:
        assert prob.dropped_bytes > 0 and str(prob)
    try:
        strict = list(recording.RecordingReader(path, strict=True))
    except FormatError as exc:
        assert "byte" in str(exc)  # says where
    else:
        assert len(strict) == len(recs)
    return recs


@fuzz_settings(200)
@given(data=mutated(st.just(VALID_SEGMENT)))
def test_damaged_segment_reads_back_with_every_byte_accounted_for(counter, tmp_path_factory,
                                                                  data):
    counter.tick("RecordingReader")
    path = tmp_path_factory.mktemp("seg") / "seg.avr"
    path.write_bytes(data)
    recs = _check_reader(path, data)
    # every record whose frame lies wholly before the first changed byte is returned intact
    first_diff = next((i for i, (a, b) in enumerate(zip(data, VALID_SEGMENT, strict=False))
                       if a != b), min(len(data), len(VALID_SEGMENT)))
    intact = 0
    pos = 0
    for fr in recording.scan_frames(VALID_SEGMENT):
        pos = fr.offset + HDR + len(fr.payload)
        if pos > first_diff:
            break
        intact += 1
    assert len(recs) >= intact


@fuzz_settings(200)
@given(data=st.binary(max_size=4096))
def test_random_bytes_as_a_segment(counter, tmp_path_factory, data):
    counter.tick("RecordingReader")
    path = tmp_path_factory.mktemp("seg") / "seg.avr"
    path.write_bytes(data)
    _check_reader(path, data)


@fuzz_settings(150)
@given(cut=st.integers(0, len(VALID_SEGMENT)), fill=st.sampled_from([b"\x00", b"\xff"]),
       fill_len=st.integers(1, 8192))
def test_power_cut_tail_of_zeros_or_ones(counter, tmp_path_factory, cut, fill, fill_len):
    # ext4 with delayed allocation can leave a file extended by zero-filled blocks after a power
    # cut; flash can read back 0xFF. The reader keeps what is complete and reports the rest.
    counter.tick("RecordingReader")
    data = VALID_SEGMENT[:cut] + fill * fill_len
    path = tmp_path_factory.mktemp("seg") / "seg.avr"
    path.write_bytes(data)
    recs = _check_reader(path, data)
    # Complete = the original frame's bytes are all there (the fill may even complete the
    # frame cut in two, when its missing tail happened to be those very bytes).
    complete = [fr for fr in recording.scan_frames(VALID_SEGMENT)
                if data[fr.offset:fr.offset + HDR + len(fr.payload)]
                == VALID_SEGMENT[fr.offset:fr.offset + HDR + len(fr.payload)]]
    assert len(recs) == len(complete)
    assert all(r["seq"] == frames.decode(fr.payload)["seq"] for r, fr in zip(recs, complete,
                                                                             strict=True))


@fuzz_settings(200)
@given(payload=st.one_of(wrong_type_records(), msgpack_values.map(
    lambda v: msgpack.packb(v, use_bin_type=True)), st.binary(max_size=64)),
    where=st.integers(0, 6))
def test_crc_valid_frames_with_hostile_records(counter, tmp_path_factory, payload, where):
    # A hostile (or buggy) writer: the CRC is right, the record inside is not.
    counter.tick("RecordingReader")
    good = [recording.frame(frames.encode(r)) for r in _segment_records(2)]
    good.insert(min(where, len(good)), recording.frame(payload))
    data = b"".join(good)
    path = tmp_path_factory.mktemp("seg") / "seg.avr"
    path.write_bytes(data)
    _check_reader(path, data)
    # The whole-recording loaders see only validated records: they succeed or say why.
    counter.tick("load_recording")
    try:
        rec = recording.load_recording(path)
    except AvardError as exc:
        assert str(exc)
    else:
        assert rec.accel.ndim == 2 and rec.accel.shape[1] == 3
        assert np.isfinite(rec.accel).all()
    counter.tick("replay_allan")
    try:
        recording.replay_allan(path)
    except AvardError as exc:
        assert str(exc)


@fuzz_settings(100)
@given(rec=valid_records())
def test_any_valid_record_survives_the_disk(counter, tmp_path_factory, rec):
    counter.tick("RecordingReader")
    path = tmp_path_factory.mktemp("seg") / "seg.avr"
    data = recording.frame(frames.encode(rec))
    path.write_bytes(data)
    recs = _check_reader(path, data)
    assert len(recs) == 1 and recs[0]["kind"] == rec["kind"] and recs[0]["seq"] == rec["seq"]


@pytest.mark.parametrize("claimed", [2**32 - 1, recording.MAX_FRAME_BYTES + 1,
                                     recording.MAX_FRAME_BYTES, 2**20])
def test_huge_declared_frame_length_allocates_nothing_big(counter, tmp_path, claimed):
    counter.tick("RecordingReader")
    body = b"\x81\xa4kind\xa3raw" + b"\x00" * 64
    data = VALID_SEGMENT + struct.pack("<II", claimed, zlib.crc32(body)) + body
    path = tmp_path / "seg.avr"
    path.write_bytes(data)

    def read(_: bytes) -> list:
        return list(recording.RecordingReader(path))

    recs = assert_bounded_allocation(read, data, factor=16)
    assert len(recs) == len(_segment_records())


def test_directory_of_damaged_and_empty_segments(counter, tmp_path):
    counter.tick("RecordingReader", 4)
    (tmp_path / "20260101T000000Z.avr").write_bytes(VALID_SEGMENT)
    (tmp_path / "20260101T010000Z.avr").write_bytes(b"")
    (tmp_path / "20260101T020000Z.avr").write_bytes(VALID_SEGMENT[: len(VALID_SEGMENT) // 2])
    (tmp_path / "20260101T030000Z.avr").write_bytes(b"\x00" * 4096 + VALID_SEGMENT)
    (tmp_path / "notes.txt").write_text("not a segment")
    recs, reader = _read_all(tmp_path)
    n = len(_segment_records())
    assert n * 2 < len(recs) < n * 3
    assert {p.kind for p in reader.problems} <= {"truncated", "corrupt", "undecodable"}
    assert sum(p.dropped_bytes for p in reader.problems) >= 4096


def test_not_a_recording_is_a_clear_error(counter, tmp_path):
    counter.tick("RecordingReader", 2)
    with pytest.raises(FormatError, match=r"no \.avr segment files"):
        recording.RecordingReader(tmp_path)
    with pytest.raises(FormatError, match="no such recording"):
        recording.RecordingReader(tmp_path / "missing.avr")
