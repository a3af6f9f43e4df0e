"""The segment writer: rotation, fsync, disk full (injected ENOSPC), retention, SIGHUP."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
from avard.core.io import frames
from avard.core.io.recording import RecordingReader
from avard.daemon.service.recorder import FileOps, Recorder


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class FaultyOps(FileOps):
    """Real files, with a switchable full disk and counted fsyncs."""

    def __init__(self) -> None:
        self.full = False
        self.fsyncs = 0
        self.partial = True

    def write(self, f, data: bytes) -> None:  # type: ignore[no-untyped-def]
        if self.full:
            if self.partial:  # a real ENOSPC can leave part of the write behind
                f.write(data[: len(data) // 2])
                f.flush()
            raise OSError(errno.ENOSPC, "No space left on device")
        super().write(f, data)

    def fsync(self, f) -> None:  # type: ignore[no-untyped-def]
        self.fsyncs += 1
        super().fsync(f)

    def free_bytes(self, directory: Path) -> int:
        return 0 if self.full else 10**12


def _header() -> dict:
    return frames.header_record("run1", rate_hz=125.0, t_mono=0.0, t_real=1.7e9,
                                scale_m_s2_per_count=1e-5)


def _raw(i0: int, n: int = 10) -> dict:
    counts = np.arange(i0 * 3, (i0 + n) * 3, dtype=np.int32).reshape(n, 3)
    return frames.raw_record("x", 0, i0, counts, i0 / 125, 1.7e9 + i0 / 125)


def _make(tmp: Path, clock: Clock, wall: Clock, ops: FileOps | None = None, **kw) -> Recorder:
    return Recorder(tmp, "run1", _header, clock=clock, wall=wall,
                    realtime=lambda: 1.7e9 + clock.t, fileops=ops, **kw)


def test_rotation_each_segment_self_describing(tmp_path: Path) -> None:
    clock, wall = Clock(), Clock()
    rec = _make(tmp_path, clock, wall, segment_s=10.0)
    for k in range(30):
        clock.t = k
        assert rec.write(_raw(10 * k))
    rec.close()
    segs = sorted(tmp_path.glob("*.avr"))
    assert len(segs) == 3
    for seg in segs:
        kinds = [r["kind"] for r in RecordingReader(seg)]
        assert kinds[0] == "header" and kinds.count("header") == 1
    idx = [r["i0"] for r in RecordingReader(tmp_path) if r["kind"] == "raw"]
    assert idx == [10 * k for k in range(30)]


def test_fsync_at_the_configured_interval(tmp_path: Path) -> None:
    clock, wall = Clock(), Clock()
    ops = FaultyOps()
    rec = _make(tmp_path, clock, wall, ops, fsync_interval_s=5.0)
    for k in range(101):
        wall.t = k * 0.1          # 10 s of wall time
        rec.write(_raw(10 * k))
    assert ops.fsyncs == 2          # at 5 s and 10 s, not per record
    wall.t = 10.05
    rec.write(_raw(2000))
    assert ops.fsyncs == 2
    rec.close()
    assert ops.fsyncs == 3          # and on close, so nothing written is left unsynced


def test_disk_full_pauses_then_resumes_with_a_gap(tmp_path: Path) -> None:
    clock, wall = Clock(), Clock()
    ops = FaultyOps()
    rec = _make(tmp_path, clock, wall, ops, retry_s=1.0)
    for k in range(5):
        assert rec.write(_raw(10 * k))
    ops.full = True
    for k in range(5, 12):
        wall.t += 0.5
        assert not rec.write(_raw(10 * k))
    assert rec.disk_full and rec.status()["state"] == "disk_full"
    assert rec.samples_lost == 70
    ops.full = False
    wall.t += 2.0
    for k in range(12, 15):
        assert rec.write(_raw(10 * k))
    rec.close()
    reader = RecordingReader(tmp_path)
    recs = list(reader)
    assert reader.problems == []      # the half-written frame was cut off again
    gaps = [r for r in recs if r["kind"] == "gap"]
    assert [(g["i0"], g["n"], g["reason"]) for g in gaps] == [(50, 70, "disk_full")]
    raw = [r["i0"] for r in recs if r["kind"] == "raw"]
    assert raw == [0, 10, 20, 30, 40, 120, 130, 140]
    assert len(list(tmp_path.glob("*.avr"))) == 2   # resumed in a new segment


def test_min_free_bytes_counts_as_full(tmp_path: Path) -> None:
    clock, wall = Clock(), Clock()

    class Low(FileOps):
        def free_bytes(self, directory: Path) -> int:
            return 1000

    rec = _make(tmp_path, clock, wall, Low(), min_free_bytes=1 << 20)
    assert not rec.write(_raw(0))
    assert rec.disk_full


def test_retention_by_size_and_age_never_deletes_open_segment(tmp_path: Path) -> None:
    clock, wall = Clock(), Clock()
    # a segment two days of samples older than the newest (age is sample time: #26 item 4)
    old = Recorder(tmp_path, "20000101T000000Z-old", _header, clock=clock, wall=wall)
    old.write(_raw(0))
    old.close()
    assert old.path is not None
    rec = _make(tmp_path, clock, wall, segment_s=10.0, retention_days=1.0)
    rec.write(_raw(2 * 86400 * 125))
    clock.t = 10.0                                  # the next rotation applies retention
    rec.write(_raw(2 * 86400 * 125 + 10))
    assert not old.path.exists() and rec.deleted == [old.path.name]
    rec.close()
    clock2, wall2 = Clock(), Clock()
    rec2 = Recorder(tmp_path / "b", "r", _header, segment_s=1.0, retention_max_bytes=3000,
                    clock=clock2, wall=wall2, realtime=lambda: 1.7e9 + clock2.t)
    for k in range(40):
        clock2.t = float(k)
        rec2.write(_raw(10 * k))
    total = sum(p.stat().st_size for p in (tmp_path / "b").glob("*.avr"))
    assert total <= 3000 + 2 * len(frames.encode(_raw(0))) + 400
    assert rec2.path is not None and rec2.path.exists()
    assert rec2.deleted
    rec2.close()


def test_reopen_starts_a_new_segment(tmp_path: Path) -> None:
    clock, wall = Clock(), Clock()
    rec = _make(tmp_path, clock, wall)
    rec.write(_raw(0))
    first = rec.path
    assert first is not None
    moved = tmp_path / "rotated.old"
    first.rename(moved)           # logrotate moves the file away, then sends SIGHUP
    rec.reopen()
    clock.t = 1.0
    rec.write(_raw(10))
    rec.close()
    assert rec.path is not None and rec.path.exists() and rec.path != first
    assert [r["kind"] for r in RecordingReader(rec.path)] == ["header", "raw"]


class NoPermission(FileOps):
    """A segment the service may not write (EACCES), until ``allowed``."""

    def __init__(self) -> None:
        self.allowed = True

    def open_append(self, path: Path):  # type: ignore[no-untyped-def]
        if not self.allowed:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return super().open_append(path)


def test_a_permission_error_is_reported_as_what_it_is_not_as_a_full_disk(tmp_path: Path,
                                                                         caplog) -> None:
    """#26 item 11: EACCES on a segment was reported as ``disk_full`` (state and gap)."""
    clock, wall = Clock(), Clock()
    ops = NoPermission()
    rec = _make(tmp_path, clock, wall, ops, segment_s=10.0, retry_s=5.0)
    assert rec.write(_raw(0))
    ops.allowed = False
    clock.t = wall.t = 10.0                       # rotation: the new segment cannot be opened
    assert not rec.write(_raw(10))
    st = rec.status()
    assert st["state"] == "write_error" and not rec.disk_full
    assert "Permission denied" in st["error"]
    assert "disk full" not in " ".join(r.getMessage() for r in caplog.records).lower()
    ops.allowed = True
    clock.t = wall.t = 20.0
    assert rec.write(_raw(20))
    rec.close()
    gaps = [r for r in RecordingReader(tmp_path) if r["kind"] == "gap"]
    assert [(g["reason"], g["i0"], g["n"]) for g in gaps] == [("write_error", 10, 10)]
    assert rec.status()["state"] == "writing"


class FailingFsync(FileOps):
    """Real files whose fsync fails with EIO (a dying SD card) while ``fail`` is set."""

    def __init__(self) -> None:
        self.fail = True

    def fsync(self, f) -> None:  # type: ignore[no-untyped-def]
        if self.fail:
            raise OSError(errno.EIO, "Input/output error")
        super().fsync(f)


def test_flush_says_whether_the_data_is_on_disk(tmp_path: Path) -> None:
    clock, wall = Clock(), Clock()
    ops = FailingFsync()
    rec = _make(tmp_path, clock, wall, ops, fsync_interval_s=3600.0)
    assert rec.write(_raw(0))
    assert rec.flush() is False                # EIO: paused with write_error, not on disk
    assert rec.status()["state"] == "write_error"
    assert rec.flush() is False                # and still not, though nothing is dirty now
    rec.close()
    ops.fail = False
    rec2 = _make(tmp_path / "b", clock, wall, ops, fsync_interval_s=3600.0)
    assert rec2.write(_raw(0))
    assert rec2.flush() is True
    rec2.close()


def test_a_failed_fsync_never_writes_the_state_file(tmp_path: Path) -> None:
    """The state file names a checkpoint record as on disk: written only when the fsync
    before it succeeded (a state file ahead of the recording is a restore from samples the
    recording does not hold)."""
    import threading
    from types import SimpleNamespace

    from avard.daemon.service.header import RunHeader
    from avard.daemon.service.recorder_stage import RecorderStage
    from avard.daemon.service.ring import Ring

    clock, wall = Clock(), Clock()
    ops = FailingFsync()
    rec = _make(tmp_path, clock, wall, ops, fsync_interval_s=3600.0)
    ring = Ring(100)
    consumer = ring.consumer("recorder")
    stated: list[dict] = []
    header = RunHeader(lambda: _header(), SimpleNamespace(odr_hz=125.0),  # type: ignore[arg-type]
                       lambda: 0.0, lambda: 0, lambda: 0.0)
    stage = RecorderStage(consumer, rec, run_id="run1", real_offset=0.0,
                          rate_hz=lambda: 125.0, real_now=lambda: 1.7e9, header=header,
                          checkpoint_written=stated.append, reopen=threading.Event(),
                          block_samples=1000)
    ring.push(np.ones((10, 3), np.int32), np.arange(10), np.arange(10) / 125.0)
    ring.mark(frames.checkpoint_record("run1", 0, 10, 10, {}, 0.08, 1.7e9))
    stage.handle(consumer.read())
    assert stated == []
    rec.close()
    ops.fail = False
    rec2 = _make(tmp_path / "b", clock, wall, ops, fsync_interval_s=3600.0)
    stage.rec = rec2
    ring.mark(frames.checkpoint_record("run1", 1, 10, 10, {}, 0.09, 1.7e9))
    stage.handle(consumer.read())
    assert [r["i_end"] for r in stated] == [10]
    rec2.close()


def test_a_segment_cut_short_counts_every_record_it_lost_not_only_the_sample_ones(
        tmp_path: Path) -> None:
    """``lost_records`` of a ``segment_removed`` gap counted only the raw and gap records
    past the cut; the temperature readings and events written there went uncounted."""
    clock, wall = Clock(), Clock()
    rec = _make(tmp_path, clock, wall)
    assert rec.write(_raw(0)) and rec.write(_raw(10))
    assert rec.path is not None
    keep = rec.path.stat().st_size
    # past the cut: two events, a temperature reading and one raw block
    assert rec.write(frames.event_record("x", 0, "note", 0.1, 1.7e9))
    assert rec.write(frames.temp_record("x", 0, 20, ["a"], [21.0], 0.15, 1.7e9))
    assert rec.write(_raw(20))
    assert rec.write(frames.event_record("x", 0, "note", 0.2, 1.7e9))
    os.truncate(rec.path, keep)
    clock.t = 0.3
    assert rec.write(_raw(30))
    rec.close()
    gaps = [r for r in RecordingReader(tmp_path) if r["kind"] == "gap"]
    assert [(g["reason"], g["i0"], g["n"], g["lost_records"]) for g in gaps] == [
        ("segment_removed", 20, 10, 4)]


def test_the_record_marks_of_an_open_segment_stay_compact(tmp_path: Path) -> None:
    """One tuple of five Python numbers per raw record, held for the whole segment: some
    84 MB for an hour-long segment at block_s = 0.01. Columns of machine numbers now,
    under 64 bytes a record (48 and the arrays' spare room)."""
    import tracemalloc

    clock, wall = Clock(), Clock()
    rec = _make(tmp_path, clock, wall)
    assert rec.write(_raw(0, 1))
    n = 20_000
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for k in range(1, n + 1):
            rec.write(_raw(k, 1))
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert rec.segments_written == 1
    assert grown / n < 64, grown / n
