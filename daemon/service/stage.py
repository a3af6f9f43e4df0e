"""A pipeline stage: one ring consumer in its own thread, woken by work.

Each stage is handed exactly what it needs (its ring cursor, the objects it writes to, small
callables for what it must ask); none holds a reference back to the service.
"""

from __future__ import annotations

import itertools
import logging
import threading
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
        if int(sub[-1]) - int(sub[0]) == b - a - 1:
            # indices only ever grow (a gap jumps them forward): first and last tell that
            # the run is contiguous, the usual case, without a pass over it
            out.append((kind, val))
            continue
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

    The thread sleeps until ``batch_samples`` samples are in the ring for it (the ring wakes
    it then, not at every drain: the per-wake cost is fixed, and at 125 Hz a 0.25 s batch is
    every other drain); marks wait for the batch they came with, or wake it at once when it
    takes single samples. ``batch_samples`` / rate is the latency this stage adds. ``idle_s``
    is the longest wait before the thread reads what there is (marks while no samples come)
    and runs :meth:`idle` (a stage with something to do on a timer, such as the status
    record, does it there); the thread never wakes on a timer to look for samples."""

    name = "stage"
    #: Whether a death of this stage's thread may be restarted in place (the supervisor does,
    #: a few times): only for a stage whose output nothing downstream depends on for
    #: correctness, and which can say what the dead thread's chunk lost (:meth:`lost_in_death`).
    restartable = False

    def __init__(self, consumer: Consumer, *, idle_s: float = 5.0, batch_samples: int = 1,
                 max_samples: int | None = None) -> None:
        self.consumer = consumer
        self.idle_s = idle_s
        self.batch_samples = max(1, int(batch_samples))
        self.max_samples = max_samples
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self.restarts = 0
        self._chunk: Chunk | None = None     # the chunk being handled (lost if it dies)

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
            while True:
                # the wake count before the stop flag: a stop() between the two still ends
                # the wait below (stop sets the flag, then wakes the ring)
                since = self.consumer.ring.wakes
                stopping = self._stop.is_set()
                if not stopping and not self.consumer.wait(self.idle_s, self.batch_samples,
                                                           since=since):
                    self.idle()
                chunk = self.consumer.read(self.max_samples)
                if chunk.n or chunk.marks or chunk.lost_samples or chunk.lost_marks:
                    self._chunk = chunk
                    self.handle(chunk)
                    self._chunk = None
                    continue
                if stopping:
                    break
            self.finish()
        except BaseException as exc:
            log.exception("%s thread died", self.name)
            self.error = exc

    def restart(self) -> None:
        """A new thread after this one died (``error`` set): what the dead thread's chunk
        lost is said first (:meth:`lost_in_death`), then the stage reads on from its cursor."""
        if self._thread is not None:
            self._thread.join(1.0)
        chunk, self._chunk = self._chunk, None
        self.error = None
        self.restarts += 1
        if chunk is not None:
            self.lost_in_death(chunk)
        self.start()

    def lost_in_death(self, chunk: Chunk) -> None:
        """The chunk the dead thread was handling may be partly lost: say so (a gap)."""
        return None

    def handle(self, chunk: Chunk) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def idle(self) -> None:
        """Called after ``idle_s`` without work."""
        return None

    def finish(self) -> None:
        return None
