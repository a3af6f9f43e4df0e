"""The acquisition service behind ``avard run``: reader thread, ring, consumers, systemd.

::

    reader thread (acquisition.py) ──▶ Ring ──▶ AllanWorker     (StreamingAllan, snapshots,
       drain, stamp, push, marks       │                          checkpoints → ring marks)
    DS18B20 threads ──marks──────────▶ │ ──▶ RecorderWorker  (segments, recorder.py)
                                       └──▶ PublisherWorker (PUB, publisher.py)
    main thread: signals, sd_notify (READY/WATCHDOG/STATUS), duration, shutdown

Each consumer has its own ring cursor and thread, so a slow disk never delays publishing or
the accumulators, and nothing ever waits for a consumer: a consumer that falls behind by more
than the ring loses the oldest samples, and that loss is written and published as a ``gap``.
Snapshots and checkpoints made by the Allan worker travel as ring marks too, so the recording
and the stream see them in sample order.

Restart: the Allan accumulators are checkpointed (``allan-state.ckpt`` beside the segments,
written atomically, and a ``checkpoint`` record in the recording). A new run restores the
checkpoint, replays what the previous run recorded after it, records a ``restart`` gap from the
last recorded sample to its own first one (the sample index continues, advanced by the elapsed
time × rate) and goes on: the 60-hour Allan result survives restarts.
"""

from __future__ import annotations

import functools
import itertools
import logging
import os
import secrets
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from avard.core import frames
from avard.core.errors import AvardError, ConfigError, FormatError
from avard.core.recording import (
    AllanFeed,
    RecordingReader,
    first_record,
    frame,
    last_record,
    scan_frames,
)

from . import __version__
from .acquisition import Acquisition
from .config import effective_poll_hz
from .ring import Chunk, Consumer, Ring
from .snapshots import SnapshotBoard
from .timebase import TimeBase

log = logging.getLogger(__name__)

STATE_FILE = "allan-state.ckpt"
#: Seconds of samples each consumer lets accumulate between reads (its added latency).
ALLAN_BATCH_S = 0.25
RECORDER_BATCH_S = 0.25
PUBLISH_BATCH_S = 0.05
#: A `recent` reply: counts (3 × int32), index (int64), t_mono (float64) per sample; capped
#: so that one reply stays well below the request socket's per-peer bound (publisher.py).
RECENT_BYTES_PER_SAMPLE = 28
RECENT_MAX_BYTES = 2 << 20


def _runs_of(chunk: Chunk) -> list[tuple[int, int]]:
    """[start, end) offsets of index-contiguous runs within a chunk."""
    if chunk.n == 0:
        return []
    breaks = np.flatnonzero(np.diff(chunk.index) != 1) + 1
    edges = [0, *breaks.tolist(), chunk.n]
    return list(itertools.pairwise(edges))


def _split(chunk: Chunk) -> list[tuple[str, Any]]:
    """The chunk as an ordered list of ("samples", (a, b)) and ("mark", record) items."""
    items: list[tuple[str, Any]] = []
    cur = 0
    for pos, rec in chunk.marks:
        off = min(max(pos - chunk.pos0, 0), chunk.n)
        if off > cur:
            items.append(("samples", (cur, off)))
            cur = off
        items.append(("mark", rec))
    if cur < chunk.n:
        items.append(("samples", (cur, chunk.n)))
    out: list[tuple[str, Any]] = []
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


class Worker:
    """A consumer thread: block on the ring until it holds work, hand each chunk to ``handle``.

    After handling a chunk the thread lets ``batch_s`` pass before it reads again, so that at
    4 kHz it takes one larger chunk instead of waking at every drain (the per-wake cost is
    fixed; ``batch_s`` is the latency this part adds). ``idle_s`` is the longest wait without
    work before :meth:`idle` runs (a part with something to do on a timer, such as the status
    record, does it there); the thread never wakes on a timer to look for samples."""

    name = "worker"

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
            while True:
                stopping = self._stop.is_set()
                chunk = self.consumer.read(self.max_samples)
                if chunk.n or chunk.marks or chunk.lost_samples:
                    self.handle(chunk)
                    if self.batch_s and not stopping and not self.consumer.backlog:
                        self._stop.wait(self.batch_s)
                    continue
                if stopping:
                    break
                if not self.consumer.wait(self.idle_s):
                    self.idle()
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


class AllanWorker(Worker):
    """Feeds the streaming accumulators; publishes snapshots and checkpoints as ring marks."""

    name = "allan"

    def __init__(self, consumer: Consumer, allan: Any, feed: AllanFeed, service: Service,
                 *, snapshot_interval_s: float, checkpoint_interval_s: float,
                 batch_s: float = 0.0) -> None:
        super().__init__(consumer, batch_s=batch_s)
        self.allan = allan
        self.feed = feed
        self.svc = service
        self.snapshot_interval_s = snapshot_interval_s
        self.checkpoint_interval_s = checkpoint_interval_s
        self._next_snap: float | None = None
        self._next_ckpt: float | None = None
        self._t = 0.0
        self.latest: dict[str, Any] | None = None
        self.lock = threading.Lock()

    def handle(self, chunk: Chunk) -> None:
        with self.lock:
            if chunk.lost_samples:
                self.feed.gap()
            for kind, val in _split(chunk):
                if kind == "samples":
                    a, b = val
                    self.feed.raw(int(chunk.index[a]), chunk.counts[a:b])
                elif val["kind"] == "temp":
                    self.feed.temp(val["i0"], val["names"], val["values_c"])
                elif val["kind"] == "gap":
                    self.feed.gap()
            if chunk.n:
                self._t = float(chunk.t_mono[-1])
        if self._next_snap is None:
            self._next_snap = self._t + self.snapshot_interval_s
            self._next_ckpt = self._t + self.checkpoint_interval_s
        if self._t >= self._next_snap:
            self._next_snap = self._t + self.snapshot_interval_s
            rec = self.snapshot_record()
            if rec is not None:
                self.svc.ring.mark(rec)
        if self._next_ckpt is not None and self._t >= self._next_ckpt:
            self._next_ckpt = self._t + self.checkpoint_interval_s
            self.checkpoint()

    def snapshot_record(self) -> dict[str, Any] | None:
        """The ``avar`` record of everything fed so far; None before the first τ point (a
        snapshot without one would carry (0, C) arrays whose shape msgpack lists lose)."""
        with self.lock:
            snap = self.allan.snapshot().to_dict()
            if not snap["m"]:
                return None
            relabel_tau(snap, float(self.svc.timebase.odr_hz))
            snap.update(channels=self.feed.channels,
                        units=["m/s^2"] * 3 + ["degC"] * len(self.feed.temp_names),
                        allan_rate_hz=float(self.allan.rate_hz),
                        fitted_rate_hz=snap["rate_hz"])
            rec = frames.avar_record(self.svc.run_id, 0, self.feed.next_index or 0,
                                     int(self.allan.n_samples), snap, self._t,
                                     self._t + self.svc.real_offset)
        self.latest = rec
        return rec

    def checkpoint(self) -> None:
        with self.lock:
            rec = frames.checkpoint_record(self.svc.run_id, 0, self.feed.next_index or 0,
                                           int(self.allan.n_samples), self.allan.state(),
                                           self._t, self._t + self.svc.real_offset)
            rec["feed"] = feed_state(self.feed)
        self.svc.ring.mark(rec)
        if not self.svc.cfg["recording"]["enabled"]:
            self.svc.save_state(rec)
        # With a recording, the recorder saves the state file once the checkpoint record
        # (and every sample before it) is written and fsynced: a checkpoint never covers
        # samples the recording lost in a crash, so restore + replay equals the recording.

    def finish(self) -> None:
        rec = self.snapshot_record()
        if rec is not None:
            self.svc.ring.mark(rec)
        self.checkpoint()


def relabel_tau(snap: dict[str, Any], odr_hz: float) -> None:
    """τ = m / ODR with the *fitted* ODR (docs/architecture.md: τ0 = 1/fitted ODR).

    The accumulators count in samples and were built with the nominal rate, which only labels
    τ; the variances themselves (of sample averages) do not depend on the rate. ``rate_hz``
    becomes the fitted rate too, so a client computing τ = m / rate_hz agrees."""
    snap["tau"] = [float(m) / odr_hz for m in snap["m"]]
    snap["rate_hz"] = float(odr_hz)


def offset_after_mark(record: dict[str, Any], offset: float) -> float:
    """The CLOCK_REALTIME − CLOCK_MONOTONIC offset in force after a ring mark: a clock_step
    event changes it. Workers apply it in sample order, so blocks before a step keep the old
    wall-clock times even when written after the reader already saw the step."""
    if record.get("kind") == "event" and record.get("name") == "clock_step":
        return float(record["detail"]["t_real_after"]) - float(record["t_mono"])
    return offset


def feed_state(feed: AllanFeed) -> dict[str, Any]:
    """What an AllanFeed needs to continue exactly: held temperatures, pending readings."""
    return {"next_index": feed.next_index, "held": [float(v) for v in feed._held],
            "pending": [[int(i), [float(v) for v in h]] for i, h in feed._pending],
            "temp_names": feed.temp_names, "scale": feed.scale, "open": feed._open}


def restore_feed(feed: AllanFeed, state: dict[str, Any]) -> None:
    feed.next_index = state["next_index"]
    feed._held = np.array(state["held"], dtype=float)
    feed._pending = [(int(i), np.array(h, dtype=float)) for i, h in state["pending"]]
    feed._open = bool(state.get("open", False))


class RecorderWorker(Worker):
    """Writes raw blocks of about ``block_s`` seconds and every mark, in sample order."""

    name = "recorder"

    def __init__(self, consumer: Consumer, recorder: Any, service: Service, *,
                 block_samples: int, batch_s: float = 0.0) -> None:
        super().__init__(consumer, batch_s=batch_s)
        self.rec = recorder
        self.svc = service
        self.block_samples = max(1, int(block_samples))
        self.real_offset = service.real_offset
        self._header_version = service.run_header.version   # the segment's own header
        self._parts: list[np.ndarray] = []
        self._i0 = 0
        self._t0 = 0.0
        self._n = 0

    def _flush(self) -> None:
        if not self._n:
            return
        hdr = self.svc.run_header
        if hdr.version != self._header_version:
            # The fitted rate moved: the recording gets the new header (load_recording takes
            # each run's newest), before the block whose times use that fit.
            rec = self.svc.segment_header()
            self._header_version = hdr.version
            self.rec.write(rec)
        counts = np.concatenate(self._parts) if len(self._parts) > 1 else self._parts[0]
        self.rec.write(frames.raw_record(self.svc.run_id, 0, self._i0, counts, self._t0,
                                         self._t0 + self.real_offset,
                                         rate_hz=self.svc.timebase.odr_hz))
        self._parts, self._n = [], 0

    def handle(self, chunk: Chunk) -> None:
        if chunk.lost_samples:
            self._flush()
            i0, i1 = chunk.lost_index or (0, 0)
            self.rec.write(frames.gap_record(self.svc.run_id, 0, i0, max(0, i1 - i0),
                                             float(chunk.t_mono[0]) if chunk.n else 0.0,
                                             self.svc.real_now(), "recorder_behind"))
        for kind, val in _split(chunk):
            if kind == "mark":
                self._flush()
                self.real_offset = offset_after_mark(val, self.real_offset)
                written = self.rec.write(val)
                if val["kind"] == "checkpoint" and written:
                    self.rec.flush()
                    self.svc.save_state(val)
                continue
            a, b = val
            i0 = int(chunk.index[a])
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
        if self.svc.reopen_requested.is_set():
            self.svc.reopen_requested.clear()
            self._flush()
            self.rec.reopen()

    def finish(self) -> None:
        self._flush()
        self.rec.close()


class PublisherWorker(Worker):
    """Publishes raw blocks, marks, and a status record every ``status_interval_s``."""

    name = "publisher"

    def __init__(self, consumer: Consumer, publisher: Any, service: Service, *,
                 status_interval_s: float, max_block: int, batch_s: float = 0.0) -> None:
        super().__init__(consumer, idle_s=status_interval_s, batch_s=batch_s,
                         max_samples=max_block)
        self.pub = publisher
        self.svc = service
        self.status_interval_s = status_interval_s
        self.real_offset = service.real_offset
        self._next_status = 0.0
        self._header_version = -1

    def handle(self, chunk: Chunk) -> None:
        if chunk.lost_samples:
            i0, i1 = chunk.lost_index or (0, 0)
            self.pub.publish("event", frames.gap_record(
                self.svc.run_id, 0, i0, max(0, i1 - i0), float(chunk.t_mono[0]),
                self.svc.real_now(), "publisher_behind"))
        rate = self.svc.timebase.odr_hz
        for kind, val in _split(chunk):
            if kind == "mark":
                self.real_offset = offset_after_mark(val, self.real_offset)
                if val["kind"] in frames.TOPIC_OF_KIND:
                    self.pub.publish(None, val)
                if val["kind"] == "avar":
                    self.svc.snapshots.publish(val)   # what `snapshot` requests answer
                continue
            a, b = val
            t0 = float(chunk.t_mono[a])
            self.pub.publish("raw", frames.raw_record(
                self.svc.run_id, 0, int(chunk.index[a]), chunk.counts[a:b], t0,
                t0 + self.real_offset, rate_hz=rate))
        self.idle()

    def idle(self) -> None:
        now = time.monotonic()
        if now >= self._next_status:
            self._next_status = now + self.status_interval_s
            self.publish_status()

    def publish_status(self) -> None:
        hdr = self.svc.run_header.current()
        if self.svc.run_header.version != self._header_version:
            self._header_version = self.svc.run_header.version
            self.pub.publish("status", hdr)   # a new fit of the rate: on the status topic
        t = self.svc.clock.monotonic()
        self.pub.publish("status", frames.status_record(self.svc.run_id, 0, self.svc.status(),
                                                        t, t + self.svc.real_offset))

    def finish(self) -> None:
        self.publish_status()


class RunHeader:
    """The run's ``header`` record, built once and rebuilt only when the fitted rate has moved
    by more than ``ppm`` (at most every ``min_interval_s``): the recorder writes each new one
    (every segment starts with the current one), the publisher sends it on the ``status``
    topic, and the ``header`` request returns it, so all three carry the same record."""

    def __init__(self, build: Callable[[], dict[str, Any]], timebase: TimeBase,
                 clock: Callable[[], float], *, ppm: float = 2.0,
                 min_interval_s: float = 10.0) -> None:
        self._build = build
        self._tb = timebase
        self._clock = clock
        self.ppm = ppm
        self.min_interval_s = min_interval_s
        self._lock = threading.Lock()
        self._rec: dict[str, Any] | None = None
        self._rate = 0.0
        self._t = 0.0
        self.version = 0

    def current(self) -> dict[str, Any]:
        with self._lock:
            rate = float(self._tb.odr_hz)
            now = self._clock()
            if self._rec is None or (abs(rate / self._rate - 1.0) * 1e6 > self.ppm
                                     and now - self._t >= self.min_interval_s):
                self._rec = self._build()
                self._rate, self._t = rate, now
                self.version += 1
            return self._rec


class Service:
    """One acquisition run: builds nothing itself (see :func:`build_service` and
    ``commands/run.py``); owns the threads and their shutdown."""

    def __init__(self, cfg: dict[str, dict[str, Any]], sensor: Any, clock: Any, *,
                 run_id: str | None = None, speed: float | None = None,
                 temperature_bank: Any = None,
                 simulate: str | None = None, notifier: Any = None,
                 recorder_factory: Callable[..., Any] | None = None,
                 publisher_factory: Callable[..., Any] | None = None,
                 request_factory: Callable[..., Any] | None = None,
                 streaming_cls: Any = None, on_tick: Callable[[float], None] | None = None,
                 sensor_info: dict[str, Any] | None = None,
                 extra_temperature_names: list[str] | None = None,
                 interrupt: Any = None) -> None:
        self.cfg = cfg
        self.sensor = sensor
        self.clock = clock
        self.run_id = run_id or (time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()) + "-"
                                 + secrets.token_hex(3))
        self.speed = speed
        self.simulate = simulate
        self.bank = temperature_bank       # a ds18b20.Ds18b20Bank (its threads read)
        self._temp_ok: dict[str, bool] = {}
        self.sensor_info = dict(sensor_info or {})
        self.notifier = notifier
        self.interrupt = interrupt        # interrupt.InterruptPin on the FIFO watermark
        self.stop_requested = threading.Event()
        self.reopen_requested = threading.Event()
        self._reload_keys = threading.Event()   # SIGHUP: re-read CURVE client keys
        odr = float(cfg["sensor"]["odr_hz"])
        self.odr = odr
        self.timebase = TimeBase(odr, group_delay_samples=float(
            getattr(sensor, "group_delay_samples", 0.0)))
        cap = int(cfg["service"]["ring_s"] * odr * 1.1) + 64
        self.ring = Ring(cap)
        self.real_offset = clock.realtime() - clock.monotonic()
        self.scale = float(getattr(sensor, "scale_mps2", 9.80665 / 256000))
        # Channels: the chip's own sensor, the DS18B20 threads, and sources that mark their
        # readings themselves (the simulated DS18B20 of --simulate).
        self.temp_names = ["chip", *(self.bank.names if self.bank is not None else []),
                           *(extra_temperature_names or [])]
        self.data_dir = Path(cfg["recording"]["data_dir"])
        if streaming_cls is None:
            from avard.core.streaming import StreamingAllan as streaming_cls
        self.streaming_cls = streaming_cls
        self.allan = streaming_cls(3 + len(self.temp_names), odr,
                                   overlap=int(cfg["allan"]["overlap"]),
                                   names=["x", "y", "z", *self.temp_names])
        self.feed = AllanFeed(self.allan, self.scale, self.temp_names)
        self.start_index = 0
        self.restored: dict[str, Any] | None = None
        self._recorder_factory = recorder_factory
        self._publisher_factory = publisher_factory
        self._request_factory = request_factory
        self.recorder = None
        self.publisher = None
        self.request_server = None
        self.acq: Acquisition | None = None
        self.workers: list[Worker] = []
        self._on_tick = on_tick
        self.t_start = clock.monotonic()
        self.ready = False
        self.run_header = RunHeader(self._build_header, self.timebase, clock.monotonic)
        self.snapshots = SnapshotBoard(functools.partial(fit_snapshot,
                                                         filter_corner_hz=odr / 4))

    # -- helpers ------------------------------------------------------------------------
    def real_now(self) -> float:
        return self.clock.realtime()

    def header(self) -> dict[str, Any]:
        """The run's current header record (see :class:`RunHeader`)."""
        return self.run_header.current()

    def segment_header(self) -> dict[str, Any]:
        """The header that starts a segment: the current one with ``i0`` at the reader's
        next index (never behind the segment's first sample: restore skips the segments whose
        header ``i0`` is at or before a checkpoint's end, so a stale one would skip data)."""
        t = self.clock.monotonic()
        return dict(self.run_header.current(), t_mono=t, t_real=t + self.real_offset,
                    i0=self.acq.next_index if self.acq else self.start_index)

    def _build_header(self) -> dict[str, Any]:
        tb = self.timebase
        try:
            rate = tb.rate()
            timebase = {"odr_hz": rate.odr_hz, "odr_u_hz": rate.odr_u_hz, "ppm": rate.ppm,
                        "ppm_u": rate.ppm_u, "jitter_s": rate.jitter_s,
                        "n_points": rate.n_points}
        except (ValueError, ZeroDivisionError, AttributeError):
            timebase = {"odr_hz": tb.odr_hz}
        t = self.clock.monotonic()
        return frames.header_record(
            self.run_id, rate_hz=float(tb.odr_hz), t_mono=t, t_real=t + self.real_offset,
            i0=self.acq.next_index if self.acq else self.start_index,
            scale_m_s2_per_count=self.scale, range_g=self.cfg["sensor"]["range_g"],
            sensor=self.sensor_info, temperature_sensors=self.temp_names[1:],
            software=f"avard {__version__}", config=self.cfg,
            temperature_channels=self.temp_names, nominal_odr_hz=self.odr,
            allan_rate_hz=float(self.allan.rate_hz), timebase=timebase,
            simulate=self.simulate, restored=self.restored)

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
        return st

    def status_line(self) -> str:
        st = self.status()
        disk = st.get("disk", {})
        return (f"{st['rate_hz']:.3f} Hz, {st['samples']} samples, {st['gaps']} gaps, "
                f"{st.get('subscribers', 0)} subscribers, disk "
                f"{disk.get('state', 'off')}")

    # -- checkpoint state file ----------------------------------------------------------
    def save_state(self, rec: dict[str, Any]) -> None:
        if not self.cfg["recording"]["enabled"]:
            return
        path = self.data_dir / STATE_FILE
        tmp = path.with_suffix(".tmp")
        try:
            data = frame(frames.encode(dict(rec, seq=0)))
            with open(tmp, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except OSError as exc:
            log.error("cannot save the Allan checkpoint to %s: %s", path, exc)

    def _load_state(self) -> dict[str, Any] | None:
        path = self.data_dir / STATE_FILE
        if not path.exists():
            return None
        probs: list = []
        try:
            frs = list(scan_frames(path.read_bytes(), str(path), problems=probs))
            if not frs:
                raise FormatError(f"{path}: no valid frame ({'; '.join(map(str, probs))})")
            return frames.decode(frs[0].payload)
        except (OSError, FormatError) as exc:
            log.error("ignoring the Allan checkpoint %s: %s; starting the accumulators "
                      "afresh", path, exc)
            return None

    def restore(self) -> None:
        """Restore the accumulators from the last checkpoint and replay what the previous run
        recorded after it; continue the sample index across the restart."""
        ckpt = self._load_state() if self.cfg["allan"]["restore"] else None
        last = self._last_recorded()
        if ckpt is not None:
            state = ckpt["state"]
            try:
                allan = self.streaming_cls.from_state(state)
            except (AvardError, KeyError, ValueError, TypeError) as exc:
                log.error("cannot restore the Allan checkpoint: %s; starting afresh", exc)
                allan = None
            if allan is not None and list(allan.names) == list(self.allan.names) \
                    and float(allan.rate_hz) == float(self.allan.rate_hz):
                feed = AllanFeed(allan, ckpt["feed"]["scale"], ckpt["feed"]["temp_names"])
                restore_feed(feed, ckpt["feed"])
                replayed = self._replay_after(ckpt, feed)
                feed.gap()
                self.allan = allan
                self.feed = AllanFeed(allan, self.scale, self.temp_names)
                self.restored = {"run": ckpt["run"], "i_end": ckpt["i_end"],
                                 "n_samples": int(allan.n_samples), "replayed": replayed}
                log.warning("restored the Allan accumulators of run %s (%d samples, %d "
                            "replayed from the recording)", ckpt["run"], allan.n_samples,
                            replayed)
            elif allan is not None:
                log.warning("the checkpoint's channels/rate (%s at %g Hz) differ from this "
                            "configuration; starting the accumulators afresh",
                            allan.names, allan.rate_hz)
        if last is not None:
            i_end, t_real_end = last
            elapsed = max(0.0, self.real_now() - t_real_end)
            self.start_index = i_end + round(elapsed * self.odr)
            self._restart_gap = (i_end, self.start_index - i_end, t_real_end)

    def _last_recorded(self) -> tuple[int, float] | None:
        """(index after the last recorded sample, its CLOCK_REALTIME) of the newest segment
        that holds samples; read from the file's end, so an hour-long segment costs little."""
        if not self.cfg["recording"]["enabled"] or not self.data_dir.is_dir():
            return None
        for seg in reversed(sorted(self.data_dir.glob("*.avr"))):
            try:
                rec = last_record(seg, "raw")
            except (OSError, FormatError):
                continue
            if rec is not None:
                rate = float(rec.get("rate_hz") or self.odr)
                return rec["i0"] + rec["n"], rec["t_real"] + rec["n"] / rate
        return None

    def _replay_after(self, ckpt: dict[str, Any], feed: AllanFeed) -> int:
        """Feed what run ``ckpt['run']`` recorded after the checkpoint (crash window)."""
        run = ckpt["run"]
        start = int(ckpt["feed"]["next_index"] or ckpt["i_end"])
        n0 = feed.fed
        segs = [s for s in sorted(self.data_dir.glob("*.avr")) if s.name.startswith(f"{run}_")]
        # Only the segment the checkpoint falls in and the later ones (headers carry the
        # index their segment starts at): a 60-hour run is not read again at every restart.
        keep = 0
        for k, seg in enumerate(segs):
            head = first_record(seg)
            if head is not None and head.get("kind") == "header" and head["i0"] <= start:
                keep = k
        segs = segs[keep:]
        if not segs:
            return 0
        for seg in segs:
            for rec in RecordingReader(seg):
                kind = rec["kind"]
                if kind == "raw" and rec["i0"] + rec["n"] > start:
                    cut = max(0, start - rec["i0"])
                    feed.raw(rec["i0"] + cut, np.asarray(rec["counts"])[cut:])
                    start = rec["i0"] + rec["n"]
                elif kind == "temp" and rec["i0"] >= start:
                    feed.temp(rec["i0"], rec["names"], rec["values_c"])
                elif kind == "gap" and rec["i0"] >= start:
                    feed.gap()
        return feed.fed - n0

    # -- lifecycle ----------------------------------------------------------------------
    def start(self, before_acquisition: Callable[[], None] | None = None) -> None:
        """Build the consumers and start every thread; ``before_acquisition`` runs once the
        sockets are bound and before the first drain (a subscriber can connect then)."""
        cfg = self.cfg
        self._restart_gap: tuple[int, int, float] | None = None
        if cfg["recording"]["enabled"]:
            try:
                self.data_dir.mkdir(parents=True, exist_ok=True)
                if not os.access(self.data_dir, os.W_OK | os.X_OK):
                    raise PermissionError(13, "not writable")
            except OSError as exc:
                raise ConfigError(
                    f"recording.data_dir = {str(self.data_dir)!r}: cannot write there "
                    f"({exc.strerror}); under systemd StateDirectory= provides it, by hand "
                    "use --data-dir DIR or `sudo install -d -o $USER /var/lib/avard`") from None
            self.restore()
        poll = effective_poll_hz(cfg)
        self.acq = Acquisition(self.sensor, self.ring, self.timebase, self.clock,
                               poll_hz=poll, chip_interval_s=cfg["temperature"]["chip_interval_s"],
                               run_id=self.run_id, speed=self.speed, on_tick=self._on_tick,
                               start_index=self.start_index,
                               on_clock_step=self._on_clock_step,
                               backpressure=self.simulate is not None,
                               interrupt=self.interrupt)
        acfg = cfg["allan"]
        # Consumers take what accumulated over a batch time instead of every drain; not when
        # a simulation runs unpaced (its reader waits for them: batching would slow it).
        paced = not (self.simulate is not None and self.speed is None)
        self.workers.append(AllanWorker(
            self.ring.consumer("allan"), self.allan, self.feed, self,
            snapshot_interval_s=acfg["snapshot_interval_s"],
            checkpoint_interval_s=acfg["checkpoint_interval_s"],
            batch_s=ALLAN_BATCH_S if paced else 0.0))
        if cfg["recording"]["enabled"]:
            factory = self._recorder_factory or _default_recorder
            self.recorder = factory(self)
            self.workers.append(RecorderWorker(
                self.ring.consumer("recorder"), self.recorder, self,
                block_samples=int(cfg["recording"]["block_s"] * self.odr),
                batch_s=min(RECORDER_BATCH_S, cfg["recording"]["block_s"]) if paced else 0.0))
        if cfg["publish"]["enabled"]:
            self.publisher = (self._publisher_factory or _default_publisher)(self)
            self.request_server = (self._request_factory or _default_request_server)(self)
            self.workers.append(PublisherWorker(
                self.ring.consumer("publisher"), self.publisher, self,
                status_interval_s=cfg["publish"]["status_interval_s"],
                max_block=max(32, int(self.odr)), batch_s=PUBLISH_BATCH_S if paced else 0.0))
        # The first marks (restart gap, start event) for every consumer, in order.
        if self._restart_gap is not None:
            i0, n, t_real = self._restart_gap
            self.ring.mark(frames.gap_record(self.run_id, 0, i0, n, t_real - self.real_offset,
                                             t_real, "restart", estimated=True))
        self.ring.mark(frames.event_record(
            self.run_id, 0, "start", self.clock.monotonic(), self.real_now(),
            i0=self.start_index, detail={"software": f"avard {__version__}",
                                         "restored": self.restored or {}}))
        for w in self.workers:
            w.start()
        if self.bank is not None:
            self.bank.sink = self._on_temperature
            self.bank.start()
        if before_acquisition is not None:
            before_acquisition()
        self.acq.start()
        log.info("run %s started: ADXL355 %g Hz, ±%d g, drained at %g Hz; temperature "
                 "channels %s", self.run_id, self.odr, cfg["sensor"]["range_g"], poll,
                 ", ".join(self.temp_names))

    def _on_clock_step(self, real_offset: float) -> None:
        """The reader saw CLOCK_REALTIME step (and recorded it): wall-clock times written from
        now on follow the new offset (one float assignment, safe across threads)."""
        self.real_offset = real_offset

    def _on_temperature(self, reading: Any) -> None:
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

    def check_threads(self) -> None:
        """Raise when a thread died (the service must stop with an error, not limp on)."""
        if self.acq is not None and self.acq.error is not None:
            raise AvardError(f"the reader thread stopped: {self.acq.error}")
        for w in self.workers:
            if w.error is not None:
                raise AvardError(f"the {w.name} thread stopped: {w.error}")

    def run(self, duration_s: float | None = None, *, tick_s: float = 0.5,
            before_acquisition: Callable[[], None] | None = None) -> int:
        """Start, supervise until ``duration_s`` of (virtual) time or a stop request, stop."""
        self.start(before_acquisition)
        n = self.notifier
        wd = n.watchdog_interval_s() if n is not None else None
        next_wd = time.monotonic()
        last_samples = -1
        next_status_log = time.monotonic() + self.cfg["service"]["status_log_interval_s"]
        try:
            while not self.stop_requested.is_set():
                self.check_threads()
                assert self.acq is not None
                if not self.ready and self.acq.first_samples.is_set():
                    self.ready = True
                    log.info("samples flow; ready")
                    if n is not None:
                        n.ready()
                        n.status(self.status_line())
                now = time.monotonic()
                if n is not None and wd and self.ready and now >= next_wd:
                    # WATCHDOG=1 only while samples advance: a stuck sensor lets systemd act.
                    if self.acq.samples != last_samples and not self.acq.stalled:
                        n.watchdog()
                        last_samples = self.acq.samples
                    n.status(self.status_line())
                    next_wd = now + wd
                if self._reload_keys.is_set():
                    # Not in the signal handler: zmq calls belong in a normal thread context.
                    self._reload_keys.clear()
                    log.info("SIGHUP: reopening the recording files, re-reading client keys")
                    if n is not None:
                        n.reloading()
                    for sock in (self.publisher, self.request_server):
                        reload = getattr(sock, "reload_keys", None)
                        if reload is not None:
                            reload()
                    if n is not None:
                        n.ready()   # reload finished (Type=notify protocol)
                if now >= next_status_log:
                    next_status_log = now + self.cfg["service"]["status_log_interval_s"]
                    log.info("status: %s", self.status_line())
                wait = tick_s if self.ready else min(tick_s, 0.05)   # READY promptly
                if duration_s is not None:
                    left = duration_s - (self.clock.monotonic() - self.t_start)
                    if left <= 0:
                        break
                    # virtual seconds → real seconds at this pace; unpaced: look often
                    wait = min(wait, left / self.speed if self.speed else 0.05)
                if n is not None and wd and self.ready:
                    wait = min(wait, max(0.0, next_wd - time.monotonic()))
                self.stop_requested.wait(wait)
        finally:
            self.stop()
        self.check_threads()
        return 0

    def stop(self) -> None:
        """Flush and close everything, in data order: reader, Allan, recorder, publisher."""
        if getattr(self, "stop_signal", None):
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
        if self.publisher is not None:
            self.publisher.close()
            self.publisher = None

    def install_signals(self) -> None:
        """SIGTERM/SIGINT stop cleanly, SIGHUP reopens the recording (main thread only)."""
        def _term(signum: int, _frame: Any) -> None:
            self.stop_signal = signum      # logged by the main loop, not here (locks)
            self.stop_requested.set()

        def _hup(_signum: int, _frame: Any) -> None:
            # Only flags here: the handler runs in the main thread, which may be inside the
            # notifier's or a socket's lock at this moment.
            self.reopen_requested.set()
            self._reload_keys.set()

        signal.signal(signal.SIGTERM, _term)
        signal.signal(signal.SIGINT, _term)
        signal.signal(signal.SIGHUP, _hup)

    # -- request handlers ---------------------------------------------------------------
    def handlers(self) -> dict[str, Callable[[dict[str, Any]], dict[str, Any]]]:
        return {"snapshot": self._req_snapshot, "status": lambda _a: self.status(),
                "recent": self._req_recent, "header": lambda _a: self.header()}

    def _req_snapshot(self, _args: dict[str, Any]) -> dict[str, Any]:
        rec = self.snapshots.reply()
        if rec is None:
            raise AvardError("no Allan snapshot yet; ask again after snapshot_interval_s")
        return rec

    def _req_recent(self, args: dict[str, Any]) -> dict[str, Any]:
        seconds = args.get("seconds", 1.0)
        if not isinstance(seconds, int | float) or not 0 <= seconds <= \
                self.cfg["publish"]["recent_max_s"]:
            raise AvardError(f"recent: seconds={seconds!r}; allowed is 0 to "
                             f"{self.cfg['publish']['recent_max_s']:g} s")
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
                "scale_m_s2_per_count": self.scale, "rate_hz": float(self.timebase.odr_hz)}


def fit_snapshot(rec: dict[str, Any], *, filter_corner_hz: float) -> dict[str, Any]:
    """IEEE noise terms with intervals per axis from an avar record ({} if unavailable)."""
    try:
        from avard.core.allan import AllanResult
        from avard.core.fit import fit_noise
    except ImportError:
        return {}
    snap = rec["snapshot"]
    out: dict[str, Any] = {}
    try:
        var = np.asarray(snap["avar"], dtype=float)
        base = {k: np.asarray(snap[k]) for k in ("tau", "m", "stride", "n")}
        for c, axis in enumerate(("x", "y", "z")):
            res = AllanResult(kind="oavar", rate_hz=float(snap["rate_hz"]), var=var[:, c],
                              edf=np.asarray(snap["edf"], dtype=float)[:, c],
                              lo=np.asarray(snap["lo"], dtype=float)[:, c],
                              hi=np.asarray(snap["hi"], dtype=float)[:, c],
                              alpha=np.asarray(snap["alpha"], dtype=float)[:, c],
                              ci=float(snap["ci"]), **base)
            out[axis] = fit_noise(res, filter_corner_hz=filter_corner_hz).to_dict()
    except (AvardError, KeyError, TypeError, ValueError) as exc:
        log.info("no fit for the snapshot yet: %s", exc)
    return out


def _default_recorder(svc: Service) -> Any:
    from .recorder import Recorder

    r = svc.cfg["recording"]
    return Recorder(svc.data_dir, svc.run_id, svc.segment_header, segment_s=r["segment_s"],
                    fsync_interval_s=r["fsync_interval_s"], retention_days=r["retention_days"],
                    retention_max_bytes=r["retention_max_bytes"],
                    min_free_bytes=r["min_free_bytes"], clock=svc.clock.monotonic,
                    realtime=svc.clock.realtime)


def _curve(svc: Service) -> Any:
    if not svc.cfg["curve"]["enabled"]:
        return None
    from .curve import CurveServerConfig

    c = CurveServerConfig.from_mapping(svc.cfg["curve"])
    c.check()
    return c


def _default_publisher(svc: Service) -> Any:
    from .publisher import Publisher

    p = svc.cfg["publish"]
    return Publisher(p["endpoint"], svc.run_id, hwm=p["hwm"], curve=_curve(svc),
                     allow_remote=p["allow_remote"])


def _default_request_server(svc: Service) -> Any:
    from .publisher import RequestServer

    return RequestServer(svc.cfg["publish"]["request_endpoint"], svc.handlers(),
                         curve=_curve(svc),
                         allow_remote=svc.cfg["publish"]["allow_remote"]).start()
