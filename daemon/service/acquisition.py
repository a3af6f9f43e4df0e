"""The reader thread: the only code that talks to the ADXL355 bus.

It does nothing slow: sleep until the FIFO is due to hold a useful block (pacing.py: from the
fitted output rate and the FIFO depth, with margin), drain the FIFO, give each sample its index
and a time from the fitted time base, push the block into the ring, and (every
``chip_interval_s``) read the chip's temperature. Everything it learns about loss goes into the
ring as a mark, in order with the samples:

- an overrun (STATUS.FIFO_OVR) becomes a ``gap`` record whose size is counted from time (the
  chip does not say): the fitted rate × the time from the last good drain to the burst that
  read the full FIFO, less the sets read since and what the full FIFO held; the sample index
  jumps by it so that index and the true count of sets stay together. Sets lost before the
  first drain (a slow start) count from when measurement started. A drain whose sets arrive
  later than time says, by more than the clock's uncertainty, is a loss nobody reported: it
  becomes an ``unaccounted`` gap of that size (the invariant "every loss becomes a gap of the
  right size", checked at run time);
- a failed transfer (BusError) becomes a ``bus_error`` event; the FIFO keeps filling, so a
  short bus fault costs nothing, and a long one shows up as an overrun gap;
- a device that stops producing samples (the source raises DeviceStalledError: it owns that
  detection) becomes one ``stalled`` event (and the watchdog is no longer fed, see
  service/supervisor.py); ``resumed`` when samples flow again, with one gap over the whole
  outage counted from time (its empty drains and recoveries are no loss of their own; a
  part that never resumes made nothing, and nothing is counted lost).

Temperatures of other sources (DS18B20 threads) are marked with :meth:`Acquisition.stamp`,
which gives the index of the next sample, so the time base of every channel is the sample
index.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from avard.core.errors import AvardError, DeviceStalledError, HardwareError
from avard.core.io import frames
from avard.daemon.hw.interrupt import InterruptPin
from avard.daemon.hw.pacing import drain_period_s
from avard.daemon.hw.registers import FIFO_LOCATIONS, FIFO_OVERRUN_LOCATIONS
from avard.daemon.hw.source import GapReason, SampleSource
from avard.daemon.hw.thread_priority import raise_thread_priority
from avard.daemon.hw.timebase import TimeBase
from avard.daemon.service.ring import Ring

log = logging.getLogger(__name__)

#: Paced (simulated) reader: waits up to this long are plain sleeps, longer ones can be cut
#: short by stop().
_PACE_SLEEP_MAX_S = 0.2
#: Sets the full FIFO holds after an overrun (96 locations and the 3 of the sync stage): the
#: first set a drain reads then is this many sets before the newest.
FIFO_FULL_SETS = FIFO_OVERRUN_LOCATIONS // 3
#: Gap reasons after which the part started measuring afresh (the time line restarts).
_RESTARTED = frozenset({GapReason.STALL, GapReason.RESET, GapReason.STANDBY,
                        GapReason.RESTART, GapReason.RECOVERED, GapReason.SELF_TEST})
#: A complete drain's first set may lie up to ~2 sets off the time line (the newest set is
#: dated within one sample period, at both ends): more than this behind is a loss.
UNACCOUNTED_MIN_SETS = 2.5


@dataclass
class _Outage:
    """A stall in progress: the last good drain's anchor (t_mono, index of its newest set)
    and the gap reasons its empty drains reported."""

    anchor: tuple[float, float] | None
    reasons: set[str] = field(default_factory=set)


class StoppedWithBus(AvardError):
    """A sensor's reader stopped because another sensor on its bus raised (that one holds
    the error itself): the blame is not this sensor's."""

    def __init__(self, cause: BaseException) -> None:
        super().__init__(f"stopped with its bus's reader ({cause!r} in another sensor)")
        self.cause = cause


class Acquisition:
    """Drain loop over an ``Adxl355``-like driver (``drain()``, ``read_temperature_c()``).

    ``clock`` provides ``monotonic()``, ``realtime()`` and ``sleep()``; under simulation it is
    a stepped virtual clock and ``speed`` caps how much faster than real time the loop runs
    (None: as fast as the CPU allows).
    """

    def __init__(self, sensor: SampleSource, ring: Ring, timebase: TimeBase, clock: Any, *,
                 poll_hz: float, chip_interval_s: float = 1.0, run_id: str = "",
                 speed: float | None = None,
                 on_tick: Callable[[float], None] | None = None,
                 start_index: int = 0, backpressure: bool = False,
                 on_clock_step: Callable[[float], None] | None = None,
                 stop_at: float | None = None,
                 interrupt: InterruptPin | None = None,
                 start_measuring: Callable[[], None] | None = None) -> None:
        self.sensor = sensor
        self.ring = ring
        self.tb = timebase
        self.clock = clock
        self.poll_hz = float(poll_hz)     # the least drain rate (sensor.poll_hz)
        # INT1 on the FIFO watermark (interrupt.py): wait on the pin, the timer as fallback
        self.interrupt = interrupt
        self.chip_interval_s = float(chip_interval_s)
        self.run_id = run_id
        self.speed = speed
        self.on_tick = on_tick          # called with t_mono after each poll (simulated temps)
        # called with the new CLOCK_REALTIME − CLOCK_MONOTONIC offset after a realtime step
        self.on_clock_step = on_clock_step
        self.clock_steps = 0
        self.next_index = int(start_index)
        # Simulation only: time is virtual, so waiting for a slow consumer costs nothing and
        # keeps "as fast as possible" from outrunning the recorder. On hardware the reader
        # never waits (the sensor does not), and a consumer that falls behind gets a gap.
        self.backpressure = bool(backpressure)
        self.samples = 0
        self.overruns = 0
        self.lost_estimate = 0
        self.bus_errors = 0
        self._consecutive_errors = 0
        self.stalled = False
        self.last_sample_t: float | None = None
        self._last_drain_t: float | None = None
        self._next_chip = 0.0
        self._next_recover = 0.0
        self.max_drain_interval_s = 0.0   # longest drain-to-drain interval (benchmarks)
        #: the most FIFO entries (of 96) a drain found: how near the FIFO came to overrunning
        self.fifo_high_water = 0
        # (t_mono, index) of the newest set of the last good drain (complete, no gap), or of
        # the set before the first when measurement started: where counting from time starts
        started = getattr(sensor, "t_started", None)
        self._anchor: tuple[float, float] | None = (
            None if started is None else (float(started), float(start_index) - 1.0))
        self.unaccounted = 0      # losses found by the time check, not reported by the chip
        # the part's start of measurement when its reader begins (hw/rig.py Rig.start_measuring)
        self._start_measuring = start_measuring
        self._overrun_after_read = False   # an overrun seen after a burst: its gap is next
        self._outage: _Outage | None = None   # a stall since the last samples
        self._stop = threading.Event()
        self._reader: BusReader | None = None   # start(): this sensor's own reader
        self.error: BaseException | None = None
        self.first_samples = threading.Event()
        # The reader itself ends at clock time ``stop_at`` (a --duration): a supervisor that
        # looks at a fast virtual clock every few wall milliseconds would stop at a
        # thread-timing-dependent sample, and the same seed would give different records.
        self.stop_at = stop_at
        self.finished = threading.Event()

    # -- control ------------------------------------------------------------------------
    def start(self) -> None:
        """This sensor's own reader thread (several sensors on one bus: :func:`share_reader`,
        whose :class:`BusReader` is started instead and this is never called)."""
        self._reader = BusReader([self])
        self._reader.start()

    def stop(self, timeout: float = 5.0) -> None:
        if self._reader is not None:
            self._reader.stop(timeout)
        else:
            self.request_stop()

    def begin(self) -> None:
        """On the reader thread, before the first drain: start the part measuring if its rig
        left that to the reader, and count losses from that start."""
        if self._start_measuring is None:
            return
        self._start_measuring()
        started = getattr(self.sensor, "t_started", None)
        if started is not None:
            self._anchor = (float(started), float(self.next_index) - 1.0)

    def request_stop(self) -> None:
        """End the drains (and a wait for slow consumers) soon; the reader joins."""
        self._stop.set()

    @property
    def alive(self) -> bool:
        return self._reader is not None and self._reader.alive

    def stamp(self) -> int:
        """Index of the next sample: where a reading taken now belongs on the sample grid."""
        return self.next_index

    def mark(self, record: dict[str, Any]) -> None:
        self.ring.mark(record)

    @property
    def period(self) -> float:
        """Seconds between drains at the rate fitted so far."""
        return drain_period_s(self.tb.odr_hz, self.poll_hz)

    def _wait_for_consumers(self) -> None:
        limit = self.ring.capacity // 2
        while not self._stop.is_set() and any(c.backlog > limit for c in self.ring.consumers):
            self._stop.wait(0.002)

    def poll_once(self) -> int:
        """One drain; returns the number of samples pushed."""
        if self.backpressure:
            self._wait_for_consumers()
        try:
            d = self.sensor.drain()
        except DeviceStalledError as exc:
            # The source owns stall detection (it knows its rate and FIFO): it raises once
            # the part has produced nothing for its stall timeout. Recorded once per stall.
            t = self.clock.monotonic()
            self.bus_errors += 1
            if not self.stalled:
                self.stalled = True
                if self._outage is None:
                    # one gap for the whole outage, sized by time once samples flow again:
                    # its empty drains and recoveries are no loss of their own
                    self._outage = _Outage(self._anchor)
                log.error("the ADXL355 stopped producing: %s", exc)
                self.mark(frames.event_record(
                    self.run_id, 0, "stalled", t, self.clock.realtime(), i0=self.next_index,
                    detail={"error": str(exc), "count": self.bus_errors,
                            "since_s": None if self.last_sample_t is None
                            else t - self.last_sample_t}))
            self._try_recover(t)      # a reset loses the FIFO, but nothing flows anyway
            return 0
        except HardwareError as exc:
            self.bus_errors += 1
            t = self.clock.monotonic()
            if self.bus_errors <= 10 or self.bus_errors % 1000 == 0:
                log.warning("bus_error #%d while draining: %s", self.bus_errors, exc)
            self.mark(frames.event_record(self.run_id, 0, "bus_error", t, self.clock.realtime(),
                                          i0=self.next_index,
                                          detail={"error": str(exc), "count": self.bus_errors}))
            self._consecutive_errors += 1
            # A single failed transfer costs nothing (the FIFO keeps the data); only a
            # persistent failure is worth a reset, which loses the FIFO.
            if self._consecutive_errors >= 3:
                self._try_recover(t)
            return 0
        self._consecutive_errors = 0
        self.fifo_high_water = max(self.fifo_high_water, int(getattr(d, "fifo_entries", 0)))
        counts = np.asarray(d.counts, dtype=np.int32)
        n = int(counts.shape[0])
        t_mono, t_real = float(d.t_mono), float(d.t_real)
        self._check_clock_step(t_mono, t_real, float(getattr(d, "t_real_u", 0.0)))
        reasons = reported = d.gap_reasons     # a property that parses: read it once
        if self._overrun_after_read and GapReason.FIFO_OVERRUN not in reasons:
            reasons = (*reasons, GapReason.FIFO_OVERRUN)
        outage = self._outage
        if outage is not None:
            outage.reasons.update(reasons)
        restarted = outage is not None or any(r in _RESTARTED for r in reasons)
        # After the part was stopped and started again (a recovery, a self-test) time since
        # the last good drain does not count its sets: the gap is the time since the last
        # drain that reached it (an unplugged part's outage; nothing for a stall, whose empty
        # drains kept coming), and the time line starts again at the part's new start.
        behind = None if restarted else self._behind(d, n, reasons)
        post_entries = int(getattr(d, "post_entries", -1))
        after_read = bool(getattr(d, "overrun_in_drain", False)) and (
            post_entries >= FIFO_LOCATIONS
            or (post_entries < 0 and behind is not None and behind < 0.5))
        if outage is not None:
            if n:
                self._end_outage(outage, n, t_mono, t_real)
        elif (GapReason.FIFO_OVERRUN in reported and after_read
                and not self._overrun_after_read):
            # The FIFO was not full yet when this drain's burst read it: the overrun its
            # second STATUS read saw came after, so the loss lies between these sets and the
            # next drain's (whose burst finds the FIFO still full): counted there.
            self.overruns += 1
            self._overrun_after_read = True
            reasons = tuple(r for r in reported if r != GapReason.FIFO_OVERRUN)
            behind = None
            if reasons:
                self._overrun(n, t_mono, t_real, reasons, ",".join(reasons), d.since_last_s,
                              None, count=False)
        elif d.overrun or self._overrun_after_read:
            self._overrun(n, t_mono, t_real, reasons, ",".join(reasons) or "overrun",
                          d.since_last_s, behind, count=not self._overrun_after_read)
            self._overrun_after_read = False
        elif behind is not None and behind > UNACCOUNTED_MIN_SETS:
            self.unaccounted += 1
            self._gap(round(behind), t_mono, t_real, GapReason.UNACCOUNTED)
            restarted = True     # the time line broke: a new segment of the time base fit
        started = getattr(self.sensor, "t_started", None)
        if restarted and started is not None:
            self._anchor = (float(started), float(self.next_index) - 1.0)
        if n and d.complete and not d.overrun and not self._overrun_after_read:
            self._anchor = (t_mono, float(self.next_index + n - 1))
        if n:
            i0 = self.next_index
            # a restarted part (or an unreported loss) starts a new time line: a new segment
            # of the fit (its slope kept), or the points after a stall would pull the fitted
            # rate far off (91 Hz for 125 after a 10 s stall: a rig's alignment showed it)
            self.tb.update(i0 + n - 1, t_mono, gap=bool(d.overrun) or restarted,
                           exact=bool(d.complete))
            times = self.tb.timestamps(i0, n)
            self.ring.push(counts, np.arange(i0, i0 + n, dtype=np.int64), times)
            self.next_index += n
            self.samples += n
            self.last_sample_t = t_mono
            if self.stalled:
                self.stalled = False
                log.warning("samples flow again")
                self.mark(frames.event_record(self.run_id, 0, "resumed", t_mono, t_real,
                                              i0=i0))
            self.first_samples.set()
        if self._last_drain_t is not None:
            self.max_drain_interval_s = max(self.max_drain_interval_s, t_mono - self._last_drain_t)
        self._last_drain_t = t_mono
        if t_mono >= self._next_chip:
            self._next_chip = t_mono + self.chip_interval_s
            self._chip_temperature(t_mono, t_real)
        if self.on_tick is not None:
            self.on_tick(t_mono)
        return n

    def _check_clock_step(self, t_mono: float, t_real: float, u_s: float = 0.0) -> None:
        """CLOCK_REALTIME jumped (NTP step, a date change, a Pi without RTC getting its time):
        record a ``clock_step`` event. Sample order and times stay on CLOCK_MONOTONIC; only
        the wall-clock times written beside them follow the new offset from here on."""
        step = self.tb.realtime_step(t_mono, t_real, u_s=u_s)
        if step is None:
            return
        self.clock_steps += 1
        log.warning("CLOCK_REALTIME stepped by %+.3f s; sample times stay on CLOCK_MONOTONIC",
                    step)
        self.mark(frames.event_record(self.run_id, 0, "clock_step", t_mono, t_real,
                                      i0=self.next_index,
                                      detail={"step_s": step, "t_real_after": t_real}))
        if self.on_clock_step is not None:
            self.on_clock_step(t_real - t_mono)

    def _try_recover(self, t: float) -> None:
        """After a failed drain, re-probe and restart the part (at most once a second)."""
        if t < self._next_recover:
            return
        self._next_recover = t + 1.0
        try:
            self.sensor.recover()
            log.warning("ADXL355 recovered (probed, reset, reconfigured, restarted)")
        except AvardError as exc:
            log.debug("recovery failed: %s", exc)

    def _behind(self, d: Any, n: int, reasons: tuple[GapReason, ...]) -> float | None:
        """How many sets the first set of this drain lies beyond ``next_index`` by time (the
        sets lost before it), or None when time cannot date it.

        From the anchor (the newest set of the last good drain, at its ``t_mono``) the set
        due at time t has index anchor + (t − t_anchor) × the fitted rate. After an overrun
        the FIFO was full at the burst (``t_burst``): the first set read was then the
        FIFO_FULL_SETS-th newest. In a complete drain the newest set read is the one due at
        ``t_mono`` (within a sample period), so the first is n − 1 before it."""
        if self._anchor is None or not n:
            return None
        t_a, i_a = self._anchor
        rate = float(self.tb.odr_hz)
        post_entries = int(getattr(d, "post_entries", -1))
        if (GapReason.FIFO_OVERRUN in reasons and getattr(d, "overrun_in_drain", False)
                and 0 <= post_entries < FIFO_LOCATIONS):
            # Full when the burst read it, whenever that was: after the burst the FIFO held
            # the sets that followed these, newest the one due at the second STATUS read.
            first = (i_a + (float(d.t_post) - t_a) * rate - post_entries // 3 - (n - 1))
        elif GapReason.FIFO_OVERRUN in reasons:
            t_b = float(getattr(d, "t_burst", 0.0) or d.t_mono)
            t_e = float(getattr(d, "t_burst_end", 0.0) or t_b)
            if t_e - t_b > 1.0 / rate:
                t_b = t_e       # pre-empted in the transfer: the FIFO was read near its end
            first = i_a + (t_b - t_a) * rate - (FIFO_FULL_SETS - 1)
        elif d.complete:
            first = i_a + (float(d.t_mono) - t_a) * rate - (n - 1)
        else:
            return None
        return first - self.next_index

    def _overrun(self, n_read: int, t_mono: float, t_real: float,
                 reasons: tuple[GapReason, ...], reason: str,
                 since_last_s: float | None = None, behind: float | None = None, *,
                 count: bool = True) -> None:
        """A gap the source reported: its size counted from time (:meth:`_behind`); without
        an anchor (a source that does not say when it started, before its first good drain)
        estimated from the time since the last drain × the fitted rate."""
        if count:
            self.overruns += 1
        # An overrun lost at least one set by definition; other gaps (a failed transfer,
        # a realignment) may have lost none: then the gap has n = 0 but still ends the
        # Allan segment, because continuity cannot be proven.
        floor = 1 if GapReason.FIFO_OVERRUN in reasons else 0
        if behind is not None:
            lost = max(floor, round(behind))
        else:
            if since_last_s is not None:
                elapsed = float(since_last_s)
            else:
                elapsed = t_mono - self._last_drain_t if self._last_drain_t is not None else 0.0
            lost = max(floor, round(elapsed * self.tb.odr_hz) - n_read)
        self._gap(lost, t_mono, t_real, reason)

    def _end_outage(self, outage: _Outage, n: int, t_mono: float, t_real: float) -> None:
        """Samples flow again after a stall: one gap from the last good drain's newest set to
        this drain's first, counted by time at the fitted rate (the index then stays on the
        time line the alignment of a rig reads; without an anchor, none can be counted)."""
        self._outage = None
        self._overrun_after_read = False       # inside the outage: its gap covers it
        lost = 0
        if outage.anchor is not None:
            t_a, i_a = outage.anchor
            rate = float(self.tb.odr_hz)
            first = i_a + (t_mono - (n - 1) / rate - t_a) * rate
            lost = max(0, round(first - self.next_index))
        reasons = sorted({GapReason.STALL, *outage.reasons})
        self._gap(lost, t_mono, t_real, ",".join(reasons))

    def _gap(self, lost: int, t_mono: float, t_real: float, reason: str) -> None:
        i0 = self.next_index
        self.next_index += lost
        self.lost_estimate += lost
        log.warning("gap (%s): about %d samples lost at index %d", reason, lost, i0)
        self.mark(frames.gap_record(self.run_id, 0, i0, lost, t_mono, t_real, reason,
                                    estimated=True))

    def _chip_temperature(self, t_mono: float, t_real: float) -> None:
        try:
            value = float(self.sensor.read_temperature_c())
        except AvardError as exc:
            log.debug("chip temperature read failed: %s", exc)
            return
        self.mark(frames.temp_record(self.run_id, 0, self.next_index, ["chip"], [value],
                                     t_mono, t_real, source="adxl355"))


class BusReader:
    """The reader thread of one bus: drains each of its sensors in turn (each keeps its own
    index, time base, ring and marks; one sensor's fault is its own), at the shortest of
    their drain periods, until stopped or the first sensor's ``stop_at``. It owns what the
    sensors share: the thread, stop, ``finished`` and, when it dies, each sensor's ``error``
    (the one that raised its exception, the others :class:`StoppedWithBus`). INT1 paces a
    reader of one sensor that has the pin; a shared bus drains on the timer; a bus drained by
    a reader process (hw/drain_process.py) takes each part's drains as they come. On its
    thread it first starts the parts its rig left to it (``Rig.start_measuring``) and, asked
    to (``rt_priority``), raises itself to SCHED_FIFO."""

    def __init__(self, members: Sequence[Acquisition], *, rt_priority: int = 0) -> None:
        if not members:
            raise ValueError("a bus reader needs at least one sensor")
        self.members = tuple(members)
        lead = self.members[0]
        self.clock = lead.clock
        self.speed = lead.speed
        self.stop_at = lead.stop_at
        self.interrupt = lead.interrupt if len(self.members) == 1 else None
        #: SCHED_FIFO priority the thread asks for (0: none; refused without the right,
        #: thread_priority.py): a rig's bus readers on the real clock, as the one-sensor
        #: reader process does
        self.rt_priority = int(rt_priority)
        self.realtime = False          # SCHED_FIFO granted
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="avard-reader", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        for m in self.members:
            m.request_stop()
        if self._thread is not None:
            self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def period(self) -> float:
        """Seconds between drains: the shortest of its sensors' at their fitted rates."""
        return min(m.period for m in self.members)

    def _run(self) -> None:
        polling = self.members[0]   # the sensor being drained: blamed if the thread dies
        # a reader process (hw/drain_process.py) paces its chips itself: their drains are
        # taken as they come (the members are the parts of one process)
        wait_for_drain = getattr(polling.sensor, "wait_for_drain", None)
        try:
            if self.rt_priority:
                self.realtime = raise_thread_priority(self.rt_priority)
            for m in self.members:
                polling = m
                m.begin()
            wall0 = time.monotonic()
            t0 = self.clock.monotonic()
            next_t = t0
            while not self._stop.is_set():
                if self.stop_at is not None and self.clock.monotonic() >= self.stop_at:
                    for m in self.members:
                        m.finished.set()
                    break
                if wait_for_drain is not None:
                    if wait_for_drain(_PACE_SLEEP_MAX_S):
                        for m in self.members:
                            ready = getattr(m.sensor, "ready", None)
                            if ready is None or ready():
                                polling = m
                                m.poll_once()
                    continue
                for m in self.members:
                    # one sensor's fault is its own (poll_once marks it); the bus goes on
                    polling = m
                    m.poll_once()
                period = self.period
                if self.interrupt is not None:
                    # The pin rises at the watermark (FIFO half full); the timeout is the
                    # timer's fallback (a pin that never rises costs latency, not data), and
                    # a pin stuck asserted cannot make the reader drain more than 4× as often.
                    t_drain = self.clock.monotonic()
                    self.interrupt.wait(1.5 * period)
                    early = t_drain + 0.25 * period - self.clock.monotonic()
                    if early > 0:
                        self.clock.sleep(early)
                else:
                    next_t += period
                    now = self.clock.monotonic()
                    if next_t < now - 10 * period:
                        next_t = now  # fell far behind (a slow machine): do not catch up
                    self.clock.sleep(max(0.0, next_t - now))
                if self.speed:
                    # Cap the pace at speed × real time (the virtual clock is stepped).
                    ahead = (self.clock.monotonic() - t0) / self.speed - (time.monotonic() - wall0)
                    if ahead > _PACE_SLEEP_MAX_S:
                        self._stop.wait(ahead)      # long: stay responsive to stop()
                    elif ahead > 0:
                        # a drain period: a plain sleep, as the hardware path's clock does
                        # (Event.wait costs twice the CPU per wake-up, 250 times a second)
                        time.sleep(ahead)
        except BaseException as exc:  # the service sees it and stops with an error
            log.exception("reader thread died")
            # the sensor that raised is blamed; the others on its bus stopped with it
            polling.error = exc
            for m in self.members:
                if m is not polling:
                    m.error = StoppedWithBus(exc)


def share_reader(acqs: Sequence[Acquisition], *, rt_priority: int = 0) -> BusReader:
    """One reader thread for several sensors on one bus (docs/architecture.md, "Several
    sensors"): the :class:`BusReader` to start and stop; the sensors' own start() is never
    called."""
    return BusReader(acqs, rt_priority=rt_priority)
