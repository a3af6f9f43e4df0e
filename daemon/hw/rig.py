"""The rig as data, and the one place that builds its hardware side: the real ADXL355 (and
DS18B20s) or the register-level emulator fed by the simulator.

A :class:`RigSpec` (frozen: sensors, their buses, the clock) is what the configuration and the
command line describe (:func:`describe_rig`); :func:`build_rig` turns it into a :class:`Rig`:
the opened, started drivers, the clock, the temperature sources and the INT1 pin. The service
is composed over a Rig by daemon/compose.py (the composition root); nothing here imports the
service. The backend comes from ``--simulate PRESET`` when given, else from
``$AVARD_BACKEND`` (``hardware`` or ``simulate:PRESET``), else it is the hardware.
:func:`open_sensor` opens the ADXL355 driver over the described bus (or over the emulator) and
:func:`bring_up` is the one probe/reset/[self-test]/configure/start sequence. ``avard run`` and
``avard demo`` compose a Rig; ``avard probe`` uses :func:`open_sensor` and :func:`bring_up`
(with the self-test) and reads the driver itself.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from avard.core.errors import ConfigError, HardwareError
from avard.daemon.config_types import Config, SensorConfig, TemperatureConfig
from avard.daemon.hw.pacing import reader_in_process, watermark_settings

if TYPE_CHECKING:
    from avard.daemon.hw.adxl355 import Adxl355, DeviceInfo, SelfTestResult
    from avard.daemon.hw.drain_process import ReaderProcess
    from avard.daemon.hw.ds18b20 import Ds18b20Bank, TemperatureReading
    from avard.daemon.hw.interrupt import InterruptPin
    from avard.daemon.hw.source import SampleSource
    from avard.daemon.hw.timebase import Clock

log = logging.getLogger(__name__)

BACKEND_ENV = "AVARD_BACKEND"
#: What the reader process opens on the hardware (drain_process.py's ``module:function``).
HARDWARE_OPENER = "avard.daemon.hw.drain_process:open_hardware"
#: ... the ADXL355s of one bus, and an emulated rig on the real clock
HARDWARE_BUS_OPENER = "avard.daemon.hw.drain_process:open_hardware_bus"
EMULATED_RIG_OPENER = "avard.daemon.hw.drain_process:open_emulated_rig"

# -- the rig as data ----------------------------------------------------------------------------

@dataclass(frozen=True)
class BusSpec:
    """How one ADXL355 is reached: ``spi`` (/dev/spidevNUMBER.DEVICE) or ``i2c``
    (/dev/i2c-NUMBER at ADDRESS)."""

    kind: str
    number: int
    device: int = 0
    address: int = 0x1D
    speed_hz: int = 5_000_000


@dataclass(frozen=True)
class SensorSpec:
    """One ADXL355 of the rig: its name, its bus and how it is run."""

    name: str
    bus: BusSpec
    range_g: int = 2
    odr_hz: float = 125.0
    int1_gpio: str = ""
    temp_intercept_lsb: float = 1885.0
    poll_hz: float = 4.0

    @classmethod
    def from_config(cls, s: SensorConfig) -> SensorSpec:
        bus = BusSpec(s.bus, s.bus_number, device=s.spi_device, address=s.i2c_address,
                      speed_hz=s.spi_speed_hz)
        return cls(s.name, bus, range_g=s.range_g, odr_hz=s.odr_hz, int1_gpio=s.int1_gpio,
                   temp_intercept_lsb=s.temp_intercept_lsb, poll_hz=s.poll_hz)


@dataclass(frozen=True)
class ClockSpec:
    """The rig's clock: the host's (``system``) or the emulator's stepped ``virtual`` clock,
    which a simulated rig (``simulate`` names the simulator preset) runs on. A simulated rig
    on the ``system`` clock makes its sets on CLOCK_MONOTONIC as the parts do, whether read
    or not: a reader that comes late overruns their FIFOs (the real-clock check)."""

    kind: str = "system"
    simulate: str | None = None
    seed: int | None = None
    odr_error_ppm: float | None = None
    #: the virtual clock runs at most this many times real time (None: as fast as it can)
    speed: float | None = None

    @property
    def stepped(self) -> bool:
        """Time is the virtual clock the reader steps: waiting for a slow consumer costs
        nothing, and no FIFO can overrun."""
        return self.kind == "virtual"


@dataclass(frozen=True)
class RigSpec:
    """What is bolted together: the sensors (each on its bus), the clock, the DS18B20s."""

    sensors: tuple[SensorSpec, ...]
    clock: ClockSpec = field(default_factory=ClockSpec)
    temperature: TemperatureConfig = field(default_factory=TemperatureConfig)

    def __post_init__(self) -> None:
        if not self.sensors:
            raise ConfigError("a rig needs at least one sensor")
        names = [s.name for s in self.sensors]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(f"sensor names must differ: {', '.join(dup)} is used twice")
        seen: dict[tuple[str, int, int], str] = {}
        for s in self.sensors:
            b = s.bus
            where = (b.kind, b.number, b.device if b.kind == "spi" else b.address)
            if where in seen:
                wire = (f"/dev/spidev{b.number}.{b.device}" if b.kind == "spi"
                        else f"/dev/i2c-{b.number} address 0x{b.address:02X}")
                raise ConfigError(f"sensors {seen[where]} and {s.name} are both on {wire}; "
                                  "give each its own chip select or I2C address")
            seen[where] = s.name

    @property
    def simulate(self) -> str | None:
        return self.clock.simulate


def describe_rig(config: Config, *, simulate: str | None = None, seed: int | None = None,
                 odr_error_ppm: float | None = None, speed: float | None = 1.0,
                 real_clock: bool = False) -> RigSpec:
    """The rig ``config`` describes, on :func:`choose_backend`'s backend; a simulated rig's
    virtual clock runs at most ``speed`` times real time (None: as fast as it can), or with
    ``real_clock`` its emulated parts run on the host's clock (``speed`` is then 1)."""
    preset = choose_backend(simulate)
    if preset is not None:
        from avard.core.sim.presets import PRESETS

        if preset not in PRESETS:
            raise ConfigError(f"--simulate {preset!r}: unknown preset; choose one of "
                              f"{', '.join(sorted(PRESETS))}")
        clock = (ClockSpec("system", preset, seed, odr_error_ppm) if real_clock
                 else ClockSpec("virtual", preset, seed, odr_error_ppm, speed))
    else:
        clock = ClockSpec()
    return RigSpec(tuple(SensorSpec.from_config(s) for s in config.rig_sensors), clock,
                   config.temperature)


def choose_backend(simulate: str | None) -> str | None:
    """The simulator preset to use, or None for the hardware."""
    if simulate:
        return simulate
    value = os.environ.get(BACKEND_ENV, "").strip()
    if not value or value == "hardware":
        return None
    kind, _, preset = value.partition(":")
    if kind != "simulate" or not preset:
        raise ConfigError(f"{BACKEND_ENV}={value!r}: expected 'hardware' or "
                          "'simulate:PRESET' (e.g. simulate:quiet-lab)")
    return preset


# -- the rig built ------------------------------------------------------------------------------

class TemperatureFeed(Protocol):
    """Temperatures the rig produces itself (the simulated DS18B20s): they go to ``deliver``,
    which the composition root points at the service's reading handler. Files the feed needs
    (the simulated 1-Wire tree) go in ``workdir``, which the composition root points at the
    service's recording directory when it records (else None: a private temporary folder);
    ``close`` removes them."""

    deliver: Callable[[TemperatureReading], None] | None
    workdir: Path | None

    def close(self) -> None: ...


@dataclass(frozen=True)
class Rig:
    """The rig built: what a :class:`~avard.daemon.service.supervisor.Service` is handed."""

    spec: RigSpec
    sensor: SampleSource
    clock: Clock
    info: Mapping[str, object]
    temperature_bank: Ds18b20Bank | None = None
    interrupt: InterruptPin | None = None
    #: names of the temperature channels the rig's own feed delivers (simulated DS18B20s)
    extra_temperature_names: tuple[str, ...] = ()
    #: called by the reader after each poll with CLOCK_MONOTONIC (the simulated conversions)
    on_tick: Callable[[float], None] | None = None
    temperature_feed: TemperatureFeed | None = None
    parts: Mapping[str, object] = field(default_factory=dict)   # emulator, simulator (tests)
    #: what the rig started and the service's stop ends (the reader process)
    closers: tuple[Callable[[], None], ...] = ()
    #: the part's start of measurement, left to its reader thread just before the first
    #: drain (None: measuring already): on the real clock the FIFO fills from the start on,
    #: and the service's own start-up (lanes, sockets, restore) can outlast it (0.256 s at
    #: 125 Hz), which cost the first drain an overrun
    start_measuring: Callable[[], None] | None = None

    def close(self) -> None:
        """End what the rig started (the service calls it when it stops)."""
        for close in self.closers:
            close()

    @property
    def simulate(self) -> str | None:
        return self.spec.simulate


@dataclass(frozen=True)
class OpenedSensor:
    """The chosen backend's ADXL355 driver, opened but not yet brought up."""

    driver: Adxl355
    clock: Any                      # timebase.SystemClock or emulator.VirtualClock
    simulate: str | None = None     # the simulator preset, None for hardware or a still sensor
    emulated: bool = False          # no hardware at all (no 1-Wire bus either)
    parts: dict[str, Any] = field(default_factory=dict)   # emulator, simulator


@dataclass(frozen=True)
class BringUp:
    """What :func:`bring_up` found: the IDs, and the self-test result when one was run."""

    info: DeviceInfo
    self_test: SelfTestResult | None = None


#: The self-test runs at ±8 g, where gravity plus the deflection cannot clip.
SELF_TEST_RANGE_G = 8


def open_sensor(config: Config, *, simulate: str | None = None, seed: int | None = None,
                odr_error_ppm: float | None = None,
                still_odr_error_ppm: float | None = None) -> OpenedSensor:
    """The backend's driver, before probe/reset/configure/start. ``still_odr_error_ppm``
    asks for the emulator holding 1 g on Z exactly (``avard probe --emulate``); otherwise
    the backend is :func:`choose_backend`'s: the simulated rig of a preset, or the hardware."""
    spec = describe_rig(config, simulate=simulate, seed=seed, odr_error_ppm=odr_error_ppm)
    sensor = spec.sensors[0]
    if still_odr_error_ppm is not None:
        return _still(sensor, still_odr_error_ppm)
    if spec.simulate is not None:
        return _open_simulated(sensor, spec)
    return _open_hardware(sensor)


def bring_up(dev: Adxl355, sensor: SensorSpec | SensorConfig, *, int1: bool = False,
             self_test: bool = False, start: bool = True,
             found: Callable[[DeviceInfo], None] | None = None) -> BringUp:
    """The one start-up sequence of the ADXL355: probe the IDs, reset, optionally run the
    self-test (at ±8 g), configure the range and rate (and the FIFO watermark on INT1 when a
    reader waits on it), start measuring (unless ``start`` is False: then the reader starts
    it, :attr:`Rig.start_measuring`). ``found`` is told the IDs as soon as they are read
    (``avard probe`` prints them even when a later step fails)."""
    info = dev.probe()
    if found is not None:
        found(info)
    dev.reset()
    st = None
    if self_test:
        dev.configure(range_g=SELF_TEST_RANGE_G, odr_hz=sensor.odr_hz)
        st = dev.self_test()
    dev.configure(range_g=sensor.range_g, odr_hz=sensor.odr_hz, **watermark_settings(int1))
    if start:
        dev.start()
    return BringUp(info, st)


def _still(sensor: SensorSpec, odr_error_ppm: float) -> OpenedSensor:
    from avard.daemon.hw.adxl355 import Adxl355
    from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, constant_source
    from avard.daemon.hw.registers import sensitivity_lsb_per_g
    from avard.daemon.hw.transport import SpiBus

    clock = VirtualClock()
    one_g = round(sensitivity_lsb_per_g(sensor.range_g))
    emu = EmulatedAdxl355(constant_source((0, 0, one_g)), clock, odr_error_ppm=odr_error_ppm,
                          temperature=24.0)
    return OpenedSensor(Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock), clock, emulated=True,
                        parts={"emulator": emu})


def _open_simulated(sensor: SensorSpec, spec: RigSpec) -> OpenedSensor:
    from avard.daemon.hw.simulation import open_simulated

    c = spec.clock
    assert c.simulate is not None
    dev, clock, sims, emu = open_simulated(sensor, c.simulate, seed=c.seed,
                                           odr_error_ppm=c.odr_error_ppm,
                                           interval_s=spec.temperature.interval_s)
    return OpenedSensor(dev, clock, simulate=c.simulate, emulated=True,
                        parts={"sims": sims, "emulator": emu})


def _open_hardware(sensor: SensorSpec) -> OpenedSensor:
    from avard.daemon.hw.adxl355 import Adxl355
    from avard.daemon.hw.timebase import SystemClock
    from avard.daemon.hw.transport import open_bus

    b = sensor.bus
    bus = open_bus(b.kind, bus=b.number, device=b.device, address=b.address,
                   speed_hz=b.speed_hz)
    clock = SystemClock()
    return OpenedSensor(Adxl355(bus, clock=clock, temp_intercept_lsb=sensor.temp_intercept_lsb),
                        clock)


def build_rig(spec: RigSpec) -> Rig:
    """The described rig's configured, started sensor and what goes with it."""
    if len(spec.sensors) != 1:
        raise ConfigError(f"this rig has {len(spec.sensors)} sensors; the service runs one "
                          "sensor per rig so far")
    if spec.simulate is not None:
        return _simulated(spec)
    return _hardware(spec)


def _simulated(spec: RigSpec) -> Rig:
    from avard.daemon.hw.interrupt import EmulatedInterruptPin

    sensor = spec.sensors[0]
    opened = _open_simulated(sensor, spec)
    use_int1 = bool(sensor.int1_gpio)
    bring_up(opened.driver, sensor, int1=use_int1)
    sims, emu = opened.parts["sims"], opened.parts["emulator"]
    pin = EmulatedInterruptPin(emu, opened.clock) if use_int1 else None
    return Rig(spec, opened.driver, opened.clock,
               {"device": "ADXL355 (emulated)", "preset": spec.simulate,
                "name": sensor.name},
               interrupt=pin, extra_temperature_names=tuple(sims.names),
               on_tick=sims.on_tick, temperature_feed=sims, parts=dict(opened.parts))


def _hardware(spec: RigSpec) -> Rig:
    s = spec.sensors[0]
    if reader_in_process(bool(s.int1_gpio)):
        return _hardware_in_reader_process(spec)
    interrupt = None
    if s.int1_gpio:
        from avard.daemon.hw.interrupt import GpiodPin

        interrupt = GpiodPin(s.int1_gpio)
    opened = _open_hardware(s)
    info = bring_up(opened.driver, s, int1=interrupt is not None, start=False).info
    return Rig(spec, opened.driver, opened.clock,
               {"device": info.name, "partid": info.partid, "revid": info.revid,
                "bus": s.bus.kind, "name": s.name},
               temperature_bank=_ds18b20_bank(spec.temperature), interrupt=interrupt,
               start_measuring=opened.driver.start)


def _hardware_in_reader_process(spec: RigSpec) -> Rig:
    """The ADXL355 drained by a child process of its own (drain_process.py), SCHED_FIFO where
    the system allows it: a reader thread sharing the GIL with the service's other threads
    lets the FIFO overrun beside a CPU-bound process (pacing.reader_in_process)."""
    from avard.daemon.hw.drain_process import READER_RT_PRIORITY, ReaderProcess, ReaderSpec
    from avard.daemon.hw.timebase import SystemClock

    s = spec.sensors[0]
    b = s.bus
    reader = ReaderProcess(ReaderSpec(
        HARDWARE_OPENER, _chip_params(s), poll_hz=s.poll_hz, rt_priority=READER_RT_PRIORITY,
        chip_interval_s=spec.temperature.chip_interval_s)).start()
    return Rig(spec, reader, SystemClock(),
               {"device": "ADXL355", "bus": b.kind, "name": s.name,
                "reader": f"process {reader.pid}"},
               temperature_bank=_ds18b20_bank(spec.temperature), closers=(reader.close,))


def _chip_params(s: SensorSpec) -> dict[str, str | int | float | None]:
    """What a reader process's opener is told of one ADXL355 (drain_process.py)."""
    b = s.bus
    return {"kind": b.kind, "number": b.number, "device": b.device, "address": b.address,
            "speed_hz": b.speed_hz, "range_g": s.range_g, "odr_hz": s.odr_hz,
            "temp_intercept_lsb": s.temp_intercept_lsb}


@dataclass(frozen=True)
class RigLanes:
    """A rig of several sensors built: one single-sensor :class:`Rig` per sensor (a *lane*,
    sharing the clock), which lanes one reader thread drains (by index into ``lanes``: one
    reader per bus, taking the drains of the bus's reader process where it has one; a
    simulated rig has one, since its reader steps the virtual clock, and so has an emulated
    rig on the real clock, whose one reader process makes and drains every part), and the
    DS18B20 bank every lane hears."""

    spec: RigSpec
    lanes: tuple[Rig, ...]
    readers: tuple[tuple[int, ...], ...]
    clock: Clock
    temperature_bank: Ds18b20Bank | None = None
    parts: Mapping[str, object] = field(default_factory=dict)   # emulators (tests)


def wiring(bus: BusSpec) -> str:
    """Where a sensor is wired, as the Pi names it."""
    return (f"/dev/spidev{bus.number}.{bus.device}" if bus.kind == "spi"
            else f"/dev/i2c-{bus.number} address 0x{bus.address:02X}")


def build_lanes(spec: RigSpec, *, reader_process: bool = True) -> RigLanes:
    """The described rig of several sensors, each configured and started (a sensor that does
    not answer at start refuses the whole rig: the config says it is there).

    On the real clock each bus is drained by a reader process (drain_process.py, SCHED_FIFO
    where allowed; an emulated rig's parts share one bed, so one process drains them all),
    unless ``reader_process`` is False or a sensor of the bus waits on INT1: then by a reader
    thread of the service (acquisition.BusReader). A reader thread shares the interpreter
    lock with the service's other threads: when the thread that holds it is pre-empted by a
    busy neighbour, every reader thread waits with it (three sensors overran together that
    way at 125 Hz, SCHED_FIFO or not; docs/service.md)."""
    lane_spec = [RigSpec((s,), spec.clock, spec.temperature) for s in spec.sensors]
    from avard.daemon.hw.timebase import SystemClock

    if spec.simulate is not None and not spec.clock.stepped and reader_process:
        return _emulated_in_reader_process(spec, lane_spec)
    if spec.simulate is not None:
        from avard.daemon.hw.simulation import BedSpec, emulated_rig

        rates = {s.odr_hz for s in spec.sensors}
        if len(rates) > 1:
            raise ConfigError("a simulated rig runs every sensor at one odr_hz; found "
                              f"{', '.join(f'{r:g}' for r in sorted(rates))} Hz")
        stepped = spec.clock.stepped
        clock, emulated = emulated_rig(spec.sensors, spec.simulate,
                                       bed=BedSpec(seed=spec.clock.seed), seed=spec.clock.seed,
                                       clock=None if stepped else SystemClock())
        lanes = []
        for ls, s, (_name, dev, _emu) in zip(lane_spec, spec.sensors, emulated, strict=True):
            bring_up(dev, s, start=stepped)
            lanes.append(Rig(ls, dev, clock, {"device": "ADXL355 (emulated)",
                                              "preset": spec.simulate, "name": s.name,
                                              "bus": s.bus.kind, "wiring": wiring(s.bus)},
                             start_measuring=None if stepped else dev.start))
        # a stepped clock has one reader (it steps the clock); on the real clock, one per
        # bus as on the Pi
        readers = ((tuple(range(len(lanes))),) if stepped
                   else bus_readers(spec.sensors))
        return RigLanes(spec, tuple(lanes), readers, clock,
                        parts={"emulators": [e for _n, _d, e in emulated]})
    system = SystemClock()
    bank = _ds18b20_bank(spec.temperature)
    names = tuple(bank.names) if bank is not None else ()
    by_index: dict[int, Rig] = {}
    started: list[Callable[[], None]] = []
    try:
        for group in bus_readers(spec.sensors):
            chips = [spec.sensors[k] for k in group]
            if reader_process and not any(s.int1_gpio for s in chips):
                proc = _bus_process(chips, spec)
                started.append(proc.close)
                for j, k in enumerate(group):
                    s = spec.sensors[k]
                    info = {"device": "ADXL355", "bus": s.bus.kind, "wiring": wiring(s.bus),
                            "name": s.name, "reader": f"process {proc.pid}"}
                    by_index[k] = Rig(lane_spec[k], proc.source(j), system, info,
                                      extra_temperature_names=names, closers=(proc.close,))
                continue
            for k in group:
                by_index[k] = _thread_lane(lane_spec[k], spec.sensors[k], system, names)
    except BaseException:
        for close in started:
            close()
        raise
    return RigLanes(spec, tuple(by_index[k] for k in range(len(spec.sensors))),
                    bus_readers(spec.sensors), system, temperature_bank=bank)


def _thread_lane(ls: RigSpec, s: SensorSpec, system: Clock, names: tuple[str, ...]) -> Rig:
    """A sensor drained by a reader thread of the service: configured, its start of
    measurement left to that thread."""
    interrupt = None
    if s.int1_gpio:
        from avard.daemon.hw.interrupt import GpiodPin

        interrupt = GpiodPin(s.int1_gpio)
    opened = _open_hardware(s)
    info = bring_up(opened.driver, s, int1=interrupt is not None, start=False).info
    return Rig(ls, opened.driver, system,
               {"device": info.name, "partid": info.partid, "revid": info.revid,
                "bus": s.bus.kind, "wiring": wiring(s.bus), "name": s.name},
               interrupt=interrupt, extra_temperature_names=names,
               start_measuring=opened.driver.start)


def _bus_process(chips: list[SensorSpec], spec: RigSpec) -> ReaderProcess:
    """The reader process of one bus's ADXL355s, started (they measure)."""
    from avard.daemon.hw.drain_process import READER_RT_PRIORITY, ReaderProcess, ReaderSpec

    return ReaderProcess(ReaderSpec(
        HARDWARE_BUS_OPENER, {"chips": [_chip_params(s) for s in chips]},
        poll_hz=max(s.poll_hz for s in chips), rt_priority=READER_RT_PRIORITY,
        chip_interval_s=spec.temperature.chip_interval_s, chips=len(chips))).start()


def _emulated_in_reader_process(spec: RigSpec, lane_spec: list[RigSpec]) -> RigLanes:
    """An emulated rig on the real clock, its parts made and drained in one reader process
    (they share the bed's motion) as a bus's parts are on the Pi."""
    from avard.daemon.hw.drain_process import READER_RT_PRIORITY, ReaderProcess, ReaderSpec
    from avard.daemon.hw.timebase import SystemClock

    assert spec.simulate is not None
    sensors = [{**_chip_params(s), "name": s.name} for s in spec.sensors]
    proc = ReaderProcess(ReaderSpec(
        EMULATED_RIG_OPENER, {"sensors": sensors, "preset": spec.simulate,
                              "seed": spec.clock.seed},
        poll_hz=max(s.poll_hz for s in spec.sensors), rt_priority=READER_RT_PRIORITY,
        chip_interval_s=spec.temperature.chip_interval_s, chips=len(spec.sensors))).start()
    system = SystemClock()
    lanes = tuple(Rig(ls, proc.source(k), system,
                      {"device": "ADXL355 (emulated)", "preset": spec.simulate, "name": s.name,
                       "bus": s.bus.kind, "wiring": wiring(s.bus),
                       "reader": f"process {proc.pid}"}, closers=(proc.close,))
                  for k, (ls, s) in enumerate(zip(lane_spec, spec.sensors, strict=True)))
    return RigLanes(spec, lanes, (tuple(range(len(lanes))),), system,
                    parts={"reader_process": proc})


def bus_readers(sensors: tuple[SensorSpec, ...]) -> tuple[tuple[int, ...], ...]:
    """The sensors (by index) each reader drains: one reader per bus (SPI0's two chip
    selects share one, as do the I2C addresses of one bus)."""
    groups: dict[tuple[str, int], list[int]] = {}
    for k, s in enumerate(sensors):
        groups.setdefault((s.bus.kind, s.bus.number), []).append(k)
    return tuple(tuple(g) for g in groups.values())


def _ds18b20_bank(t: TemperatureConfig) -> Ds18b20Bank | None:
    """The DS18B20 reader threads for the configured (or every present) sensor."""
    if not t.ds18b20:
        return None
    from avard.daemon.hw import ds18b20

    present = ds18b20.discover()
    wanted = [ds18b20.normalise_id(i) for i in t.ids]
    missing = sorted(set(wanted) - set(present))
    if missing and t.required:
        raise HardwareError(f"DS18B20 {', '.join(missing)} not found on the 1-Wire bus; check "
                            "the wiring and dtoverlay=w1-gpio, or set temperature.required = "
                            "false")
    if missing:
        log.warning("DS18B20 %s not found now; reading them anyway (they may appear)",
                    ", ".join(missing))
    ids = wanted or present
    if not ids:
        return None
    return ds18b20.Ds18b20Bank([f"28-{i}" for i in ids], interval_s=t.interval_s)
