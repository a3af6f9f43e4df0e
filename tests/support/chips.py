"""Openers for a reader process (daemon/hw/drain_process.py) that drains several parts: the
counter-fed emulator (set k carries k) on the real clock, once per part."""

from __future__ import annotations

from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.drain_process import open_emulated


def open_counter_chips(n: int, odr_hz: float) -> list[Adxl355]:
    """``n`` counter-fed emulated ADXL355s, each started (what open_hardware_bus returns for
    the parts of one bus)."""
    return [open_emulated(odr_hz) for _ in range(n)]
