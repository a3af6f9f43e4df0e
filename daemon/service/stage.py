"""A pipeline stage: one ring consumer in its own thread, woken by work.

Each stage is handed exactly what it needs (its ring cursor, the objects it writes to, small
callables for what it must ask); none holds a reference back to the service.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from typing import Any

import numpy as np
from avard.core.io import frames
from avard.daemon.service.ring import Chunk, Consumer

log = logging.getLogger("avard.daemon.service")

#: An item of a chunk in sample order: ("samples", (a, b)) or ("mark", record).
Item = tuple[str, Any]


def split_chunk(chunk: Chunk) -> list[Item]:
    """The chunk as an ordered list of ("samples", (a, b)) index-contiguous runs and
    ("mark", record) items, in the order the reader produced them."""
    items: list[Item] = []
    cur = 0
    for pos, rec in chunk.marks:
        off = min(max(pos - chunk.pos0, 0), chunk.n)
        if off > cur:
            items.append(("samples", (cur, off)))
            cur = off
        items.append(("mark", rec))
    if cur < chunk.n:
        items.append(("samples", (cur, chunk.n)))
    out: list[Item] = []
    for kind, val in items:
        if kind != "samples":
            out.append((kind, val))
            continue
        a, b = val
        sub = chunk.index[a:b]
        brk = np.flatnonzero(np.diff(sub) != 1) + 1
        edges = [a, *(a + brk).tolist(), b]
        out.extend(("samples", (x, y)) for x, y in itertools.pairwise(edges))
    return out


def offset_after_mark(record: dict[str, Any], offset: float) -> float:
    """The CLOCK_REALTIME − CLOCK_MONOTONIC offset in force after a ring mark: a clock_step
    event changes it. Stages apply it in sample order, so blocks before a step keep the old
    wall-clock times even when written after the reader already saw the step."""
    if record.get("kind") == "event" and record.get("name") == "clock_step":
        return float(record["detail"]["t_real_after"]) - float(record["t_mono"])
    return offset


def lost_marks_records(run_id: str, chunk: Chunk, consumer: str,
                       t_real: float) -> list[dict[str, Any]]:
    """Marks (temperatures, gaps, events) dropped by the ring before ``consumer`` read them:
    a ``marks_lost`` event, and a zero-length ``marks_lost`` gap before the chunk's first
    sample, so the Allan feed and every reader of the recording break their segment there (a
    lost mark may have been a gap)."""
    i0 = int(chunk.index[0]) if chunk.n else 0
    t = float(chunk.t_mono[0]) if chunk.n else 0.0
    log.warning("the %s stage lost %d ring marks before sample %d (the mark queue "
                "overflowed)", consumer, chunk.lost_marks, i0)
    return [frames.event_record(run_id, 0, "marks_lost", t, t_real, i0=i0,
                                detail={"count": int(chunk.lost_marks), "consumer": consumer}),
            frames.gap_record(run_id, 0, i0, 0, t, t_real, "marks_lost",
                              marks=int(chunk.lost_marks))]


class Stage:
    """A consumer thread: block on the ring until it holds work, hand each chunk to ``handle``.

    After handling a chunk the thread lets ``batch_s`` pass before it reads again (unless it
    is behind, or it had waited that long for the chunk anyway), so that at 4 kHz it takes
    one larger chunk instead of waking at every drain (the per-wake cost is fixed;
    ``batch_s`` is the latency this stage adds). ``idle_s`` is
    the longest wait without work before :meth:`idle` runs (a stage with something to do on a
    timer, such as the status record, does it there); the thread never wakes on a timer to
    look for samples."""

    name = "stage"

    def __init__(self, consumer: Consumer, *, idle_s: float = 5.0, batch_s: float = 0.0,
                 max_samples: int | None = None) -> None:
        self.consumer = consumer
        self.idle_s = idle_s
        self.batch_s = batch_s
        self.max_samples = max_samples
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f"avard-{self.name}",
                                        daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        """Finish what is in the ring, then stop."""
        self._stop.set()
        self.consumer.ring.wake()
        if self._thread is not None:
            self._thread.join(timeout)

    def _run(self) -> None:
        try:
            waited = 0.0   # seconds blocked on the ring before the chunk handled now
            while True:
                stopping = self._stop.is_set()
                chunk = self.consumer.read(self.max_samples)
                if chunk.n or chunk.marks or chunk.lost_samples or chunk.lost_marks:
                    self.handle(chunk)
                    # Batch only while work comes faster than batch_s: a stage that had to
                    # wait that long for this chunk would gather nothing more by sleeping,
                    # only wake twice per drain (at 125 Hz the reader pushes every 128 ms).
                    if (self.batch_s and not stopping and not self.consumer.backlog
                            and waited < self.batch_s):
                        self._stop.wait(self.batch_s)
                    waited = 0.0
                    continue
                if stopping:
                    break
                t0 = time.monotonic()
                if not self.consumer.wait(self.idle_s):
                    self.idle()
                waited += time.monotonic() - t0
            self.finish()
        except BaseException as exc:
            log.exception("%s thread died", self.name)
            self.error = exc

    def handle(self, chunk: Chunk) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def idle(self) -> None:
        """Called after ``idle_s`` without work."""
        return None

    def finish(self) -> None:
        return None
