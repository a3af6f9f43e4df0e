"""Waiting on the ADXL355's INT1 pin instead of a timer: the reader sleeps until the FIFO
reaches its watermark (FIFO_FULL routed to INT1, active high; see ``Adxl355.configure``).

On the Pi the pin is a GPIO line read through the kernel's GPIO character device with
libgpiod's Python binding (``gpiod``, optional: Debian's python3-libgpiod, API 1.x, or the
2.x binding). Under simulation :class:`EmulatedInterruptPin` plays the same pin from the
emulated part's FIFO. Either way the reader keeps its timer as a fallback: ``wait`` returns
after at most ``timeout_s`` whatever the pin does, so a pin that never rises (miswired, the
part reset and its INT_MAP cleared) costs latency, never data (the FIFO holds twice the
watermark; see pacing.py).
"""

from __future__ import annotations

import datetime
import logging
import math
from typing import Any, Protocol

from avard.core.errors import ConfigError, HardwareError

log = logging.getLogger(__name__)


class InterruptPin(Protocol):
    """A level-triggered wait on the FIFO watermark pin."""

    def wait(self, timeout_s: float) -> bool:
        """Return True once the pin is asserted (at once if it already is), False after
        ``timeout_s`` without it."""
        ...

    def close(self) -> None: ...


class EmulatedInterruptPin:
    """INT1 of an :class:`~avard.daemon.hw.emulator.EmulatedAdxl355`, on its (virtual) clock."""

    def __init__(self, device: Any, clock: Any, pin: int = 1) -> None:
        self.device = device
        self.clock = clock
        self.pin = pin
        self.waits = 0
        self.asserted = 0

    def wait(self, timeout_s: float) -> bool:
        self.waits += 1
        if self.device.int_level(self.pin):
            self.asserted += 1
            return True
        due = self.device.seconds_to_int(self.pin)
        self.clock.sleep(min(timeout_s, due) if math.isfinite(due) else timeout_s)
        level = bool(self.device.int_level(self.pin))
        self.asserted += level
        return level

    def close(self) -> None:
        return None


class GpiodPin:
    """A GPIO line (``CHIP:LINE``, e.g. ``gpiochip0:25``) requested for rising edges."""

    def __init__(self, spec: str, consumer: str = "avard") -> None:
        chip, line = parse_spec(spec)
        try:
            import gpiod  # type: ignore[import-not-found]
        except ImportError:
            raise ConfigError(
                f"sensor.int1_gpio = {spec!r} needs libgpiod's Python binding: `sudo apt "
                "install python3-libgpiod` (or `pip install gpiod`), or set int1_gpio = \"\" "
                "to drain on a timer") from None
        self._gpiod = gpiod
        path = chip if chip.startswith("/") else f"/dev/{chip}"
        self.spec = spec
        try:
            if hasattr(gpiod, "request_lines"):                       # binding 2.x
                settings = gpiod.LineSettings(edge_detection=gpiod.line.Edge.RISING)
                self._req = gpiod.request_lines(path, consumer=consumer,
                                                config={line: settings})
                self._line = line
                self._v2 = True
            else:                                                     # binding 1.x
                self._chip = gpiod.Chip(path)
                self._req = self._chip.get_line(line)
                self._req.request(consumer=consumer, type=gpiod.LINE_REQ_EV_RISING_EDGE)
                self._v2 = False
        except (OSError, ValueError) as exc:
            raise HardwareError(f"cannot request GPIO {spec} for the ADXL355 INT1 pin: {exc};"
                                " check the line number and that nothing else holds it") from None

    def _level(self) -> bool:
        if self._v2:
            return bool(self._req.get_value(self._line).value)
        return bool(self._req.get_value())

    def wait(self, timeout_s: float) -> bool:
        if self._level():
            return True
        if self._v2:
            if self._req.wait_edge_events(datetime.timedelta(seconds=max(0.0, timeout_s))):
                self._req.read_edge_events()
                return True
            return False
        sec = max(0.0, timeout_s)
        if self._req.event_wait(sec=int(sec), nsec=int((sec % 1) * 1e9)):
            self._req.event_read()
            return True
        return False

    def close(self) -> None:
        try:
            self._req.release()
        except (AttributeError, OSError):
            pass


def parse_spec(spec: str) -> tuple[str, int]:
    """``CHIP:LINE`` → (chip, line); ConfigError naming the expected form otherwise."""
    chip, sep, line = spec.rpartition(":")
    if not sep or not chip or not line.isdigit():
        raise ConfigError(f"sensor.int1_gpio = {spec!r}: expected CHIP:LINE such as "
                          "'gpiochip0:25' (the GPIO the ADXL355's INT1 pin is wired to)")
    return chip, int(line)
