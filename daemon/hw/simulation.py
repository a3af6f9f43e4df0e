"""``--simulate PRESET``: the same service over the register-level emulator fed by the simulator.

The ADXL355 driver talks SPI to :class:`~avard.daemon.hw.emulator.EmulatedAdxl355` through
:class:`~avard.daemon.hw.emulator.FakeSpiDev`, so every byte goes through the same decode, marker
and overrun logic as on the Pi. The emulator's samples come from
:class:`avard.core.sim.simulate.SensorSimulator`; its chip temperature and two simulated DS18B20
(plate and ambient) follow the simulator's thermal model at the sample being produced. The
DS18B20s reach the service the way real ones do: written into a fake 1-Wire sysfs tree
(w1_sysfs.py) and read by the real :class:`~avard.daemon.hw.ds18b20.Ds18b20Bank` (w1thermsensor,
0.0625 °C quantisation, CRC checks), synchronously on the virtual clock. The backend is chosen
in daemon/hw/rig.py, the service composed over it in daemon/compose.py. Time is a stepped
:class:`VirtualClock` advanced by the reader thread's sleeps, so ``--speed`` never causes
overruns from host scheduling jitter.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import shutil
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from avard.daemon.config_types import Config, as_config
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.ds18b20 import ERROR, Ds18b20Bank, TemperatureReading
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock
from avard.daemon.hw.transport import SpiBus
from avard.daemon.hw.w1_sysfs import SysfsTree

if TYPE_CHECKING:
    from avard.daemon.hw.rig import SensorSpec

log = logging.getLogger(__name__)

#: The folder of the simulated 1-Wire tree inside the directory its owner gives
#: (:attr:`SimulatedSensors.workdir`: the recording directory of a service that records).
W1_DIR = ".simulated-w1"


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
    #: where the fake 1-Wire tree is made (compose.py gives the service's recording
    #: directory, which its lock covers, when it records: a folder of /tmp stayed behind
    #: whenever the process was killed); None: a private temporary folder
    workdir: Path | None = None
    _tmp: Any = None
    _write_problem: str | None = None    # why the tree could not be written (said once)

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
        """The fake sysfs tree and the bank reading it, made at the first conversion."""
        if self._bus is None:
            root = self._w1_root()
            tree = SysfsTree(root / "devices")
            bank = Ds18b20Bank(dict(zip(self.names, self.ids, strict=True)),
                               interval_s=self.interval_s, base_directory=tree.base,
                               clock=self.clock)
            self._bus = (root, tree, bank)
        return self._bus[1], self._bus[2]

    def _w1_root(self) -> Path:
        """The tree's folder: :data:`W1_DIR` in :attr:`workdir`, replacing the one a killed
        process left there (one service records into a directory, as one owns its state
        file), so a kill leaves at most that one small folder, inside its owner's directory,
        until the next start; without a ``workdir``, a new temporary folder."""
        if self.workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="avard-sim-w1-")
            return Path(self._tmp.name)
        root = Path(self.workdir) / W1_DIR
        if root.is_symlink() or (root.exists() and not root.is_dir()):
            root.unlink()           # a link is removed, never followed
        else:
            shutil.rmtree(root, ignore_errors=True)
        root.mkdir(parents=True)
        return root

    def close(self) -> None:
        """Remove the fake 1-Wire tree (the service's stop calls it through the rig)."""
        if self._bus is not None:
            shutil.rmtree(self._bus[0], ignore_errors=True)
            self._bus = None

    def on_tick(self, t_mono: float) -> None:
        """Called by the reader thread after each poll: simulated DS18B20 conversions."""
        deliver = self.deliver
        if deliver is None or t_mono < self._next:
            return
        plate, ambient, _chip = self._temperatures()
        if math.isnan(plate):
            return
        self._next = t_mono + self.interval_s
        # The tree is files on this host's disk (the kernel's sysfs never fails to be
        # written): a full disk or a full fd table must not end the reader thread. A sensor
        # whose file could not be written reads as failed this round, never as the value
        # its file held from before.
        failed: dict[str, str] = {}
        try:
            tree, bank = self._one_wire()
        except OSError as exc:
            # no tree (a full disk at the first conversion): every sensor reads as failed,
            # so the service marks them lost as it would a bus that is gone
            self._cannot_write(exc)
            t_real = self.clock.realtime() if self.clock is not None else time.time()
            for name, sid in zip(self.names, self.ids, strict=True):
                deliver(TemperatureReading(name, sid, math.nan, ERROR, t_mono, t_real, 0.0,
                                           f"simulated 1-Wire tree not made: {exc}"))
            return
        for name, sid, v in zip(self.names, self.ids, (plate, ambient),
                                strict=True):
            lost = name in self.fail
            try:
                if lost and name not in self._lost:
                    tree.remove(sid)
                    self._lost.add(name)
                elif not lost and name in self._lost:
                    tree.restore(sid)
                    self._lost.discard(name)
                if not lost:
                    tree.set_temperature(sid, v)
            except OSError as exc:
                failed[name] = f"simulated w1_slave not written: {exc}"
                self._cannot_write(exc)
        if not failed and self._write_problem is not None:
            log.info("the simulated 1-Wire files are written again")
            self._write_problem = None
        for reading in bank.read_all():
            if reading.name in failed:
                reading = dataclasses.replace(reading, value_c=math.nan, status=ERROR,
                                              detail=failed[reading.name])
            deliver(reading)

    def _cannot_write(self, exc: OSError) -> None:
        if self._write_problem is None:
            log.warning("cannot write the simulated 1-Wire files (%s); their DS18B20 "
                        "readings fail until they can", exc)
        self._write_problem = str(exc)


def open_simulated(sensor: SensorSpec, preset: str, *, seed: int | None = None,
                   odr_error_ppm: float | None = None, interval_s: float = 1.0
                   ) -> tuple[Adxl355, VirtualClock, SimulatedSensors, EmulatedAdxl355]:
    """Driver over emulator over simulator for the described sensor, not yet brought up;
    the simulated DS18B20s convert every ``interval_s``."""
    from avard.core.sim.simulate import SensorSimulator, make_config

    sim_cfg = make_config(preset, odr_hz=sensor.odr_hz, range_g=sensor.range_g)
    # CLOCK_REALTIME of the simulation starts at the host's real time, so that restarts of a
    # simulated service see the real time between them.
    clock = VirtualClock(epoch=time.time() - 1000.0)
    sims = SimulatedSensors(SensorSimulator(sim_cfg, seed=seed), interval_s=interval_s,
                            clock=clock)
    ppm = sim_cfg.odr_error_ppm if odr_error_ppm is None else odr_error_ppm
    emu = EmulatedAdxl355(sims.source, clock, odr_error_ppm=ppm,
                          temperature=sims.chip_temperature)
    # The emulated chip has the later revision's intercept; the driver uses the configured one,
    # as on hardware, so a wrong intercept shows up as the chip-vs-DS18B20 offset it causes.
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock,
                  temp_intercept_lsb=sensor.temp_intercept_lsb)
    return dev, clock, sims, emu


def build_simulated(cfg: Config | Mapping[str, Mapping[str, Any]], preset: str, *,
                    seed: int | None = None, odr_error_ppm: float | None = None
                    ) -> tuple[Adxl355, VirtualClock, SimulatedSensors, EmulatedAdxl355]:
    """Driver over emulator over simulator, configured like ``cfg``'s sensor says and started:
    the parts of the simulated rig daemon/hw/rig.py builds (for tests that take it apart)."""
    from avard.daemon.hw.rig import build_rig, describe_rig

    rig = build_rig(describe_rig(as_config(cfg), simulate=preset, seed=seed,
                                 odr_error_ppm=odr_error_ppm))
    parts = rig.parts
    return (cast(Adxl355, rig.sensor), cast(VirtualClock, rig.clock),
            cast(SimulatedSensors, parts["sims"]), cast(EmulatedAdxl355, parts["emulator"]))


# -- several emulated sensors on one bed --------------------------------------------------------

@dataclass(frozen=True)
class BedSpec:
    """The motion every sensor of an emulated rig feels (per axis, SI): a white part (a
    building's floor vibration; its ADEV at τ = 1 s, m/s/√s) within ``band_hz`` (floor
    vibration lies below a few tens of Hz), and a slow tilt (a random walk of the
    acceleration, m/s²/√s)."""

    white: float = 5e-5
    tilt: float = 1e-6
    seed: int | None = None
    band_hz: float = 10.0


#: The bed's grid, in samples of the sensors' rate (linear interpolation between its points
#: then barely smooths the band the bed holds).
BED_GRID = 4


class BedMotion:
    """The bed's motion as a function of time, as real hardware feels it (m/s², (n, 3)): drawn
    once on a grid of :data:`BED_GRID` × ``rate_hz`` from the clock's ``t0``, the white part
    smoothed to ``band_hz`` (two moving averages: a triangle, whose side lobes are low), and
    read by each sensor at its own sampling instants (linear interpolation between grid
    points far above the band). Sensors that started measuring a fraction of a sample apart
    feel the bed a fraction of a sample apart, as on a plate; a stretch of the grid is
    dropped once every sensor has read past it."""

    def __init__(self, spec: BedSpec, n_sensors: int, rate_hz: float, t0: float) -> None:
        self.spec = spec
        self.rate_hz = float(rate_hz) * BED_GRID        # the grid's rate
        self.t0 = float(t0)
        # two moving averages of L points: −3 dB at about 0.32 grid rate / L
        self.width = max(1, round(0.32 * self.rate_hz / spec.band_hz)) \
            if spec.band_hz > 0 else 1
        self._rng = np.random.default_rng(spec.seed)
        self._buf = np.zeros((0, 3))
        self._base = 0                      # grid index of _buf[0]
        self._read = [0.0] * n_sensors      # the grid position each sensor read up to
        self._level = np.zeros(3)           # the tilt's current value
        # the points each average still needs from the previous draw
        self._tails = [np.zeros((self.width - 1, 3)) for _ in range(2)]

    def _smooth(self, x: np.ndarray, k: int) -> np.ndarray:
        """One moving average of ``width`` points, continued across draws."""
        if self.width == 1:
            return x
        both = np.concatenate([self._tails[k], x])
        self._tails[k] = both[len(both) - (self.width - 1):]
        c = np.concatenate([np.zeros((1, 3)), np.cumsum(both, axis=0)])
        out: np.ndarray = (c[self.width:] - c[:-self.width]) / self.width
        return out

    def _extend(self, upto: int) -> None:
        n = upto - (self._base + len(self._buf))
        if n <= 0:
            return
        raw = self._rng.normal(0.0, self.spec.white * math.sqrt(self.rate_hz), (n, 3))
        steps = self._rng.normal(0.0, self.spec.tilt / math.sqrt(self.rate_hz), (n, 3))
        walk = self._level + np.cumsum(steps, axis=0)
        self._level = walk[-1]
        white = self._smooth(self._smooth(raw, 0), 1)
        self._buf = np.concatenate([self._buf, white + walk])

    def at(self, sensor: int, t: np.ndarray) -> np.ndarray:
        """The bed at CLOCK_MONOTONIC instants ``t`` (increasing), read by ``sensor``."""
        x = np.maximum((np.asarray(t, dtype=np.float64) - self.t0) * self.rate_hz, 0.0)
        self._extend(math.floor(x[-1]) + 2)
        k = np.floor(x).astype(np.int64)
        f = (x - k)[:, None]
        lo = self._buf[k - self._base]
        out: np.ndarray = lo + f * (self._buf[k + 1 - self._base] - lo)
        self._read[sensor] = float(x[-1])
        drop = int(min(self._read)) - 1 - self._base
        if drop > 4096 * BED_GRID:
            self._buf = self._buf[drop:]
            self._base += drop
        return out


def emulated_rig(sensors: Sequence[SensorSpec], preset: str, *, bed: BedSpec = BedSpec(),
                 seed: int | None = None, clock: Any = None
                 ) -> tuple[Any, list[tuple[str, Adxl355, EmulatedAdxl355]]]:
    """Several ADXL355s (each over its described emulated transport: SPI bus/chip select or
    I2C address) on one clock (a stepped virtual one unless ``clock`` is given: the host's
    makes the parts produce on CLOCK_MONOTONIC, read or not), each the simulator's ``preset``
    (its own noise, its own seed) plus the one :class:`BedMotion`, each feeling it at its own
    sampling instants: (clock, [(name, driver, emulator)]), not yet brought up. All sensors
    run at the first one's ODR."""
    from avard.core.sim.simulate import SensorSimulator, make_config
    from avard.daemon.hw.emulator import FakeSMBus
    from avard.daemon.hw.registers import STANDARD_GRAVITY, sensitivity_lsb_per_g
    from avard.daemon.hw.transport import I2cBus

    odr = sensors[0].odr_hz
    if clock is None:
        clock = VirtualClock(epoch=time.time() - 1000.0)
    motion = BedMotion(bed, len(sensors), odr, clock.monotonic())
    rng = np.random.default_rng(seed)
    out = []
    for i, s in enumerate(sensors):
        sim = SensorSimulator(make_config(preset, odr_hz=odr, range_g=s.range_g),
                              seed=int(rng.integers(2**31)))
        lsb = STANDARD_GRAVITY / sensitivity_lsb_per_g(s.range_g)
        part: list[EmulatedAdxl355] = []
        # sets handed out since the part's count last moved (it produces in chunks and
        # counts them after the last): {produced: count at the last call, given: since}
        at = {"produced": -1, "given": 0}

        def source(n: int, sim: Any = sim, i: int = i, lsb: float = lsb,
                   part: list[EmulatedAdxl355] = part, at: dict[str, int] = at
                   ) -> np.ndarray:
            emu = part[0]
            if emu.produced != at["produced"]:
                at["produced"], at["given"] = emu.produced, 0
            t = emu.sampled_at(emu.produced + at["given"], n)
            at["given"] += n
            accel = sim.next(n).accel + motion.at(i, t)
            return np.clip(np.rint(accel / lsb), -(1 << 19), (1 << 19) - 1).astype(np.int32)

        emu = EmulatedAdxl355(source, clock, odr_error_ppm=0.0, temperature=25.0)
        part.append(emu)
        bus: Any = (SpiBus(FakeSpiDev(emu)) if s.bus.kind == "spi"
                    else I2cBus(FakeSMBus(emu, address=s.bus.address, bus=s.bus.number),
                                address=s.bus.address))
        out.append((s.name, Adxl355(bus, clock=clock,
                                    temp_intercept_lsb=s.temp_intercept_lsb), emu))
    return clock, out
