"""The supervisor of one acquisition run: builds the pipeline's parts, starts and stops them
in data order, and talks to systemd (sd_notify READY/WATCHDOG/STATUS/STOPPING) and to signals.

::

    reader (acquisition.py) ──▶ Ring ──▶ AllanStage     ─ avar/checkpoint marks (outbound) ─┐
       drain, stamp, push, marks │                                                       │
    DS18B20 threads ──marks────▶ │ ──▶ RecorderStage  (segments, recorder.py)  ◀─────────┤
                                 └──▶ PublisherStage (PUB, publisher.py)       ◀─────────┘
                                      RequestHandlers (ROUTER, its own thread; fits: snapshots.py)
    main thread (this module): start/stop order, signals, sd_notify, watchdog, duration

Each stage has its own ring cursor and thread and is handed what it needs (no stage holds the
service): a slow disk never delays publishing or the accumulators, and nothing ever waits for
a stage: one that falls behind by more than the ring loses the oldest samples, and that loss is
written and published as a ``gap``. Restart: see checkpoint.py.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

from avard.core.allan.feed import AllanFeed
from avard.core.errors import ConfigError, ServiceFault
from avard.core.io import frames
from avard.daemon import __version__
from avard.daemon.config import DATA_DIR_ADVICE
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import Rig
from avard.daemon.hw.timebase import SystemClock, TimeBase
from avard.daemon.service import dirlock
from avard.daemon.service.acquisition import Acquisition
from avard.daemon.service.allan_stage import AllanStage
from avard.daemon.service.checkpoint import restore_accumulators, save_state
from avard.daemon.service.header import RunHeader, time_of_index
from avard.daemon.service.publisher_stage import PublisherStage, RequestHandlers
from avard.daemon.service.recorder import (
    RestartGap,
    kernel_boot_id,
    last_recorded,
    new_run_id,
    rate_conflict,
    restart_gap,
)
from avard.daemon.service.recorder_stage import RecorderStage
from avard.daemon.service.ring import Ring
from avard.daemon.service.signal_latch import SignalLatch, WakingEvent
from avard.daemon.service.snapshots import SnapshotBoard, fit_record
from avard.daemon.service.stage import Stage

log = logging.getLogger("avard.daemon.service")

#: Times a restartable stage (the publisher) is restarted in place before a death exits 70.
MAX_STAGE_RESTARTS = 3

#: Seconds of samples each stage lets accumulate between reads (its added latency; each read
#: has a fixed cost). The Allan stage's output is a snapshot every snapshot_interval_s and the
#: recorder writes raw blocks of recording.block_s (a mark writes a partial one), so neither
#: gains from reading more often than once a second. The publisher's is the live stream's
#: latency: a quarter second (every other drain at 125 Hz) is well inside what a view that
#: redraws every 2 s shows, and halves its wake-ups.
ALLAN_BATCH_S = 1.0
RECORDER_BATCH_S = 1.0
PUBLISH_BATCH_S = 0.25


def disk_words(state: object) -> str:
    """The recorder's state as STATUS= and the log say it: "disk writing", "disk full",
    "disk write error", "disk off" (the state itself, ``disk_full``, is the status map's)."""
    words = str(state).replace("_", " ")
    return words if words.startswith("disk") else f"disk {words}"


@dataclass(frozen=True)
class ServiceHooks:
    """Replacements for the parts the service makes itself (tests and benchmarks inject faulty
    disks or counting sockets): each factory is called with the service."""

    recorder: Callable[[Service], Any] | None = None
    publisher: Callable[[Service], Any] | None = None
    request_server: Callable[[Service], Any] | None = None
    streaming_cls: Any = None       # the accumulator class (StreamingAllan by default)


@dataclass(frozen=True)
class Progress:
    """What the supervising loop reads off the readers: samples flow (READY), how many (the
    watchdog is fed only while they advance), a stalled sensor, a --duration reached."""

    first_samples: bool
    samples: int
    stalled: bool
    finished: bool


@dataclass(frozen=True)
class RigFacts:
    """What a lane's header says of the rig it is part of: every sensor's name and wiring in
    config order, this lane's place, the configured ``sync`` and the alignment's reference."""

    sensors: tuple[str, ...]
    index: int
    sync: str
    wiring: tuple[str, ...]
    reference: str

    def to_dict(self) -> dict[str, Any]:
        return {"sensors": list(self.sensors), "index": self.index, "sync": self.sync,
                "wiring": list(self.wiring), "reference": self.reference}


class Supervised:
    """The main thread's part of a run: start, supervise until a duration or a stop request
    (signals, sd_notify READY/WATCHDOG/STATUS/RELOADING), stop. :class:`Service` (one sensor)
    and :class:`~avard.daemon.service.rig_service.RigService` (several) supply start, stop,
    check_threads, refresh, progress, sockets and status_line."""

    def __init__(self, config: Config, clock: Any, notifier: Any,
                 speed: float | None) -> None:
        self.config = config
        self.clock: Any = clock
        self.notifier = notifier
        self.speed = speed
        self.stop_requested = WakingEvent()
        self._latch: SignalLatch | None = None   # signals and stop requests wake the loop
        self.reopen_requested = threading.Event()
        self._reload_keys = threading.Event()   # SIGHUP: re-read CURVE client keys
        self.stop_signal: int | None = None
        self.t_start = clock.monotonic()
        self.ready = False

    def start(self, before_acquisition: Callable[[], None] | None = None, *,
              stop_at: float | None = None) -> None:
        """Start every thread; the readers end themselves at clock time ``stop_at``."""
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    def check_threads(self, *, restart: bool = True) -> None:
        """Raise ServiceFault when a thread died; ``restart``: a stage that is safe to
        restart in place (the publisher) is restarted instead, a few times."""
        raise NotImplementedError

    def refresh(self) -> None:
        """Periodic work of the main loop (a new header when the fitted rate has moved)."""

    def progress(self) -> Progress:
        raise NotImplementedError

    def sockets(self) -> tuple[Any, ...]:
        """The sockets whose CURVE client keys SIGHUP re-reads."""
        return ()

    def status_line(self) -> str:
        raise NotImplementedError

    def run(self, duration_s: float | None = None, *, tick_s: float = 1.0,
            before_acquisition: Callable[[], None] | None = None) -> int:
        """Start, supervise until ``duration_s`` of (virtual) time or a stop request, stop.
        The reader stops itself at exactly ``duration_s`` of clock time, so a simulated run
        of a given seed always holds the same samples. Signals and stop requests wake the
        loop; ``tick_s`` bounds how late it sees a dead thread or a moved rate (the header
        is rebuilt at most every 10 s); the watchdog and the status log keep their own
        deadlines."""
        stop_at = None if duration_s is None else self.t_start + duration_s
        latch = self._signal_latch()
        try:
            self.start(before_acquisition, stop_at=stop_at)
        except BaseException:
            # a start that failed midway: what did start is stopped and flushed (stop() is
            # safe after a partial start), then the error goes on
            self.stop()
            self._close_latch()
            raise
        n = self.notifier
        wd = n.watchdog_interval_s() if n is not None else None
        next_wd = time.monotonic()
        last_samples = -1
        next_status_log = time.monotonic() + self.config.service.status_log_interval_s
        try:
            while not self.stop_requested.is_set():
                self._handle_signals(latch.wait(0.0) if latch.pending() else [])
                if self.stop_requested.is_set():
                    break
                self.check_threads()
                self.refresh()   # a new header when the fitted rate has moved
                progress = self.progress()
                if not self.ready and progress.first_samples:
                    self.ready = True
                    log.info("samples flow; ready")
                    if n is not None:
                        n.ready()
                        n.status(self.status_line())
                now = time.monotonic()
                if n is not None and wd and self.ready and now >= next_wd:
                    # WATCHDOG=1 only while samples advance: a stuck sensor lets systemd act.
                    if progress.samples != last_samples and not progress.stalled:
                        n.watchdog()
                        last_samples = progress.samples
                    n.status(self.status_line())
                    next_wd = now + wd
                if self._reload_keys.is_set():
                    # Not in the signal handler: zmq calls belong in a normal thread context,
                    # and a burst of SIGHUPs before this point is one reload.
                    self._reload_keys.clear()
                    log.info("SIGHUP: reopening the recording files, re-reading client keys")
                    if n is not None:
                        n.reloading()
                    for sock in self.sockets():
                        reload = getattr(sock, "reload_keys", None)
                        if reload is not None:
                            reload()
                    if n is not None:
                        n.ready()   # reload finished (Type=notify protocol)
                if now >= next_status_log:
                    next_status_log = now + self.config.service.status_log_interval_s
                    log.info("status: %s", self.status_line())
                wait = tick_s if self.ready else min(tick_s, 0.05)   # READY promptly
                if duration_s is not None:
                    if progress.finished:
                        break
                    left = max(0.0, duration_s - (self.clock.monotonic() - self.t_start))
                    # virtual seconds → real seconds at this pace; past the end the reader
                    # is finishing its last drain at stop_at: look again shortly
                    wait = max(0.005, min(wait, left / self.speed if self.speed else 0.05))
                if n is not None and wd and self.ready:
                    wait = min(wait, max(0.0, next_wd - time.monotonic()))
                self._handle_signals(latch.wait(wait))
        finally:
            self.stop()
            self._close_latch()
        self.check_threads(restart=False)
        return 0

    def _signal_latch(self) -> SignalLatch:
        if self._latch is None:
            self._latch = SignalLatch()
            self.stop_requested.latch = self._latch
        return self._latch

    def _close_latch(self) -> None:
        if self._latch is not None:
            self.stop_requested.latch = None
            installed = self._latch.close()
            self._latch = None
            if signal.SIGHUP in installed:
                # the run is over: a late reload has nothing to reopen, and SIGHUP's default
                # action would end the process while it flushes and exits
                signal.signal(signal.SIGHUP, signal.SIG_IGN)

    def _handle_signals(self, signums: list[int]) -> None:
        """Act on the signals the latch noted, in the main loop's normal context."""
        for signum in signums:
            if signum in (signal.SIGTERM, signal.SIGINT):
                self.stop_signal = signum
                self.stop_requested.set()
            elif signum == signal.SIGHUP:
                self.reopen_requested.set()
                self._reload_keys.set()

    def install_signals(self) -> None:
        """SIGTERM/SIGINT stop cleanly, SIGHUP reopens the recording and re-reads client keys
        (main thread only). The handlers only note the signal (signal_latch.py: a handler
        that takes a lock deadlocks, a burst of them recursed); the main loop acts on it."""
        self._signal_latch().install((signal.SIGTERM, signal.SIGINT, signal.SIGHUP))



class Service(Supervised):
    """One acquisition run over a built :class:`~avard.daemon.hw.rig.Rig`: builds nothing
    hardware-side itself (daemon/compose.py composes it); owns the threads and their
    shutdown."""

    def __init__(self, config: Config, rig: Rig, *, run_id: str | None = None,
                 notifier: Any = None, hooks: ServiceHooks | None = None,
                 rig_facts: RigFacts | None = None, own_reader: bool = True,
                 avar_fields: Callable[[], dict[str, Any]] | None = None,
                 status_fields: Callable[[], dict[str, Any]] | None = None) -> None:
        if not isinstance(config, Config):
            # the contract is typed: build the Config at the edge (config_types.load/as_config)
            raise TypeError(f"Service takes a config_types.Config, not {type(config).__name__}")
        if not isinstance(rig, Rig):
            raise TypeError(f"Service takes a hw.rig.Rig, not {type(rig).__name__}")
        hooks = hooks or ServiceHooks()
        sensor, clock = rig.sensor, rig.clock
        super().__init__(config, clock, notifier, rig.spec.clock.speed)
        self.cfg = config.as_dict()    # the checked dict: what the header stores as ``config``
        self.rig = rig
        self.sensor: Any = sensor
        self.sensor_name = rig.spec.sensors[0].name
        #: the rig's facts for the header (several sensors: names, sync, this one's place)
        self.rig_facts = rig_facts
        #: False when a shared reader drains this sensor (RigService: one reader per bus)
        self.own_reader = own_reader
        # a run sequence number from the recording first: name order is data order even
        # when CLOCK_REALTIME is wrong (recorder.new_run_id)
        self.run_id = run_id or new_run_id(config.recording.data_dir, clock.realtime())
        self.boot_id: str | None = getattr(clock, "boot_id", None)
        if self.boot_id is None and isinstance(clock, SystemClock):
            self.boot_id = kernel_boot_id()
        self.simulate = rig.simulate
        #: the reader steps a virtual clock (a simulation not on the real clock)
        self.stepped = rig.spec.clock.stepped
        self.bank = rig.temperature_bank       # a ds18b20.Ds18b20Bank (its threads read)
        self._temp_ok: dict[str, bool] = {}
        self.sensor_info = dict(rig.info)
        self.interrupt = rig.interrupt        # interrupt.InterruptPin on the FIFO watermark
        extra_temperature_names = list(rig.extra_temperature_names)
        on_tick = rig.on_tick
        odr = config.sensor.odr_hz
        self.odr = odr
        self.timebase = TimeBase(odr, group_delay_samples=float(
            getattr(sensor, "group_delay_samples", 0.0)))
        cap = int(config.service.ring_s * odr * 1.1) + 64
        self.ring = Ring(cap)
        self.real_offset = clock.realtime() - clock.monotonic()
        self.scale = float(getattr(sensor, "scale_mps2", 9.80665 / 256000))
        # Channels: the chip's own sensor, the DS18B20 threads, and sources that mark their
        # readings themselves (the simulated DS18B20 of --simulate).
        self.temp_names = ["chip", *(self.bank.names if self.bank is not None else []),
                           *extra_temperature_names]
        self.data_dir = config.recording.path
        streaming_cls = hooks.streaming_cls
        if streaming_cls is None:
            from avard.core.allan.streaming import StreamingAllan

            streaming_cls = StreamingAllan
        self.streaming_cls = streaming_cls
        self.allan = self._fresh_allan()
        self.feed = self._new_feed()
        self.start_index = 0
        self.restored: dict[str, Any] | None = None
        self._restart_gap: RestartGap | None = None
        self._recorder_factory = hooks.recorder
        self._publisher_factory = hooks.publisher
        self._request_factory = hooks.request_server
        self.recorder: Any = None
        self._dir_lock: Path | None = None
        self.publisher: Any = None
        self.request_server: Any = None
        self.acq: Acquisition | None = None
        self.workers: list[Stage] = []
        self._on_tick = on_tick
        self.final_status: dict[str, Any] = {}
        self.run_header = RunHeader(self._build_header, self.timebase, clock.monotonic,
                                    self._next_index, lambda: self.real_offset,
                                    time_before_first_drain=self._time_before_first_drain)
        self.snapshots = SnapshotBoard(fit_record)
        #: optional fields of every ``avar`` record (RigService: the live separation)
        self.avar_fields = avar_fields
        #: optional fields of the status (RigService: the live separation's slips and pairs)
        self.status_fields = status_fields

    # -- helpers ------------------------------------------------------------------------
    def _fresh_allan(self) -> Any:
        """Empty accumulators of this configuration."""
        return self.streaming_cls(3 + len(self.temp_names), self.odr,
                                  overlap=self.config.allan.overlap,
                                  names=["x", "y", "z", *self.temp_names])

    def real_now(self) -> float:
        return float(self.clock.realtime())

    def _next_index(self) -> int:
        return self.acq.next_index if self.acq else self.start_index

    def _time_before_first_drain(self, index: int) -> float:
        """The time of sample ``index`` before the time base has a drain, on the line the
        time base will fit: the part's k-th set after its start is due (k + 1) periods
        later and reaches FIFO_ENTRIES one period after that (the sync stage holds the
        newest set), and TimeBase.time_of dates a set half a period and the filter's group
        delay before it is seen. The clock now when the source does not say when it
        started."""
        started = getattr(self.sensor, "t_started", None)
        if started is None:
            return float(self.clock.monotonic())
        k = index - self.start_index          # sets after the part's start
        gd = float(getattr(self.sensor, "group_delay_samples", 0.0))
        return float(started) + (k + 1.5 - gd) / self.odr

    def header(self) -> dict[str, Any]:
        """The run's current header record (see :class:`RunHeader`)."""
        return self.run_header.current()

    def _build_header(self) -> dict[str, Any]:
        tb = self.timebase
        try:
            rate = tb.rate()
            timebase = {"odr_hz": rate.odr_hz, "odr_u_hz": rate.odr_u_hz, "ppm": rate.ppm,
                        "ppm_u": rate.ppm_u, "jitter_s": rate.jitter_s,
                        "n_points": rate.n_points}
        except (ValueError, ZeroDivisionError, AttributeError):
            timebase = {"odr_hz": tb.odr_hz}
        i0 = self._next_index()
        t = time_of_index(tb, i0, self._time_before_first_drain)
        return frames.header_record(
            self.run_id, rate_hz=float(tb.odr_hz), t_mono=t, t_real=t + self.real_offset,
            i0=i0,
            scale_m_s2_per_count=self.scale, range_g=self.config.sensor.range_g,
            sensor=self.sensor_info, temperature_sensors=self.temp_names[1:],
            software=f"avard {__version__}", config=self.cfg,
            temperature_channels=self.temp_names, nominal_odr_hz=self.odr,
            allan_rate_hz=float(self.allan.rate_hz), timebase=timebase,
            simulate=self.simulate, restored=self.restored, boot_id=self.boot_id,
            **({"rig": self.rig_facts.to_dict()} if self.rig_facts is not None else {}))

    def status(self) -> dict[str, Any]:
        acq = self.acq
        st: dict[str, Any] = {
            "run": self.run_id, "samples": acq.samples if acq else 0,
            "index": acq.next_index if acq else 0,
            "rate_hz": float(self.timebase.odr_hz),
            "overruns": acq.overruns if acq else 0,
            "lost_samples_estimate": acq.lost_estimate if acq else 0,
            "bus_errors": acq.bus_errors if acq else 0,
            "clock_steps": acq.clock_steps if acq else 0,
            "stalled": bool(acq.stalled) if acq else False,
            "allan_samples": int(self.allan.n_samples),
            "consumers_lost": {c.name: c.lost_total for c in self.ring.consumers},
            # gap records so far: sensor overruns and consumers that fell behind the ring
            "gaps": (acq.overruns if acq else 0)
            + sum(1 for c in self.ring.consumers if c.lost_total),
            "sim_time_s": self.clock.monotonic() - self.t_start,
        }
        if self.recorder is not None:
            st["disk"] = self.recorder.status()
        if self.publisher is not None:
            try:
                ps = self.publisher.stats()
            except Exception:  # closing under us at shutdown: no numbers, no crash
                ps = {}
            st["subscribers"] = ps.get("peers", 0)
            st["published"] = ps.get("sent", 0)
            st["publish_dropped"] = ps.get("dropped", 0)
            st["stalled_shut_down"] = ps.get("stalled_shut_down", 0)
            st["subscriptions_dropped"] = ps.get("subscriptions_dropped", 0)
        if self.status_fields is not None:
            st.update(self.status_fields())
        return st

    def status_line(self) -> str:
        st = self.status()
        return (f"{st['rate_hz']:.3f} Hz, {st['samples']} samples, {st['gaps']} gaps, "
                f"{st.get('subscribers', 0)} subscribers, "
                f"{disk_words(st.get('disk', {}).get('state', 'off'))}")

    def save_state(self, rec: dict[str, Any]) -> None:
        """The state file for a checkpoint (only with a recording: it lives beside it)."""
        if self.config.recording.enabled:
            save_state(self.data_dir, rec)

    def _new_feed(self) -> AllanFeed:
        """The live feed of the accumulators, at this run and this ODR. The ODR is set
        here, not left to a header (the live feed never sees one): a checkpoint stored
        ``"nominal_hz": null``, and whoever read it back knew no rate to refuse another by."""
        feed = AllanFeed(self.allan, self.scale, self.temp_names)
        feed.run = self.run_id
        feed.nominal_hz = float(self.odr)
        return feed

    def restore(self) -> None:
        """Restore the accumulators from the last checkpoint (with what was recorded after
        it replayed) and continue the sample index across the restart."""
        covered = 0
        if self.config.allan.restore:
            got = restore_accumulators(self.data_dir, self.streaming_cls,
                                       list(self.allan.names), float(self.allan.rate_hz),
                                       fresh=self._fresh_allan)
            if got is not None:
                # None: the restored state broke an invariant and was dropped (logged)
                self.allan = got.allan if got.allan is not None else self._fresh_allan()
                self.feed = self._new_feed()
                self.feed.cover(got.covered)
                covered = got.covered
                self.feed.origin = got.origin
                self.restored = got.info
        last = last_recorded(self.data_dir, self.odr)
        if last is not None:
            # the index continues from the recording; the gap is measured on CLOCK_MONOTONIC
            # within one boot, on CLOCK_REALTIME across boots (recorder.restart_gap)
            gap = restart_gap(last, boot_id=self.boot_id, t_mono=self.clock.monotonic(),
                              t_real=self.real_now(), rate_hz=self.odr)
            # Never below what the accumulators already hold (a lost tail and a gap the
            # clocks cannot measure would reuse those indices): the gap then ends there.
            if covered > last.i_end + gap.n:
                gap = replace(gap, n=covered - last.i_end)
            self._restart_gap = gap
            self.start_index = last.i_end + gap.n
        # The accumulators account for every sample before this run's first (restored and
        # replayed, or deliberately not: a fresh start), so a checkpoint taken before this run
        # feeds anything still says exactly what they hold (#26 item 1).
        self.feed.cover(self.start_index)
        if self.feed.origin is None and int(self.allan.n_samples) == 0:
            self.feed.origin = self.start_index      # fresh accumulators start here

    # -- lifecycle ----------------------------------------------------------------------
    def _check_data_dir(self) -> None:
        try:
            self.data_dir.mkdir(parents=True, exist_ok=True)
            if not os.access(self.data_dir, os.W_OK | os.X_OK):
                raise PermissionError(13, "not writable")
        except OSError as exc:
            raise ConfigError(
                f"recording.data_dir = {str(self.data_dir)!r}: cannot write there "
                f"({exc.strerror}); {DATA_DIR_ADVICE}") from None

    def _check_recorded_rate(self) -> None:
        """One recording directory holds one output data rate: a run at another ODR could
        not join the restored accumulators (their τ are sample counts) and would make a
        record that ``avard analyze`` refuses as a whole. Raises ConfigError saying what to do."""
        got = rate_conflict(self.data_dir, float(self.odr))
        if got is not None:
            run, nominal = got
            raise ConfigError(
                f"recording.data_dir = {str(self.data_dir)!r} holds a recording at a nominal "
                f"{nominal:g} Hz (run {run}) and this configuration records at "
                f"{float(self.odr):g} Hz: one recording directory holds one output data rate; "
                "give this rate its own data directory (recording.data_dir or --data-dir), or "
                "move the old segments out of this one")

    def start(self, before_acquisition: Callable[[], None] | None = None, *,
              stop_at: float | None = None) -> None:
        """Build the stages and start every thread, consumers before the reader;
        ``before_acquisition`` runs once the sockets are bound and before the first drain
        (a subscriber can connect then)."""
        cfg = self.config
        recording = cfg.recording.enabled
        if recording:
            self._check_data_dir()
            # one service per recording directory, held until stop() (dirlock.py)
            self._dir_lock = dirlock.hold(self.data_dir)
            try:
                self._check_recorded_rate()
            except ConfigError:
                dirlock.release(self._dir_lock)
                self._dir_lock = None
                raise
            self.restore()
        self.acq = Acquisition(self.sensor, self.ring, self.timebase, self.clock,
                               poll_hz=cfg.sensor.poll_hz,
                               chip_interval_s=cfg.temperature.chip_interval_s,
                               run_id=self.run_id, speed=self.speed, on_tick=self._on_tick,
                               start_index=self.start_index,
                               on_clock_step=self._on_clock_step,
                               backpressure=self.stepped,
                               interrupt=self.interrupt, stop_at=stop_at,
                               start_measuring=self.rig.start_measuring)
        rate = self.timebase_rate
        # Stages take what accumulated over a batch time instead of every drain; not when a
        # simulation runs unpaced (its reader waits for them: batching would slow it).
        paced = not (self.stepped and self.speed is None)
        acfg = cfg.allan
        self.workers.append(AllanStage(
            self.ring.consumer("allan"), self.allan, self.feed, run_id=self.run_id,
            real_offset=self.real_offset, rate_hz=rate, emit=self.ring.mark,
            on_checkpoint=None if recording else self.save_state,
            snapshot_interval_s=acfg.snapshot_interval_s,
            checkpoint_interval_s=acfg.checkpoint_interval_s,
            batch_samples=self._batch(ALLAN_BATCH_S, paced), record_fields=self.avar_fields))
        if recording:
            self.recorder = (self._recorder_factory or _default_recorder)(self)
            self.workers.append(RecorderStage(
                self.ring.consumer("recorder"), self.recorder, run_id=self.run_id,
                real_offset=self.real_offset, rate_hz=rate, real_now=self.real_now,
                header=self.run_header, checkpoint_written=self.save_state,
                reopen=self.reopen_requested,
                block_samples=int(cfg.recording.block_s * self.odr),
                batch_samples=self._batch(min(RECORDER_BATCH_S, cfg.recording.block_s),
                                          paced)))
        if cfg.publish.enabled:
            self.publisher = (self._publisher_factory or _default_publisher)(self)
            self.request_server = (self._request_factory or _default_request_server)(self)
            self.workers.append(PublisherStage(
                self.ring.consumer("publisher"), self.publisher, run_id=self.run_id,
                real_offset=self.real_offset, rate_hz=rate, clock=self.clock,
                status=self.status, header=self.run_header, snapshots=self.snapshots,
                status_interval_s=cfg.publish.status_interval_s,
                max_block=max(32, int(self.odr)),
                batch_samples=self._batch(PUBLISH_BATCH_S, paced)))
        # The first marks (restart gap, start event) for every consumer, in order.
        if self._restart_gap is not None:
            g = self._restart_gap
            self.ring.mark(frames.gap_record(self.run_id, 0, g.i0, g.n,
                                             g.t_real - self.real_offset, g.t_real, "restart",
                                             estimated=True, clock=g.clock))
        self.ring.mark(frames.event_record(
            self.run_id, 0, "start", self.clock.monotonic(), self.real_now(),
            i0=self.start_index, detail={"software": f"avard {__version__}",
                                         "restored": self.restored or {}}))
        for w in self.workers:
            w.start()
        if self.bank is not None:
            self.bank.sink = self.temperature_reading
            self.bank.start()
        if before_acquisition is not None:
            before_acquisition()
        if self.own_reader:
            self.acq.start()
        log.info("run %s started: ADXL355 %g Hz, ±%d g, drained every %.3g s (FIFO half "
                 "full%s); temperature channels %s", self.run_id, self.odr,
                 cfg.sensor.range_g, self.acq.period,
                 ", INT1 pin" if self.interrupt is not None else "",
                 ", ".join(self.temp_names))

    def _batch(self, seconds: float, paced: bool) -> int:
        """A stage's batch in samples: ``seconds`` at the nominal rate when paced; one sample
        when a simulation runs unpaced (its reader waits for the stages)."""
        return max(1, int(seconds * self.odr)) if paced else 1

    def refresh(self) -> None:
        self.run_header.refresh()

    def progress(self) -> Progress:
        acq = self.acq
        assert acq is not None
        return Progress(acq.first_samples.is_set(), acq.samples, acq.stalled,
                        acq.finished.is_set())

    def sockets(self) -> tuple[Any, ...]:
        return (self.publisher, self.request_server)

    def timebase_rate(self) -> float:
        """The fitted output rate, Hz (the nominal one until the fit has data)."""
        return float(self.timebase.odr_hz)

    def handlers(self) -> dict[str, Callable[[dict[str, Any]], dict[str, Any]]]:
        return RequestHandlers(
            snapshots=self.snapshots, status=self.status, header=self.run_header,
            ring=self.ring, nominal_odr_hz=self.odr, rate_hz=self.timebase_rate,
            scale_m_s2_per_count=self.scale,
            recent_max_s=self.config.publish.recent_max_s).table() | {
                "sensors": lambda _args: {"sensors": [self.sensor_name], "alignment": None}}

    def _on_clock_step(self, real_offset: float) -> None:
        """The reader saw CLOCK_REALTIME step (and recorded it): wall-clock times written from
        now on follow the new offset (one float assignment, safe across threads)."""
        self.real_offset = real_offset

    def temperature_reading(self, reading: Any) -> None:
        """A DS18B20 reading (from its bank thread): stamp it with the next sample index so
        it joins the sample time base, and mark drop-outs and returns as events."""
        if self.acq is None:
            return
        i0 = self.acq.stamp()
        t = self.clock.monotonic()
        name = reading.name
        ok = bool(reading.ok)
        was = self._temp_ok.get(name, True)
        if was != ok:
            self._temp_ok[name] = ok
            self.ring.mark(frames.event_record(
                self.run_id, 0, "sensor_back" if ok else "sensor_lost", t,
                t + self.real_offset, i0=i0,
                detail={"sensor": name, "status": reading.status, "detail": reading.detail}))
        self.ring.mark(frames.temp_record(self.run_id, 0, i0, [name],
                                          [reading.value_c if ok else None], t,
                                          t + self.real_offset, source="ds18b20"))

    def check_threads(self, *, restart: bool = True) -> None:
        """Raise ServiceFault when a thread died: the service stops (flushing what the other
        stages hold) and exits with status 70, which the unit restarts, instead of limping on
        without a stage or exiting 2, which RestartPreventExitStatus=2 would keep down."""
        if self.acq is not None and self.acq.error is not None:
            raise ServiceFault(f"the reader thread stopped: {self.acq.error!r}; exiting for "
                               "systemd to restart the service")
        for w in self.workers:
            if w.error is None:
                continue
            if restart and w.restartable and w.restarts < MAX_STAGE_RESTARTS:
                # safe in place: nothing the recording or the accumulators hold depends on it
                log.error("the %s thread stopped: %r; restarting it (#%d of %d)", w.name,
                          w.error, w.restarts + 1, MAX_STAGE_RESTARTS)
                w.restart()
                continue
            raise ServiceFault(f"the {w.name} thread stopped: {w.error!r}; exiting for "
                               "systemd to restart the service")

    def stop(self) -> None:
        """Flush and close everything, in data order: reader, Allan, recorder, publisher."""
        if self.stop_signal:
            log.info("signal %d: stopping", self.stop_signal)
        if self.notifier is not None:
            self.notifier.stopping()
        self.stop_requested.set()
        if self.acq is not None:
            self.acq.stop()
        if self.bank is not None:
            self.bank.stop()
        for w in self.workers:  # Allan first: its final snapshot/checkpoint are ring marks
            w.stop()
        self.final_status = self.status()
        log.info("run %s stopped: %s", self.run_id, self.status_line())
        if self.request_server is not None:
            self.request_server.stop()
        self.snapshots.stop()
        if self.interrupt is not None:
            self.interrupt.close()      # release the GPIO line
        self.rig.close()                # the reader process, where the rig started one
        if self.publisher is not None:
            self.publisher.close()
            self.publisher = None
        if self._dir_lock is not None:   # every writer of the directory has stopped
            dirlock.release(self._dir_lock)
            self._dir_lock = None


def _default_recorder(svc: Service) -> Any:
    from avard.daemon.service.recorder import Recorder

    r = svc.config.recording
    return Recorder(svc.data_dir, svc.run_id, svc.run_header.for_segment, segment_s=r.segment_s,
                    fsync_interval_s=r.fsync_interval_s, retention_days=r.retention_days,
                    retention_max_bytes=r.retention_max_bytes,
                    min_free_bytes=r.min_free_bytes, clock=svc.clock.monotonic,
                    realtime=svc.clock.realtime)


class Serving(Protocol):
    """What the request server is built from: a Service, or a RigService for all its lanes."""

    config: Config
    cfg: dict[str, Any]

    def handlers(self) -> dict[str, Callable[[dict[str, Any]], dict[str, Any]]]: ...


def _curve(svc: Serving) -> Any:
    if not svc.config.curve.enabled:
        return None
    from avard.daemon.net.curve import CurveServerConfig

    c = CurveServerConfig.from_mapping(svc.cfg["curve"])
    c.check()
    return c


def _default_publisher(svc: Service) -> Any:
    from avard.daemon.net.publisher import Publisher

    p = svc.config.publish
    return Publisher(p.endpoint, svc.run_id, hwm=p.hwm, curve=_curve(svc),
                     allow_remote=p.allow_remote)


def _default_request_server(svc: Serving) -> Any:
    from avard.daemon.net.publisher import RequestServer

    p = svc.config.publish
    return RequestServer(p.request_endpoint, svc.handlers(), curve=_curve(svc),
                         allow_remote=p.allow_remote).start()
