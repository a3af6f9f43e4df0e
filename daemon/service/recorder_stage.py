"""The recorder stage: raw blocks of about ``block_s`` seconds and every mark, in sample order,
into the segment files (daemon/service/recorder.py)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from avard.core.io import frames
from avard.daemon.service.header import RunHeader
from avard.daemon.service.ring import Chunk, Consumer
from avard.daemon.service.stage import Stage, lost_marks_records, offset_after_mark, split_chunk

Record = dict[str, Any]
log = logging.getLogger("avard.daemon.service")


class RecorderStage(Stage):
    """Writes through ``recorder`` (``write``, ``flush``, ``reopen``, ``close``); hands each
    checkpoint record, once written and flushed, to ``checkpoint_written`` (the state file);
    reopens the files when ``reopen`` is set (SIGHUP)."""

    name = "recorder"

    def __init__(self, consumer: Consumer, recorder: Any, *, run_id: str, real_offset: float,
                 rate_hz: Callable[[], float], real_now: Callable[[], float],
                 header: RunHeader, checkpoint_written: Callable[[Record], None],
                 reopen: threading.Event, block_samples: int, batch_samples: int = 1) -> None:
        super().__init__(consumer, batch_samples=batch_samples)
        self.rec = recorder
        self.run_id = run_id
        self.real_offset = real_offset
        self.rate_hz = rate_hz
        self.real_now = real_now
        self.header = header
        self.checkpoint_written = checkpoint_written
        self.reopen = reopen
        self.block_samples = max(1, int(block_samples))
        header.current()
        self._header_version = header.version   # what the first segment starts with
        self._parts: list[np.ndarray] = []
        self._i0 = 0
        self._t0 = 0.0
        self._n = 0
        # index ranges received from the ring (and lost from it) not yet checked against a
        # checkpoint: the run-time invariant (check_checkpoint)
        self._received: list[tuple[int, int]] = []
        self._lost: list[tuple[int, int]] = []
        self.violations = 0

    def _write_header_if_new(self) -> None:
        if self.header.version != self._header_version:
            # The fitted rate moved: the recording gets the new header (load_recording takes
            # each run's newest), before the block whose times use that fit.
            rec = self.header.for_segment()
            self._header_version = self.header.version
            self.rec.write(rec)

    def _flush(self) -> None:
        if not self._n:
            return
        self._write_header_if_new()
        counts = np.concatenate(self._parts) if len(self._parts) > 1 else self._parts[0]
        self.rec.write(frames.raw_record(self.run_id, 0, self._i0, counts, self._t0,
                                         self._t0 + self.real_offset, rate_hz=self.rate_hz()))
        self._parts, self._n = [], 0

    def handle(self, chunk: Chunk) -> None:
        if chunk.lost_samples:
            self._flush()
            i0, i1 = chunk.lost_index or (0, 0)
            self._lost.append((i0, i1))
            self.rec.write(frames.gap_record(self.run_id, 0, i0, max(0, i1 - i0),
                                             float(chunk.t_mono[0]) if chunk.n else 0.0,
                                             self.real_now(), "recorder_behind"))
        if chunk.lost_marks:
            self._flush()
            for rec in lost_marks_records(self.run_id, chunk, "recorder", self.real_now()):
                self.rec.write(rec)
        for kind, val in split_chunk(chunk):
            if kind == "mark":
                self._flush()
                self.real_offset = offset_after_mark(val, self.real_offset)
                written = self.rec.write(val)
                if val["kind"] == "checkpoint":
                    self.check_checkpoint(val)
                    # the state file names this record as on disk: only once it is (a
                    # failed fsync pauses the recorder and flush says so)
                    if written and self.rec.flush():
                        self.checkpoint_written(val)
                continue
            a, b = val
            i0 = int(chunk.index[a])
            if self._received and self._received[-1][1] == i0:     # contiguous: extend
                self._received[-1] = (self._received[-1][0], i0 + b - a)
            else:
                self._received.append((i0, i0 + b - a))
            if self._n and i0 != self._i0 + self._n:
                self._flush()
            while a < b:
                if not self._n:
                    self._i0, self._t0 = int(chunk.index[a]), float(chunk.t_mono[a])
                take = min(b - a, self.block_samples - self._n)
                self._parts.append(chunk.counts[a:a + take])
                self._n += take
                a += take
                if self._n >= self.block_samples:
                    self._flush()
        if self.reopen.is_set():
            self.reopen.clear()
            self._flush()
            self.rec.reopen()

    def check_checkpoint(self, ckpt: Record) -> None:
        """The run-time invariant: the samples the accumulators took since the last checkpoint
        (the checkpoint's ``check``: indices [from, to)) are exactly the samples this stage
        received for the recording in that range. Checked when neither stage lost samples
        from the ring there (those losses are recorded gaps of their own). A violation is
        logged at ERROR and recorded as an ``invariant_violated`` event."""
        check = ckpt.get("check")
        if not isinstance(check, dict):
            return
        lo, hi = int(check["from"]), int(check["to"])

        def inside(ranges: list[tuple[int, int]]) -> int:
            return sum(max(0, min(b, hi) - max(a, lo)) for a, b in ranges)

        got, lost = inside(self._received), inside(self._lost)
        self._received = [(max(a, hi), b) for a, b in self._received if b > hi]
        self._lost = [(max(a, hi), b) for a, b in self._lost if b > hi]
        if lost or int(check["lost"]):
            return
        if got != int(check["seen"]):
            self.violations += 1
            detail = {"from": lo, "to": hi, "accumulators_took": int(check["seen"]),
                      "recorded": got}
            log.error("invariant violated: the Allan accumulators took %d samples of indices "
                      "[%d, %d) but the recording received %d", check["seen"], lo, hi, got)
            self.rec.write(frames.event_record(self.run_id, 0, "invariant_violated",
                                               float(ckpt["t_mono"]), self.real_now(), i0=hi,
                                               detail=detail))

    def finish(self) -> None:
        self._flush()
        self._write_header_if_new()     # the last version too: it is the best fit
        self.rec.close()
