"""``--simulate PRESET``: the same service over the register-level emulator fed by the simulator.

The ADXL355 driver talks SPI to :class:`~avard.daemon.hw.emulator.EmulatedAdxl355` through
:class:`~avard.daemon.hw.emulator.FakeSpiDev`, so every byte goes through the same decode, marker
and overrun logic as on the Pi. The emulator's samples come from
:class:`avard.core.sim.simulate.SensorSimulator`; its chip temperature and two simulated DS18B20
(plate and ambient) follow the simulator's thermal model at the sample being produced. The
DS18B20s reach the service the way real ones do: written into a fake 1-Wire sysfs tree
(w1_sysfs.py) and read by the real :class:`~avard.daemon.hw.ds18b20.Ds18b20Bank` (w1thermsensor,
0.0625 °C quantisation, CRC checks), synchronously on the virtual clock. The backend is chosen
in daemon/hw/rig.py. Time is a stepped :class:`VirtualClock` advanced by the
reader thread's sleeps, so ``--speed`` never causes overruns from host scheduling jitter.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.daemon.config_types import Config, as_config
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.ds18b20 import Ds18b20Bank
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock
from avard.daemon.hw.interrupt import EmulatedInterruptPin
from avard.daemon.hw.transport import SpiBus
from avard.daemon.hw.w1_sysfs import SysfsTree

if TYPE_CHECKING:
    from avard.daemon.service.supervisor import Service



@dataclass
class SimulatedSensors:
    """The simulator behind the emulator, remembering the newest temperatures produced.

    Its two DS18B20s (plate, ambient) are served to the real :class:`Ds18b20Bank` through a
    fake 1-Wire sysfs tree (w1_sysfs.py): at each conversion the simulated temperatures are
    written as the kernel would present them, the bank reads and checks them with
    w1thermsensor (12-bit quantisation, CRC), and the readings go to ``deliver`` (the
    service's DS18B20 handler, which marks drop-outs and returns). A name in ``fail`` makes
    that sensor vanish from the bus until it is taken out again."""

    sim: Any
    names: tuple[str, str] = ("28-00000000plate", "28-0000000ambient")
    ids: tuple[str, str] = ("00000000a001", "00000000a002")   # 1-Wire ids in the fake tree
    interval_s: float = 1.0
    clock: Any = None
    deliver: Callable[[Any], None] | None = None   # the service's DS18B20 reading handler
    _next: float = field(default=0.0)
    fail: set[str] = field(default_factory=set)   # simulated DS18B20 dropouts (by name)
    _lost: set[str] = field(default_factory=set)
    _bus: Any = None

    batch: int = 4096
    _buf: Any = None
    _pos: int = 0

    def source(self, n: int) -> np.ndarray:
        """The next ``n`` samples' counts. The simulator is called in batches (its cost is
        per call); the temperatures follow the sample handed out last, and are read from
        the batch only when asked for (once a second, not at every drain)."""
        buf = self._buf
        if buf is not None and self._pos + n <= len(buf.counts):   # the usual drain
            self._pos += n
            return buf.counts[self._pos - n:self._pos]
        parts = []
        while n > 0:
            if self._buf is None or self._pos >= len(self._buf.counts):
                self._buf = self.sim.next(max(self.batch, n))
                self._pos = 0
            take = min(n, len(self._buf.counts) - self._pos)
            parts.append(self._buf.counts[self._pos:self._pos + take])
            self._pos += take
            n -= take
        return np.concatenate(parts) if len(parts) != 1 else parts[0]

    def _temperatures(self) -> tuple[float, float, float]:
        """Plate, ambient and die temperature (°C) at the sample handed out last (NaN before
        the first)."""
        if self._buf is None or self._pos == 0:
            return (math.nan,) * 3
        plate, ambient, chip = self._buf.temperatures_at(np.array([self._pos - 1]))[0]
        return float(plate), float(ambient), float(chip)

    @property
    def plate_c(self) -> float:
        return self._temperatures()[0]

    @property
    def ambient_c(self) -> float:
        return self._temperatures()[1]

    @property
    def chip_c(self) -> float:
        return self._temperatures()[2]

    def chip_temperature(self) -> float:
        """The die temperature now; before the first sample (the driver reads TEMP while it
        configures the chip) that of the first sample, not a made-up 25 °C that showed as a
        spike at the start of every simulated run. The first batch is the one the first
        drain would make, so the samples are the same."""
        if self._buf is None:
            self._buf = self.sim.next(self.batch)
            self._pos = 0
        if self._pos == 0:
            return float(self._buf.temperatures_at(np.array([0]))[0][2])
        return self.chip_c

    def _one_wire(self) -> tuple[SysfsTree, Ds18b20Bank]:
        """The fake sysfs tree (in a temporary folder, removed with this object) and the
        bank reading it, made at the first conversion."""
        if self._bus is None:
            tmp = tempfile.TemporaryDirectory(prefix="avard-sim-w1-")
            tree = SysfsTree(Path(tmp.name) / "devices")
            bank = Ds18b20Bank(dict(zip(self.names, self.ids, strict=True)),
                               interval_s=self.interval_s, base_directory=tree.base,
                               clock=self.clock)
            self._bus = (tmp, tree, bank)
        return self._bus[1], self._bus[2]

    def on_tick(self, t_mono: float) -> None:
        """Called by the reader thread after each poll: simulated DS18B20 conversions."""
        deliver = self.deliver
        if deliver is None or t_mono < self._next:
            return
        plate, ambient, _chip = self._temperatures()
        if math.isnan(plate):
            return
        self._next = t_mono + self.interval_s
        tree, bank = self._one_wire()
        for name, sid, v in zip(self.names, self.ids, (plate, ambient),
                                strict=True):
            lost = name in self.fail
            if lost and name not in self._lost:
                tree.remove(sid)
                self._lost.add(name)
            elif not lost and name in self._lost:
                tree.restore(sid)
                self._lost.discard(name)
            if not lost:
                tree.set_temperature(sid, v)
        for reading in bank.read_all():
            deliver(reading)


def open_simulated(cfg: Config | Mapping[str, Mapping[str, Any]], preset: str, *,
                   seed: int | None = None, odr_error_ppm: float | None = None
                   ) -> tuple[Adxl355, VirtualClock, SimulatedSensors, EmulatedAdxl355]:
    """Driver over emulator over simulator for ``cfg``'s sensor, not yet brought up."""
    from avard.core.sim.simulate import SensorSimulator, make_config

    config = as_config(cfg)
    s = config.sensor
    sim_cfg = make_config(preset, odr_hz=s.odr_hz, range_g=s.range_g)
    # CLOCK_REALTIME of the simulation starts at the host's real time, so that restarts of a
    # simulated service see the real time between them.
    clock = VirtualClock(epoch=time.time() - 1000.0)
    sims = SimulatedSensors(SensorSimulator(sim_cfg, seed=seed),
                            interval_s=config.temperature.interval_s, clock=clock)
    ppm = sim_cfg.odr_error_ppm if odr_error_ppm is None else odr_error_ppm
    emu = EmulatedAdxl355(sims.source, clock, odr_error_ppm=ppm,
                          temperature=sims.chip_temperature)
    # The emulated chip has the later revision's intercept; the driver uses the configured one,
    # as on hardware, so a wrong intercept shows up as the chip-vs-DS18B20 offset it causes.
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock, temp_intercept_lsb=s.temp_intercept_lsb)
    return dev, clock, sims, emu


def build_simulated(cfg: Config | Mapping[str, Mapping[str, Any]], preset: str, *,
                    seed: int | None = None, odr_error_ppm: float | None = None
                    ) -> tuple[Adxl355, VirtualClock, SimulatedSensors, EmulatedAdxl355]:
    """Driver over emulator over simulator, configured like ``cfg``'s sensor says and started
    (daemon/hw/rig.py's one start-up sequence)."""
    from avard.daemon.hw.rig import bring_up

    config = as_config(cfg)
    dev, clock, sims, emu = open_simulated(config, preset, seed=seed,
                                           odr_error_ppm=odr_error_ppm)
    bring_up(dev, config.sensor, int1=bool(config.sensor.int1_gpio))
    return dev, clock, sims, emu


def simulated_service(cfg: Config | Mapping[str, Mapping[str, Any]], preset: str, *,
                      seed: int | None = None,
                      odr_error_ppm: float | None = None,
                      after_tick: Callable[[float], None] | None = None,
                      **service_kw: Any) -> tuple[Service, SimulatedSensors, EmulatedAdxl355]:
    """The service over the simulated rig (``build_simulated``), wired both ways: the reader
    thread's ticks drive the simulated DS18B20 conversions (then ``after_tick``, a test's or
    benchmark's hook, if given), and those readings go into this service's ring. The driver
    and the virtual clock are ``svc.sensor`` and ``svc.clock``. ``service_kw`` go to
    ``Service`` (speed, notifier, factories, …)."""
    from avard.daemon.service.supervisor import Service

    config = as_config(cfg)
    dev, clock, sims, emu = build_simulated(config, preset, seed=seed,
                                            odr_error_ppm=odr_error_ppm)

    def tick(t_mono: float) -> None:
        sims.on_tick(t_mono)
        if after_tick is not None:
            after_tick(t_mono)

    if config.sensor.int1_gpio:
        service_kw.setdefault("interrupt", EmulatedInterruptPin(emu, clock))
    svc = Service(config, dev, clock, simulate=preset,
                  on_tick=sims.on_tick if after_tick is None else tick,
                  extra_temperature_names=list(sims.names), **service_kw)
    sims.deliver = svc.temperature_reading
    return svc, sims, emu
