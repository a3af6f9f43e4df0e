"""The segment writer: CRC-framed records appended to rotating segment files.

- Every segment starts with the run's header, so each file can be read on its own, and
  repeats it every ``header_every_s`` of data time: a damaged first header then costs no
  samples (the reader interprets the records before the copy with it).
- Rotation every ``segment_s`` of *data* time (the service clock, virtual under ``--speed``),
  and on SIGHUP (:meth:`Recorder.reopen`), so log rotation tools can move files away.
- ``fsync`` at most every ``fsync_interval_s`` of wall time: a power cut loses at most that.
- Disk full (ENOSPC/EDQUOT, or free space below ``min_free_bytes``): the failed frame is cut
  off again (no half frame stays in the file), writing pauses, acquisition and publishing go
  on, the state shows in :attr:`Recorder.status` and the log; free space is re-checked every
  ``retry_s`` and writing resumes in a new segment that starts with a ``gap`` record naming
  the samples lost (reason ``disk_full``).
- Any other write error (EACCES on a segment, EIO, EROFS): the same pause and retry, but
  reported as what it is: state ``write_error`` with the error, gap reason ``write_error``.
- Retention after every rotation: segments older than ``retention_days`` and then the oldest
  while the total exceeds ``retention_max_bytes`` are deleted (never the open one). Age and
  "oldest" are measured in the recording's own time, from its frames: sample indices over the
  output rate, segments in (run, index) order. Never file mtimes against CLOCK_REALTIME: a Pi
  without an RTC whose clock NTP steps forward by days would lose every older segment.

All file-system access goes through :class:`FileOps`, so tests can inject ENOSPC, slow disks or
failing fsyncs without filling a real disk.
"""

from __future__ import annotations

import bisect
import errno
import logging
import os
import re
import secrets
import shutil
import stat
import threading
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from avard.core.allan.feed import nominal_of
from avard.core.errors import FormatError
from avard.core.io import frames
from avard.core.io.recording import (
    NO_INDEX,
    SEGMENT_SUFFIX,
    SegmentKey,
    first_record,
    frame,
    keyed_segments,
    order_segments,
    records_backwards,
    segment_end,
)
from avard.daemon.service import dirlock

log = logging.getLogger(__name__)

_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


class FileOps:
    """The recorder's file-system layer (real files); subclass it to inject faults.

    Segments are opened unbuffered: a buffered file would flush its buffer again inside
    ``truncate()`` and hit ENOSPC a second time, leaving the torn frame in the file."""

    #: Attempts (and the pause between them) to cut a torn frame off after a failed write.
    truncate_attempts = 3
    truncate_pause_s = 0.01

    def open_append(self, path: Path) -> IO[bytes]:
        return open(path, "ab", buffering=0)

    def write(self, f: IO[bytes], data: bytes) -> None:
        view = memoryview(data)
        while view:
            # A raw file may write only part (the disk filled up under it); the next call
            # then raises the error that says why.
            done = f.write(view)
            if not done:
                raise OSError(errno.EIO, "write wrote nothing")
            view = view[done:]

    def fsync(self, f: IO[bytes]) -> None:
        os.fsync(f.fileno())

    def stat(self, f: IO[bytes]) -> os.stat_result:
        """The open segment's inode: its links (0 once deleted) and size."""
        return os.fstat(f.fileno())

    def truncate(self, f: IO[bytes], size: int) -> None:
        # ftruncate on the descriptor: no buffer to flush first, and shrinking a file needs
        # no free blocks, so this works on a full disk.
        os.ftruncate(f.fileno(), size)
        f.seek(size)

    def free_bytes(self, directory: Path) -> int:
        return shutil.disk_usage(directory).free

    def remove(self, path: Path) -> None:
        path.unlink()

    def segments(self, directory: Path) -> list[tuple[Path, int, float]]:
        """(path, size bytes, mtime s) of the segment files (retention orders them by their
        frames, recording.keyed_segments; the mtime is not used for age)."""
        out = []
        for p in sorted(directory.glob("*" + SEGMENT_SUFFIX)):
            try:
                st = p.stat()
            except FileNotFoundError:
                continue
            if not stat.S_ISREG(st.st_mode):
                continue            # a directory in a segment's place is not ours to delete
            out.append((p, st.st_size, st.st_mtime))
        return out


@dataclass
class LostSpan:
    """Samples that reached the recorder but could not be written."""

    i0: int
    n: int
    t_mono: float
    t_real: float
    records: int = 0
    reason: str = "disk_full"       # or "write_error": why they could not be written


class _Marks:
    """Where each record of the open segment ends (byte offset after its frame), and for
    the sample records (raw, gap) their indices and clocks: what a segment deleted or cut
    short behind the recorder's back took with it.

    Columns of machine numbers, not a tuple per record: at block_s = 0.01 an hour-long
    segment holds some 360 000 raw records, which as tuples took about 84 MB; here 48 bytes
    each. Offsets only grow within a segment, so what lies past a size is found by bisection."""

    def __init__(self) -> None:
        self.ends = array("q")        # every record
        self.at = array("q")          # the sample records: their end offsets
        self.i0 = array("q")
        self.stop = array("q")        # the index after the samples it names
        self.t_mono = array("d")
        self.t_real = array("d")

    def add(self, end: int, record: dict[str, Any]) -> None:
        self.ends.append(end)
        if record["kind"] in ("raw", "gap") and "i0" in record:
            i0 = int(record["i0"])
            self.at.append(end)
            self.i0.append(i0)
            self.stop.append(i0 + int(record.get("n", 0)))
            self.t_mono.append(float(record.get("t_mono", 0.0)))
            self.t_real.append(float(record.get("t_real", 0.0)))

    def records_after(self, kept: int) -> int:
        """The records not whole in the first ``kept`` bytes."""
        return len(self.ends) - bisect.bisect_right(self.ends, kept)

    def lost_after(self, kept: int) -> tuple[int, int, float, float] | None:
        """(first index, index after the last, t_mono, t_real of the first) of the samples
        the records not whole in ``kept`` bytes named; None when they named none."""
        k = bisect.bisect_right(self.at, kept)
        if k == len(self.at):
            return None
        return self.i0[k], max(self.stop[k:]), self.t_mono[k], self.t_real[k]

    def nbytes(self) -> int:
        cols = (self.ends, self.at, self.i0, self.stop, self.t_mono, self.t_real)
        return sum(c.buffer_info()[1] * c.itemsize for c in cols)


class Recorder:
    """Append records to segment files under ``data_dir``; thread-safe, never raises OSError
    into the service for a full disk (it pauses and says so instead)."""

    def __init__(self, data_dir: str | Path, run_id: str,
                 header: Callable[[], dict[str, Any]], *,
                 segment_s: float = 3600.0, fsync_interval_s: float = 5.0,
                 retention_days: float = 0.0, retention_max_bytes: int = 0,
                 min_free_bytes: int = 0, retry_s: float = 5.0, header_every_s: float = 60.0,
                 clock: Callable[[], float] = time.monotonic,
                 wall: Callable[[], float] = time.monotonic,
                 realtime: Callable[[], float] = time.time,
                 fileops: FileOps | None = None) -> None:
        self.dir = Path(data_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.run_id = run_id
        self._header = header
        self.segment_s = float(segment_s)
        self.fsync_interval_s = float(fsync_interval_s)
        self.retention_days = float(retention_days)
        self.retention_max_bytes = int(retention_max_bytes)
        self.min_free_bytes = int(min_free_bytes)
        self.retry_s = float(retry_s)
        self.header_every_s = float(header_every_s)
        self._header_at = 0.0
        self.clock, self.wall, self.realtime = clock, wall, realtime
        self.ops = fileops or FileOps()
        self._lock = threading.RLock()
        self._f: IO[bytes] | None = None
        self.path: Path | None = None
        self._size = 0
        self._opened_at = 0.0
        self._last_sync = wall()
        self._dirty = False
        self._segment_no = 0
        self._seq: dict[str, int] = {}
        self._full_since: float | None = None    # paused since (disk full or write error)
        self._pause: str | None = None           # "disk_full" | "write_error" while paused
        self._pause_detail = ""
        self._next_retry = 0.0
        self.lost: LostSpan | None = None
        self.records = 0
        self.bytes = 0
        self.segments_written = 0
        self.records_lost = 0
        self.samples_lost = 0
        self.deleted: list[str] = []
        self._index_end = 0        # the index after the newest sample named by a record written
        self._rate_hz = 0.0        # the output rate the records give (fitted, else nominal)
        self.errors = 0
        self.torn_frames = 0      # torn frames that could not be cut off (see _cut_torn_frame)
        self._marks = _Marks()       # what the open segment holds, to name what it lost
        self._lock_checked_at = -1e300   # record time of the last dirlock.recheck (write())
        self._lock_gen = 0               # dirlock.generation when the open segment was opened
        self.segments_removed = 0    # open segments deleted or cut short behind our back
        self._removed: list[dict[str, Any]] = []   # their gaps, for the next segment

    # -- public -------------------------------------------------------------------------
    @property
    def disk_full(self) -> bool:
        return self._pause == "disk_full"

    @property
    def paused(self) -> bool:
        """Writing is paused: a full disk or another write error (retried every retry_s)."""
        return self._full_since is not None

    def status(self) -> dict[str, Any]:
        """For STATUS= and the status record: state, file, bytes, losses, free space."""
        try:
            free = self.ops.free_bytes(self.dir)
        except OSError:
            free = -1
        return {"state": self._pause or "writing", "error": self._pause_detail or None,
                "segment": self.path.name if self.path else None,
                "records": self.records, "bytes": self.bytes,
                "segments": self.segments_written, "records_lost": self.records_lost,
                "samples_lost": self.samples_lost, "torn_frames": self.torn_frames,
                "segments_removed": self.segments_removed,
                "free_bytes": free}

    def write(self, record: dict[str, Any]) -> bool:
        """Write one record (its ``run``/``seq`` are set here). False when it was lost to a
        full disk; the loss is then remembered and written as a gap on resume."""
        with self._lock:
            now = self.clock()
            if self.paused and not self._try_resume(now):
                self._remember_lost(record)
                return False
            if self._f is not None:
                self._check_segment()
            t_data = record.get("t_mono")
            t_data = float(t_data) if isinstance(t_data, int | float) else now
            if self._f is not None and abs(t_data - self._lock_checked_at) >= 1.0:
                # the lock file removed alone (rm DIR/.avard.lock) leaves the segment as it
                # is: checked once a second of the records' own time too, not only at the
                # next rotation (a stat of each path component, some 30 µs: not at every
                # record; the records' time, since a stage catching up writes many records
                # at one clock reading)
                self._lock_checked_at = t_data
                lost_lock = dirlock.recheck(self.dir)
                if lost_lock is not None:
                    self._lost_lock(lost_lock)
                    self._remember_lost(record)
                    return False
                if dirlock.generation(self.dir) != self._lock_gen:
                    # locked again: the directory at the path is not the one the open
                    # segment is in (``mv DIR DIR.old; mkdir DIR``: the segment moved with
                    # the old one, whole, so nothing else rotates); what follows goes to
                    # the path, beside the state file, and the old segment keeps its part
                    # (removed rather than moved, and the path made again between the
                    # segment check above and the recheck: the segment check first, so its
                    # samples are a segment_removed gap, not closed as if kept)
                    self._check_segment()
                    if self._f is not None:
                        log.warning("%s was replaced (moved away and made again?); %s keeps "
                                    "what was written before, recording goes on in %s",
                                    self.dir, self.path.name if self.path else "the segment",
                                    self.dir)
                        self._close_file()
            if self._f is None or now - self._opened_at >= self.segment_s:
                if not self._rotate(now):
                    self._remember_lost(record)
                    return False
            if self.header_every_s and now - self._header_at >= self.header_every_s:
                self._header_at = now
                if not self._append(self._header()):
                    self._remember_lost(record)
                    return False
            if not self._append(record):
                self._remember_lost(record)
                return False
            self._maybe_sync()
            return True

    def flush(self) -> bool:
        """fsync now (before a checkpoint is trusted, and at stop). True when what was
        written is on disk; False when the fsync failed or writing is paused (a checkpoint
        record then must not be named in the state file)."""
        with self._lock:
            if self._f is not None and self._dirty:
                try:
                    self.ops.fsync(self._f)
                except OSError as exc:
                    self._failed(exc, "fsync")
                self._dirty = False
                self._last_sync = self.wall()
            return not self.paused

    def reopen(self) -> None:
        """SIGHUP: close the current segment; the next record opens a new one."""
        with self._lock:
            log.info("reopening the recording (SIGHUP)")
            if self._f is not None:
                self._check_segment()       # removed before the SIGHUP: said in the next
            self._close_file()

    def close(self) -> None:
        with self._lock:
            if self._f is not None:
                self._check_segment()
            if self._removed and not self.paused:
                self._rotate(self.clock())  # a last segment to say what went
            if self.lost is not None and not self.paused:
                self._flush_lost()
            self._close_file()

    # -- internals ----------------------------------------------------------------------
    def _stamp(self, record: dict[str, Any]) -> dict[str, Any]:
        rec = dict(record)
        kind = rec["kind"]
        rec["run"] = self.run_id
        rec["seq"] = self._seq.get(kind, 0)
        self._seq[kind] = rec["seq"] + 1
        return rec

    def _append(self, record: dict[str, Any]) -> bool:
        assert self._f is not None
        data = frame(frames.encode(self._stamp(record)))
        if self.min_free_bytes and self._free() < self.min_free_bytes + len(data):
            self._enter_full(f"free space below min_free_bytes={self.min_free_bytes}",
                             "disk_full")
            return False
        try:
            self.ops.write(self._f, data)
        except OSError as exc:
            self._cut_torn_frame()
            self._failed(exc, "write")
            return False
        self._size += len(data)
        self.bytes += len(data)
        self.records += 1
        self._marks.add(self._size, record)
        self._note_time(record)
        self._dirty = True
        return True

    def _note_time(self, record: dict[str, Any]) -> None:
        """Keep the recording's own clock: the newest sample index written and the rate."""
        if "i0" in record:
            end = int(record["i0"]) + (int(record["n"]) if record["kind"] == "raw" else 0)
            self._index_end = max(self._index_end, end)
        rate = record.get("rate_hz")
        if isinstance(rate, int | float) and rate > 0:
            self._rate_hz = float(rate)

    def _cut_torn_frame(self) -> None:
        """Cut a partly written frame off again so the file stays a clean frame sequence.

        Retried: a truncate can fail transiently (EINTR, a busy NFS server). If it still
        fails, the torn frame stays at the end of this segment, which is never appended to
        again (writing resumes in a new segment), so the reader reports it as that segment's
        truncated tail and loses nothing else; the lost records are in the resume gap."""
        assert self._f is not None
        last: OSError | None = None
        for attempt in range(self.ops.truncate_attempts):
            try:
                self.ops.truncate(self._f, self._size)
                return
            except OSError as exc:
                last = exc
                if attempt + 1 < self.ops.truncate_attempts:
                    time.sleep(self.ops.truncate_pause_s)
        self.torn_frames += 1
        log.error("cannot cut the torn frame off %s at byte %d (%s); the segment is closed "
                  "and the reader will skip its truncated tail", self.path, self._size, last)

    def _free(self) -> int:
        try:
            return self.ops.free_bytes(self.dir)
        except OSError:
            return 1 << 62

    def _maybe_sync(self) -> None:
        if self._dirty and self.wall() - self._last_sync >= self.fsync_interval_s:
            self.flush()

    def _rotate(self, now: float) -> bool:
        self._close_file()
        t_real = self.realtime()
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(t_real))
        # Run id first (it starts with the run's sequence number), then the segment number,
        # eight digits wide so names sort in data order for any run the service can make
        # (four digits put segment 10 000 before 9 998). Readers do not rely on names: they
        # order segments by run and sample index from the frames (recording.order_segments).
        # The segment's own start time is for humans.
        name = f"{self.run_id}_{self._segment_no:08d}_{stamp}{SEGMENT_SUFFIX}"
        path = self.dir / name
        try:
            # the directory too: removed with everything in it while the service ran, the
            # recording goes on in it again instead of pausing until someone makes it
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            self._failed(exc, "open")
            return False
        # made again, the directory has a new lock file, which another service may have
        # locked: never a segment beside its own (paused and retried as a write error)
        lost_lock = dirlock.recheck(self.dir)
        if lost_lock is not None:
            self._lost_lock(lost_lock)
            return False
        self._lock_gen = dirlock.generation(self.dir)
        try:
            self._f = self.ops.open_append(path)
        except OSError as exc:
            self._failed(exc, "open")
            return False
        self._segment_no += 1
        self.path = path
        self._size = 0
        self._marks = _Marks()
        self._opened_at = now
        self.segments_written += 1
        log.info("recording into %s", path)
        self._header_at = now
        if not self._append(self._header()):
            return False
        while self._removed and self._append(self._removed[0]):
            self._removed.pop(0)            # earlier samples than a pause's loss: first
        if self.lost is not None:
            self._flush_lost()
        self._retention()
        return True

    def _lost_lock(self, why: str) -> None:
        """Another process holds the directory's lock: pause (retried every retry_s, as a
        write error) rather than write beside it; the open segment is closed."""
        self.errors += 1
        self._close_file()
        self._enter_full(why, "write_error")

    def _check_segment(self) -> None:
        """Whether the open segment still holds what was written to it. Deleted (also when
        a directory or another file took its name) or cut short (``: > segment``, logrotate's
        copytruncate), the records written there are gone, and so would be everything
        appended until the next rotation, up to ``segment_s`` later, with no word of it.
        Then: close it, and keep what it lost as a gap (reason ``segment_removed``) for the
        start of the next segment, which the caller opens next (kept across a pause: a
        failed open does not lose it). A file grown behind our back is left alone (the
        reader skips what is not a frame)."""
        assert self._f is not None
        try:
            st = self.ops.stat(self._f)
        except OSError:
            return                  # cannot tell; the write itself will report a failure
        if st.st_nlink > 0 and st.st_size >= self._size:
            return
        kept = 0 if st.st_nlink == 0 else st.st_size
        lost = self._marks.lost_after(kept)
        records = self._marks.records_after(kept)       # every kind, not only the samples
        how = "deleted" if st.st_nlink == 0 else f"cut to {st.st_size} bytes"
        self.segments_removed += 1
        log.error("the open segment %s was %s behind the recorder's back; %s; continuing "
                  "in a new segment", self.path, how,
                  f"samples [{lost[0]}, {lost[1]}) and {records} records went with it "
                  "(recorded as a segment_removed gap)" if lost
                  else f"{records} records but no sample record went with it")
        self._close_file_quietly()
        if lost:
            i0, end, t_mono, t_real = lost
            self._removed.append(frames.gap_record(
                self.run_id, 0, i0, end - i0, t_mono, t_real, "segment_removed", how=how,
                lost_records=records))

    def _flush_lost(self) -> None:
        lost = self.lost
        if lost is None or self._f is None:
            return
        rec = frames.gap_record(self.run_id, 0, lost.i0, lost.n, lost.t_mono, lost.t_real,
                                lost.reason, lost_records=lost.records)
        if self._append(rec):
            log.warning("recording resumed; samples [%d, %d) and %d records were lost to %s "
                        "(recorded as a gap)", lost.i0, lost.i0 + lost.n, lost.records,
                        "a full disk" if lost.reason == "disk_full" else "a write error")
            self.lost = None

    def _close_file(self) -> None:
        if self._f is None:
            return
        try:
            if self._dirty:
                self.ops.fsync(self._f)
        except OSError as exc:
            self._failed(exc, "fsync")
        try:
            self._f.close()
        except OSError as exc:
            self._failed(exc, "close")
        self._f = None
        self._dirty = False

    def _failed(self, exc: OSError, what: str) -> None:
        self.errors += 1
        if exc.errno in _FULL_ERRNOS:
            self._enter_full(f"{what} failed: {exc.strerror}", "disk_full")
        else:
            # Other I/O errors (EACCES, EIO, EROFS): pause and retry like a full disk, never
            # crash acquisition, and say what it was: not a full disk.
            self._enter_full(f"{what} failed: {exc}", "write_error")

    def _enter_full(self, why: str, reason: str) -> None:
        if self._full_since is None:
            self._full_since = self.clock()
            self._pause, self._pause_detail = reason, why
            log.error("recording paused (%s: %s) in %s; acquisition and publishing go on, "
                      "the lost interval will be recorded as a %s gap when writing resumes",
                      reason.replace("_", " "), why, self.dir, reason)
            self._close_file_quietly()
        self._next_retry = self.wall() + self.retry_s

    def _close_file_quietly(self) -> None:
        if self._f is not None:
            try:
                self._f.close()
            except OSError:
                pass
            self._f = None

    def _try_resume(self, now: float) -> bool:
        if self.wall() < self._next_retry:
            return False
        self._next_retry = self.wall() + self.retry_s
        if self._free() < max(self.min_free_bytes, 1):
            return False
        if self._pause == "disk_full":
            log.warning("disk space is back (%d bytes free); resuming the recording",
                        self._free())
        else:
            log.warning("retrying the recording after %s", self._pause_detail)
        self._full_since, self._pause, self._pause_detail = None, None, ""
        return self._rotate(now)

    def _remember_lost(self, record: dict[str, Any]) -> None:
        self.records_lost += 1
        kind = record.get("kind")
        if self.lost is None:
            i0 = int(record.get("i0", record.get("i_end", 0)))
            self.lost = LostSpan(i0, 0, float(record.get("t_mono", 0.0)),
                                 float(record.get("t_real", 0.0)),
                                 reason=self._pause or "disk_full")
        self.lost.records += 1
        if kind == "raw":
            if self.lost.n == 0:
                self.lost.i0 = int(record["i0"])
            self.lost.n = int(record["i0"]) + int(record["n"]) - self.lost.i0
            self.samples_lost += int(record["n"])

    def _retention(self) -> None:
        if not self.retention_days and not self.retention_max_bytes:
            return
        try:
            segs = [s for s in self.ops.segments(self.dir) if s[0] != self.path]
        except OSError as exc:
            log.error("retention: cannot list %s: %s", self.dir, exc)
            return
        size = {p: s for p, s, _mtime in segs}
        keyed = keyed_segments(size)          # oldest first, in the recording's own order
        keep = [p for _, p in keyed]
        if self.retention_days and self._rate_hz > 0:
            keep = self._retain_by_age(keyed)
        if self.retention_max_bytes:
            total = sum(size[p] for p in keep) + self._size
            for p in keep:
                if total <= self.retention_max_bytes:
                    break
                self._delete(p, "recording above retention_max_bytes")
                total -= size[p]

    def _retain_by_age(self, keyed: list[tuple[SegmentKey, Path]]) -> list[Path]:
        """Delete the segments whose every sample is more than ``retention_days`` of sample
        time (indices over the rate) older than the newest sample written; the rest, oldest
        first. A segment's end is its last raw block's (read from the file's end once); one
        without raw blocks ends before the next segment's first index. A segment without a
        readable index has no known age and is kept."""
        limit = self.retention_days * 86400.0 * self._rate_hz      # in samples
        ends = []                     # the first index of the next segment that names one
        end = self._index_end
        for key, _p in reversed(keyed):
            ends.append(end)
            if key.i0 != NO_INDEX:
                end = key.i0
        ends.reverse()
        keep: list[Path] = []
        for (key, p), bound in zip(keyed, ends, strict=True):
            last = segment_end(p)
            end = last if last != NO_INDEX else bound
            if key.i0 != NO_INDEX and self._index_end - end > limit:
                age_d = (self._index_end - end) / self._rate_hz / 86400.0
                self._delete(p, f"its newest sample is {age_d:.2f} days of recording older "
                                f"than the newest, above retention_days={self.retention_days:g}")
            else:
                keep.append(p)
        return keep

    def _delete(self, path: Path, why: str) -> None:
        try:
            self.ops.remove(path)
            self.deleted.append(path.name)
            log.info("deleted %s (%s)", path.name, why)
        except OSError as exc:
            log.error("retention: cannot delete %s: %s", path, exc)


def write_atomic(path: Path, data: bytes) -> None:
    """Replace ``path`` by ``data`` all at once (write a temporary file, fsync, rename).

    On any failure (a full disk) the temporary file is removed again and the error raised:
    the old file stays whole and no partial ``.tmp`` is left behind."""
    tmp = path.with_suffix(".tmp")
    try:
        # A temporary file left by a process killed inside this write, or a link put in its
        # place, is removed, never written through: opening it for writing followed a
        # symlink and overwrote whatever it pointed at.
        if tmp.is_symlink() or tmp.is_file():
            tmp.unlink()
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC,
                     0o644)
        with open(fd, "wb", buffering=0) as f:
            FileOps().write(f, data)
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError:
        if tmp.is_symlink() or tmp.is_file():
            tmp.unlink(missing_ok=True)
        raise


# --------------------------------------------------------------------------------------------
# order that does not depend on the wall clock: run ids, restart gaps

#: Run ids are ``nSSSSSSSS-YYYYMMDDTHHMMSSZ-xxxxxx``: a run sequence number taken from the
#: recording itself (one more than the highest there), then the UTC start for humans. Name
#: order is the sequence order, so it is data order even when CLOCK_REALTIME was wrong at
#: boot (a Pi without RTC before NTP); the ``n`` sorts these after the older stamp-first ids.
_RUN_SEQ = re.compile(r"n(\d{8})-")


def new_run_id(data_dir: str | Path, t_real: float) -> str:
    """The next run id for a recording directory (see ``_RUN_SEQ``), after its runs and
    those of its subdirectories: a rig records each sensor in ``data_dir/NAME``, so a
    one-sensor run in ``data_dir`` after a rig's (or a rig's after it) comes later in run
    order. A subdirectory this user cannot read (lost+found) holds no run of ours."""
    seq = 0
    d = Path(data_dir)
    if d.is_dir():
        for f in d.iterdir():
            m = _RUN_SEQ.match(f.name)
            if m:
                seq = max(seq, int(m.group(1)))
            elif _is_dir(f):
                seq = max(seq, *(int(m.group(1)) for m in map(_RUN_SEQ.match, _names(f))
                                 if m), 0)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(t_real))
    return f"n{seq + 1:08d}-{stamp}-{secrets.token_hex(3)}"


def _is_dir(p: Path) -> bool:
    try:
        return p.is_dir()
    except OSError:
        return False


def _names(d: Path) -> list[str]:
    try:
        return [f.name for f in d.iterdir()]
    except OSError:
        return []


def kernel_boot_id() -> str | None:
    """The kernel's boot id: CLOCK_MONOTONIC readings compare only within one boot."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip() or None
    except OSError:
        return None


@dataclass(frozen=True)
class LastRecorded:
    """Where the recording ends: the index after its last sample and that moment's clocks."""

    i_end: int
    t_mono: float
    t_real: float
    boot_id: str | None


@dataclass(frozen=True)
class RestartGap:
    """Samples ``[i0, i0 + n)`` the service did not acquire across a restart, measured with
    ``clock``: "monotonic" (same boot: exact up to the rate), "realtime" (another boot: as
    good as the wall clock) or "unknown" (the wall clock went back: n = 0, said so)."""

    i0: int
    n: int
    t_real: float
    clock: str


def last_recorded(data_dir: str | Path, nominal_hz: float) -> LastRecorded | None:
    """Where the recording ends: after its last raw block, or at the start of a later run
    that recorded no sample (its ``start`` event: the index it started from and when), so
    runs restarted in quick succession each own the part of the hole after the last one's
    start instead of all claiming it from the last sample (overlapping ``restart`` gaps).
    Segments newest first in data order (recording.order_segments), each read from its end,
    so an hour-long segment costs little."""
    d = Path(data_dir)
    if not d.is_dir():
        return None
    # files only: a directory in a segment's place has no frames, and sorted among them
    # it set off the warning below about names that do not sort in data order
    ordered = order_segments(f for f in d.glob("*" + SEGMENT_SUFFIX) if f.is_file())
    by_name = sorted(ordered, key=lambda p: p.name)
    if by_name != ordered:
        # the invariant "order comes from the data" holds (every reader orders by the
        # frames), but the names say otherwise: renamed files, or four-digit segment
        # numbers past 9 999 from an older version; tools that sort names would misread it
        first = next(k for k, (a, b) in enumerate(zip(by_name, ordered, strict=True))
                     if a != b)
        log.warning("segment names in %s do not sort in data order (by name %s comes where "
                    "the frames put %s); avard reads them in frame order", d,
                    by_name[first].name, ordered[first].name)
    for seg in reversed(ordered):
        try:
            end = next((r for r in records_backwards(seg) if r["kind"] == "raw"
                        or (r["kind"] == "event" and r["name"] == "start" and "i0" in r)),
                       None)
            head = first_record(seg) if end is not None else None
        except (OSError, FormatError):
            continue
        if end is None:
            continue
        boot = head.get("boot_id") if head and head.get("run") == end["run"] else None
        boot = boot if isinstance(boot, str) else None
        if end["kind"] == "event":
            return LastRecorded(int(end["i0"]), float(end["t_mono"]), float(end["t_real"]),
                                boot)
        span = end["n"] / float(end.get("rate_hz") or nominal_hz)
        return LastRecorded(int(end["i0"]) + int(end["n"]), float(end["t_mono"]) + span,
                            float(end["t_real"]) + span, boot)
    return None


def recorded_rate(data_dir: str | Path) -> tuple[str, float] | None:
    """The run and nominal ODR (Hz) of the newest header in a recording directory (segments
    in data order, newest first), or None when it holds none that says its ODR."""
    d = Path(data_dir)
    if not d.is_dir():
        return None
    for seg in reversed(order_segments(f for f in d.glob("*" + SEGMENT_SUFFIX) if f.is_file())):
        try:
            head = first_record(seg)
        except (OSError, FormatError):
            continue
        if head is None or head.get("kind") != "header":
            continue
        nominal = nominal_of(head)
        if nominal is not None:
            return str(head.get("run")), nominal
    return None


def rate_conflict(data_dir: str | Path, nominal_hz: float | None) -> tuple[str, float] | None:
    """The run and nominal ODR (Hz) of the newest recorded header in ``data_dir`` when that
    rate is not ``nominal_hz``: one recording directory holds one output data rate (a run at
    another ODR could not join the restored accumulators, whose τ are sample counts, and makes
    a record ``avard analyze`` refuses as a whole). None when they agree, when the directory
    holds no header that says its ODR, or when ``nominal_hz`` is None (a stream that does not
    say its own). The service and ``avard record`` each say what to do in their own words."""
    if nominal_hz is None:
        return None
    got = recorded_rate(data_dir)
    return got if got is not None and got[1] != float(nominal_hz) else None


def restart_gap(last: LastRecorded, *, boot_id: str | None, t_mono: float, t_real: float,
                rate_hz: float) -> RestartGap:
    """How many samples a restart lost: from CLOCK_MONOTONIC when the last run was in this
    boot, else from CLOCK_REALTIME, and 0 (clock "unknown") when that went backwards."""
    if boot_id is not None and boot_id == last.boot_id and t_mono >= last.t_mono:
        elapsed, how = t_mono - last.t_mono, "monotonic"
    elif t_real >= last.t_real:
        elapsed, how = t_real - last.t_real, "realtime"
    else:
        elapsed, how = 0.0, "unknown"
        log.warning("CLOCK_REALTIME is %.0f s behind the end of the recording and the last "
                    "run was in another boot: the restart gap's length is unknown (recorded "
                    "as 0 samples)", last.t_real - t_real)
    return RestartGap(last.i_end, round(elapsed * rate_hz), last.t_real, how)
