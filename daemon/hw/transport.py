"""Register access over SPI (py-spidev) or I2C (smbus2): one small interface, two framings.

``RegisterBus`` is what the driver sees: ``read(addr, n) -> bytes``, ``write(addr, data)``,
``close()``. ``SpiBus`` wraps an object with the ``spidev.SpiDev`` methods, ``I2cBus`` one with
the ``smbus2.SMBus`` methods; the emulator's ``FakeSpiDev``/``FakeSMBus`` present the same
methods, so the code below runs unchanged in tests. :func:`open_bus` is the only place that
opens a real ``/dev/spidevX.Y`` or ``/dev/i2c-N``, and only when called.

Every ``OSError`` of a transfer becomes a :class:`~avard.core.errors.BusError` that keeps the
errno, so the driver can tell a transient EIO from a missing device.
"""

from __future__ import annotations

import errno as errno_mod
import os
from collections.abc import Callable, Iterable
from typing import Any, Protocol, runtime_checkable

from avard.core.errors import BusError, ConfigError, HardwareError
from avard.daemon.hw.registers import ADDR

FIFO_DATA = ADDR["FIFO_DATA"]
#: py-spidev refuses a single xfer2 longer than its buffer (4096 bytes by default).
SPI_MAX_TRANSFER = 4096
SPI_MAX_SPEED_HZ = 10_000_000  # ADXL355 SPI clock limit
SPI_DEFAULT_SPEED_HZ = 5_000_000
I2C_ADDRESSES = (0x1D, 0x53)  # ASEL low / high


@runtime_checkable
class RegisterBus(Protocol):
    """Byte-level register access to one ADXL355."""

    def read(self, addr: int, n: int) -> bytes: ...

    def write(self, addr: int, data: bytes | Iterable[int] | int) -> None: ...

    def close(self) -> None: ...


def _as_bytes(data: bytes | Iterable[int] | int) -> bytes:
    if isinstance(data, int):
        return bytes([data & 0xFF])
    return bytes(data)


def _bus_error(what: str, exc: OSError) -> BusError:
    code = exc.errno
    name = errno_mod.errorcode.get(code, "?") if code is not None else "?"
    return BusError(f"{what} failed: {exc.strerror or exc} (errno {code} {name}); check the "
                    "wiring and that no other driver owns the bus", code)


class SpiBus:
    """ADXL355 register access over SPI, mode 0.

    Framing (datasheet "SPI protocol"): command byte ``(addr << 1) | 1`` to read,
    ``addr << 1`` to write, then the data; multi-byte transfers auto-increment the address
    (except at FIFO_DATA, which pops the FIFO). One ``xfer2`` per burst keeps CS asserted for
    the whole burst; bursts longer than the spidev buffer are split (only ever needed for
    FIFO_DATA, where splitting is harmless because the address does not advance).
    """

    def __init__(self, spi: Any, *, speed_hz: int = SPI_DEFAULT_SPEED_HZ,
                 max_transfer: int = SPI_MAX_TRANSFER) -> None:
        if not 100_000 <= speed_hz <= SPI_MAX_SPEED_HZ:
            raise ConfigError(f"SPI clock {speed_hz} Hz is outside the ADXL355's 0.1–10 MHz; "
                              "set spi_speed_hz between 100000 and 10000000")
        self.spi = spi
        self.max_transfer = int(max_transfer)
        spi.mode = 0
        spi.max_speed_hz = int(speed_hz)
        self.transfers = 0  # number of xfer2 calls, for benchmarks and tests

    def _xfer(self, tx: list[int], what: str | Callable[[], str]) -> list[int]:
        try:
            rx = self.spi.xfer2(tx)
        except OSError as exc:
            raise _bus_error(what if isinstance(what, str) else what(), exc) from exc
        self.transfers += 1
        return rx

    def read(self, addr: int, n: int) -> bytes:
        if n <= 0:
            return b""
        step = self.max_transfer - 1
        cmd = ((addr & 0x7F) << 1) | 1
        if n <= step:   # one transfer (every read but a long FIFO burst); runs at every drain
            rx = self._xfer([cmd] + [0] * n, lambda: f"SPI read of {n} bytes at 0x{addr:02X}")
            return bytes(rx[1:])
        if addr != FIFO_DATA:
            raise ValueError(f"a {n}-byte burst from 0x{addr:02X} does not fit one SPI transfer")
        out = bytearray()
        while len(out) < n:
            k = min(step, n - len(out))
            rx = self._xfer([cmd] + [0] * k, f"SPI read of {k} bytes at 0x{addr:02X}")
            out += bytes(rx[1:])
        return bytes(out)

    def write(self, addr: int, data: bytes | Iterable[int] | int) -> None:
        payload = _as_bytes(data)
        self._xfer([(addr & 0x7F) << 1, *payload], f"SPI write at 0x{addr:02X}")

    def close(self) -> None:
        self.spi.close()


class I2cBus:
    """ADXL355 register access over I2C (7-bit address 0x1D or 0x53).

    A read is one combined transaction: a register-pointer write, a repeated start, and the
    read (``i2c_rdwr``), so no other master can move the pointer in between and bursts are not
    limited to the 32 bytes of SMBus block reads.
    """

    #: Bits on the wire per data byte (8 + ACK).
    BITS_PER_BYTE = 9

    def __init__(self, smbus: Any, address: int = 0x1D, *, bitrate_hz: int = 100_000) -> None:
        """``bitrate_hz`` is the bus clock set in the device tree (Raspberry Pi default
        100 kHz; ``dtparam=i2c_arm_baudrate=400000`` for fast mode). The driver only uses it to
        warn when a rate cannot be carried."""
        if address not in I2C_ADDRESSES:
            raise ConfigError(f"I2C address 0x{address:02X} is not an ADXL355 address; use 0x1D "
                              "(ASEL low) or 0x53 (ASEL high)")
        self.smbus = smbus
        self.address = address
        self.bitrate_hz = int(bitrate_hz)
        self.transfers = 0

    def max_odr_hz(self) -> float:
        """Highest ODR whose FIFO data (9 bytes per set) fits in 60 % of the bus time, Hz."""
        return 0.6 * self.bitrate_hz / (9 * self.BITS_PER_BYTE)

    def read(self, addr: int, n: int) -> bytes:
        if n <= 0:
            return b""
        from smbus2 import i2c_msg  # the message struct only; opens nothing

        wr = i2c_msg.write(self.address, [addr & 0xFF])
        rd = i2c_msg.read(self.address, n)
        try:
            self.smbus.i2c_rdwr(wr, rd)
        except OSError as exc:
            raise _bus_error(f"I2C read of {n} bytes at 0x{addr:02X} "
                             f"(device 0x{self.address:02X})", exc) from exc
        self.transfers += 1
        return bytes(rd)

    def write(self, addr: int, data: bytes | Iterable[int] | int) -> None:
        payload = _as_bytes(data)
        try:
            if len(payload) == 1:
                self.smbus.write_byte_data(self.address, addr, payload[0])
            else:
                self.smbus.write_i2c_block_data(self.address, addr, list(payload))
        except OSError as exc:
            raise _bus_error(f"I2C write at 0x{addr:02X} (device 0x{self.address:02X})",
                             exc) from exc
        self.transfers += 1

    def close(self) -> None:
        self.smbus.close()


def open_bus(kind: str = "spi", *, bus: int | None = None, device: int = 0,
             address: int = 0x1D, speed_hz: int = SPI_DEFAULT_SPEED_HZ,
             i2c_bitrate_hz: int = 100_000) -> SpiBus | I2cBus:
    """Open a real bus: ``"spi"`` → /dev/spidev{bus}.{device}, ``"i2c"`` → /dev/i2c-{bus}.

    Defaults: SPI bus 0, I2C bus 1 (the Raspberry Pi header). Errors say what to fix.
    ``i2c_bitrate_hz`` tells the driver the I2C clock the device tree set (it cannot be set
    from user space).
    """
    if kind == "spi":
        n = 0 if bus is None else bus
        path = f"/dev/spidev{n}.{device}"
        try:
            import spidev  # type: ignore[import-not-found]
        except ImportError as exc:
            raise HardwareError("the spidev package is missing; pip install spidev") from exc
        spi = spidev.SpiDev()
        try:
            spi.open(n, device)
        except OSError as exc:
            raise HardwareError(_open_advice(path, exc, "spi")) from exc
        return SpiBus(spi, speed_hz=speed_hz)
    if kind == "i2c":
        n = 1 if bus is None else bus
        path = f"/dev/i2c-{n}"
        from smbus2 import SMBus

        try:
            smb = SMBus(n)
        except OSError as exc:
            raise HardwareError(_open_advice(path, exc, "i2c")) from exc
        return I2cBus(smb, address, bitrate_hz=i2c_bitrate_hz)
    raise ConfigError(f"unknown bus kind {kind!r}; use 'spi' or 'i2c'")


def _open_advice(path: str, exc: OSError, group: str) -> str:
    if exc.errno == errno_mod.EACCES:
        return (f"cannot open {path}: permission denied; add the service user to group "
                f"'{group}' (usermod -aG {group} USER) or run the systemd unit")
    if exc.errno == errno_mod.ENOENT or not os.path.exists(path):
        hint = ("enable it with dtparam=spi=on in /boot/firmware/config.txt (raspi-config); if "
                "the kernel's adxl355 overlay is loaded it owns the chip and no spidev node "
                "exists: remove that dtoverlay") if group == "spi" else (
                "enable it with dtparam=i2c_arm=on (raspi-config)")
        return f"cannot open {path}: no such device; {hint}"
    return f"cannot open {path}: {exc}"
