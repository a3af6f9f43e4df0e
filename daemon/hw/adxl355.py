"""ADXL355 driver: probe, reset, configure, FIFO drain with marker checks, temperature,
self-test and offsets, over any :class:`~avard.daemon.hw.transport.RegisterBus`.

Facts used here are in ``../shared/notes/adxl355.md`` (datasheet Rev. 0+, the Linux IIO
driver, ADI's no-OS driver). The parts that bite and how they are handled:

* The FIFO holds single-axis entries; a drain reads FIFO_ENTRIES, takes whole XYZ sets only,
  bursts them in one transfer, checks the X marker of each set and the empty bit of each entry,
  and realigns on the markers when the FIFO does not start with X (ADI no-OS issue 2431).
  Entries of an unfinished set at the end of a burst are carried to the next drain, so a
  misaligned FIFO costs one set once, not one set per drain.
* STATUS.FIFO_OVR means newer data overwrote older: the chip does not say how many sets
  were lost. The drain says so (``overrun=True``) with the moment of its burst read
  (``t_burst``: the FIFO was full then, so the first set read is the FIFO_FULL_SETS-th
  newest), and the moment measurement started (``Adxl355.t_started``); the service counts the
  loss from time and records a gap of that size. The driver's ``index0`` counts the sets
  received only.
* A failed transfer during a drain may have popped entries or cleared FIFO_OVR on the chip, so
  it is also reported as a gap (``gap_reason`` says which), after ``retries`` attempts.
* TEMP2/TEMP1 are not double-buffered: they are read in one burst and re-read if TEMP2 moved.
"""

from __future__ import annotations

import errno
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from avard.core.errors import (
    BusError,
    ConfigError,
    DeviceStalledError,
    HardwareError,
)
from avard.daemon.hw import registers as R
from avard.daemon.hw.source import GapReason, parse_reasons
from avard.daemon.hw.timebase import SystemClock, read_clock_pair
from avard.daemon.hw.transport import I2cBus, RegisterBus

log = logging.getLogger(__name__)
_T = TypeVar("_T")

A = R.ADDR


def _often(count: int) -> bool:
    """Whether the ``count``-th repeat of a problem is worth a WARNING line: the first ten, then
    one in a thousand (a bus fault at 100 polls/s must not flood the journal)."""
    return count <= 10 or count % 1000 == 0


# -- decoding ----------------------------------------------------------------------------------
def decode_counts(data: bytes | bytearray | np.ndarray) -> np.ndarray:
    """Raw 20-bit values of 3-byte entries, vectorised: ``(b0 << 12) | (b1 << 4) | (b2 >> 4)``
    sign-extended from bit 19. Returns an int32 array with one value per entry."""
    return _decode_entries(np.frombuffer(bytes(data), dtype=np.uint8).reshape(-1, 3))


def _decode_entries(a: np.ndarray) -> np.ndarray:
    """:func:`decode_counts` of (m, 3) entry bytes: the three bytes, MSB first, as the top of
    a big-endian int32 whose arithmetic shift right by 12 is the sign-extended 20-bit value
    (four numpy calls; the drain's decode runs 250 times a second at 4 kHz)."""
    word = np.zeros((a.shape[0], 4), dtype=np.uint8)
    word[:, :3] = a
    return (word.view(">i4").reshape(-1) >> 12).astype(np.int32)


def decode_counts_naive(data: bytes) -> list[int]:
    """The same decode one entry at a time in plain Python (reference for tests/benchmarks)."""
    out = []
    for i in range(0, len(data) - len(data) % 3, 3):
        v = (data[i] << 12) | (data[i + 1] << 4) | (data[i + 2] >> 4)
        out.append(v - (1 << 20) if v & 0x80000 else v)
    return out


#: The marker bits of a well-formed burst: X on every third entry, none empty (fast path of
#: :func:`decode_fifo`, long enough for any burst of the 96-entry FIFO plus a carried set).
_XYZ_MARKS = bytes([R.FIFO_MARK_X, 0, 0]) * (2 * R.FIFO_LOCATIONS)


@dataclass(frozen=True)
class FifoDecode:
    """Result of :func:`decode_fifo`.

    ``counts`` (n, 3) int32 complete sets, oldest first; ``dropped`` entries thrown away
    because they were not part of a complete X-Y-Z set (their data are lost); ``empty``
    entries read with the empty bit (no data); ``carry`` the bytes of a set whose X (and maybe
    Y) entries were read but whose rest is still in the FIFO."""

    counts: np.ndarray
    dropped: int
    empty: int
    carry: bytes


def decode_fifo(buf: bytes | bytearray) -> FifoDecode:
    """Decode a FIFO burst into XYZ sets, checking markers and realigning when needed.

    Fast path: entries come as X,Y,Z,X,Y,Z… with the X marker exactly on every third entry and
    no empty bit (the normal case). Otherwise every X-marked entry followed by two non-X,
    non-empty entries starts a set; everything else is dropped, except an unfinished set at the
    very end (carried over).
    """
    nb = len(buf) - len(buf) % 3
    a = np.frombuffer(bytes(buf[:nb]), dtype=np.uint8).reshape(-1, 3)
    m = len(a)
    if m == 0:
        return FifoDecode(np.empty((0, 3), np.int32), 0, 0, b"")
    b2 = a[:, 2]
    marks = b2 & (R.FIFO_MARK_X | R.FIFO_MARK_EMPTY)
    if m % 3 == 0 and marks.tobytes() == _XYZ_MARKS[:m]:
        return FifoDecode(_decode_entries(a).reshape(-1, 3), 0, 0, b"")
    is_x = (b2 & R.FIFO_MARK_X).astype(bool)
    empty = (b2 & R.FIFO_MARK_EMPTY).astype(bool)
    raw = _decode_entries(a)
    n_empty = int(empty.sum())
    keep = np.flatnonzero(~empty)
    vx = is_x[keep]
    k = len(keep)
    xpos = np.flatnonzero(vx)
    ok = xpos[(xpos + 2 < k)]
    ok = ok[~vx[np.minimum(ok + 1, k - 1)] & ~vx[np.minimum(ok + 2, k - 1)]]
    sets = raw[keep[ok[:, None] + np.arange(3)]] if len(ok) else np.empty((0, 3), np.int32)
    carry = b""
    if len(xpos) and xpos[-1] + 2 >= k and not vx[xpos[-1] + 1:].any():
        # An unfinished set at the end: its remaining entries are still in the FIFO — unless
        # the FIFO ran dry after it (empty entries follow), in which case it cannot complete.
        start = keep[xpos[-1]]
        if not empty[start:].any():
            carry = a[start:].tobytes()
    dropped = k - 3 * len(ok) - len(carry) // 3
    return FifoDecode(np.ascontiguousarray(sets, dtype=np.int32), int(dropped), n_empty, carry)


def fit_temperature_intercept(raw: Any, reference_c: Any) -> tuple[float, float]:
    """Calibrate the TEMP intercept against a reference thermometer (a DS18B20 on the plate).

    With the datasheet slope fixed, T = 25 + (raw − b)/(−9.05) gives for each pair
    b_i = raw_i + 9.05·(T_i − 25); the estimate is their mean and its 1σ standard error
    s/√n (LSB). Pairs with a NaN reference (missing DS18B20 readings) are ignored. Use pairs
    taken in thermal equilibrium: the die runs warmer than the plate while measuring.
    """
    r = np.asarray(raw, dtype=float).ravel()
    t = np.asarray(reference_c, dtype=float).ravel()
    if r.shape != t.shape:
        raise ConfigError(f"{r.size} TEMP values but {t.size} reference temperatures")
    ok = np.isfinite(r) & np.isfinite(t)
    if ok.sum() < 2:
        raise ConfigError("need at least two (TEMP, reference °C) pairs to fit the intercept")
    b = r[ok] - R.TEMP_SLOPE_LSB_PER_C * (t[ok] - 25.0)
    return float(b.mean()), float(b.std(ddof=1) / np.sqrt(b.size))


# -- results -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DeviceInfo:
    devid_ad: int
    devid_mst: int
    partid: int
    revid: int

    @property
    def name(self) -> str:
        return "ADXL359" if self.partid == R.PARTID_ADXL359 else "ADXL355"


@dataclass(frozen=True)
class Drain:
    """One FIFO drain.

    counts      (n, 3) int32 raw counts X, Y, Z, oldest first (× ``Adxl355.scale_mps2`` → m/s²)
    overrun     True when a gap of unknown size precedes ``counts[0]`` (FIFO overrun,
                misaligned data dropped, a failed transfer, a restart); see ``gap_reason``
    t_mono      CLOCK_MONOTONIC, s, just before FIFO_ENTRIES was read: the newest set in
                ``counts`` was produced within one sample period before it
    t_real      CLOCK_REALTIME, s, at the same moment (for records; never for ordering)
    index0      sample index of ``counts[0]``: sets received before it (lost sets not counted)
    """

    counts: np.ndarray
    overrun: bool
    t_mono: float
    t_real: float
    index0: int
    gap_reason: str | None = None
    status: int = 0
    fifo_entries: int = 0
    dropped_entries: int = 0
    t_mono_end: float = 0.0
    #: True when the newest set in the FIFO at ``t_mono`` is ``counts[-1]``: all counted sets
    #: were read, FIFO_ENTRIES was below 96 (at 96 the sync buffer may hold one more set),
    #: the STATUS/FIFO_ENTRIES read finished within one sample period of ``t_mono`` and no
    #: overrun happened during the drain. Only such drains feed the time-base fit.
    complete: bool = True
    #: CLOCK_MONOTONIC seconds since the previous drain's stamp (None for the first).
    since_last_s: float | None = None
    #: CLOCK_MONOTONIC just before the FIFO_DATA burst (``t_mono`` when there was none). After
    #: an overrun the FIFO is full at that moment: ``counts[0]`` is the
    #: ``FIFO_FULL_SETS``-th newest set then, which dates it (the loss before it is counted
    #: from time: service/acquisition.py).
    t_burst: float = 0.0
    #: CLOCK_MONOTONIC just after the burst returned: a burst that took longer than a sample
    #: period was pre-empted, and its sets were taken from the FIFO near its end
    t_burst_end: float = 0.0
    #: uncertainty of ``t_real`` as the CLOCK_REALTIME of the moment ``t_mono``, s
    t_real_u: float = 0.0
    #: the overrun was seen only by the STATUS read after the burst (at ``t_post``), which
    #: also read FIFO_ENTRIES (``post_entries``; −1 when not read): 96 means the FIFO overran
    #: after the burst; fewer, that it was full when read and these sets follow a loss
    overrun_in_drain: bool = False
    t_post: float = 0.0
    post_entries: int = -1

    @property
    def n_sets(self) -> int:
        return int(self.counts.shape[0])

    @property
    def gap_reasons(self) -> tuple[GapReason, ...]:
        """``gap_reason`` as the typed reasons (source.py)."""
        return parse_reasons(self.gap_reason)

    @property
    def last_index(self) -> int:
        """Index of the newest set in this drain (``index0 − 1`` when empty)."""
        return self.index0 + self.n_sets - 1


@dataclass(frozen=True)
class SelfTestResult:
    """Self-test deflection (ST1+ST2 minus ST1 only) per axis X, Y, Z in g, and the verdict
    against ``limits_g`` (datasheet typical 0.3, 0.3, 1.5 g)."""

    delta_g: tuple[float, float, float]
    limits_g: tuple[tuple[float, float], ...]
    passed: bool
    n_samples: int
    range_g: int
    saturated: bool = False  # an axis hit full scale: the delta is meaningless, use ±4/±8 g


@dataclass
class _Config:
    range_g: int = 2
    rate: R.Rate = field(default_factory=lambda: R.RATES[0])
    watermark: int = R.FIFO_LOCATIONS
    int1_watermark: bool = False


# -- the driver ----------------------------------------------------------------------------------
class Adxl355:
    """One ADXL355 on a :class:`RegisterBus`.

    Typical use::

        dev = Adxl355(SpiBus(spidev_obj))
        dev.probe(); dev.reset(); dev.configure(range_g=2, odr_hz=1000)
        dev.start()
        while running:
            d = dev.drain()       # Drain(counts, overrun, t_mono, t_real, index0, …)

    ``clock`` supplies ``monotonic()``, ``realtime()`` and ``sleep()`` (default the system
    clocks; the emulator's :class:`~avard.daemon.hw.emulator.VirtualClock` in tests).
    """

    def __init__(self, bus: RegisterBus, *, clock: Any = None,
                 temp_intercept_lsb: float = R.TEMP_INTERCEPT_LATER, retries: int = 2,
                 retry_delay_s: float = 0.001, stall_timeout_s: float | None = None) -> None:
        self.bus = bus
        self.clock = clock if clock is not None else SystemClock()
        self.temp_intercept_lsb = float(temp_intercept_lsb)
        self.retries = int(retries)
        self.retry_delay_s = float(retry_delay_s)
        self._stall_timeout_s = stall_timeout_s
        self.config = _Config()
        self.info: DeviceInfo | None = None
        self.bus_errors = 0
        self.overruns = 0
        self.realignments = 0
        self._next_index = 0
        self._carry = b""
        self._gap_reasons: list[GapReason] = []
        self._measuring = False
        self._last_data_t: float | None = None
        self._last_drain_t: float | None = None
        #: CLOCK_MONOTONIC when measurement last started: the first set after it is due one
        #: period later (what the service counts loss before the first drain from)
        self.t_started: float | None = None

    # -- bus access with retries -----------------------------------------------------------
    def _read(self, addr: int, n: int, *, in_drain: bool = False) -> bytes:
        return self._retried("read", addr, lambda: self.bus.read(addr, n), in_drain=in_drain)

    def _write(self, addr: int, data: bytes | int) -> None:
        self._retried("write", addr, lambda: self.bus.write(addr, data))

    def _retried(self, what: str, addr: int, op: Callable[[], _T], *,
                 in_drain: bool = False) -> _T:
        """Run one bus transfer, retrying ``self.retries`` times after a BusError; every
        failure is counted and logged (a drain's failure also marks a gap), the last one is
        raised."""
        last: BusError | None = None
        for attempt in range(self.retries + 1):
            try:
                return op()
            except BusError as exc:
                last = exc
                self.bus_errors += 1
                if in_drain:
                    self._note_gap(GapReason.BUS_ERROR)
                (log.warning if _often(self.bus_errors) else log.debug)(
                    "ADXL355 %s at 0x%02X failed (attempt %d of %d, bus error #%d): %s",
                    what, addr, attempt + 1, self.retries + 1, self.bus_errors, exc)
                self.clock.sleep(self.retry_delay_s)
        assert last is not None
        raise last

    def _note_gap(self, reason: GapReason, *, keep_carry: bool = False) -> None:
        if reason not in self._gap_reasons:
            self._gap_reasons.append(reason)
        if not keep_carry:
            # After an overrun or a failed transfer the FIFO may resume anywhere: joining the
            # carried X (and Y) with entries of another set would invent a sample.
            self._carry = b""

    # -- identification and setup ------------------------------------------------------------
    def probe(self) -> DeviceInfo:
        """Read DEVID_AD, DEVID_MST, PARTID, REVID; raise ``HardwareError`` saying what was read
        and what it most likely means."""
        try:
            ids = self._read(A["DEVID_AD"], 4)
        except BusError as exc:
            if exc.errno in (errno.EREMOTEIO, errno.ENXIO):
                addr = getattr(self.bus, "address", None)
                where = f" at I2C address 0x{addr:02X}" if addr is not None else ""
                raise HardwareError(
                    f"ADXL355 probe: nothing acknowledges{where} ({exc}); check power, SDA/SCL "
                    "wiring and the ASEL pin (low: 0x1D, high: 0x53)") from exc
            raise HardwareError(
                f"ADXL355 probe: the bus transfer failed ({exc}); is another driver (the "
                "kernel's adxl355 overlay) bound to the device, or is it unpowered?") from exc
        info = DeviceInfo(*ids)
        seen = " ".join(f"0x{b:02X}" for b in ids)
        expected = f"0x{R.DEVID_AD:02X} 0x{R.DEVID_MST:02X} 0x{R.PARTID_ADXL355:02X}"
        if all(b == 0xFF for b in ids):
            raise HardwareError(
                f"ADXL355 probe: IDs read {seen} (all ones): no device answers — MISO/SDA is "
                "floating or pulled up. Check power, the chip-select line and MISO wiring.")
        if all(b == 0x00 for b in ids):
            raise HardwareError(
                f"ADXL355 probe: IDs read {seen} (all zeros): MISO/SDA held low or the chip "
                "is unpowered. Check VDD, ground and the MISO wire.")
        if (info.devid_ad, info.devid_mst) != (R.DEVID_AD, R.DEVID_MST):
            shifted = {R.DEVID_AD >> 1, (R.DEVID_AD << 1) & 0xFF}
            hint = (" The value is 0xAD shifted by one bit: SPI mode is not 0 or the clock is "
                    "too fast for the wiring." if info.devid_ad in shifted else
                    " Another device answers at this chip select / address, or the bus is "
                    "wired wrong.")
            raise HardwareError(f"ADXL355 probe: IDs read {seen}, expected {expected}.{hint}")
        if info.partid not in (R.PARTID_ADXL355, R.PARTID_ADXL359):
            raise HardwareError(
                f"ADXL355 probe: PARTID reads 0x{info.partid:02X}, expected 0xED (ADXL355): "
                "an Analog Devices MEMS part but not this one; check the board.")
        if info.partid == R.PARTID_ADXL359:
            log.warning("PARTID 0xE9: this is an ADXL359; its ranges differ (±10/20/40 g), "
                        "count scaling will be wrong")
        log.info("found %s rev %d", info.name, info.revid)
        self.info = info
        return info

    def reset(self, timeout_s: float = 0.1) -> None:
        """Power-on reset (write 0x52 to RESET), wait 5 ms, poll NVM_BUSY until clear."""
        self._write(A["RESET"], R.RESET_CODE)
        self.clock.sleep(0.005)
        t_end = self.clock.monotonic() + timeout_s
        while True:
            status = self._read(A["STATUS"], 1)[0]
            if not status & R.STATUS_NVM_BUSY:
                break
            if self.clock.monotonic() > t_end:
                raise HardwareError(f"ADXL355 reset: NVM_BUSY still set after {timeout_s} s "
                                    f"(STATUS 0x{status:02X}); power-cycle the sensor")
            self.clock.sleep(0.001)
        self._stopped(GapReason.RESET)

    def _stopped(self, reason: GapReason) -> None:
        if self._next_index:  # a gap only means something after delivered samples
            self._note_gap(reason)
        self._measuring = False
        self._carry = b""

    def configure(self, range_g: int = 2, odr_hz: float = 4000.0,
                  watermark: int | None = None, *, int1_watermark: bool = False) -> None:
        """Program range (±2/4/8 g), output rate (low-pass at ODR/4, high-pass off: an Allan
        variance needs the DC path) and the FIFO watermark in FIFO *locations* (1–96, one axis
        each; default 96). ``int1_watermark``: route FIFO_FULL (the watermark reached) to the
        INT1 pin, active high, for a reader that waits on the pin (interrupt.py). Goes to
        standby first; every register is read back."""
        code = R.range_code(range_g)
        rate = R.rate_for(odr_hz)
        wm = R.FIFO_LOCATIONS if watermark is None else int(watermark)
        if not 1 <= wm <= R.FIFO_LOCATIONS:
            raise ConfigError(f"FIFO watermark {wm} is outside 1..96 locations (3 per set)")
        self.standby()
        rng = self._read(A["RANGE"], 1)[0]
        rng = R.REGISTERS["RANGE"].fields["RANGE"].put(rng, code)
        rng = R.REGISTERS["RANGE"].fields["INT_POL"].put(rng, 1 if int1_watermark else 0)
        int_map = R.INT_MAP_FULL_EN1 if int1_watermark else 0
        for name, value in (("FILTER", rate.code), ("RANGE", rng), ("FIFO_SAMPLES", wm),
                            ("INT_MAP", int_map)):
            self._write(A[name], value)
            back = self._read(A[name], 1)[0]
            if back != value:
                raise HardwareError(
                    f"ADXL355 configure: wrote 0x{value:02X} to {name}, read back 0x{back:02X};"
                    " the chip refused the write (not in standby?) or the bus corrupts data")
        self.config = _Config(int(range_g), rate, wm, int1_watermark)
        if isinstance(self.bus, I2cBus) and rate.odr_hz > self.bus.max_odr_hz():
            log.warning("ODR %g Hz needs %.0f kbit/s of FIFO data; the %g kHz I2C bus carries "
                        "about %g Hz: expect overruns. Use SPI, a lower ODR, or "
                        "dtparam=i2c_arm_baudrate=400000", rate.odr_hz,
                        rate.odr_hz * 81 / 1e3, self.bus.bitrate_hz / 1e3,
                        self.bus.max_odr_hz())
        log.info("ADXL355 configured: ±%d g, ODR %g Hz (low-pass %g Hz), watermark %d",
                 range_g, rate.odr_hz, rate.lowpass_hz, wm)

    def start(self) -> None:
        """Enter measurement mode (temperature on, DRDY on)."""
        if self._next_index:
            self._note_gap(GapReason.RESTART)
        self._write(A["POWER_CTL"], 0x00)
        self._measuring = True
        self._carry = b""
        self._last_data_t = self.clock.monotonic()
        self.t_started = self._last_data_t

    def standby(self) -> None:
        """Enter standby (the chip clears its FIFO)."""
        ctl = self._read(A["POWER_CTL"], 1)[0]
        self._write(A["POWER_CTL"], ctl | R.POWER_STANDBY)
        self._stopped(GapReason.STANDBY)

    def recover(self) -> DeviceInfo:
        """After a hardware error: probe, reset, reprogram the last configuration and start
        again. The next drain reports a gap (``gap_reason`` contains "recovered")."""
        info = self.probe()
        self.reset()
        c = self.config
        self.configure(c.range_g, c.rate.odr_hz, c.watermark, int1_watermark=c.int1_watermark)
        self._note_gap(GapReason.RECOVERED)
        self.start()
        return info

    def close(self) -> None:
        """Put the part in standby (best effort: the bus may be gone) and close the bus."""
        try:
            if self._measuring:
                self.standby()
        except HardwareError as exc:
            log.warning("ADXL355 standby on close failed: %s", exc)
        finally:
            self.bus.close()

    # -- properties --------------------------------------------------------------------------
    @property
    def odr_hz(self) -> float:
        return self.config.rate.odr_hz

    @property
    def group_delay_samples(self) -> float:
        return self.config.rate.group_delay_samples

    @property
    def scale_mps2(self) -> float:
        """m/s² per count for the configured range (typical sensitivity, ±8 % part to part)."""
        return R.counts_to_mps2(self.config.range_g)

    @property
    def stall_timeout_s(self) -> float:
        if self._stall_timeout_s is not None:
            return self._stall_timeout_s
        return max(0.5, 20.0 / self.odr_hz)

    @property
    def sets_received(self) -> int:
        return self._next_index

    # -- the FIFO ------------------------------------------------------------------------------
    def drain(self, max_sets: int | None = None) -> Drain:
        """Read every whole XYZ set in the FIFO (at most ``max_sets``). See :class:`Drain`."""
        # a tight CLOCK_MONOTONIC/CLOCK_REALTIME pair (a pre-emption between the two reads
        # looked like a CLOCK_REALTIME step)
        t_mono, t_real, t_real_u = read_clock_pair(self.clock)
        status, entries_reg = self._read(A["STATUS"], 2, in_drain=True)
        # FIFO_ENTRIES was sampled somewhere between t_mono and now: if that window is longer
        # than a sample period (preempted, retried), t_mono no longer dates the newest set.
        tight = self.clock.monotonic() - t_mono < 1.0 / self.odr_hz
        entries = entries_reg & 0x7F
        if entries > R.FIFO_LOCATIONS:
            raise HardwareError(
                f"ADXL355: FIFO_ENTRIES reads {entries} (> 96) and STATUS 0x{status:02X}: the "
                "bus returns garbage (all ones: device unplugged or MISO floating); check the "
                "wiring, then recover()")
        if status & R.STATUS_FIFO_OVR:
            self.overruns += 1
            self._note_gap(GapReason.FIFO_OVERRUN)
            (log.warning if _often(self.overruns) else log.debug)(
                "ADXL355 FIFO overrun #%d: an unknown number of sets was lost", self.overruns)
        c = len(self._carry) // 3
        n_all = entries - (entries + c) % 3
        n_read = n_all
        if max_sets is not None:
            n_read = min(n_all, max(3 * max_sets - c, 0))
        data = b""
        t_burst = t_burst_end = t_post = t_mono
        post_entries = -1
        overrun_in_drain = False
        if n_read > 0:
            t_burst = self.clock.monotonic()
            data = self._read(A["FIFO_DATA"], 3 * n_read, in_drain=True)
            t_burst_end = self.clock.monotonic()
            # If this thread was preempted between the STATUS read and the burst, the FIFO
            # may have overrun in between: the oldest entries (the ones just read were to
            # follow the carried set and the previous drain) were overwritten. STATUS again
            # tells; then the gap precedes this drain's first set and the carry is void.
            # It cannot have happened if less time passed than the FIFO's free room takes
            # to fill (half of it, for any clock error): then the read is saved (one of
            # three transfers per drain).
            room_s = (R.FIFO_LOCATIONS - entries) // 3 / self.odr_hz
            t_post = self.clock.monotonic()
            preempted = t_post - t_mono >= 0.5 * room_s
            post = 0
            if preempted:
                # STATUS and FIFO_ENTRIES: a FIFO still full after the burst overran after
                # it (the loss follows these sets); otherwise the sets it holds date them
                post, post_reg = self._read(A["STATUS"], 2, in_drain=True)
                post_entries = post_reg & 0x7F
            if post & R.STATUS_FIFO_OVR:
                overrun_in_drain = not (status & R.STATUS_FIFO_OVR)
                tight = False  # the sets read were produced after t_mono
                self.overruns += 1
                self._note_gap(GapReason.FIFO_OVERRUN)
                status |= post
                (log.warning if _often(self.overruns) else log.debug)(
                    "ADXL355 FIFO overrun #%d during the drain: an unknown number of sets was "
                    "lost", self.overruns)
        dec = decode_fifo(self._carry + data)
        if dec.dropped or dec.empty:
            self.realignments += 1
            self._note_gap(GapReason.REALIGNED, keep_carry=True)
            (log.warning if _often(self.realignments) else log.debug)(
                "ADXL355 FIFO misaligned (#%d): %d entries dropped, %d empty; realigned on the "
                "X marker", self.realignments, dec.dropped, dec.empty)
        self._carry = dec.carry
        t_end = self.clock.monotonic()
        n = dec.counts.shape[0]
        reasons = self._gap_reasons
        drain = Drain(counts=dec.counts, overrun=bool(reasons), t_mono=t_mono, t_real=t_real,
                      index0=self._next_index, gap_reason=",".join(reasons) or None,
                      status=status, fifo_entries=entries,
                      dropped_entries=dec.dropped + dec.empty, t_mono_end=t_end,
                      complete=tight and n_read == n_all and entries < R.FIFO_LOCATIONS,
                      since_last_s=None if self._last_drain_t is None
                      else t_mono - self._last_drain_t, t_burst=t_burst,
                      t_burst_end=t_burst_end, t_real_u=t_real_u,
                      overrun_in_drain=overrun_in_drain, t_post=t_post,
                      post_entries=post_entries)
        self._last_drain_t = t_mono
        self._gap_reasons = []  # each gap is reported once, even on a drain without sets
        if n:
            self._next_index += n
            self._last_data_t = t_mono
        elif self._measuring and self._last_data_t is not None \
                and t_mono - self._last_data_t > self.stall_timeout_s:
            self._diagnose_stall(t_mono - self._last_data_t)
        return drain

    def _diagnose_stall(self, silent_s: float) -> None:
        self.probe()  # raises HardwareError when the bus reads nonsense
        ctl = self._read(A["POWER_CTL"], 1)[0]
        self._note_gap(GapReason.STALL)
        if ctl & R.POWER_STANDBY:
            raise DeviceStalledError(
                f"ADXL355 returned no samples for {silent_s:.2f} s and is in standby "
                f"(POWER_CTL 0x{ctl:02X}): it was reset or lost power; call recover()")
        raise DeviceStalledError(
            f"ADXL355 answers but produced no samples for {silent_s:.2f} s at {self.odr_hz:g} "
            "Hz ODR; call recover() (reset and reconfigure) or check its power supply")

    def read_xyz(self) -> np.ndarray:
        """The newest sample from XDATA3..ZDATA1 (one burst), (3,) int32 counts."""
        return decode_counts(self._read(A["XDATA3"], 9))

    # -- temperature ---------------------------------------------------------------------------
    def read_temperature_raw(self) -> int:
        """12-bit TEMP value; TEMP2/TEMP1 in one burst, re-read while TEMP2 changed under us
        (the pair is not double-buffered)."""
        for _ in range(4):
            hi, lo = self._read(A["TEMP2"], 2)
            again = self._read(A["TEMP2"], 1)[0]
            if (again & 0x0F) == (hi & 0x0F):
                return ((hi & 0x0F) << 8) | lo
        log.warning("ADXL355 TEMP2 kept changing during reads; using the last burst")
        return ((hi & 0x0F) << 8) | lo

    def read_temperature_c(self) -> float:
        """Chip temperature, °C: 25 + (raw − intercept)/(−9.05); uncalibrated (±several °C
        from the intercept alone): calibrate the intercept against a DS18B20."""
        return R.temperature_from_raw(self.read_temperature_raw(), self.temp_intercept_lsb)

    # -- offsets and self-test -------------------------------------------------------------------
    def _with_standby(self, action: Any) -> None:
        was = self._measuring
        if was:
            self.standby()
        try:
            action()
        finally:
            if was:
                self.start()

    def set_offsets(self, x: float, y: float, z: float) -> tuple[int, int, int]:
        """Program the offset registers; arguments in data counts (LSB of the 20-bit output),
        which the chip *adds* to its output after filtering. 1 offset LSB = 16 counts, so the
        values are rounded to multiples of 16. Returns the register values written. If measuring,
        goes to standby and back (the FIFO is cleared: the next drain reports a gap)."""
        regs = []
        for v in (x, y, z):
            r = round(float(v) / R.OFFSET_LSB_COUNTS)
            if not -32768 <= r <= 32767:
                raise ConfigError(f"offset {v} counts is outside the 16-bit offset registers "
                                  f"(±{32768 * R.OFFSET_LSB_COUNTS} counts)")
            regs.append(r)

        def write() -> None:
            payload = b"".join(int(r & 0xFFFF).to_bytes(2, "big") for r in regs)
            self._write(A["OFFSET_X_H"], payload)
            back = self._read(A["OFFSET_X_H"], 6)
            if back != payload:
                raise HardwareError(f"ADXL355 offsets: wrote {payload.hex()}, read back "
                                    f"{back.hex()}")

        self._with_standby(write)
        return regs[0], regs[1], regs[2]

    def get_offsets(self) -> tuple[int, int, int]:
        """Offset registers as data counts (register value × 16)."""
        b = self._read(A["OFFSET_X_H"], 6)
        vals = [int.from_bytes(b[i:i + 2], "big", signed=True) * R.OFFSET_LSB_COUNTS
                for i in (0, 2, 4)]
        return vals[0], vals[1], vals[2]

    def _mean_xyz(self, n: int) -> np.ndarray:
        period = 1.0 / self.odr_hz
        acc = np.zeros(3)
        for _ in range(n):
            self.clock.sleep(period)
            acc += self.read_xyz()
        return acc / n

    def self_test(self, n_samples: int = 16,
                  limits_g: tuple[tuple[float, float], ...] = R.SELF_TEST_LIMITS_G
                  ) -> SelfTestResult:
        """Electrostatic self-test (datasheet "Self-test"): average the output with ST1 set,
        then with ST1+ST2, and compare the difference with ``limits_g`` per axis. Runs in
        measurement mode (started here if needed, standby afterwards if it was not running);
        the samples it consumes are not part of any record (the next drain reports a gap)."""
        was = self._measuring
        if not was:
            self._write(A["POWER_CTL"], 0x00)
            self._measuring = True
        settle_s = max(0.01, 25.0 / self.odr_hz)  # filter and electrostatic settling
        try:
            self._write(A["SELF_TEST"], R.SELF_TEST_ST1)
            self.clock.sleep(settle_s)
            off = self._mean_xyz(n_samples)
            self._write(A["SELF_TEST"], R.SELF_TEST_ST1 | R.SELF_TEST_ST2)
            self.clock.sleep(settle_s)
            on = self._mean_xyz(n_samples)
        finally:
            self._write(A["SELF_TEST"], 0x00)
            self.clock.sleep(settle_s)
        delta = (on - off) / R.sensitivity_lsb_per_g(self.config.range_g)
        # 1 g of gravity plus the 1.5 g Z deflection exceeds ±2 g: a clipped axis cannot pass.
        saturated = bool(np.any(np.abs(np.concatenate([on, off])) >= 0.99 * R.DATA_MAX))
        passed = not saturated and all(
            lo <= d <= hi for d, (lo, hi) in zip(delta, limits_g, strict=True))
        if was and self._next_index:
            self._note_gap(GapReason.SELF_TEST)
        else:
            self.standby()
        result = SelfTestResult((float(delta[0]), float(delta[1]), float(delta[2])),
                                tuple(limits_g), passed, n_samples, self.config.range_g,
                                saturated)
        (log.info if passed else log.error)(
            "ADXL355 self-test %s: Δ = %.3f, %.3f, %.3f g (limits %s)%s",
            "passed" if passed else "FAILED", *result.delta_g, limits_g,
            " — output saturated: run the self-test at ±4 g or ±8 g" if saturated else "")
        return result
