"""``--simulate PRESET``: the same service over the register-level emulator fed by the simulator.

The ADXL355 driver talks SPI to :class:`~avard.daemon.emulator.EmulatedAdxl355` through
:class:`~avard.daemon.emulator.FakeSpiDev`, so every byte goes through the same decode, marker
and overrun logic as on the Pi. The emulator's samples come from
:class:`avard.core.simulate.SensorSimulator`; its chip temperature and two simulated DS18B20
(plate and ambient, quantised to 0.0625 °C like the real part) follow the simulator's thermal
model at the sample being produced. Time is a stepped :class:`VirtualClock` advanced by the
reader thread's sleeps, so ``--speed`` never causes overruns from host scheduling jitter.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core import frames

from .adxl355 import Adxl355
from .emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock
from .interrupt import EmulatedInterruptPin
from .pacing import watermark_settings
from .source import MarkSink
from .transport import SpiBus

if TYPE_CHECKING:
    from .service import Service

DS18B20_LSB_C = 0.0625


@dataclass
class SimulatedSensors:
    """The simulator behind the emulator, remembering the newest temperatures produced."""

    sim: Any
    plate_c: float = float("nan")
    ambient_c: float = float("nan")
    chip_c: float = float("nan")
    names: tuple[str, str] = ("28-00000000plate", "28-0000000ambient")
    interval_s: float = 1.0
    sink: MarkSink | None = None      # where the simulated DS18B20 readings go
    _next: float = field(default=0.0)
    fail: set[str] = field(default_factory=set)   # simulated DS18B20 dropouts (by name)
    _lost: set[str] = field(default_factory=set)

    batch: int = 4096
    _buf: Any = None
    _pos: int = 0

    def source(self, n: int) -> np.ndarray:
        """The next ``n`` samples' counts. The simulator is called in batches (its cost is
        per call), and the temperatures follow the sample handed out last."""
        parts = []
        while n > 0:
            if self._buf is None or self._pos >= len(self._buf.counts):
                self._buf = self.sim.next(max(self.batch, n))
                self._pos = 0
            take = min(n, len(self._buf.counts) - self._pos)
            parts.append(self._buf.counts[self._pos:self._pos + take])
            self._pos += take
            n -= take
            last = self._pos - 1
            self.plate_c, self.ambient_c = (float(v) for v in self._buf.temp_c[last])
            self.chip_c = float(self._buf.chip_temp_c[last])
        return np.concatenate(parts) if len(parts) != 1 else parts[0]

    def chip_temperature(self) -> float:
        return 25.0 if np.isnan(self.chip_c) else self.chip_c

    def on_tick(self, t_mono: float) -> None:
        """Called by the reader thread after each poll: simulated DS18B20 conversions."""
        sink = self.sink
        if sink is None or t_mono < self._next or np.isnan(self.plate_c):
            return
        self._next = t_mono + self.interval_s
        values = []
        i0 = sink.stamp()
        t_real = t_mono + sink.real_offset()
        for name, v in zip(self.names, (self.plate_c, self.ambient_c), strict=True):
            lost = name in self.fail
            values.append(None if lost else round(v / DS18B20_LSB_C) * DS18B20_LSB_C)
            if lost != (name in self._lost):
                (self._lost.add if lost else self._lost.discard)(name)
                sink.mark(frames.event_record(
                    sink.run_id, 0, "sensor_lost" if lost else "sensor_back", t_mono, t_real,
                    i0=i0, detail={"sensor": name}))
        sink.mark(frames.temp_record(sink.run_id, 0, i0, list(self.names), values, t_mono,
                                     t_real, source="ds18b20-sim"))


def build_simulated(cfg: dict[str, dict[str, Any]], preset: str, *, seed: int | None = None,
                    odr_error_ppm: float | None = None) -> tuple[Adxl355, VirtualClock,
                                                                 SimulatedSensors,
                                                                 EmulatedAdxl355]:
    """Driver over emulator over simulator, configured like ``cfg['sensor']`` says."""
    from avard.core.simulate import SensorSimulator, make_config

    s = cfg["sensor"]
    sim_cfg = make_config(preset, odr_hz=float(s["odr_hz"]), range_g=int(s["range_g"]))
    sims = SimulatedSensors(SensorSimulator(sim_cfg, seed=seed),
                            interval_s=float(cfg["temperature"]["interval_s"]))
    # CLOCK_REALTIME of the simulation starts at the host's real time, so that restarts of a
    # simulated service see the real time between them.
    clock = VirtualClock(epoch=time.time() - 1000.0)
    ppm = sim_cfg.odr_error_ppm if odr_error_ppm is None else odr_error_ppm
    emu = EmulatedAdxl355(sims.source, clock, odr_error_ppm=ppm,
                          temperature=sims.chip_temperature)
    # The emulated chip has the later revision's intercept; the driver uses the configured one,
    # as on hardware, so a wrong intercept shows up as the chip-vs-DS18B20 offset it causes.
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock,
                  temp_intercept_lsb=float(s["temp_intercept_lsb"]))
    dev.probe()
    dev.reset()
    dev.configure(range_g=int(s["range_g"]), odr_hz=float(s["odr_hz"]),
                  **watermark_settings(bool(s.get("int1_gpio"))))
    dev.start()
    return dev, clock, sims, emu



def simulated_service(cfg: dict[str, dict[str, Any]], preset: str, *, seed: int | None = None,
                      odr_error_ppm: float | None = None,
                      after_tick: Callable[[float], None] | None = None,
                      **service_kw: Any) -> tuple[Service, SimulatedSensors, EmulatedAdxl355]:
    """The service over the simulated rig (``build_simulated``), wired both ways: the reader
    thread's ticks drive the simulated DS18B20 conversions (then ``after_tick``, a test's or
    benchmark's hook, if given), and those readings go into this service's ring. The driver
    and the virtual clock are ``svc.sensor`` and ``svc.clock``. ``service_kw`` go to
    ``Service`` (speed, notifier, factories, …)."""
    from .service import Service

    dev, clock, sims, emu = build_simulated(cfg, preset, seed=seed, odr_error_ppm=odr_error_ppm)

    def tick(t_mono: float) -> None:
        sims.on_tick(t_mono)
        if after_tick is not None:
            after_tick(t_mono)

    if cfg["sensor"].get("int1_gpio"):
        service_kw.setdefault("interrupt", EmulatedInterruptPin(emu, clock))
    svc = Service(cfg, dev, clock, simulate=preset,
                  on_tick=sims.on_tick if after_tick is None else tick,
                  extra_temperature_names=list(sims.names), **service_kw)
    sims.sink = svc.mark_sink()
    return svc, sims, emu
