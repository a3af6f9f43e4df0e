"""The run's ``header`` record: one object shared by the recorder, publisher and requests."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from avard.daemon.hw.timebase import TimeBase

Record = dict[str, Any]


def time_of_index(timebase: TimeBase, index: int, fallback: Callable[[int], float]) -> float:
    """CLOCK_MONOTONIC time of sample ``index`` on the fitted time base: a header's
    (``i0``, ``t_mono``) is a point of the raw blocks' time line (wire-format.md). The clock
    at the moment the header was built lay up to a drain period and a batch after it (139 ms
    off at 125 Hz); ``fallback(index)`` before the first drain (the supervisor's: from when
    the part started measuring, at the nominal rate)."""
    try:
        return float(timebase.time_of(index))
    except (ValueError, ZeroDivisionError):
        return float(fallback(index))


class RunHeader:
    """The run's ``header`` record, built once and rebuilt by :meth:`refresh` only when the
    fitted rate has moved by more than ``ppm`` (at most every ``min_interval_s``): the recorder
    writes each new one
    (and every segment starts with the current one, :meth:`for_segment`), the publisher sends
    it on the ``status`` topic, and the ``header`` request returns it, so all three carry the
    same record."""

    def __init__(self, build: Callable[[], Record], timebase: TimeBase,
                 clock: Callable[[], float], next_index: Callable[[], int],
                 real_offset: Callable[[], float], *, ppm: float = 2.0,
                 min_interval_s: float = 10.0,
                 time_before_first_drain: Callable[[int], float] | None = None) -> None:
        self._build = build
        self._time_before = time_before_first_drain or (lambda _i: clock())
        self._tb = timebase
        self._clock = clock
        self._next_index = next_index
        self._real_offset = real_offset
        self.ppm = ppm
        self.min_interval_s = min_interval_s
        self._lock = threading.Lock()
        self._rec: Record | None = None
        self._rate = 0.0
        self._t = 0.0
        self.version = 0

    def current(self) -> Record:
        """The current header (built at the first call, then only by :meth:`refresh`)."""
        with self._lock:
            if self._rec is None:
                self._rec = self._build()
                self._rate, self._t = float(self._tb.odr_hz), self._clock()
                self.version += 1
            return self._rec

    def refresh(self) -> bool:
        """Rebuild the header if the fitted rate has moved enough (the supervisor calls this,
        one owner, so the recorder writes every version before it closes); True if rebuilt."""
        self.current()
        with self._lock:
            rate = float(self._tb.odr_hz)
            now = self._clock()
            if abs(rate / self._rate - 1.0) * 1e6 <= self.ppm or \
                    now - self._t < self.min_interval_s:
                return False
            self._rec = self._build()
            self._rate, self._t = rate, now
            self.version += 1
            return True

    def for_segment(self) -> Record:
        """The header that starts a segment: the current one with ``i0`` at the reader's
        next index (never behind the segment's first sample: restore skips the segments whose
        header ``i0`` is at or before a checkpoint's end, so a stale one would skip data)."""
        i0 = self._next_index()
        t = time_of_index(self._tb, i0, self._time_before)
        return dict(self.current(), t_mono=t, t_real=t + self._real_offset(), i0=i0)
