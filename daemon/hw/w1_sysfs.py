"""The Linux w1 sysfs interface of DS18B20 sensors, written out: scratchpad bytes, CRC, files.

The kernel's w1_therm driver exposes each sensor as ``/sys/bus/w1/devices/28-XXXXXXXXXXXX/
w1_slave`` with two lines::

    72 01 4b 46 7f ff 0e 10 57 : crc=57 YES
    72 01 4b 46 7f ff 0e 10 57 t=23125

(the 9 scratchpad bytes: temperature LSB/MSB in 1/16 °C, TH, TL, config, reserved, count
remain, 0x10, CRC-8/MAXIM of the first 8). w1thermsensor computes the temperature from the
bytes, so a fake must carry consistent bytes and CRC. :class:`SysfsTree` builds such a tree in
any folder: the tests use it, and so can ``avard run --simulate`` (it lets the real
w1thermsensor code path read simulated temperatures).
"""

from __future__ import annotations

import shutil
from pathlib import Path

DS18B20_FAMILY = "28"
RESET_VALUE_C = 85.0  # power-on value of the temperature register


def crc8_maxim(data: bytes) -> int:
    """Dallas/Maxim 1-Wire CRC-8 (x⁸ + x⁵ + x⁴ + 1, reflected 0x8C, init 0)."""
    crc = 0
    for byte in data:
        b = byte
        for _ in range(8):
            mix = (crc ^ b) & 1
            crc >>= 1
            if mix:
                crc ^= 0x8C
            b >>= 1
    return crc


def scratchpad(temp_c: float, *, resolution: int = 12, th: int = 0x4B, tl: int = 0x46) -> bytes:
    """The 9 scratchpad bytes of a DS18B20 reading ``temp_c`` (12-bit: 1/16 °C steps)."""
    if not 9 <= resolution <= 12:
        raise ValueError("DS18B20 resolution is 9..12 bits")
    if not -55.0 <= temp_c <= 125.0:
        raise ValueError(f"{temp_c} °C is outside the DS18B20 range −55..125 °C")
    raw = round(temp_c * 16) & 0xFFFF
    config = ((resolution - 9) << 5) | 0x1F
    body = bytes([raw & 0xFF, raw >> 8, th, tl, config, 0xFF, (0x10 - (raw & 0x0F)) & 0xFF,
                  0x10])
    return body + bytes([crc8_maxim(body)])


def w1_slave_text(pad: bytes, *, crc_ok: bool | None = None) -> str:
    """The two lines of ``w1_slave`` for scratchpad ``pad``; ``crc_ok`` overrides the YES/NO
    the kernel prints (default: whatever the CRC of ``pad`` says)."""
    if len(pad) != 9:
        raise ValueError("a scratchpad has 9 bytes")
    ok = crc8_maxim(pad[:8]) == pad[8] if crc_ok is None else crc_ok
    hexes = " ".join(f"{b:02x}" for b in pad)
    raw = int.from_bytes(pad[:2], "little", signed=True)
    return (f"{hexes} : crc={pad[8]:02x} {'YES' if ok else 'NO'}\n"
            f"{hexes} t={round(raw * 1000 / 16)}\n")


class SysfsTree:
    """A fake ``/sys/bus/w1/devices`` folder with DS18B20 sensors whose state can be changed.

    ``tree.base`` is what ``W1ThermSensor.BASE_DIRECTORY`` should point at. Every change
    rewrites the ``w1_slave`` file (atomically, by rename) as the kernel would present it.
    """

    def __init__(self, root: str | Path) -> None:
        self.base = Path(root)
        self.base.mkdir(parents=True, exist_ok=True)
        # The kernel also lists the bus master; readers must ignore it.
        (self.base / "w1_bus_master1").mkdir(exist_ok=True)
        self._hidden = self.base.parent / (self.base.name + ".removed")
        self._written: dict[Path, str] = {}   # the last text written to each w1_slave

    @staticmethod
    def full_id(sensor_id: str) -> str:
        return sensor_id if "-" in sensor_id else f"{DS18B20_FAMILY}-{sensor_id}"

    def path(self, sensor_id: str) -> Path:
        return self.base / self.full_id(sensor_id) / "w1_slave"

    def _write(self, sensor_id: str, text: str) -> None:
        p = self.path(sensor_id)
        if self._written.get(p) == text and p.exists():
            # unchanged (a 0.0625 °C step is rare second to second): the simulated rig
            # rewrites each sensor every conversion, and a rename costs milliseconds here
            return
        self._written[p] = text
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp = p.with_suffix(".tmp")
        tmp.write_text(text)
        tmp.replace(p)

    def add(self, sensor_id: str = "0316a2797cff", temp_c: float = 21.5) -> str:
        """Add a sensor reading ``temp_c``; returns its full id (``28-…``)."""
        self.set_temperature(sensor_id, temp_c)
        return self.full_id(sensor_id)

    def set_temperature(self, sensor_id: str, temp_c: float) -> None:
        self._write(sensor_id, w1_slave_text(scratchpad(temp_c)))

    def set_crc_failure(self, sensor_id: str, temp_c: float = 21.5) -> None:
        """A read disturbed on the wire: one byte flipped, the CRC no longer matches, NO."""
        pad = bytearray(scratchpad(temp_c))
        pad[1] ^= 0x04
        self._write(sensor_id, w1_slave_text(bytes(pad)))

    def set_bad_crc_but_yes(self, sensor_id: str, temp_c: float = 21.5) -> None:
        """Bytes whose CRC is wrong while the line still says YES (a kernel/bus oddity that
        only a reader checking the bytes itself notices)."""
        pad = bytearray(scratchpad(temp_c))
        pad[0] ^= 0x01
        self._write(sensor_id, w1_slave_text(bytes(pad), crc_ok=True))

    def set_reset_value(self, sensor_id: str) -> None:
        """The 85 °C power-on value: the conversion never ran (power glitch, parasite power)."""
        self.set_temperature(sensor_id, RESET_VALUE_C)

    def set_all_zero(self, sensor_id: str) -> None:
        """All-zero bytes: the kernel read nothing (sensor not answering)."""
        self._write(sensor_id, w1_slave_text(bytes(9), crc_ok=True))

    def remove(self, sensor_id: str) -> None:
        """The sensor disappears from the bus (its sysfs folder goes away)."""
        src = self.base / self.full_id(sensor_id)
        self._hidden.mkdir(exist_ok=True)
        dst = self._hidden / src.name
        if dst.exists():
            shutil.rmtree(dst)
        src.rename(dst)

    def restore(self, sensor_id: str) -> None:
        """The sensor comes back, with the file it had."""
        (self._hidden / self.full_id(sensor_id)).rename(self.base / self.full_id(sensor_id))
