"""Segment order comes from the frames, not from the file names (#26 item 2).

``Recorder._rotate`` named segments ``{n:04d}``: segment 10 000 sorted before 9 998 (a 28 h
run at ``segment_s = 10``), so ``analyze`` read samples out of order, ``last_recorded`` took
segment 9 999 as the newest and the restart gap claimed present samples as lost. Now every
reader orders segments by (run, sample index) read from their frames, and the names are wide
enough to sort correctly anyway.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from avard.core.io import frames
from avard.core.io.recording import (
    RecordingReader,
    load_recording,
    order_segments,
    scan_frames,
    segment_files,
    segment_key,
)
from avard.core.io.recording import frame as frame_bytes
from avard.daemon.service.recorder import Recorder, last_recorded

RUN = "n00000007-20260101T000000Z-abcdef"
RATE = 125.0


def _record(d: Path, first_segment: int, n_segments: int, block: int = 50) -> list[Path]:
    """One run of ``n_segments`` segments numbered from ``first_segment``, one raw block of
    ``block`` samples each; returns the files in the order they were written."""
    now = [0.0]
    nxt = [1000]

    def header() -> dict:
        return frames.header_record(RUN, rate_hz=RATE, t_mono=now[0], t_real=1.7e9 + now[0],
                                    i0=nxt[0], scale_m_s2_per_count=3.9e-5)

    rec = Recorder(d, RUN, header, segment_s=1.0, clock=lambda: now[0])
    rec._segment_no = first_segment
    written = []
    rng = np.random.default_rng(5)
    for _ in range(n_segments):
        counts = rng.integers(-500, 500, size=(block, 3)).astype(np.int32)
        rec.write(frames.raw_record(RUN, 0, nxt[0], counts, now[0], 1.7e9 + now[0],
                                    rate_hz=RATE))
        assert rec.path is not None
        written.append(rec.path)
        nxt[0] += block
        now[0] += 1.0
    rec.close()
    return written


def test_segment_names_sort_in_data_order_past_segment_9999(tmp_path):
    written = _record(tmp_path, 9997, 5)
    assert sorted(p.name for p in written) == [p.name for p in written]


def test_readers_order_segments_by_their_frames_whatever_the_names_say(tmp_path, caplog):
    written = _record(tmp_path, 9997, 5)
    # the names the old recorder gave them: four digits wide, 10 000 sorts before 9 997
    old = []
    for k, p in enumerate(written):
        q = p.with_name(f"{RUN}_{9997 + k:04d}_20260101T000000Z.avr")
        p.rename(q)
        old.append(q)
    assert sorted(p.name for p in old) != [p.name for p in old]
    assert segment_files(tmp_path) == old
    assert order_segments(reversed(old)) == old
    idx = np.concatenate([r["i0"] + np.arange(r["n"]) for r in RecordingReader(tmp_path)
                          if r["kind"] == "raw"])
    assert np.array_equal(idx, 1000 + np.arange(250))           # data order, no jump
    rec = load_recording(tmp_path)
    assert rec.meta["segment_bounds"] == [0, 250]                # no spurious break
    assert rec.meta["samples_lost"] == 0
    # the service's start: the newest segment is the one holding the last samples
    last = last_recorded(tmp_path, RATE)
    assert last is not None and last.i_end == 1250
    # the service's start says so, loudly
    assert any("do not sort in data order" in r.getMessage() for r in caplog.records
               if r.levelname == "WARNING")


def test_a_segment_whose_header_is_damaged_is_placed_by_its_records(tmp_path):
    written = _record(tmp_path, 9997, 4)
    victim = written[1]
    data = bytearray(victim.read_bytes())
    data[12] ^= 0xFF                                             # the header's payload
    victim.write_bytes(bytes(data))
    names = [victim.with_name(f"z{k}.avr") for k in (3, 0, 2, 1)]   # in no useful order
    for p, q in zip(written, names, strict=True):
        p.rename(q)
    key = segment_key(names[1])
    assert key.header_seq == -1 and key.i0 == 1050                # from its raw block
    assert segment_files(tmp_path) == names


def test_a_temperature_stamped_before_a_rotation_does_not_key_the_next_segment_early(tmp_path):
    """The temperature thread stamps a ``temp`` (or ``event``) record with the ring's index
    before ``ring.mark``; when the segment rotates between the previous raw flush and that
    record, the new segment starts with a record naming an index the previous segment's
    samples still cover. The segment's key is its first sample record (raw or gap), so the
    restore's replay never starts one segment too late and skips samples."""
    from avard.core.allan.feed import AllanFeed
    from avard.core.allan.replay import replay_after
    from avard.core.allan.streaming import StreamingAllan

    def header(i0: int) -> dict:
        return frames.header_record(RUN, rate_hz=RATE, t_mono=0.0, t_real=1.7e9, i0=i0,
                                    scale_m_s2_per_count=3.9e-5)

    def raw(i0: int) -> dict:
        return frames.raw_record(RUN, 0, i0, np.ones((100, 3), np.int32), i0 / RATE,
                                 1.7e9 + i0 / RATE, rate_hz=RATE)

    a, b = tmp_path / f"{RUN}_000000_a.avr", tmp_path / f"{RUN}_000001_b.avr"
    a.write_bytes(b"".join(frame_bytes(frames.encode(r))
                           for r in [header(0), raw(0), raw(100)]))
    early = frames.temp_record(RUN, 0, 150, ["chip"], [21.0], 150 / RATE, 1.7e9)
    b.write_bytes(b"".join(frame_bytes(frames.encode(r))
                           for r in [header(200), early, raw(200)]))
    assert segment_key(b).i0 == 200
    feed = AllanFeed(StreamingAllan(3, RATE), 3.9e-5, [])
    assert replay_after(tmp_path, feed, 180) == 120            # [180, 300): none skipped


def test_last_recorded_survives_a_flipped_bit_in_a_length_field(tmp_path):
    """The reviewer's case end to end: a plausible length running past the end of the
    newest segment made last_recorded return an old end (the next run then called recorded
    samples lost and, with clock "unknown", reused their indices)."""
    rec = Recorder(tmp_path, RUN, lambda: frames.header_record(
        RUN, rate_hz=RATE, t_mono=0.0, t_real=1.7e9, i0=1050, scale_m_s2_per_count=3.9e-5))
    for k in range(20):
        rec.write(frames.raw_record(RUN, 0, 1050 + 50 * k, np.zeros((50, 3), np.int32),
                                    k, 1.7e9 + k, rate_hz=RATE))
    assert rec.path is not None
    newest = rec.path
    rec.close()
    data = bytearray(newest.read_bytes())
    offs = [f.offset for f in scan_frames(bytes(data))]
    n = int.from_bytes(data[offs[4]:offs[4] + 4], "little") | (1 << 20)
    data[offs[4]:offs[4] + 4] = n.to_bytes(4, "little")
    newest.write_bytes(bytes(data))
    last = last_recorded(tmp_path, RATE)
    assert last is not None and last.i_end == 1050 + 50 * 20
