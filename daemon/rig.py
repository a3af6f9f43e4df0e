"""The one place that chooses and builds the sensor backend: the real ADXL355 (and DS18B20s)
or the register-level emulator fed by the simulator.

The backend comes from ``--simulate PRESET`` when given, else from ``$AVARD_BACKEND``
(``hardware`` or ``simulate:PRESET``), else it is the hardware. ``open_driver`` opens the
ADXL355 driver over the configured bus (or over the emulator); :func:`build_rig` adds the
probe/reset/configure/start sequence, the temperature sources and the INT1 pin, and
:meth:`Rig.service` builds the service over it. ``avard run`` and ``avard demo`` use it.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from avard.core.errors import ConfigError, HardwareError

from .pacing import watermark_settings

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


@dataclass
class Rig:
    """A sensor and what goes with it, ready for a :class:`~avard.daemon.service.Service`."""

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

    def service(self, cfg: dict[str, dict[str, Any]], **service_kw: Any) -> Any:
        from .service import Service

        for key, value in (("temperature_bank", self.temperature_bank),
                           ("interrupt", self.interrupt), ("on_tick", self.on_tick)):
            if value is not None:
                service_kw.setdefault(key, value)
        svc = Service(cfg, self.sensor, self.clock, simulate=self.simulate,
                      sensor_info=self.sensor_info,
                      extra_temperature_names=list(self.extra_temperature_names),
                      **service_kw)
        if self.attach is not None:
            self.attach(svc)
        return svc


def build_rig(cfg: dict[str, dict[str, Any]], *, simulate: str | None = None,
              seed: int | None = None, odr_error_ppm: float | None = None) -> Rig:
    """The configured, started sensor of the chosen backend."""
    preset = choose_backend(simulate)
    if preset is not None:
        return _simulated(cfg, preset, seed, odr_error_ppm)
    return _hardware(cfg)


def _simulated(cfg: dict[str, dict[str, Any]], preset: str, seed: int | None,
               odr_error_ppm: float | None) -> Rig:
    from avard.core.presets import PRESETS

    from .interrupt import EmulatedInterruptPin
    from .simulation import build_simulated

    if preset not in PRESETS:
        raise ConfigError(f"--simulate {preset!r}: unknown preset; choose one of "
                          f"{', '.join(sorted(PRESETS))}")
    dev, clock, sims, emu = build_simulated(cfg, preset, seed=seed, odr_error_ppm=odr_error_ppm)
    pin = EmulatedInterruptPin(emu, clock) if cfg["sensor"]["int1_gpio"] else None

    def attach(svc: Any) -> None:
        sims.deliver = svc.temperature_reading

    return Rig(dev, clock, {"device": "ADXL355 (emulated)", "preset": preset},
               simulate=preset, interrupt=pin, extra_temperature_names=list(sims.names),
               on_tick=sims.on_tick, attach=attach, parts={"sims": sims, "emulator": emu})


def _hardware(cfg: dict[str, dict[str, Any]]) -> Rig:
    from .adxl355 import Adxl355
    from .timebase import SystemClock
    from .transport import open_bus

    s = cfg["sensor"]
    interrupt = None
    if s["int1_gpio"]:
        from .interrupt import GpiodPin

        interrupt = GpiodPin(s["int1_gpio"])
    bus = open_bus(s["bus"], bus=s["spi_bus"] if s["bus"] == "spi" else s["i2c_bus"],
                   device=s["spi_device"], address=s["i2c_address"],
                   speed_hz=s["spi_speed_hz"])
    dev = Adxl355(bus, temp_intercept_lsb=float(s["temp_intercept_lsb"]))
    info = dev.probe()
    dev.reset()
    dev.configure(range_g=int(s["range_g"]), odr_hz=float(s["odr_hz"]),
                  **watermark_settings(interrupt is not None))
    dev.start()
    return Rig(dev, SystemClock(), {"device": info.name, "partid": info.partid,
                                    "revid": info.revid, "bus": s["bus"]},
               temperature_bank=_ds18b20_bank(cfg), interrupt=interrupt)


def _ds18b20_bank(cfg: dict[str, dict[str, Any]]) -> Any:
    """The DS18B20 reader threads for the configured (or every present) sensor."""
    t = cfg["temperature"]
    if not t["ds18b20"]:
        return None
    from . import ds18b20

    present = ds18b20.discover()
    wanted = [ds18b20.normalise_id(i) for i in t["ids"]]
    missing = sorted(set(wanted) - set(present))
    if missing and t["required"]:
        raise HardwareError(f"DS18B20 {', '.join(missing)} not found on the 1-Wire bus; check "
                            "the wiring and dtoverlay=w1-gpio, or set temperature.required = "
                            "false")
    if missing:
        log.warning("DS18B20 %s not found now; reading them anyway (they may appear)",
                    ", ".join(missing))
    ids = wanted or present
    if not ids:
        return None
    return ds18b20.Ds18b20Bank([f"28-{i}" for i in ids], interval_s=float(t["interval_s"]))
