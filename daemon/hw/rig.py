"""The one place that chooses and builds the sensor backend: the real ADXL355 (and DS18B20s)
or the register-level emulator fed by the simulator.

The backend comes from ``--simulate PRESET`` when given, else from ``$AVARD_BACKEND``
(``hardware`` or ``simulate:PRESET``), else it is the hardware. :func:`open_sensor` opens the
ADXL355 driver over the configured bus (or over the emulator) and :func:`bring_up` is the one
probe/reset/[self-test]/configure/start sequence; :func:`build_rig` adds the temperature
sources and the INT1 pin, and :meth:`Rig.service` builds the service over it. ``avard run``
and ``avard demo`` use :func:`build_rig`; ``avard probe`` uses :func:`open_sensor` and
:func:`bring_up` (with the self-test) and reads the driver itself.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from avard.core.errors import ConfigError, HardwareError
from avard.daemon.config_types import Config, SensorConfig, TemperatureConfig
from avard.daemon.hw.pacing import watermark_settings

if TYPE_CHECKING:
    from avard.daemon.hw.adxl355 import Adxl355, DeviceInfo, SelfTestResult

log = logging.getLogger(__name__)

BACKEND_ENV = "AVARD_BACKEND"


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
    if still_odr_error_ppm is not None:
        return _still(config.sensor, still_odr_error_ppm)
    preset = choose_backend(simulate)
    if preset is not None:
        return _open_simulated(config, preset, seed, odr_error_ppm)
    return _open_hardware(config.sensor)


def bring_up(dev: Adxl355, sensor: SensorConfig, *, int1: bool = False,
             self_test: bool = False,
             found: Callable[[DeviceInfo], None] | None = None) -> BringUp:
    """The one start-up sequence of the ADXL355: probe the IDs, reset, optionally run the
    self-test (at ±8 g), configure the range and rate (and the FIFO watermark on INT1 when a
    reader waits on it), start measuring. ``found`` is told the IDs as soon as they are read
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
    dev.start()
    return BringUp(info, st)


def _still(sensor: SensorConfig, odr_error_ppm: float) -> OpenedSensor:
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


def _open_simulated(config: Config, preset: str, seed: int | None,
                    odr_error_ppm: float | None) -> OpenedSensor:
    from avard.core.sim.presets import PRESETS
    from avard.daemon.hw.simulation import open_simulated

    if preset not in PRESETS:
        raise ConfigError(f"--simulate {preset!r}: unknown preset; choose one of "
                          f"{', '.join(sorted(PRESETS))}")
    dev, clock, sims, emu = open_simulated(config, preset, seed=seed,
                                           odr_error_ppm=odr_error_ppm)
    return OpenedSensor(dev, clock, simulate=preset, emulated=True,
                        parts={"sims": sims, "emulator": emu})


def _open_hardware(sensor: SensorConfig) -> OpenedSensor:
    from avard.daemon.hw.adxl355 import Adxl355
    from avard.daemon.hw.timebase import SystemClock
    from avard.daemon.hw.transport import open_bus

    bus = open_bus(sensor.bus, bus=sensor.bus_number, device=sensor.spi_device,
                   address=sensor.i2c_address, speed_hz=sensor.spi_speed_hz)
    clock = SystemClock()
    return OpenedSensor(Adxl355(bus, clock=clock, temp_intercept_lsb=sensor.temp_intercept_lsb),
                        clock)


@dataclass
class Rig:
    """A sensor and what goes with it, ready for a
    :class:`~avard.daemon.service.supervisor.Service`."""

    sensor: Any
    clock: Any
    sensor_info: dict[str, Any]
    simulate: str | None = None
    temperature_bank: Any = None
    interrupt: Any = None
    extra_temperature_names: list[str] = field(default_factory=list)
    on_tick: Callable[[float], None] | None = None
    attach: Callable[[Any], None] | None = None     # wires a simulated rig to its service
    parts: dict[str, Any] = field(default_factory=dict)   # emulator, simulator (tests)

    def service(self, config: Config, **service_kw: Any) -> Any:
        from avard.daemon.service.supervisor import Service

        for key, value in (("temperature_bank", self.temperature_bank),
                           ("interrupt", self.interrupt), ("on_tick", self.on_tick)):
            if value is not None:
                service_kw.setdefault(key, value)
        svc = Service(config, self.sensor, self.clock, simulate=self.simulate,
                      sensor_info=self.sensor_info,
                      extra_temperature_names=list(self.extra_temperature_names),
                      **service_kw)
        if self.attach is not None:
            self.attach(svc)
        return svc


def build_rig(config: Config, *, simulate: str | None = None, seed: int | None = None,
              odr_error_ppm: float | None = None) -> Rig:
    """The configured, started sensor of the chosen backend."""
    preset = choose_backend(simulate)
    if preset is not None:
        return _simulated(config, preset, seed, odr_error_ppm)
    return _hardware(config)


def _simulated(config: Config, preset: str, seed: int | None,
               odr_error_ppm: float | None) -> Rig:
    from avard.daemon.hw.interrupt import EmulatedInterruptPin

    opened = _open_simulated(config, preset, seed, odr_error_ppm)
    use_int1 = bool(config.sensor.int1_gpio)
    bring_up(opened.driver, config.sensor, int1=use_int1)
    sims, emu = opened.parts["sims"], opened.parts["emulator"]
    pin = EmulatedInterruptPin(emu, opened.clock) if use_int1 else None

    def attach(svc: Any) -> None:
        sims.deliver = svc.temperature_reading

    return Rig(opened.driver, opened.clock, {"device": "ADXL355 (emulated)", "preset": preset},
               simulate=preset, interrupt=pin, extra_temperature_names=list(sims.names),
               on_tick=sims.on_tick, attach=attach, parts=dict(opened.parts))


def _hardware(config: Config) -> Rig:
    s = config.sensor
    interrupt = None
    if s.int1_gpio:
        from avard.daemon.hw.interrupt import GpiodPin

        interrupt = GpiodPin(s.int1_gpio)
    opened = _open_hardware(s)
    info = bring_up(opened.driver, s, int1=interrupt is not None).info
    return Rig(opened.driver, opened.clock, {"device": info.name, "partid": info.partid,
                                             "revid": info.revid, "bus": s.bus},
               temperature_bank=_ds18b20_bank(config.temperature), interrupt=interrupt)


def _ds18b20_bank(t: TemperatureConfig) -> Any:
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
