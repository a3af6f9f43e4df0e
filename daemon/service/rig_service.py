"""The service of a rig of several sensors: one :class:`Service` per sensor (its *lane*), the
readers, sockets and DS18B20s shared (docs/architecture.md, "Several sensors").

Each lane keeps everything that is the sensor's own: its sample index, fitted time base, ring,
accumulators, recording (``data_dir/NAME``, checkpoint and state file there, so a sensor added
or removed between runs leaves the others' recordings and Allan state as they were) and its
gaps (a sensor that stops answering is its own lane's ``stalled`` event and gap, the others go
on). Shared: one reader thread per bus (``readers``: acquisition.share_reader), one PUB socket
(:class:`SensorPublisher`: ``sensor_name`` in every record and ``.NAME`` on every topic), one
request socket (ops routed by their ``sensor`` argument; the first sensor without one; the
``sensors`` op lists them), the DS18B20 bank (every reading to every lane) and one run id.
Every ``alignment_interval_s`` the lanes' time bases are compared (alignment.py) and the result
goes into every lane as an ``alignment`` event: recorded and published with its samples.
"""

from __future__ import annotations

import dataclasses
import logging
import shlex
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from avard.core.errors import ConfigError, FormatError, ServiceFault
from avard.core.io import frames
from avard.core.io.recording import SEGMENT_SUFFIX, first_record, order_segments, run_order
from avard.daemon.config_types import Config
from avard.daemon.hw.drain_process import READER_RT_PRIORITY
from avard.daemon.hw.rig import RigLanes, wiring
from avard.daemon.service import dirlock
from avard.daemon.service.acquisition import BusReader, StoppedWithBus, share_reader
from avard.daemon.service.alignment import Alignment, align
from avard.daemon.service.checkpoint import STATE_FILE
from avard.daemon.service.recorder import new_run_id
from avard.daemon.service.rig_separation import RigSeparation, SeparatedLane
from avard.daemon.service.supervisor import (
    Progress,
    RigFacts,
    Service,
    ServiceHooks,
    Supervised,
    _default_publisher,
    _default_request_server,
)

log = logging.getLogger("avard.daemon.service")

#: How often the sensors' time bases are compared and the alignment recorded (s of clock).
ALIGNMENT_INTERVAL_S = 60.0


class SensorPublisher:
    """One lane's face of the shared PUB socket: the sensor's name in every record and on
    its topic (``raw.left``), so a subscriber picks one sensor by topic or by field."""

    def __init__(self, inner: Any, name: str) -> None:
        self.inner = inner
        self.name = name
        # before the first record: a client may subscribe to raw.NAME before it is sent, and
        # the publisher's subscription guard passes on only subscriptions to its topics
        declare = getattr(inner, "declare_topics", None)
        if declare is not None:
            declare(f"{kind}.{name}" for kind in frames.TOPICS)

    def publish(self, topic: str | None, record: Mapping[str, Any]) -> int:
        base = topic if topic is not None else frames.topic_of(record)
        return int(self.inner.publish(f"{base}.{self.name}",
                                      {**record, "sensor_name": self.name}))

    def stats(self) -> dict[str, Any]:
        return dict(self.inner.stats())

    def close(self) -> None:
        """The shared socket is closed once, by the RigService."""


class _NoRequestServer:
    """A lane's request server: the RigService's one serves every lane."""

    def stop(self) -> None:
        pass


class _LaneTime:
    """alignment.AlignedLane over a lane (a Service)."""

    def __init__(self, lane: Service) -> None:
        self.lane = lane
        self.sensor_name = lane.sensor_name

    def next_index(self) -> int:
        acq = self.lane.acq
        return acq.next_index if acq is not None else self.lane.start_index

    def time_of(self, index: float) -> float:
        if self.lane.acq is None or self.lane.acq.samples == 0:
            raise ValueError("no samples yet")
        return float(self.lane.timebase.time_of(index))

    def rate(self) -> tuple[float, float, float]:
        r = self.lane.timebase.rate()
        return float(r.odr_hz), float(r.odr_u_hz), float(r.jitter_s)


def lane_config(config: Config, sensor_index: int) -> Config:
    """The config one lane runs under: its own ``[sensor]`` and ``data_dir/NAME``; the rig's
    ``sensors`` stay in it (the header then says what the whole rig was)."""
    s = config.rig_sensors[sensor_index]
    rec = dataclasses.replace(config.recording,
                              data_dir=str(Path(config.recording.data_dir) / s.name))
    return dataclasses.replace(config, sensor=s, recording=rec)


def rig_run_id(data_dir: str | Path, names: Sequence[str], t_real: float) -> str:
    """One run id for every lane, after the newest run of any of them and of a one-sensor
    recording in ``data_dir`` itself (run order is data order across the move to a rig)."""
    ids = [new_run_id(Path(data_dir) / n, t_real) for n in names]
    return max([*ids, new_run_id(data_dir, t_real)], key=run_order)


def check_unmoved(data_dir: str | Path, names: Sequence[str]) -> None:
    """Refuse (ConfigError, one line saying how to move it) a one-sensor recording in
    ``data_dir`` itself whose sensor is one of the rig's while ``data_dir/NAME`` holds no
    recording yet: the lane would start afresh beside it, its Allan state, sample index and
    run order lost. Moved by hand, the lane restores from it as any restart does."""
    d = Path(data_dir)
    segments = order_segments(d.glob("*" + SEGMENT_SUFFIX)) if d.is_dir() else []
    if not segments:
        return
    try:
        head = first_record(segments[-1]) or {}
    except (OSError, FormatError):
        return                      # unreadable: not known to be one of these sensors'
    name = (head.get("sensor") or {}).get("name")
    if name not in names or any((d / str(name)).glob("*" + SEGMENT_SUFFIX)):
        return
    state = f" {shlex.quote(str(d / STATE_FILE))}" if (d / STATE_FILE).exists() else ""
    to = shlex.quote(str(d / str(name)))
    raise ConfigError(
        f"recording.data_dir {d} holds sensor {name}'s one-sensor recording, and a rig "
        f"records each sensor in DATA_DIR/NAME: move it there first (mkdir {to} && "
        f"mv {shlex.quote(str(d))}/*{SEGMENT_SUFFIX}{state} {to}/), then start again; its "
        "sample index, run order and (same channels) Allan state then continue")


class RigService(Supervised):
    """Several sensors run as one service (see the module's docstring)."""

    def __init__(self, config: Config, built: RigLanes, *, run_id: str | None = None,
                 notifier: Any = None, hooks: ServiceHooks | None = None,
                 alignment_interval_s: float = ALIGNMENT_INTERVAL_S,
                 reader_rt_priority: int = READER_RT_PRIORITY) -> None:
        clock = built.clock
        super().__init__(config, clock, notifier, built.spec.clock.speed)
        hooks = hooks or ServiceHooks()
        self.built = built
        self.reader_rt_priority = int(reader_rt_priority)
        names = [s.name for s in built.spec.sensors]
        self.names = tuple(names)
        self.run_id = run_id or rig_run_id(config.recording.data_dir, names, clock.realtime())
        self.cfg = config.as_dict()     # what the request server's CURVE set-up reads
        self.sync = ("external" if all(s.sync == "external" for s in config.rig_sensors)
                     else "none")
        self.publisher: Any = None
        self.request_server: Any = None
        self._publisher_factory = hooks.publisher
        self._request_factory = hooks.request_server
        lane_hooks = dataclasses.replace(hooks, publisher=self._lane_publisher,
                                         request_server=lambda _svc: _NoRequestServer())
        wirings = tuple(wiring(s.bus) for s in built.spec.sensors)
        # The live separation of the first 2–3 sensors (rig_separation.py): every lane's avar
        # record carries it, so a subscriber to any one sensor sees the rig's separation.
        self.separation: RigSeparation | None = None
        sep = None
        if len(names) >= 2:
            sep = self.separation = RigSeparation(
                names, config.sensor.odr_hz,
                data_dir=Path(config.recording.data_dir) if config.recording.enabled else None,
                checkpoint_interval_s=config.allan.checkpoint_interval_s)
            if sep.left_out:
                log.warning("the live separation takes the first %d sensors (%s); %s are "
                            "recorded but not separated", len(sep.names),
                            ", ".join(sep.names), ", ".join(sep.left_out))
        status = None if sep is None else (lambda: {"separation": sep.status()})
        self.lanes = tuple(
            Service(lane_config(config, k), rig, run_id=self.run_id, hooks=lane_hooks,
                    own_reader=False,
                    rig_facts=RigFacts(self.names, k, self.sync, wirings, names[0]),
                    avar_fields=None if sep is None else sep.fields_for(names[k]),
                    status_fields=status)
            for k, rig in enumerate(built.lanes))
        self.bank = built.temperature_bank
        self.alignment_interval_s = float(alignment_interval_s)
        self._next_alignment = 0.0
        self.last_alignment: Alignment | None = None
        self.readers: list[BusReader] = []
        #: the lanes whose threads were started (stop() stops those: a start may fail midway)
        self._started: list[Service] = []
        #: the lanes' directory locks taken before any lane starts (released by stop())
        self._lane_locks: list[Path] = []
        #: each lane's samples when every lane had last advanced (the watchdog's count)
        self._seen: list[int] = [0] * len(self.lanes)
        self._advances = 0

    # -- the shared sockets -------------------------------------------------------------
    def _lane_publisher(self, lane: Service) -> SensorPublisher:
        if self.publisher is None:
            factory = self._publisher_factory or _default_publisher
            self.publisher = factory(lane)
        return SensorPublisher(self.publisher, lane.sensor_name)

    def handlers(self) -> dict[str, Callable[[dict[str, Any]], dict[str, Any]]]:
        """The request ops of every lane, routed by ``sensor`` (the first without it)."""
        tables = {lane.sensor_name: lane.handlers() for lane in self.lanes}

        def route(op: str) -> Callable[[dict[str, Any]], dict[str, Any]]:
            def handle(args: dict[str, Any]) -> dict[str, Any]:
                name = args.get("sensor", self.names[0])
                if name not in tables:
                    raise ValueError(f"no sensor {name!r}; this rig has "
                                     f"{', '.join(self.names)}")
                return {**tables[name][op](args), "sensor_name": name}   # whose reply
            return handle

        ops = {op: route(op) for op in tables[self.names[0]]}
        ops["sensors"] = lambda _args: {"sensors": list(self.names),
                                        "alignment": (self.last_alignment.to_dict()
                                                      if self.last_alignment else None)}
        return ops

    # -- lifecycle ----------------------------------------------------------------------
    def start(self, before_acquisition: Callable[[], None] | None = None, *,
              stop_at: float | None = None) -> None:
        if self.config.recording.enabled:
            check_unmoved(self.config.recording.data_dir, self.names)
            # Every lane's directory checked and locked, and its recorded rate, before any
            # lane starts: lanes start one after another, so a second lane refused (another
            # service records there, or at another ODR) had already written a run into the
            # first one's directory. Held until stop() (each lane holds its own as well).
            for lane in self.lanes:
                lane._check_data_dir()
                self._lane_locks.append(dirlock.hold(lane.data_dir))
            for lane in self.lanes:
                lane._check_recorded_rate()
        for lane in self.lanes:
            self._started.append(lane)
            lane.start(stop_at=stop_at)
        if self.config.publish.enabled:
            self.request_server = (self._request_factory or _default_request_server)(self)
        if self.bank is not None:
            self.bank.sink = self._temperature_reading
            self.bank.start()
        sep = self.separation
        if sep is not None:
            chosen = [lane for lane in self.lanes if lane.sensor_name in sep.names]
            sep.restore({lane.sensor_name: lane.start_index for lane in chosen})
            sep.attach([SeparatedLane(lane.sensor_name, lane.ring.consumer("separation"),
                                      lane.scale, lane.timebase, lane.start_index)
                        for lane in chosen])
            sep.start()
        acqs = [lane.acq for lane in self.lanes]
        for group in self.built.readers:
            members = [a for a in (acqs[k] for k in group) if a is not None]
            assert len(members) == len(group)
            # a bus drained by this thread on the real clock: it asks for SCHED_FIFO, as the
            # reader process does (allowed by systemd/realtime.conf; refused, it runs as it
            # is); a reader process has the deadline itself, its thread here only the pipe
            own = not any(hasattr(a.sensor, "wait_for_drain") for a in members)
            rt = self.reader_rt_priority if own and not self.built.spec.clock.stepped else 0
            self.readers.append(share_reader(members, rt_priority=rt))
        if before_acquisition is not None:
            before_acquisition()
        for reader in self.readers:
            reader.start()
        log.info("rig of %d sensors started (%s), %d reader thread(s), run %s",
                 len(self.lanes), ", ".join(self.names), len(self.readers), self.run_id)

    def _temperature_reading(self, reading: Any) -> None:
        for lane in self.lanes:
            lane.temperature_reading(reading)

    def stop(self) -> None:
        """The readers first, then each lane flushes (Allan, recorder, publisher), then the
        shared sockets."""
        if self.notifier is not None:
            self.notifier.stopping()
        self.stop_requested.set()
        for reader in self.readers:
            reader.stop()
        if self.bank is not None:
            self.bank.stop()
        # every sample the rings hold into the separation, before the lanes' last avar
        if self.separation is not None:
            self.separation.drain()
        self._mark_alignment()
        for lane in self._started:
            lane.stop()
        if self.request_server is not None:
            self.request_server.stop()
        if self.publisher is not None:
            self.publisher.close()
            self.publisher = None
        while self._lane_locks:          # every lane has stopped writing
            dirlock.release(self._lane_locks.pop())

    def check_threads(self, *, restart: bool = True) -> None:
        err = self.separation.error_of_threads() if self.separation is not None else None
        if err is not None:
            raise ServiceFault(f"the live separation stopped: {err!r}; exiting for systemd "
                               "to restart the service")
        # the sensor whose drain raised first: the others of its bus only stopped with it
        lanes = sorted(self.lanes, key=lambda lane: isinstance(
            lane.acq.error if lane.acq is not None else None, StoppedWithBus))
        for lane in lanes:
            try:
                lane.check_threads(restart=restart)
            except ServiceFault as exc:
                k = self.names.index(lane.sensor_name)
                raise ServiceFault(f"sensor {lane.sensor_name} "
                                   f"({wiring(self.built.spec.sensors[k].bus)}): {exc}") from None

    def refresh(self) -> None:
        for lane in self.lanes:
            lane.refresh()
        now = float(self.clock.monotonic())
        if now >= self._next_alignment:
            if self._mark_alignment():
                self._next_alignment = now + self.alignment_interval_s

    def alignment(self) -> Alignment | None:
        """The sensors against the first, from their fitted time bases (None before every
        sensor has samples)."""
        return align([_LaneTime(lane) for lane in self.lanes], self.sync)

    def _mark_alignment(self) -> bool:
        got = self.alignment()
        if got is None:
            return False
        self.last_alignment = got
        t = float(self.clock.monotonic())
        for lane in self.lanes:
            real = t + lane.real_offset
            lane.ring.mark(frames.event_record(self.run_id, 0, "alignment", t, real,
                                               i0=_LaneTime(lane).next_index(),
                                               detail=got.to_dict()))
        return True

    def progress(self) -> Progress:
        """READY once every sensor delivered or is marked stalled (a part silent from the
        start is its own stalled event and STATUS line, not a rig that never starts); the
        count the watchdog follows advances only once every sensor not marked stalled has
        advanced (a reader hung inside a transfer raises no stall: its frozen count stops
        the watchdog, as for one sensor)."""
        ps = [lane.progress() for lane in self.lanes]
        if all(p.stalled or p.samples > seen for p, seen in zip(ps, self._seen, strict=True)):
            self._seen = [p.samples for p in ps]
            self._advances += 1
        return Progress(all(p.first_samples or p.stalled for p in ps), self._advances,
                        all(p.stalled for p in ps), all(p.finished for p in ps))

    def sockets(self) -> tuple[Any, ...]:
        return (self.publisher, self.request_server)

    def _handle_signals(self, signums: list[int]) -> None:
        super()._handle_signals(signums)
        if self.reopen_requested.is_set():
            self.reopen_requested.clear()
            for lane in self.lanes:
                lane.reopen_requested.set()

    def status(self) -> dict[str, Any]:
        return {"run": self.run_id, "sensors": {lane.sensor_name: lane.status()
                                                for lane in self.lanes}}

    def status_line(self) -> str:
        return "; ".join(f"{lane.sensor_name}: {_lane_state(lane)}{lane.status_line()}"
                         for lane in self.lanes)


def _lane_state(lane: Service) -> str:
    """What STATUS says first of a lane that is not delivering: it names the silent sensor."""
    acq = lane.acq
    if acq is None or not acq.stalled:
        return ""
    return "STALLED (no samples yet), " if acq.samples == 0 else "STALLED, "
