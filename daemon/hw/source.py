"""The contract between a sample source (the ADXL355 driver, over SPI, I2C or the emulator)
and the reader thread (acquisition.py).

A source drains its FIFO into a :class:`~avard.daemon.hw.adxl355.Drain` and says, with each
drain, why samples may be missing before it (:class:`GapReason`). Errors are typed
(core/errors.py): ``DeviceStalledError`` when the part answers but produces nothing (the
source owns that detection: it knows its rate and its FIFO), any other ``HardwareError`` for
a failed transfer or garbage on the bus. The reader catches them by type.
"""

from __future__ import annotations

from enum import StrEnum
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from avard.daemon.hw.adxl355 import Drain


class GapReason(StrEnum):
    """Why a drain's samples may not follow the previous drain's (recorded in ``gap``
    records as the ``reason`` string; several are joined with commas)."""

    FIFO_OVERRUN = "fifo_overrun"   # the FIFO filled: the chip overwrote unread sets
    REALIGNED = "realigned"         # entries without the X marker were dropped
    BUS_ERROR = "bus_error"         # a transfer failed and was retried
    STALL = "stall"                 # the part produced nothing for a while
    RESET = "reset"                 # soft reset (clears the FIFO)
    STANDBY = "standby"             # standby (clears the FIFO)
    RESTART = "restart"             # measurement restarted
    RECOVERED = "recovered"         # probe, reset, reconfigure, restart after an error
    SELF_TEST = "self_test"         # self-test deflected the outputs
    UNACCOUNTED = "unaccounted"     # sets arrived later than time says: a loss nobody reported
    READER_BACKLOG = "reader_backlog"  # the reader process dropped drains nobody took


def parse_reasons(text: str | None) -> tuple[GapReason, ...]:
    """The reasons of a drain's ``gap_reason`` string (unknown words are kept out)."""
    known = {r.value: r for r in GapReason}
    return tuple(known[w] for w in (text or "").split(",") if w in known)


class SampleSource(Protocol):
    """What the reader needs from the sensor driver."""

    @property
    def odr_hz(self) -> float: ...

    @property
    def group_delay_samples(self) -> float: ...

    @property
    def scale_mps2(self) -> float: ...

    def drain(self, max_sets: int | None = None) -> Drain:
        """Every whole set in the FIFO; raises DeviceStalledError or HardwareError."""
        ...

    def read_temperature_c(self) -> float: ...

    def recover(self) -> object:
        """Probe, reset, reconfigure and restart after an error (the FIFO is lost)."""
        ...

