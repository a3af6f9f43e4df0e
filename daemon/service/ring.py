"""A fixed-size ring of raw samples (counts, sample index, monotonic time) with many readers.

One writer (the reader thread that owns the bus) pushes drained blocks; every consumer (the
Allan accumulators, the recorder, the publisher) has its own cursor and reads at its own pace.
The writer never waits for a consumer: a consumer that falls more than ``capacity`` samples
behind loses the oldest samples, and the next :meth:`Consumer.read` says exactly which ones
(``lost_samples`` and the index range), so the loss becomes a recorded gap, never a silent one.

Beside the samples the ring carries *marks*: temperature readings, overrun gaps and events,
each stamped with the ring position at which it happened, so a consumer sees them in the same
order relative to the samples as the writer produced them.

Memory is fixed at construction (``capacity`` × (channels·4 + 16) bytes); the lock is held only
for the copy in or out, never while a consumer works. Consumers with nothing to read block in
:meth:`Consumer.wait` on their own condition (sharing the ring's lock), which a push notifies
only once that consumer's batch is there (``min_samples``) and a mark only when it waits for
single samples: a consumer thread wakes when its work is there (or when :meth:`Ring.wake` asks
it to look, at shutdown), not on a timer and not at every drain of a sensor it batches.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from itertools import islice
from typing import Any

import numpy as np


@dataclass
class Chunk:
    """What one consumer read: samples ``[pos0, pos0 + n)`` of the ring and the marks between."""

    counts: np.ndarray        # (n, C) int32 raw counts
    index: np.ndarray         # (n,) int64 sample index (jumps where the sensor overran)
    t_mono: np.ndarray        # (n,) float64 CLOCK_MONOTONIC seconds from the time base
    pos0: int                 # ring position of the first sample
    marks: list[tuple[int, dict[str, Any]]] = field(default_factory=list)  # (pos, mark)
    lost_samples: int = 0     # samples overwritten before this consumer read them
    lost_index: tuple[int, int] | None = None   # [first, end) sample index of the lost run
    lost_marks: int = 0

    @property
    def n(self) -> int:
        return int(self.counts.shape[0])


class Ring:
    """Fixed-capacity sample ring; single writer, any number of independent consumers."""

    def __init__(self, capacity: int, channels: int = 3, *, mark_capacity: int = 16384) -> None:
        if capacity < 1:
            raise ValueError("ring capacity must be at least one sample")
        self.capacity = int(capacity)
        self.channels = int(channels)
        self._counts = np.zeros((self.capacity, self.channels), dtype=np.int32)
        self._index = np.zeros(self.capacity, dtype=np.int64)
        self._time = np.zeros(self.capacity, dtype=np.float64)
        self._head = 0                    # samples ever pushed
        self._marks: deque[tuple[int, int, dict[str, Any]]] = deque(maxlen=mark_capacity)
        self._mark_head = 0               # marks ever pushed
        self._lock = threading.Lock()
        self._wakes = 0                   # Ring.wake() calls, so waiters can tell them apart
        self._consumers: list[Consumer] = []

    # -- writer side --------------------------------------------------------------------
    @property
    def head(self) -> int:
        """Samples ever pushed (the ring position of the next sample)."""
        return self._head

    def push(self, counts: np.ndarray, index: np.ndarray, t_mono: np.ndarray) -> None:
        """Append a drained block. Never blocks beyond the copy; overwrites the oldest."""
        counts = np.asarray(counts)
        n = counts.shape[0]
        if n == 0:
            return
        if n > self.capacity:  # keep only what fits; consumers will see the loss
            counts, index, t_mono = counts[-self.capacity:], index[-self.capacity:], \
                t_mono[-self.capacity:]
            with self._lock:
                self._head += n - self.capacity
            n = self.capacity
        with self._lock:
            start = self._head % self.capacity
            first = min(n, self.capacity - start)
            self._counts[start:start + first] = counts[:first]
            self._index[start:start + first] = index[:first]
            self._time[start:start + first] = t_mono[:first]
            if first < n:
                rest = n - first
                self._counts[:rest] = counts[first:]
                self._index[:rest] = index[first:]
                self._time[:rest] = t_mono[first:]
            self._head += n
            for c in self._consumers:
                if c._wake_at is not None and self._head >= c._wake_at:
                    c._cond.notify()

    def mark(self, item: dict[str, Any]) -> None:
        """Insert a mark (temperature, gap, event) after every sample pushed so far."""
        with self._lock:
            self._marks.append((self._mark_head, self._head, item))
            self._mark_head += 1
            for c in self._consumers:
                if c._wake_at is not None and c._wake_on_marks:
                    c._cond.notify()

    def wake(self) -> None:
        """Wake every consumer blocked in :meth:`Consumer.wait` (to see a stop request)."""
        with self._lock:
            self._wakes += 1
            for c in self._consumers:
                c._cond.notify_all()

    def _ready(self, c: Consumer, min_samples: int) -> bool:
        return (self._head - c.pos >= min_samples
                or (min_samples <= 1 and c.mark_pos < self._mark_head))

    @property
    def wakes(self) -> int:
        """:meth:`wake` calls so far (a waiter passes what it saw before its last look)."""
        return self._wakes

    def _wait(self, c: Consumer, timeout: float | None, min_samples: int,
              since: int | None) -> bool:
        with self._lock:
            wakes = self._wakes if since is None else since
            if self._ready(c, min_samples) or self._wakes != wakes:
                return True
            c._wake_at = c.pos + min_samples
            c._wake_on_marks = min_samples <= 1
            try:
                return c._cond.wait_for(
                    lambda: self._ready(c, min_samples) or self._wakes != wakes, timeout)
            finally:
                c._wake_at = None

    # -- reader side --------------------------------------------------------------------
    def consumer(self, name: str, *, from_start: bool = False) -> Consumer:
        """A new independent cursor; by default it starts at the current head."""
        with self._lock:
            c = Consumer(self, name, 0 if from_start else self._head,
                         0 if from_start else self._mark_head)
            self._consumers.append(c)
        return c

    @property
    def consumers(self) -> list[Consumer]:
        return list(self._consumers)

    def recent(self, n: int) -> Chunk:
        """The newest ``n`` samples still held (for late joiners), without a cursor."""
        with self._lock:
            n = max(0, min(int(n), self.capacity, self._head))
            p0 = self._head - n
            return self._copy(p0, self._head, [])

    def _copy(self, p0: int, p1: int, marks: list) -> Chunk:
        # at most two slices (where the ring wraps), not an index array per read
        s = p0 % self.capacity
        e = s + max(0, p1 - p0)
        out: list[np.ndarray] = []
        for arr in (self._counts, self._index, self._time):
            if e <= self.capacity:
                out.append(arr[s:e].copy())
            else:
                out.append(np.concatenate((arr[s:], arr[:e - self.capacity])))
        return Chunk(out[0], out[1], out[2], p0, marks)

    def _read(self, c: Consumer, max_samples: int | None) -> Chunk:
        with self._lock:
            head = self._head
            lost = 0
            lost_index: tuple[int, int] | None = None
            oldest = head - self.capacity
            if c.pos < oldest:
                lost = oldest - c.pos
                # The lost samples' indices are gone too; the first retained sample and the
                # last one this consumer saw bound them.
                first_kept = int(self._index[oldest % self.capacity])
                lost_index = (c.last_index + 1 if c.last_index is not None
                              else first_kept - lost, first_kept)
                c.pos = oldest
            p1 = head if max_samples is None else min(head, c.pos + max_samples)
            marks: list[tuple[int, dict[str, Any]]] = []
            lost_marks = 0
            if self._marks:
                first_seq = self._marks[0][0]
                if c.mark_pos < first_seq:
                    lost_marks = first_seq - c.mark_pos
                    c.mark_pos = first_seq
                for seq, pos, item in islice(self._marks, c.mark_pos - first_seq, None):
                    if pos > p1:
                        break
                    marks.append((pos, item))
                    c.mark_pos = seq + 1
            # Marks every consumer has read are of no use to anyone: free them now instead of
            # when mark_capacity newer ones push them out (snapshots and checkpoints are
            # large; keeping 16384 consumed marks costs tens of MB of RSS).
            done = min(x.mark_pos for x in self._consumers) if self._consumers else 0
            while self._marks and self._marks[0][0] < done:
                self._marks.popleft()
            chunk = self._copy(c.pos, p1, marks)
            chunk.lost_samples, chunk.lost_index, chunk.lost_marks = lost, lost_index, lost_marks
            c.pos = p1
            if chunk.n:
                c.last_index = int(chunk.index[-1])
            return chunk


class Consumer:
    """One reader's cursor into a :class:`Ring`."""

    def __init__(self, ring: Ring, name: str, pos: int, mark_pos: int) -> None:
        self.ring = ring
        self.name = name
        self.pos = pos
        self.mark_pos = mark_pos
        self.last_index: int | None = None
        self.lost_total = 0
        self._cond = threading.Condition(ring._lock)   # notified by the ring (its lock held)
        self._wake_at: int | None = None   # while waiting: the ring head that wakes it
        self._wake_on_marks = False        # while waiting: whether a mark wakes it

    def wait(self, timeout: float | None = None, min_samples: int = 1, *,
             since: int | None = None) -> bool:
        """Block until there is something to read, :meth:`Ring.wake` is called (after
        ``since``, a :attr:`Ring.wakes` value, when given), or ``timeout`` seconds pass; False
        on a timeout before that. Something to read is ``min_samples`` samples, or with
        ``min_samples`` ≤ 1 a sample or a mark (a consumer that batches takes the marks with
        its batch, or after the timeout)."""
        return self.ring._wait(self, timeout, max(1, int(min_samples)), since)

    def read(self, max_samples: int | None = None) -> Chunk:
        """Everything pushed since the last read (at most ``max_samples`` samples)."""
        chunk = self.ring._read(self, max_samples)
        self.lost_total += chunk.lost_samples
        return chunk

    @property
    def backlog(self) -> int:
        """Samples pushed but not yet read by this consumer."""
        return self.ring.head - self.pos
