"""SPI and I2C framing, burst splitting, error wrapping, and opening real buses."""

from __future__ import annotations

import errno

import pytest
from avard.core.errors import BusError, ConfigError, HardwareError
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSMBus, FakeSpiDev, VirtualClock
from avard.daemon.hw.transport import I2cBus, RegisterBus, SpiBus, open_bus


class RecordingSpi:
    """Records every xfer2 and answers with a counting pattern."""

    def __init__(self) -> None:
        self.calls: list[list[int]] = []
        self.mode = 3
        self.max_speed_hz = 0
        self.fail: OSError | None = None
        self.closed = False

    def xfer2(self, tx):
        if self.fail:
            raise self.fail
        self.calls.append(list(tx))
        return [0xEE] + [(i + 1) & 0xFF for i in range(len(tx) - 1)]

    def close(self):
        self.closed = True


def test_spi_command_bytes_and_mode():
    spi = RecordingSpi()
    bus = SpiBus(spi, speed_hz=2_000_000)
    assert isinstance(bus, RegisterBus)
    assert spi.mode == 0 and spi.max_speed_hz == 2_000_000
    assert bus.read(0x05, 3) == bytes([1, 2, 3])
    assert spi.calls[-1] == [(0x05 << 1) | 1, 0, 0, 0]
    bus.write(0x2D, 0x00)
    assert spi.calls[-1] == [0x2D << 1, 0x00]
    bus.write(0x1E, b"\x01\x02")
    assert spi.calls[-1] == [0x1E << 1, 1, 2]
    assert bus.read(0x00, 0) == b"" and len(spi.calls) == 3
    bus.close()
    assert spi.closed


def test_spi_fifo_burst_is_one_transfer_and_long_bursts_split():
    spi = RecordingSpi()
    bus = SpiBus(spi)
    bus.read(0x11, 288)  # a full FIFO: 1 + 288 bytes, CS held for the whole burst
    assert len(spi.calls) == 1 and len(spi.calls[0]) == 289
    spi.calls.clear()
    small = SpiBus(spi, max_transfer=100)
    assert len(small.read(0x11, 250)) == 250
    assert [len(c) for c in spi.calls] == [100, 100, 53]
    assert all(c[0] == (0x11 << 1) | 1 for c in spi.calls)
    with pytest.raises(ValueError):
        small.read(0x08, 250)  # auto-increment reads cannot be split safely


def test_spi_speed_outside_the_chip_limits_is_a_config_error():
    with pytest.raises(ConfigError, match=r"0\.1–10 MHz"):
        SpiBus(RecordingSpi(), speed_hz=20_000_000)


def test_oserror_becomes_bus_error_with_errno():
    spi = RecordingSpi()
    spi.fail = OSError(errno.EIO, "Input/output error")
    bus = SpiBus(spi)
    with pytest.raises(BusError) as exc:
        bus.read(0, 1)
    assert exc.value.errno == errno.EIO and "EIO" in str(exc.value)
    assert isinstance(exc.value, HardwareError)


def test_spi_and_i2c_read_the_same_registers_of_the_emulator():
    emu = EmulatedAdxl355(clock=VirtualClock())
    spi = SpiBus(FakeSpiDev(emu))
    i2c = I2cBus(FakeSMBus(emu, 0x53), 0x53)
    assert spi.read(0x00, 4) == i2c.read(0x00, 4) == bytes([0xAD, 0x1D, 0xED, 0x01])
    i2c.write(0x29, 0x30)
    assert spi.read(0x29, 1) == b"\x30"
    spi.write(0x1E, bytes([1, 2, 3, 4, 5, 6]))
    assert i2c.read(0x1E, 6) == bytes([1, 2, 3, 4, 5, 6])  # > 1 byte: block write path


def test_i2c_burst_longer_than_smbus_block_limit():
    emu = EmulatedAdxl355(clock=VirtualClock())
    i2c = I2cBus(FakeSMBus(emu))
    assert len(i2c.read(0x00, 48)) == 48


def test_i2c_wrong_address_and_unplugged_bus():
    with pytest.raises(ConfigError, match="0x1D"):
        I2cBus(object(), 0x50)
    emu = EmulatedAdxl355(clock=VirtualClock())
    bus = I2cBus(FakeSMBus(emu, address=0x53), 0x1D)  # chip strapped to 0x53, we ask 0x1D
    with pytest.raises(BusError) as exc:
        bus.read(0, 1)
    assert exc.value.errno == errno.EREMOTEIO


def test_open_bus_names_what_to_fix():
    with pytest.raises(HardwareError, match=r"/dev/spidev97\.0"):
        open_bus("spi", bus=97)
    with pytest.raises(HardwareError, match="/dev/i2c-97"):
        open_bus("i2c", bus=97)
    with pytest.raises(ConfigError, match="'spi' or 'i2c'"):
        open_bus("usb")
