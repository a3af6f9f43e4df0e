"""The publisher stage (raw blocks, marks, status and header on the PUB socket) and the
request handlers (``snapshot``, ``status``, ``recent``, ``header``) of the request socket."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from avard.core.errors import AvardError
from avard.core.io import frames
from avard.daemon.service.header import RunHeader
from avard.daemon.service.ring import Chunk, Consumer, Ring
from avard.daemon.service.snapshots import SnapshotBoard
from avard.daemon.service.stage import Stage, lost_marks_records, offset_after_mark, split_chunk

Record = dict[str, Any]

#: A `recent` reply: counts (3 × int32), index (int64), t_mono (float64) per sample; capped
#: so that one reply stays well below the request socket's per-peer bound (publisher.py).
RECENT_BYTES_PER_SAMPLE = 28
RECENT_MAX_BYTES = 2 << 20


class PublisherStage(Stage):
    """Publishes raw blocks and marks in sample order, hands each ``avar`` record to the
    snapshot board (what ``snapshot`` requests answer), and every ``status_interval_s`` a
    status record (and the header when it changed) on the ``status`` topic."""

    name = "publisher"
    # what it sends is a copy of what the recording and the accumulators hold: a dead
    # publisher thread is restarted in place, the block it was sending becomes a gap
    restartable = True

    def __init__(self, consumer: Consumer, publisher: Any, *, run_id: str, real_offset: float,
                 rate_hz: Callable[[], float], clock: Any, status: Callable[[], Record],
                 header: RunHeader, snapshots: SnapshotBoard, status_interval_s: float,
                 max_block: int, batch_samples: int = 1) -> None:
        super().__init__(consumer, idle_s=status_interval_s, batch_samples=batch_samples,
                         max_samples=max_block)
        self.pub = publisher
        self.run_id = run_id
        self.real_offset = real_offset
        self.rate_hz = rate_hz
        self.clock = clock
        self.status = status
        self.header = header
        self.snapshots = snapshots
        self.status_interval_s = status_interval_s
        self._next_status = 0.0
        self._header_version = -1

    def handle(self, chunk: Chunk) -> None:
        if chunk.lost_samples:
            i0, i1 = chunk.lost_index or (0, 0)
            self.pub.publish("event", frames.gap_record(
                self.run_id, 0, i0, max(0, i1 - i0), float(chunk.t_mono[0]),
                self.clock.realtime(), "publisher_behind"))
        if chunk.lost_marks:
            for rec in lost_marks_records(self.run_id, chunk, "publisher",
                                          self.clock.realtime()):
                self.pub.publish("event", rec)
        rate = self.rate_hz()
        for kind, val in split_chunk(chunk):
            if kind == "mark":
                self.real_offset = offset_after_mark(val, self.real_offset)
                if val["kind"] in frames.TOPIC_OF_KIND:
                    self.pub.publish(None, val)
                if val["kind"] == "avar":
                    self.snapshots.publish(val)
                continue
            a, b = val
            t0 = float(chunk.t_mono[a])
            self.pub.publish("raw", frames.raw_record(
                self.run_id, 0, int(chunk.index[a]), chunk.counts[a:b], t0,
                t0 + self.real_offset, rate_hz=rate))
        self.idle()

    def lost_in_death(self, chunk: Chunk) -> None:
        """The thread died while publishing ``chunk``: its samples may be partly unsent, so
        one gap record covers them all (a subscriber may then hold some twice over a gap,
        never a hole without one), after a ``publisher_restart`` event that counts the
        samples and marks it held."""
        last = self.consumer.last_index
        i0 = int(chunk.index[0]) if chunk.n else (0 if last is None else last + 1)
        t = float(chunk.t_mono[0]) if chunk.n else float(self.clock.monotonic())
        # the marks it held (temperatures, events, snapshots) may be unsent too: say how many
        self.pub.publish("event", frames.event_record(
            self.run_id, 0, "publisher_restart", t, self.clock.realtime(), i0=i0,
            detail={"samples": chunk.n, "marks": len(chunk.marks)}))
        if chunk.n:
            i1 = int(chunk.index[-1]) + 1
            self.pub.publish("event", frames.gap_record(
                self.run_id, 0, i0, i1 - i0, t, self.clock.realtime(), "publisher_restart"))

    def idle(self) -> None:
        now = time.monotonic()
        if now >= self._next_status:
            self._next_status = now + self.status_interval_s
            self.publish_status()

    def publish_status(self) -> None:
        hdr = self.header.current()
        if self.header.version != self._header_version:
            self._header_version = self.header.version
            self.pub.publish("status", hdr)   # a new fit of the rate: on the status topic
        t = self.clock.monotonic()
        self.pub.publish("status", frames.status_record(self.run_id, 0, self.status(), t,
                                                        t + self.real_offset))

    def finish(self) -> None:
        self.publish_status()


class RequestHandlers:
    """The request socket's ops. Each answers from state it is handed, at once: the fit of a
    snapshot is the board's thread's work, never a request's."""

    def __init__(self, *, snapshots: SnapshotBoard, status: Callable[[], Record],
                 header: RunHeader, ring: Ring, nominal_odr_hz: float,
                 rate_hz: Callable[[], float], scale_m_s2_per_count: float,
                 recent_max_s: float) -> None:
        self.snapshots = snapshots
        self.status = status
        self.header = header
        self.ring = ring
        self.odr = nominal_odr_hz
        self.rate_hz = rate_hz
        self.scale = scale_m_s2_per_count
        self.recent_max_s = recent_max_s

    def table(self) -> dict[str, Callable[[dict[str, Any]], Record]]:
        return {"snapshot": self.snapshot, "status": lambda _a: self.status(),
                "recent": self.recent, "header": lambda _a: self.header.current()}

    def snapshot(self, _args: dict[str, Any]) -> Record:
        rec = self.snapshots.reply()
        if rec is None:
            raise AvardError("no Allan snapshot yet; ask again after snapshot_interval_s")
        return rec

    def recent(self, args: dict[str, Any]) -> Record:
        seconds = args.get("seconds", 1.0)
        if not isinstance(seconds, int | float) or not 0 <= seconds <= self.recent_max_s:
            raise AvardError(f"recent: seconds={seconds!r}; allowed is 0 to "
                             f"{self.recent_max_s:g} s")
        n = int(seconds * self.odr)
        if n * RECENT_BYTES_PER_SAMPLE > RECENT_MAX_BYTES:
            most = RECENT_MAX_BYTES / RECENT_BYTES_PER_SAMPLE / self.odr
            raise AvardError(f"recent: seconds={seconds:g} at {self.odr:g} Hz is "
                             f"{n * RECENT_BYTES_PER_SAMPLE} bytes; at most {most:.3g} s per "
                             "request (the reply memory is bounded); ask for less")
        chunk = self.ring.recent(n)
        i0 = int(chunk.index[0]) if chunk.n else 0
        return {"i0": i0, "n": chunk.n, "counts": frames.pack_array(chunk.counts),
                "index": frames.pack_array(chunk.index),
                "t_mono": frames.pack_array(chunk.t_mono),
                "scale_m_s2_per_count": self.scale, "rate_hz": float(self.rate_hz())}
