"""The FIFO reader in a process of its own: the only code that drains the ADXL355, with no
interpreter lock shared with anyone.

At 4 kHz the FIFO overruns 8 ms after a drain. A reader *thread* shares the GIL with the
service's Allan, recorder and publisher threads: whichever of them holds it when the reader
wakes keeps it until its switch interval ends or its C call returns, and if the kernel has put
that thread aside for a CPU hog the reader waits with it, SCHED_FIFO or not
(``python -m benchmarks realtime --gil-load 1`` shows it). So the drain loop runs here, in a
child process that does nothing else: it paces the drains (pacing.py), raises itself to
SCHED_FIFO when the system allows it (thread_priority.py), and writes every drain, whole and
in order, into a pipe: the kernel's ring buffer between the two processes (1 MiB where
``fs.pipe-max-size`` allows it: seconds of data at 4 kHz). Every message is one ``write`` of
at most PIPE_BUF bytes, so it arrives whole.

The service side is :class:`ReaderProcess`, a :class:`~avard.daemon.hw.source.SampleSource`
that hands the service the child's drains one by one, exactly as the driver made them (counts,
``t_mono``, ``t_burst``, the overrun flags, ``post_entries``): the reader's loss accounting
(service/acquisition.py) works on them unchanged, and ``wait_for_drain`` lets the reader
thread wait on the pipe instead of a timer. Errors cross as their type (``DeviceStalledError``,
``HardwareError``); ``recover()`` asks the child to recover the part, or starts a new child when
the old one died (the part is brought up again: a restart gap).

If the service stops reading for long, the child never blocks (that would overrun the chip):
it keeps drains in memory up to ``BACKLOG_S`` seconds of them, then drops the oldest and says
so on the next drain (``GapReason.READER_BACKLOG``; the service counts the gap from time).

The child is ``python -m avard.daemon.hw.drain_process SPEC OUT_FD CMD_FD``; SPEC (JSON) names
the opener, a ``module:function`` that returns the started driver (:func:`open_hardware` on
the Pi, :func:`open_emulated` for benchmarks and tests: the emulator on the real clock).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import gc
import importlib
import json
import logging
import math
import os
import select
import signal
import struct
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from avard.core.errors import DeviceStalledError, HardwareError
from avard.daemon.hw.adxl355 import Adxl355, Drain
from avard.daemon.hw.pacing import FILL_TARGET_PROCESS, drain_period_s
from avard.daemon.hw.source import GapReason, SampleSource
from avard.daemon.hw.thread_priority import raise_thread_priority

log = logging.getLogger(__name__)

#: Linux's F_SETPIPE_SZ (fcntl has it from Python 3.10 on Linux; spelled out for mypy).
_F_SETPIPE_SZ = getattr(fcntl, "F_SETPIPE_SZ", 1031)
PIPE_BYTES = 1 << 20
#: Seconds of drains the child keeps while the service does not read (then the oldest go).
BACKLOG_S = 30.0
#: SCHED_FIFO priority the reader process asks for (refused without CAP_SYS_NICE or an
#: RLIMIT_RTPRIO; the drop-in systemd/realtime.conf allows it): below the kernel's threaded
#: interrupt handlers (50), so the SPI controller's interrupt still runs before it.
READER_RT_PRIORITY = 10
#: Writes up to this size are atomic on a pipe (POSIX PIPE_BUF is at least 512; Linux 4096).
PIPE_BUF = 4096

# -- the wire --------------------------------------------------------------------------------
# length, kind, flags, n_sets, reasons, status, fifo_entries, dropped, post_entries, index0,
# chip (which of the child's parts), then t_mono, t_real, t_mono_end, since_last_s, t_burst,
# t_burst_end, t_real_u, t_post
_HEAD = struct.Struct("<HBBHHBBHhqB8d")
_DRAIN, _ERROR, _TEMP, _STARTED = 1, 2, 3, 4
_F_OVERRUN, _F_COMPLETE, _F_IN_DRAIN, _F_SINCE = 1, 2, 4, 8
_E_HARDWARE, _E_STALLED = 0, 1
_REASONS = list(GapReason)
#: Sets one message can hold (the FIFO holds 32; a carried set makes at most one more).
MAX_SETS = (PIPE_BUF - _HEAD.size) // 12


def _pack(kind: int, *, flags: int = 0, counts: bytes = b"", n: int = 0, reasons: int = 0,
          status: int = 0, entries: int = 0, dropped: int = 0, post: int = -1,
          index0: int = 0, chip: int = 0, times: tuple[float, ...] = (0.0,) * 8) -> bytes:
    return _HEAD.pack(_HEAD.size + len(counts), kind, flags, n, reasons, status, entries,
                      dropped, post, index0, chip, *times) + counts


def encode_drain(d: Drain, extra: tuple[GapReason, ...] = (), chip: int = 0) -> bytes:
    """One drain as one message (``extra``: reasons the child adds, e.g. a dropped backlog)."""
    counts = np.ascontiguousarray(d.counts, dtype="<i4")
    if counts.shape[0] > MAX_SETS:
        raise HardwareError(f"a drain of {counts.shape[0]} sets does not fit one message")
    reasons = set(d.gap_reasons) | set(extra)
    mask = sum(1 << _REASONS.index(r) for r in reasons)
    flags = ((_F_OVERRUN if d.overrun or extra else 0) | (_F_COMPLETE if d.complete else 0)
             | (_F_IN_DRAIN if d.overrun_in_drain else 0)
             | (_F_SINCE if d.since_last_s is not None else 0))
    return _pack(_DRAIN, flags=flags, counts=counts.tobytes(), n=counts.shape[0],
                 reasons=mask, status=d.status & 0xFF, entries=d.fifo_entries & 0xFF,
                 dropped=min(d.dropped_entries, 0xFFFF), post=d.post_entries,
                 index0=d.index0, chip=chip,
                 times=(d.t_mono, d.t_real, d.t_mono_end,
                        d.since_last_s if d.since_last_s is not None else 0.0,
                        d.t_burst, d.t_burst_end, d.t_real_u, d.t_post))


def _decode_drain(head: tuple[int | float, ...], body: bytes) -> Drain:
    (_len, _kind, flags, n, mask, status, entries, dropped, post, index0, _chip,
     t_mono, t_real, t_end, since, t_burst, t_burst_end, t_real_u, t_post) = head
    reasons = [r.value for i, r in enumerate(_REASONS) if int(mask) >> i & 1]
    counts = np.frombuffer(body, dtype="<i4").reshape(int(n), 3).astype(np.int32)
    return Drain(counts=counts, overrun=bool(int(flags) & _F_OVERRUN), t_mono=float(t_mono),
                 t_real=float(t_real), index0=int(index0),
                 gap_reason=",".join(reasons) or None, status=int(status),
                 fifo_entries=int(entries), dropped_entries=int(dropped),
                 t_mono_end=float(t_end), complete=bool(int(flags) & _F_COMPLETE),
                 since_last_s=float(since) if int(flags) & _F_SINCE else None,
                 t_burst=float(t_burst), t_burst_end=float(t_burst_end),
                 t_real_u=float(t_real_u), overrun_in_drain=bool(int(flags) & _F_IN_DRAIN),
                 t_post=float(t_post), post_entries=int(post))


def encode_error(exc: HardwareError, chip: int = 0) -> bytes:
    code = _E_STALLED if isinstance(exc, DeviceStalledError) else _E_HARDWARE
    text = str(exc).encode("utf-8", "replace")[:PIPE_BUF - _HEAD.size - 8]
    return _pack(_ERROR, flags=code, counts=text, chip=chip)


#: A value an opener is called with (JSON's).
Param = str | int | float | None


@dataclass(frozen=True)
class ReaderSpec:
    """What the child is told: how to open the started driver, and how to run it.

    ``opener`` is ``module:function``, called with ``params`` as keyword arguments; it returns
    the driver, started (probed, reset, configured, measuring), or ``chips`` of them (the
    parts of one bus, or of an emulated rig: drained in turn, each its own messages)."""

    opener: str
    params: dict[str, Param | list[dict[str, Param]]] = field(default_factory=dict)
    poll_hz: float = 4.0
    rt_priority: int = 0
    chip_interval_s: float = 1.0
    fill: float = FILL_TARGET_PROCESS
    chips: int = 1

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> ReaderSpec:
        return cls(**json.loads(text))


# -- openers (module:function, run in the child) -------------------------------------------
def open_hardware(kind: str, number: int, device: int = 0, address: int = 0x1D,
                  speed_hz: int = 5_000_000, range_g: int = 2, odr_hz: float = 125.0,
                  temp_intercept_lsb: float = 1885.0) -> Adxl355:
    """The real ADXL355 on its bus, brought up (rig.bring_up's sequence)."""
    from avard.daemon.hw.rig import BusSpec, SensorSpec, bring_up
    from avard.daemon.hw.timebase import SystemClock
    from avard.daemon.hw.transport import open_bus

    bus = open_bus(kind, bus=number, device=device, address=address, speed_hz=speed_hz)
    dev = Adxl355(bus, clock=SystemClock(), temp_intercept_lsb=temp_intercept_lsb)
    bring_up(dev, SensorSpec("adxl355", BusSpec(kind, number, device, address, speed_hz),
                             range_g=range_g, odr_hz=odr_hz))
    return dev


def open_emulated(odr_hz: float, source: str = "counter", range_g: int = 2,
                  **_wiring: str | int | float) -> Adxl355:
    """The register-level emulator on the real clock (CLOCK_MONOTONIC: it does not wait for
    the reader and overruns as the part does), behind the SPI transport, brought up.
    ``source``: ``counter`` (set k carries k: every loss is visible) or ``still``. It takes
    :func:`open_hardware`'s arguments too and answers on any bus (a stand-in for the part)."""
    from avard.daemon.hw.emulator import (
        EmulatedAdxl355,
        FakeSpiDev,
        constant_source,
        counter_source,
    )
    from avard.daemon.hw.timebase import SystemClock
    from avard.daemon.hw.transport import SpiBus

    clock = SystemClock()
    feed = counter_source() if source == "counter" else constant_source()
    dev = Adxl355(SpiBus(FakeSpiDev(EmulatedAdxl355(feed, clock))), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=range_g, odr_hz=odr_hz)
    dev.start()
    return dev


def open_hardware_bus(chips: list[dict[str, Param]]) -> list[Adxl355]:
    """The ADXL355s of one bus (SPI0's chip selects, one I2C bus's addresses), each brought up
    as :func:`open_hardware` does: one reader process drains them in turn."""
    return [open_hardware(str(c["kind"]), int(c["number"] or 0), int(c["device"] or 0),
                          int(c["address"] or 0), int(c["speed_hz"] or 0),
                          int(c["range_g"] or 2), float(c["odr_hz"] or 0.0),
                          float(c["temp_intercept_lsb"] or 0.0))
            for c in chips]


def open_emulated_rig(sensors: list[dict[str, Param]], preset: str,
                      seed: int | None = None) -> list[Adxl355]:
    """An emulated rig (daemon/hw/simulation.emulated_rig: its parts share one bed, so they
    live in one process) on the real clock, each part over its emulated transport, brought
    up. ``sensors``: each one's ``name``, ``kind``, ``number``, ``device``, ``address``,
    ``range_g`` and ``odr_hz``."""
    from avard.daemon.hw.rig import BusSpec, SensorSpec, bring_up
    from avard.daemon.hw.simulation import BedSpec, emulated_rig
    from avard.daemon.hw.timebase import SystemClock

    specs = [SensorSpec(str(s["name"]), BusSpec(str(s["kind"]), int(s["number"] or 0),
                                                device=int(s["device"] or 0),
                                                address=int(s["address"] or 0)),
                        range_g=int(s["range_g"] or 2), odr_hz=float(s["odr_hz"] or 0.0))
             for s in sensors]
    _clock, parts = emulated_rig(specs, preset, bed=BedSpec(seed=seed), seed=seed,
                                 clock=SystemClock())
    for spec, (_name, dev, _emu) in zip(specs, parts, strict=True):
        bring_up(dev, spec)
    return [dev for _n, dev, _e in parts]


def _resolve(opener: str) -> Callable[..., Adxl355 | list[Adxl355]]:
    module, _, name = opener.partition(":")
    fn = getattr(importlib.import_module(module), name)
    if not callable(fn):
        raise HardwareError(f"reader opener {opener!r} is not a function")
    return fn  # type: ignore[no-any-return]


# -- the child -------------------------------------------------------------------------------
class _Writer:
    """Non-blocking writes of whole messages; what the pipe cannot take waits in memory,
    at most ``limit`` drains (then the oldest drains go, and the next one says so)."""

    def __init__(self, fd: int, limit: int) -> None:
        self.fd = fd
        self.limit = limit
        self.pending: deque[bytes] = deque()
        self.dropped = 0          # drains dropped since the last one sent
        self.dropped_chips: set[int] = set()    # whose drains they were

    def send(self, msg: bytes) -> None:
        self.pending.append(msg)
        self.flush()
        while len(self.pending) > self.limit:
            gone = self.pending.popleft()
            self.dropped += 1
            self.dropped_chips.add(int(_HEAD.unpack_from(gone)[10]))

    def took_drops(self, chip: int) -> bool:
        """Whether drains of ``chip`` were dropped since its last drain was sent (then
        forgotten: the next drain of that chip says so)."""
        if chip not in self.dropped_chips:
            return False
        self.dropped_chips.discard(chip)
        self.dropped = 0 if not self.dropped_chips else self.dropped
        return True

    def flush(self) -> None:
        while self.pending:
            try:
                os.write(self.fd, self.pending[0])
            except BlockingIOError:
                return
            self.pending.popleft()


def child_main(spec: ReaderSpec, out_fd: int, cmd_fd: int) -> int:
    """The drain loop. Ends when the parent closes the command pipe (or dies) or sends q."""
    os.set_blocking(out_fd, False)
    os.set_blocking(cmd_fd, False)
    with contextlib.suppress(OSError):
        fcntl.fcntl(out_fd, _F_SETPIPE_SZ, PIPE_BYTES)
    writer = _Writer(out_fd, limit=1 << 16)   # set from the drain period below
    try:
        opened = _resolve(spec.opener)(**spec.params)
    except HardwareError as exc:
        os.set_blocking(out_fd, True)
        os.write(out_fd, encode_error(exc))
        return 2
    if spec.rt_priority:
        raise_thread_priority(spec.rt_priority)
    # Everything built so far lives for the whole run: out of the collector's sight, so a
    # full collection (which walks every tracked object) costs microseconds, not milliseconds.
    gc.collect()
    gc.freeze()

    devs: list[Adxl355] = opened if isinstance(opened, list) else [opened]

    def started(k: int) -> None:
        dev = devs[k]
        writer.send(_pack(_STARTED, chip=k,
                          times=(float(dev.t_started or 0.0), dev.odr_hz,
                                 dev.group_delay_samples, dev.scale_mps2,
                                 0.0, 0.0, 0.0, 0.0)))

    for k in range(len(devs)):
        started(k)
    period = min(drain_period_s(dev.odr_hz, spec.poll_hz, spec.fill) for dev in devs)
    writer.limit = max(1, round(len(devs) * BACKLOG_S / period))
    next_t = time.monotonic()
    next_chip = next_t
    while True:
        try:
            cmd = os.read(cmd_fd, 64)
        except BlockingIOError:
            cmd = None
        if cmd is not None:
            if cmd == b"" or b"q" in cmd:
                break
            # "r" and the chip's number, one byte: recover that part
            for k in {cmd[i + 1] if i + 1 < len(cmd) else 0
                      for i, c in enumerate(cmd) if c == ord("r")}:
                if k >= len(devs):
                    continue
                try:
                    devs[k].recover()
                    started(k)
                except HardwareError as exc:
                    writer.send(encode_error(exc, k))
        for k, dev in enumerate(devs):
            try:
                d = dev.drain()
                extra = (GapReason.READER_BACKLOG,) if writer.took_drops(k) else ()
                writer.send(encode_drain(d, extra, k))
            except HardwareError as exc:
                writer.send(encode_error(exc, k))
        now = time.monotonic()
        if now >= next_chip:
            next_chip = now + spec.chip_interval_s
            for k, dev in enumerate(devs):
                with contextlib.suppress(HardwareError):
                    writer.send(_pack(_TEMP, chip=k,
                                      times=(now, dev.read_temperature_c()) + (0.0,) * 6))
        writer.flush()
        next_t += period
        now = time.monotonic()
        if next_t < now - 10 * period:
            next_t = now
        if next_t > now:
            time.sleep(next_t - now)
    for dev in devs:
        with contextlib.suppress(HardwareError):
            dev.close()
    return 0


# -- the service side ------------------------------------------------------------------------
@dataclass
class _Chip:
    """What the service side knows of one of the child's parts."""

    queue: deque[Drain | HardwareError] = field(default_factory=deque)
    t_started: float | None = None
    odr_hz: float = math.nan
    group_delay: float = 0.0
    scale: float = 0.0
    temperature: float | None = None
    # a new child's first drain follows the old child's last one across a restart of the
    # part (brought up again): it says so
    restarted: bool = False


class ReaderProcess:
    """A :class:`~avard.daemon.hw.source.SampleSource` whose drains come from the child (its
    first part's; :meth:`source` gives each part of a child that drains several).

    :meth:`start` starts the child and waits until every part measures (its ``started``
    message) or the child fails (its error, raised here). The reader thread calls
    :meth:`wait_for_drain`, then :meth:`drain` for each drain the child made."""

    def __init__(self, spec: ReaderSpec, *, start_timeout_s: float = 30.0) -> None:
        self.spec = spec
        self.start_timeout_s = float(start_timeout_s)
        self._proc: subprocess.Popen[bytes] | None = None
        self._out = -1
        self._cmd = -1
        self._buf = bytearray()
        self._eof = False
        self.chips = [_Chip() for _ in range(max(1, spec.chips))]
        self.restarts = 0

    # -- lifecycle
    def start(self) -> ReaderProcess:
        out_r, out_w = os.pipe()
        cmd_r, cmd_w = os.pipe()
        with contextlib.suppress(OSError):
            fcntl.fcntl(out_w, _F_SETPIPE_SZ, PIPE_BYTES)
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "avard.daemon.hw.drain_process", self.spec.to_json(),
                 str(out_w), str(cmd_r)], pass_fds=(out_w, cmd_r), close_fds=True)
        finally:
            os.close(out_w)
            os.close(cmd_r)
        self._out, self._cmd = out_r, cmd_w
        self._buf.clear()
        self._eof = False
        for c in self.chips:
            c.queue.clear()
            c.t_started = None
        deadline = time.monotonic() + self.start_timeout_s
        while any(c.t_started is None for c in self.chips):
            left = deadline - time.monotonic()
            if left <= 0 or self._eof:
                self.close()
                raise HardwareError("the reader process did not start the ADXL355 "
                                    f"({'it exited' if self._eof else 'timed out'}); see "
                                    "its messages above")
            self._read(left)
            for c in self.chips:
                if c.queue and isinstance(c.queue[0], HardwareError):
                    err = c.queue.popleft()
                    self.close()
                    raise err
        return self

    def close(self) -> None:
        proc, self._proc = self._proc, None
        if self._cmd >= 0:
            with contextlib.suppress(OSError):
                os.write(self._cmd, b"q")
            os.close(self._cmd)
            self._cmd = -1
        if proc is not None:
            try:
                proc.wait(5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if self._out >= 0:
            os.close(self._out)
            self._out = -1

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    def source(self, chip: int) -> ChipSource:
        """The SampleSource of the child's part number ``chip``."""
        return ChipSource(self, chip)

    # -- the pipe
    def _read(self, timeout: float) -> None:
        """Wait up to ``timeout`` for bytes; parse every whole message into the queues."""
        if self._eof or self._out < 0:
            return
        ready, _, _ = select.select([self._out], [], [], max(0.0, timeout))
        if not ready:
            return
        chunk = os.read(self._out, 1 << 16)
        if not chunk:
            self._eof = True
            return
        self._feed(chunk)

    def _feed(self, chunk: bytes) -> None:
        """Bytes from the pipe: a read may end inside a message; whole ones are parsed."""
        self._buf += chunk
        while len(self._buf) >= 2:
            size = int.from_bytes(self._buf[:2], "little")
            if len(self._buf) < size:
                break
            msg = bytes(self._buf[:size])
            del self._buf[:size]
            self._message(msg)

    def _message(self, msg: bytes) -> None:
        head = _HEAD.unpack_from(msg)
        kind, body = int(head[1]), msg[_HEAD.size:]
        chip = self.chips[int(head[10])]
        times = head[11:]
        if kind == _DRAIN:
            chip.queue.append(_decode_drain(head, body))
        elif kind == _ERROR:
            text = body.decode("utf-8", "replace")
            chip.queue.append(DeviceStalledError(text) if int(head[2]) == _E_STALLED
                              else HardwareError(text))
        elif kind == _TEMP:
            chip.temperature = float(times[1])
        elif kind == _STARTED:
            chip.t_started = float(times[0])
            chip.odr_hz, chip.group_delay, chip.scale = (float(times[1]), float(times[2]),
                                                         float(times[3]))

    def ready(self, chip: int = 0) -> bool:
        """A drain (or an error) of ``chip`` is queued, or the child has ended (its drain
        then says so)."""
        return bool(self.chips[chip].queue) or self._eof

    def wait_for_drain(self, timeout: float) -> bool:
        """True when a drain (or an error) is ready for :meth:`drain` (of any part), after
        waiting at most ``timeout`` s. A child that died is reported (by :meth:`drain`) once
        per timeout."""
        if not any(c.queue for c in self.chips):
            self._read(timeout)
        if not any(c.queue for c in self.chips) and self._eof:
            time.sleep(timeout)
            return True
        return any(bool(c.queue) for c in self.chips)

    # -- SampleSource (the first part)
    @property
    def t_started(self) -> float | None:
        return self.chips[0].t_started

    @property
    def odr_hz(self) -> float:
        return self.chips[0].odr_hz

    @property
    def group_delay_samples(self) -> float:
        return self.chips[0].group_delay

    @property
    def scale_mps2(self) -> float:
        return self.chips[0].scale

    def drain(self, max_sets: int | None = None, *, chip: int = 0) -> Drain:
        """The child's next drain of ``chip``, as it made it (``max_sets`` is the child's to
        apply)."""
        c = self.chips[chip]
        if not c.queue:
            self._read(0.0)
        if not c.queue:
            if self._eof:
                code = None if self._proc is None else self._proc.poll()
                raise HardwareError(f"the reader process ended (exit status {code})")
            raise HardwareError("no drain from the reader process")
        item = c.queue.popleft()
        if isinstance(item, HardwareError):
            raise item
        if c.restarted:
            c.restarted = False
            reasons = ",".join(filter(None, (item.gap_reason, GapReason.RESTART.value)))
            item = replace(item, overrun=True, gap_reason=reasons)
        return item

    def read_temperature_c(self, chip: int = 0) -> float:
        """The chip temperature the child read last (it reads it every chip_interval_s)."""
        t = self.chips[chip].temperature
        if t is None:
            raise HardwareError("no chip temperature from the reader process yet")
        return t

    def recover(self, chip: int = 0) -> ReaderProcess:
        """Ask the child to recover the part; a child that ended is started again (every
        part of it restarts)."""
        if self._eof or self._proc is None or self._proc.poll() is not None:
            self.close()
            self.restarts += 1
            self.start()
            for c in self.chips:
                c.restarted = True
            return self
        try:
            os.write(self._cmd, b"r" + bytes((chip,)))
        except OSError as exc:
            if exc.errno != errno.EPIPE:
                raise HardwareError(f"cannot reach the reader process: {exc}") from exc
        return self


class ChipSource:
    """One part of a reader process that drains several (a bus's, an emulated rig's): the
    SampleSource its sensor's reader thread drains, sharing the process's pipe."""

    def __init__(self, process: ReaderProcess, chip: int) -> None:
        self.process = process
        self.chip = int(chip)

    @property
    def t_started(self) -> float | None:
        return self.process.chips[self.chip].t_started

    @property
    def odr_hz(self) -> float:
        return self.process.chips[self.chip].odr_hz

    @property
    def group_delay_samples(self) -> float:
        return self.process.chips[self.chip].group_delay

    @property
    def scale_mps2(self) -> float:
        return self.process.chips[self.chip].scale

    def ready(self) -> bool:
        return self.process.ready(self.chip)

    def wait_for_drain(self, timeout: float) -> bool:
        return self.process.wait_for_drain(timeout)

    def drain(self, max_sets: int | None = None) -> Drain:
        return self.process.drain(max_sets, chip=self.chip)

    def read_temperature_c(self) -> float:
        return self.process.read_temperature_c(self.chip)

    def recover(self) -> ChipSource:
        self.process.recover(self.chip)
        return self


#: mypy holds ReaderProcess to the SampleSource contract the reader thread is written against
_check: type[SampleSource] = ReaderProcess
_check_chip: type[SampleSource] = ChipSource


def main(argv: list[str]) -> int:
    # Ctrl-C and a terminal's hang-up reach the whole process group: the service decides when
    # to stop, and the child ends when the service closes the command pipe (or dies).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="avard reader: %(levelname)s %(message)s")
    spec = ReaderSpec.from_json(argv[0])
    return child_main(spec, int(argv[1]), int(argv[2]))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
