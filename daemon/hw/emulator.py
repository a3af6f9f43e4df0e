"""A register-level ADXL355 emulator that follows the datasheet, behind fake spidev/smbus2 objects.

Nobody on the project has the hardware at hand, so this is what keeps the driver honest. The
emulated part has

* a register file with the datasheet's reset values (:mod:`.registers`); configuration
  registers accept writes only in standby (writes in measurement mode are ignored and counted
  in ``ignored_writes``); RESET (0x52) restores every default and sets NVM_BUSY for a while;
* a FIFO of 96 one-axis locations plus the 3-location sync buffer: X entries carry the marker
  bit, reads of an empty FIFO carry the empty bit, a burst at FIFO_DATA pops one entry on its
  first byte and every third byte after (the address does not advance), FIFO_ENTRIES reports
  up to 96, FIFO_FULL is set at the FIFO_SAMPLES watermark, a write past 99 locations sets
  FIFO_OVR and the newest data overwrite the oldest; reading STATUS clears FIFO_OVR;
  entering standby clears the FIFO;
* samples produced at the configured ODR, off by ``odr_error_ppm`` like a real part's internal
  clock, from a pluggable ``source(n) -> (n, 3) int`` of raw counts, against a clock that is a
  :class:`VirtualClock` (advanced by the test, or running at ``speed`` × real time);
* the TEMP registers following a temperature source ``() -> °C``, read per register (not
  double-buffered, so a burst can tear as on the part); offsets (1 offset LSB = 16
  data LSB, added to the output); self-test (ST1+ST2 adds the electrostatic deflection);
* faults on demand (:class:`BusFaults`): EIO once or always, a bus stuck at 0xFF/0x00
  (unplugged) and coming back, a device that stops producing samples, a FIFO that starts
  mid-set.

:class:`FakeSpiDev` and :class:`FakeSMBus` present the methods of ``spidev.SpiDev`` and
``smbus2.SMBus`` that the transports use, so :class:`~avard.daemon.hw.transport.SpiBus` and
:class:`~avard.daemon.hw.transport.I2cBus` run over the emulator unchanged.
"""

from __future__ import annotations

import ctypes
import errno
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from avard.daemon.hw import registers as R

log = logging.getLogger(__name__)

Source = Callable[[int], Any]  # source(n) -> (n, 3) int raw counts
TemperatureSource = Callable[[], float]  # () -> °C

_FIFO = R.ADDR["FIFO_DATA"]
_EMPTY_ENTRY = bytes([0x00, 0x00, R.FIFO_MARK_EMPTY])
# The registers the output adjustment depends on (offsets, self-test, range).
_OFFSET_FIRST, _OFFSET_LAST = R.ADDR["OFFSET_X_H"], R.ADDR["OFFSET_Z_L"]
_SELF_TEST, _RANGE = R.ADDR["SELF_TEST"], R.ADDR["RANGE"]


class VirtualClock:
    """A monotonic + wall clock the test advances, or that runs at ``speed`` × real time.

    * ``VirtualClock()``: time stands still until :meth:`advance` (or :meth:`sleep`, which
      advances instead of blocking), so a test can play hours of acquisition in milliseconds.
    * ``VirtualClock(speed=1.0)``: real time; ``speed=10`` runs ten times faster (``--speed``).

    ``monotonic()`` plays CLOCK_MONOTONIC, ``realtime()`` CLOCK_REALTIME (which
    :meth:`step_realtime` can step, as NTP does), both in seconds.
    """

    def __init__(self, start: float = 1000.0, *, speed: float | None = None,
                 epoch: float = 1.7e9) -> None:
        if speed is not None and speed <= 0:
            raise ValueError("speed must be positive")
        self.speed = speed
        self._offset = float(start)
        self._real0 = time.monotonic()
        self._epoch = float(epoch)
        self._lock = threading.Lock()

    def monotonic(self) -> float:
        if self.speed is None:
            return self._offset
        return self._offset + self.speed * (time.monotonic() - self._real0)

    def realtime(self) -> float:
        return self.monotonic() + self._epoch

    def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds`` (both clocks)."""
        if seconds < 0:
            raise ValueError("a monotonic clock never goes back")
        with self._lock:
            self._offset += seconds

    def sleep(self, seconds: float) -> None:
        if seconds <= 0:
            return
        if self.speed is None:
            self.advance(seconds)
        else:
            time.sleep(seconds / self.speed)

    def step_realtime(self, seconds: float) -> None:
        """Step CLOCK_REALTIME only (an NTP correction, a manual date change)."""
        self._epoch += seconds


def constant_source(counts: Sequence[int] = (0, 0, 256000)) -> Source:
    """A source that always returns the same raw counts (default: 1 g on Z at ±2 g)."""
    row = np.asarray(counts, dtype=np.int32).reshape(1, 3)

    def source(n: int) -> np.ndarray:
        return np.repeat(row, n, axis=0)

    return source


def array_source(data: Any, *, loop: bool = False) -> Source:
    """A source that plays an (N, 3) array of counts; past its end it repeats the last row
    (or starts over with ``loop=True``)."""
    arr = np.asarray(data, dtype=np.int32).reshape(-1, 3)
    if len(arr) == 0:
        raise ValueError("array_source needs at least one row")
    pos = 0

    def source(n: int) -> np.ndarray:
        nonlocal pos
        if loop:
            idx = (pos + np.arange(n)) % len(arr)
        else:
            idx = np.minimum(pos + np.arange(n), len(arr) - 1)
        pos += n
        return arr[idx]

    return source


def counter_source(start: int = 0) -> Source:
    """Sample k has counts (k, −k, k + 7) modulo 2^19: every set is distinct and its index can
    be read back from the data, which makes losses and duplications visible in tests."""
    pos = start

    def source(n: int) -> np.ndarray:
        nonlocal pos
        k = (pos + np.arange(n, dtype=np.int64)) % (1 << 19)
        pos += n
        return np.stack([k, -k, (k + 7) % (1 << 19)], axis=1).astype(np.int32)

    return source


def _saturate(c: np.ndarray) -> np.ndarray:
    """Counts held to the 20-bit output range (np.clip's per-call overhead is several times
    this on the 16-set blocks of a drain)."""
    return np.minimum(np.maximum(c, R.DATA_MIN), R.DATA_MAX)


def encode_entries(counts: np.ndarray) -> bytes:
    """FIFO bytes for (k, 3) counts: 3 bytes per axis, left-justified 20-bit two's complement,
    MSB first; the X entry of each set carries the marker bit (third byte, bit 0)."""
    return _encode_in_range(_saturate(np.asarray(counts, dtype=np.int64).reshape(-1, 3)))


def _encode_in_range(c: np.ndarray) -> bytes:
    """:func:`encode_entries` of (k, 3) counts already held to the 20-bit range: the 20 bits
    shifted to the top of a 24-bit big-endian word are the entry's three bytes (the low
    nibble of the third is 0 but for the marker)."""
    word = ((c & 0xFFFFF) << 4).astype(">u4").view(np.uint8).reshape(-1, 4)
    out = np.ascontiguousarray(word[:, 1:])
    out[0::3, 2] |= R.FIFO_MARK_X
    return out.tobytes()


class BusFaults:
    """Faults of the wire between host and chip, shared by the fake bus objects.

    ``fail_next(n)`` makes the next ``n`` transfers raise ``OSError(EIO)``; ``fail_always()``
    makes every transfer fail until :meth:`clear`; ``unplug(0xFF)`` / ``unplug(0x00)`` makes
    SPI reads return that level (MISO pulled up or down, writes lost; on I2C nothing acks:
    ``OSError(EREMOTEIO)``) until :meth:`replug`.
    """

    def __init__(self) -> None:
        self.eio_count = 0
        self.eio_always = False
        self.stuck_level: int | None = None
        self.injected = 0  # how many transfers failed on purpose

    def fail_next(self, n: int = 1) -> None:
        self.eio_count += int(n)

    def fail_always(self, on: bool = True) -> None:
        self.eio_always = on

    def unplug(self, level: int = 0xFF) -> None:
        if level not in (0x00, 0xFF):
            raise ValueError("an unplugged bus reads 0x00 or 0xFF")
        self.stuck_level = level

    def replug(self) -> None:
        self.stuck_level = None

    def clear(self) -> None:
        self.eio_count = 0
        self.eio_always = False
        self.stuck_level = None

    def check(self) -> None:
        """Raise the injected OSError for this transfer, if any."""
        if self.eio_always or self.eio_count > 0:
            if self.eio_count > 0:
                self.eio_count -= 1
            self.injected += 1
            raise OSError(errno.EIO, "Input/output error (injected)")


class EmulatedAdxl355:
    """The chip: registers, FIFO, sample production, temperature, self-test, faults.

    Parameters
    ----------
    source
        ``source(n) -> (n, 3)`` raw counts as the part would output them at the configured
        range (default: 1 g on Z at ±2 g). A ``SensorSimulator`` adapts with
        ``lambda n: sim.next(n).counts``.
    clock
        Anything with ``monotonic()`` (seconds); default a manual :class:`VirtualClock`.
    odr_error_ppm
        The part's internal clock error: the real rate is ``odr × (1 + ppm·1e-6)``.
    temperature
        ``() -> °C`` or a constant, read whenever the TEMP registers are read.
    """

    def __init__(self, source: Source | None = None, clock: Any = None,
                 odr_error_ppm: float = 0.0, temperature: TemperatureSource | float = 25.0, *,
                 partid: int = R.PARTID_ADXL355, revid: int = 0x01,
                 temp_intercept_lsb: float = R.TEMP_INTERCEPT_LATER,
                 nvm_busy_s: float = 0.002,
                 self_test_g: Sequence[float] = R.SELF_TEST_TYPICAL_G,
                 temp_double_buffered: bool = False,
                 chunk: int = 1 << 16) -> None:
        self.source: Source = source if source is not None else constant_source()
        self.clock = clock if clock is not None else VirtualClock()
        self.odr_error_ppm = float(odr_error_ppm)
        self.temperature = temperature
        self.partid = partid
        self.revid = revid
        self.temp_intercept_lsb = float(temp_intercept_lsb)
        self.nvm_busy_s = float(nvm_busy_s)
        self.self_test_g = tuple(float(g) for g in self_test_g)
        self.temp_double_buffered = bool(temp_double_buffered)
        self.chunk = int(chunk)
        self.faults = BusFaults()
        self.lock = threading.RLock()
        self.ignored_writes: list[tuple[int, int]] = []  # (address, value) refused in measure
        self.produced = 0  # sets produced since the last start of measurement
        self.produced_total = 0  # sets produced over the emulator's life
        self.lost = 0  # sets overwritten by newer data (overrun)
        #: sets the part's own time line had due while it made none, between its first
        #: measurement and the next it made (a stall, standby after a power cycle or a reset):
        #: with ``produced_total`` the samples a gap-sized-by-time record accounts for
        self.missed_total = 0
        self._idle_since: tuple[float, float] | None = None   # (t, rate) production stopped
        self.stalled = False
        self._measuring = False
        self._reset_state()

    # -- state ---------------------------------------------------------------------------
    def _production_stops(self) -> None:
        """The part stops making sets now (it was making them): its time line goes on."""
        if self._measuring and not self.stalled and self._idle_since is None:
            self._update()
            self._idle_since = (self.clock.monotonic(), self.true_odr_hz)

    def _production_resumes(self) -> None:
        """The part makes sets again from now: the sets its time line had due meanwhile."""
        if self._idle_since is not None and self._measuring and not self.stalled:
            t0, rate = self._idle_since
            self.missed_total += max(0, round((self.clock.monotonic() - t0) * rate))
            self._idle_since = None

    def _reset_state(self) -> None:
        self._production_stops()     # a reset or a power cycle while measuring
        self.regs = bytearray(R.N_REGISTERS)
        for reg in R.REGISTERS.values():
            self.regs[reg.address] = reg.reset
        self.regs[R.ADDR["PARTID"]] = self.partid
        self.regs[R.ADDR["REVID"]] = self.revid
        self.fifo = bytearray()  # entries of 3 bytes, oldest first; ≤ 99 locations
        self._ovr = False
        self._data_rdy = False
        self._latest = np.zeros(3, dtype=np.int64)
        self._adjust_key = b""
        self._adjust: np.ndarray | None = None
        self._measuring = False
        self._t_start = 0.0
        self.produced = 0
        self._nvm_busy_until = -math.inf

    @property
    def measuring(self) -> bool:
        return self._measuring

    @property
    def odr_hz(self) -> float:
        """Nominal ODR of the current FILTER setting, Hz."""
        return R.RATE_BY_CODE.get(self.regs[R.ADDR["FILTER"]] & 0x0F, R.RATES[-1]).odr_hz

    @property
    def true_odr_hz(self) -> float:
        """The rate the emulated part really produces at, Hz (nominal × (1 + ppm·1e-6))."""
        return self.odr_hz * (1.0 + 1e-6 * self.odr_error_ppm)

    @property
    def fifo_entries(self) -> int:
        return len(self.fifo) // 3

    def int_level(self, pin: int = 1) -> bool:
        """The INT1/INT2 pin's electrical level now: the sources INT_MAP routes to it (FIFO
        watermark, data ready, overrun), driven active high or low by RANGE.INT_POL."""
        with self.lock:
            self._update()
            status = self._status()
            imap = self.regs[R.ADDR["INT_MAP"]] >> (4 if pin == 2 else 0)
            active = bool((imap & R.INT_MAP_RDY_EN1 and status & R.STATUS_DATA_RDY)
                          or (imap & R.INT_MAP_FULL_EN1 and status & R.STATUS_FIFO_FULL)
                          or (imap & 0x04 and status & R.STATUS_FIFO_OVR))
            high = bool(self.regs[R.ADDR["RANGE"]] & 0x40)
            return active if high else not active

    def seconds_to_int(self, pin: int = 1) -> float:
        """When the pin will next assert from the FIFO watermark or data ready, the sources
        this model schedules (inf when INT_MAP routes neither to it or nothing is produced)."""
        with self.lock:
            imap = self.regs[R.ADDR["INT_MAP"]] >> (4 if pin == 2 else 0)
            if imap & R.INT_MAP_FULL_EN1:
                return self.seconds_to_watermark()
            if imap & R.INT_MAP_RDY_EN1 and self._measuring and not self.stalled:
                self._update()
                due = self._t_start + (self.produced + 1) / self.true_odr_hz
                return max(0.0, due - self.clock.monotonic())
            return math.inf

    def seconds_to_watermark(self) -> float:
        """When the FIFO will reach its FIFO_SAMPLES watermark (0 if it has; inf when the part
        is not producing)."""
        with self.lock:
            self._update()
            if not self._measuring or self.stalled:
                return math.inf
            wm = self.regs[R.ADDR["FIFO_SAMPLES"]] & 0x7F
            missing_sets = -(-(wm - self.fifo_entries) // 3)
            if missing_sets <= 0:
                return 0.0
            due = self.produced + missing_sets       # set number that completes the watermark
            return max(0.0, self._t_start + due / self.true_odr_hz - self.clock.monotonic())

    def range_g(self) -> int:
        return R.RANGE_BY_CODE.get(self.regs[R.ADDR["RANGE"]] & 0x03, 2)

    # -- faults on the device side ---------------------------------------------------------
    def stop_producing(self) -> None:
        """The part keeps answering on the bus but produces no new samples."""
        with self.lock:
            self._production_stops()
            self._update()
            self.stalled = True

    def resume_producing(self) -> None:
        """Production restarts from now (the samples of the stall are never made)."""
        with self.lock:
            self.stalled = False
            self._t_start = self.clock.monotonic() - self.produced / self.true_odr_hz
            self._production_resumes()

    def set_odr_error_ppm(self, ppm: float) -> None:
        """Change the oscillator error from now on (a temperature-driven drift), without
        producing or losing samples at the change."""
        with self.lock:
            self._update()
            now = self.clock.monotonic()
            # keep the phase within the current sample period across the change
            done = (now - self._t_start) * self.true_odr_hz if self._measuring else 0.0
            self.odr_error_ppm = float(ppm)
            if self._measuring:
                self._t_start = now - done / self.true_odr_hz

    def drop_fifo_entries(self, k: int = 1) -> None:
        """Remove the ``k`` oldest FIFO entries, leaving the FIFO mid-set (as after a partial
        read by someone else); the driver must realign on the X marker."""
        with self.lock:
            self._update()
            del self.fifo[: 3 * k]

    def power_cycle(self) -> None:
        """Power lost and back: every register at its reset value, standby, FIFO empty."""
        with self.lock:
            self._reset_state()

    def sampled_at(self, first: int, n: int) -> np.ndarray:
        """The CLOCK_MONOTONIC instants (s) at which sets ``first`` … ``first + n − 1`` of the
        current measurement are taken (each at the end of its period, when it becomes due):
        what a source shared by several parts needs to give each the input at its own time."""
        return self._t_start + (first + 1 + np.arange(n)) / self.true_odr_hz

    # -- sample production ---------------------------------------------------------------
    def _update(self) -> None:
        """Produce every set due by now (lazily, at each bus access)."""
        if not self._measuring or self.stalled:
            return
        now = self.clock.monotonic()
        due = math.floor((now - self._t_start) * self.true_odr_hz + 1e-9)
        k = due - self.produced
        if k > 0:
            self._produce(k)

    def _produce(self, k: int) -> None:
        keep = R.FIFO_OVERRUN_LOCATIONS // 3 + 1  # only the newest sets can survive in a FIFO
        tail: list[np.ndarray] = []
        left = k
        while left > 0:
            n = min(left, self.chunk)
            block = np.asarray(self.source(n))
            if block.shape != (n, 3):
                raise ValueError(f"sample source returned shape {block.shape}, expected ({n}, 3)")
            tail.append(block[-keep:])
            left -= n
        new = (tail[0] if len(tail) == 1 else np.concatenate(tail)[-keep:]).astype(np.int64)
        adjust = self._output_adjust()
        if adjust is not None:
            new += adjust
        new = _saturate(new)
        self._latest = new[-1].copy()
        self._data_rdy = True
        self.produced += k
        self.produced_total += k
        skipped = k - len(new)  # sets that were overwritten before they could even be stored
        self.fifo += _encode_in_range(new)
        excess = len(self.fifo) - 3 * R.FIFO_OVERRUN_LOCATIONS
        if excess > 0 or skipped > 0:
            # A write past 99 locations: the newest data overwrite the oldest.
            if excess > 0:
                del self.fifo[:excess]
            self._ovr = True
            self.lost += skipped + max(excess, 0) // R.SET_BYTES

    def _output_adjust(self) -> np.ndarray | None:
        """What the part adds after the source: offset registers and self-test deflection
        (None when nothing). Computed again only when those registers change: this runs at
        every drain."""
        key = bytes(self.regs[_OFFSET_FIRST:_OFFSET_LAST + 1]) + bytes(
            (self.regs[_SELF_TEST], self.regs[_RANGE]))
        if key != self._adjust_key:
            self._adjust_key = key
            adj = self._compute_output_adjust()
            self._adjust = adj if adj.any() else None
        return self._adjust

    def _compute_output_adjust(self) -> np.ndarray:
        adj = np.zeros(3, dtype=np.int64)
        for i, axis in enumerate("XYZ"):
            hi = self.regs[R.ADDR[f"OFFSET_{axis}_H"]]
            lo = self.regs[R.ADDR[f"OFFSET_{axis}_L"]]
            off = (hi << 8) | lo
            off -= (off & 0x8000) << 1
            adj[i] += off * R.OFFSET_LSB_COUNTS
        st = self.regs[R.ADDR["SELF_TEST"]]
        if st & R.SELF_TEST_ST1 and st & R.SELF_TEST_ST2:
            sens = R.sensitivity_lsb_per_g(self.range_g())
            adj += np.round(np.asarray(self.self_test_g) * sens).astype(np.int64)
        return adj

    # -- register reads ----------------------------------------------------------------------
    def _status(self) -> int:
        now = self.clock.monotonic()
        s = 0
        if self._data_rdy:
            s |= R.STATUS_DATA_RDY
        wm = self.regs[R.ADDR["FIFO_SAMPLES"]] & 0x7F
        if wm and min(self.fifo_entries, R.FIFO_LOCATIONS) >= wm:
            s |= R.STATUS_FIFO_FULL
        if self._ovr:
            s |= R.STATUS_FIFO_OVR
        if now < self._nvm_busy_until:
            s |= R.STATUS_NVM_BUSY
        return s

    def _temp_raw(self) -> int:
        t = self.temperature() if callable(self.temperature) else self.temperature
        return R.raw_from_temperature(float(t), self.temp_intercept_lsb)

    def _data_bytes(self) -> bytes:
        v = (int(x) & 0xFFFFF for x in self._latest)
        out = bytearray()
        for x in v:
            out += bytes([(x >> 12) & 0xFF, (x >> 4) & 0xFF, (x & 0x0F) << 4])
        return bytes(out)

    def _pop(self, n_entries: int) -> bytes:
        have = min(n_entries, self.fifo_entries)
        out = bytes(self.fifo[: 3 * have])
        del self.fifo[: 3 * have]
        return out + _EMPTY_ENTRY * (n_entries - have)

    def read(self, addr: int, n: int) -> bytes:
        """One read transaction of ``n`` bytes starting at ``addr`` (auto-increment, which
        stops at FIFO_DATA)."""
        with self.lock:
            self._update()
            out = bytearray()
            a = addr
            snapshot: dict[str, Any] = {}
            while len(out) < n:
                if a == _FIFO:
                    m = n - len(out)
                    # pops one entry on the first byte and every third byte after it
                    out += self._pop(-(-m // 3))[:m]
                    break
                out.append(self._read_reg(a, snapshot))
                a += 1
            return bytes(out)

    def _read_reg(self, a: int, snap: dict[str, Any]) -> int:
        if a == R.ADDR["STATUS"]:
            s = self._status()
            self._ovr = False  # reading STATUS clears FIFO_OVR
            self._data_rdy = False
            return s
        if a == R.ADDR["FIFO_ENTRIES"]:
            return min(self.fifo_entries, R.FIFO_LOCATIONS)
        if a in (R.ADDR["TEMP2"], R.ADDR["TEMP1"]):
            # TEMP2/TEMP1 are not double-buffered on the part: each register shows the
            # temperature of the moment it is read, so a burst can tear across a change of
            # TEMP2 (e.g. 0x6FF → 0x700 read as 0x600). ``temp_double_buffered`` turns that off.
            if "temp" not in snap or not self.temp_double_buffered:
                snap["temp"] = self._temp_raw()
            raw = snap["temp"]
            return (raw >> 8) & 0x0F if a == R.ADDR["TEMP2"] else raw & 0xFF
        if R.ADDR["XDATA3"] <= a <= R.ADDR["ZDATA1"]:
            if "data" not in snap:
                snap["data"] = self._data_bytes()
            return snap["data"][a - R.ADDR["XDATA3"]]
        if a == R.ADDR["RESET"] or a >= R.N_REGISTERS:
            return 0x00
        return self.regs[a]

    # -- register writes -----------------------------------------------------------------
    def write(self, addr: int, data: bytes | Sequence[int]) -> None:
        """One write transaction: bytes to ``addr``, ``addr + 1``, … (auto-increment)."""
        with self.lock:
            self._update()
            for i, value in enumerate(bytes(data)):
                self._write_reg(addr + i, value)

    def _write_reg(self, a: int, value: int) -> None:
        reg = R.BY_ADDRESS.get(a)
        if reg is None or reg.access == "r":
            return
        if a == R.ADDR["RESET"]:
            if value == R.RESET_CODE:
                self._reset_state()
                self._nvm_busy_until = self.clock.monotonic() + self.nvm_busy_s
            return
        if reg.config and self._measuring:
            # The datasheet: program configuration registers in standby only.
            self.ignored_writes.append((a, value))
            log.debug("emulator: write 0x%02X to %s ignored in measurement mode", value, reg.name)
            return
        if a == R.ADDR["POWER_CTL"]:
            standby = bool(value & R.POWER_STANDBY)
            if standby and self._measuring:
                self._production_stops()
                self._measuring = False
                self.fifo.clear()  # entering standby clears the FIFO
                self._ovr = False
            elif not standby and not self._measuring:
                self._measuring = True
                self._t_start = self.clock.monotonic()
                self.produced = 0
                self._production_resumes()
        self.regs[a] = value & 0xFF

    # -- SPI framing -----------------------------------------------------------------------
    def spi_transfer(self, tx: Sequence[int]) -> list[int]:
        """One CS-asserted SPI transfer: command byte ``addr << 1 | R/W``, then data."""
        if not tx:
            return []
        cmd = tx[0] & 0xFF
        addr = cmd >> 1
        if cmd & 1:
            return [0, *list(self.read(addr, len(tx) - 1))]
        self.write(addr, bytes(b & 0xFF for b in tx[1:]))
        return [0x00] * len(tx)


class FakeSpiDev:
    """The ``spidev.SpiDev`` surface (open, close, xfer2, xfer, mode, max_speed_hz, …) over an
    :class:`EmulatedAdxl355`. A mode other than 0 garbles the data as a real mode mismatch
    would (every byte shifted by one bit); more than 4096 bytes per transfer raises
    ``OverflowError`` like py-spidev."""

    def __init__(self, device: EmulatedAdxl355, max_transfer: int = 4096) -> None:
        self.device = device
        self.mode = 0
        self.max_speed_hz = 500_000
        self.bits_per_word = 8
        self.lsbfirst = False
        self.cshigh = False
        self.threewire = False
        self.no_cs = False
        self.max_transfer = max_transfer
        self.opened: tuple[int, int] | None = None
        self.closed = False
        self.bytes_transferred = 0

    def open(self, bus: int, device: int) -> None:
        self.opened = (bus, device)
        self.closed = False

    def close(self) -> None:
        self.closed = True

    def xfer2(self, values: Sequence[int], *_args: Any) -> list[int]:
        if self.closed:
            raise OSError(errno.EBADF, "Bad file descriptor")
        if len(values) > self.max_transfer:
            raise OverflowError(f"Argument list size exceeds {self.max_transfer} bytes.")
        faults = self.device.faults
        faults.check()
        self.bytes_transferred += len(values)
        if faults.stuck_level is not None:
            return [faults.stuck_level] * len(values)
        if self.mode != 0:
            # Sampling on the wrong edge: the host sees the chip's bits one position late.
            rx = self.device.spi_transfer([values[0] | 1, *values[1:]]) if values[0] & 1 \
                else [0] * len(values)
            return [((b >> 1) | ((p & 1) << 7)) & 0xFF for p, b in zip([0, *rx[:-1]], rx,
                                                                       strict=True)]
        return self.device.spi_transfer(list(values))

    xfer = xfer2

    def readbytes(self, n: int) -> list[int]:
        return self.xfer2([0] * n)

    def writebytes(self, values: Sequence[int]) -> None:
        self.xfer2(list(values))


class FakeSMBus:
    """The ``smbus2.SMBus`` surface the transports use, over an :class:`EmulatedAdxl355` at
    7-bit ``address``. Another address does not ack: ``OSError(EREMOTEIO)``, as on Linux."""

    def __init__(self, device: EmulatedAdxl355, address: int = 0x1D, bus: int = 1) -> None:
        self.device = device
        self.address = address
        self.bus = bus
        self.closed = False
        self._pointer = 0

    def _check(self, i2c_addr: int) -> None:
        if self.closed:
            raise OSError(errno.EBADF, "Bad file descriptor")
        self.device.faults.check()
        if i2c_addr != self.address or self.device.faults.stuck_level is not None:
            raise OSError(errno.EREMOTEIO, "Remote I/O error")

    def close(self) -> None:
        self.closed = True

    def read_byte_data(self, i2c_addr: int, register: int, force: Any = None) -> int:
        self._check(i2c_addr)
        return self.device.read(register, 1)[0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int,
                        force: Any = None) -> None:
        self._check(i2c_addr)
        self.device.write(register, bytes([value & 0xFF]))

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int,
                            force: Any = None) -> list[int]:
        if length > 32:
            raise ValueError("Desired block length over 32 bytes")
        self._check(i2c_addr)
        return list(self.device.read(register, length))

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int],
                             force: Any = None) -> None:
        if len(data) > 32:
            raise ValueError("Data length cannot exceed 32 bytes")
        self._check(i2c_addr)
        self.device.write(register, bytes(data))

    def i2c_rdwr(self, *msgs: Any) -> None:
        """Combined transaction: a write sets the register pointer (and writes any further
        bytes), a read reads a burst from the pointer (flag I2C_M_RD = 1)."""
        for msg in msgs:
            self._check(msg.addr)
        for msg in msgs:
            if msg.flags & 0x0001:
                data = self.device.read(self._pointer, msg.len)
                ctypes.memmove(msg.buf, data, len(data))
            else:
                payload = bytes(msg)
                if payload:
                    self._pointer = payload[0]
                    if len(payload) > 1:
                        self.device.write(payload[0], payload[1:])
