"""When the reader drains the ADXL355 FIFO: when it is due to hold a useful block.

The FIFO holds 96 entries = 32 X/Y/Z sets, i.e. 32/ODR seconds (256 ms at 125 Hz, 8 ms at
4 kHz); it overruns (and loses sets) when it is not drained within that time. Each drain costs a
fixed amount of CPU (a STATUS read, a burst, decoding, a push into the ring) however many sets
it returns, so the reader drains when the FIFO is due to be ``FILL_TARGET`` full at the
*fitted* output rate, leaving the rest of the FIFO as the margin for a late wake-up, and at
least ``poll_hz`` times a second (``sensor.poll_hz``: it bounds how late a sample reaches the
ring and the subscribers).
"""

from __future__ import annotations

from typing import Any

from avard.daemon.hw.registers import FIFO_LOCATIONS

#: X/Y/Z sets the FIFO holds.
FIFO_SETS = FIFO_LOCATIONS // 3
#: Drain when the FIFO is due to hold this fraction of its sets: half is the wake-up margin
#: (128 ms at 125 Hz, 4 ms at 4 kHz; Linux wakes a sleeping thread well within that).
FILL_TARGET = 0.5


#: The highest ODR measured to run 10 minutes on the real clock with 0 FIFO overruns beside a
#: CPU-bound process (`yes`) on the shared, loaded 2-core development machine, the drain loop
#: in its own process (drain_process.py) at SCHED_FIFO (systemd/realtime.conf)
#: (``python -m benchmarks realtime``, docs/service.md "The reader process"). Above it the
#: machine's own stalls (cyclictest saw a SCHED_FIFO C thread woken up to 34 ms late) outlast
#: the FIFO; every loss is then a gap of counted size. At normal priority, under that load,
#: neither the process (250 Hz) nor the reader thread (125 Hz) ran without overruns.
HELD_HZ_PROCESS_FIFO = 500.0

#: The reader process (drain_process.py) drains at a quarter: a drain there costs no one else
#: the GIL, and three quarters of the FIFO (6 ms at 4 kHz) is left for a late wake-up.
FILL_TARGET_PROCESS = 0.25


def reader_in_process(int1: bool) -> bool:
    """Whether the hardware is drained by the reader process (drain_process.py) rather than the
    service's reader thread: always, unless the reader waits on INT1 (the child does not wait
    on the pin). The thread shares the GIL with the service's other threads; beside a CPU hog
    it overran even at 125 Hz where the process at SCHED_FIFO held 500 Hz (docs/service.md)."""
    return not int1


def drain_period_s(odr_hz: float, poll_hz: float, fill: float = FILL_TARGET) -> float:
    """Seconds between drains for a (fitted) output rate and the configured least drain rate,
    draining when the FIFO is due to be ``fill`` full."""
    return min(1.0 / float(poll_hz), fill * FIFO_SETS / float(odr_hz))


def watermark_sets() -> int:
    """FIFO_SAMPLES watermark for the interrupt-driven reader, in sets (same fill target)."""
    return max(1, round(FILL_TARGET * FIFO_SETS))


def watermark_settings(use_int1: bool) -> dict[str, Any]:
    """``Adxl355.configure`` arguments for a reader that waits on INT1 at this fill."""
    if not use_int1:
        return {}
    return {"watermark": 3 * watermark_sets(), "int1_watermark": True}
