"""DS18B20 temperatures through w1thermsensor, one thread per sensor, never a fake number.

A 12-bit conversion blocks the reader for up to 750 ms, so each sensor is read in its own
thread at a configured interval; readings go, stamped with CLOCK_MONOTONIC, to a callback or a
queue that the service drains. What can go wrong on a 1-Wire bus is reported, not hidden:

======================  ============================================  ==================
what                    how it shows                                  reading
======================  ============================================  ==================
sensor gone / back      w1_slave missing                              NaN, "missing"
disturbed read          CRC line says NO                              NaN, "crc"
CRC wrong but "YES"     our own CRC-8 check of the 9 bytes            NaN, "crc"
nothing read            all-zero scratchpad bytes                     NaN, "not_ready"
power-on value          exactly 85 °C (w1thermsensor ResetValueError)  NaN, "reset_value"
======================  ============================================  ==================

Each change of a sensor's state is logged once (not every read). w1thermsensor finds the
sensors and converts the scratchpad bytes; ``w1_slave`` is read once per reading (each read
starts a 750 ms conversion), with w1thermsensor's own validity checks plus a CRC-8 check.

w1thermsensor runs ``modprobe`` when imported unless ``W1THERMSENSOR_NO_KERNEL_MODULE=1``;
:func:`import_w1thermsensor` sets that when asked (tests, simulation, a system that loads the
modules through the device tree overlay).
"""

from __future__ import annotations

import errno
import logging
import math
import os
import queue
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from avard.core.errors import ConfigError
from avard.daemon.hw.timebase import SystemClock
from avard.daemon.hw.w1_sysfs import DS18B20_FAMILY, crc8_maxim

log = logging.getLogger(__name__)

OK = "ok"
MISSING = "missing"
CRC = "crc"
NOT_READY = "not_ready"
RESET_VALUE = "reset_value"
ERROR = "error"

#: Errors of this host, not of the bus: the fd tables full, no memory.
_HOST_ERRNOS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOMEM})


def import_w1thermsensor(no_kernel_module: bool = True) -> ModuleType:
    """Import w1thermsensor without letting it run modprobe (unless told otherwise)."""
    if no_kernel_module:
        os.environ.setdefault("W1THERMSENSOR_NO_KERNEL_MODULE", "1")
    import w1thermsensor

    return w1thermsensor


@dataclass(frozen=True)
class TemperatureReading:
    """One DS18B20 reading. ``value_c`` is °C, NaN unless ``status == "ok"``; ``t_mono`` is
    CLOCK_MONOTONIC (s) when the read returned (the conversion ended within ``read_s`` before
    it); ``t_real`` CLOCK_REALTIME (s) at the same moment."""

    name: str
    sensor_id: str
    value_c: float
    status: str
    t_mono: float
    t_real: float
    read_s: float
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.status == OK


def normalise_id(sensor_id: str) -> str:
    """``28-0316a2797cff`` or ``0316a2797cff`` → ``0316a2797cff`` (w1thermsensor's id)."""
    s = sensor_id.strip().lower()
    if "-" in s:
        family, s = s.split("-", 1)
        if family != DS18B20_FAMILY:
            raise ConfigError(f"sensor id {sensor_id!r} is not a DS18B20 (family 28-)")
    if len(s) != 12 or any(c not in "0123456789abcdef" for c in s):
        raise ConfigError(f"sensor id {sensor_id!r} is not a 1-Wire id like 28-0316a2797cff")
    return s


def sensor_class(base_directory: str | Path | None = None) -> Any:
    """``W1ThermSensor`` whose ``BASE_DIRECTORY`` points at ``base_directory`` (a subclass, so
    no global state changes and two trees can coexist in one process)."""
    w1 = import_w1thermsensor()
    if base_directory is None:
        return w1.W1ThermSensor
    return type("W1ThermSensorAt", (w1.W1ThermSensor,),
                {"BASE_DIRECTORY": Path(base_directory)})


def discover(base_directory: str | Path | None = None) -> list[str]:
    """Ids of the DS18B20 sensors present (sorted); [] with a warning when the w1 bus is not
    there at all (``dtoverlay=w1-gpio`` missing)."""
    cls = sensor_class(base_directory)
    w1 = import_w1thermsensor()
    try:
        found = cls.get_available_sensors([w1.Sensor.DS18B20])
    except FileNotFoundError:
        log.warning("no 1-Wire bus at %s: enable it with dtoverlay=w1-gpio in config.txt",
                    cls.BASE_DIRECTORY)
        return []
    return sorted(s.id for s in found)


class SensorReader:
    """Reads one sensor (synchronously); keeps its state to log changes once."""

    def __init__(self, name: str, sensor_id: str, *, base_directory: str | Path | None = None,
                 clock: Any = None) -> None:
        self.name = name
        self.sensor_id = normalise_id(sensor_id)
        self.clock = clock if clock is not None else SystemClock()
        self._cls = sensor_class(base_directory)
        self._w1 = import_w1thermsensor()
        self._sensor: Any = None
        self.status: str | None = None
        self.counts: dict[str, int] = {}

    def _open(self) -> Any:
        if self._sensor is None:
            self._sensor = self._cls(self._w1.Sensor.DS18B20, self.sensor_id)
        return self._sensor

    def _measure(self) -> tuple[float, str, str]:
        w1 = self._w1
        try:
            sensor = self._open()
        except w1.NoSensorFoundError:
            return math.nan, MISSING, "w1_slave not present"
        # One read of w1_slave = one 750 ms conversion on the bus. w1thermsensor's
        # get_raw_sensor_strings() raises the same SensorNotReadyError for "CRC NO" and for
        # "no answer", and telling them apart would need a second read (a second conversion),
        # so the file is read here once, with the same checks, and converted by w1thermsensor.
        try:
            lines = sensor.sensorpath.read_text().splitlines()
        except OSError as exc:
            self._sensor = None  # build it again when the sensor is back
            if exc.errno in _HOST_ERRNOS:
                # this process cannot open a file: the sensor is not the one missing
                return math.nan, ERROR, f"cannot read w1_slave: {exc.strerror}"
            return math.nan, MISSING, "w1_slave not present"
        if len(lines) < 2:
            return math.nan, NOT_READY, f"short w1_slave ({len(lines)} lines)"
        if not lines[0].strip().endswith("YES"):
            return math.nan, CRC, "kernel reports CRC NO"
        if "00 00 00 00 00 00 00 00 00" in lines[0]:
            return math.nan, NOT_READY, "all-zero scratchpad: the sensor did not answer"
        try:
            pad = bytes.fromhex("".join(lines[0].split(":")[0].split()))
        except ValueError:
            return math.nan, ERROR, f"unparsable w1_slave line {lines[0]!r}"
        if len(pad) != 9 or crc8_maxim(pad[:8]) != pad[8]:
            return math.nan, CRC, f"scratchpad {pad.hex()} fails CRC-8"
        try:
            value = w1.core.evaluate_temperature(
                lines[1], sensor.RAW_VALUE_TO_DEGREE_CELSIUS_FACTOR, w1.Unit.DEGREES_C,
                sensor.type, sensor.id, sensor.offset, sensor.SENSOR_RESET_VALUE)
        except w1.ResetValueError:
            return math.nan, RESET_VALUE, "85 °C power-on value: conversion did not run"
        except (ValueError, IndexError) as exc:
            return math.nan, ERROR, f"unparsable w1_slave: {exc}"
        return float(value), OK, ""

    def read(self) -> TemperatureReading:
        t0 = self.clock.monotonic()
        try:
            value, status, detail = self._measure()
        except Exception as exc:  # a reader thread must never die of one bad read
            log.exception("DS18B20 %s (%s): unexpected error", self.name, self.sensor_id)
            value, status, detail = math.nan, ERROR, repr(exc)
        t1 = self.clock.monotonic()
        self.counts[status] = self.counts.get(status, 0) + 1
        if status != self.status:
            if status == OK:
                if self.status is not None:
                    log.info("DS18B20 %s (28-%s) reads again: %.4f °C", self.name,
                             self.sensor_id, value)
            else:
                log.warning("DS18B20 %s (28-%s): %s (%s); recorded as missing (NaN)",
                            self.name, self.sensor_id, status, detail)
            self.status = status
        return TemperatureReading(self.name, self.sensor_id, value, status, t1,
                                  self.clock.realtime(), t1 - t0, detail)


Sink = Callable[[TemperatureReading], None]


class Ds18b20Bank:
    """All DS18B20 sensors, one reader thread each.

    ``sensors`` maps names to ids (e.g. ``{"plate": "28-0316a2797cff", "ambient": "…"}``);
    ``None`` discovers every DS18B20 present and names it by its id. Readings go to ``sink``
    (a callable) or, if none is given, to :attr:`queue` (``queue.Queue``) that the service
    drains. ``interval_s`` is the time from one read's start to the next (a read that takes
    longer simply starts the next one at once).
    """

    def __init__(self, sensors: Mapping[str, str] | Sequence[str] | None = None, *,
                 interval_s: float = 1.0, sink: Sink | None = None,
                 base_directory: str | Path | None = None, clock: Any = None) -> None:
        if interval_s <= 0:
            raise ConfigError(f"DS18B20 interval {interval_s} s must be positive")
        if sensors is None:
            ids = discover(base_directory)
            if not ids:
                log.warning("no DS18B20 sensor found; temperatures will not be recorded")
            named = {i: i for i in ids}
        elif isinstance(sensors, Mapping):
            named = dict(sensors)
        else:
            named = {normalise_id(i): i for i in sensors}
        self.interval_s = float(interval_s)
        self.queue: queue.Queue[TemperatureReading] = queue.Queue()
        self.sink: Sink = sink if sink is not None else self.queue.put
        self.readers = [SensorReader(n, i, base_directory=base_directory, clock=clock)
                        for n, i in named.items()]
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    @property
    def names(self) -> list[str]:
        return [r.name for r in self.readers]

    def read_all(self) -> list[TemperatureReading]:
        """One synchronous read of every sensor (no threads)."""
        return [r.read() for r in self.readers]

    def _loop(self, reader: SensorReader) -> None:
        while not self._stop.is_set():
            reading = reader.read()
            try:
                self.sink(reading)
            except Exception:
                log.exception("DS18B20 sink failed for %s", reader.name)
            self._stop.wait(max(0.0, self.interval_s - reading.read_s))

    def start(self) -> None:
        if self._threads:
            return
        self._stop.clear()
        for r in self.readers:
            t = threading.Thread(target=self._loop, args=(r,), name=f"ds18b20-{r.name}",
                                 daemon=True)
            t.start()
            self._threads.append(t)

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the threads; a read in progress finishes first (≤ 750 ms on hardware)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout_s)
            if t.is_alive():
                log.warning("DS18B20 thread %s did not stop within %.1f s", t.name, timeout_s)
        self._threads = []

    def drain(self) -> list[TemperatureReading]:
        """Everything in :attr:`queue` now (for services that did not give a sink)."""
        out = []
        while True:
            try:
                out.append(self.queue.get_nowait())
            except queue.Empty:
                return out

    def __enter__(self) -> Ds18b20Bank:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
