"""Every set the FIFO loses becomes a gap of the right size and the sample index stays with the
true count (issue 26, item 5), on the emulator's virtual clock with the reader late at chosen
moments: before the first drain, between drains, and inside a drain (between its STATUS read
and its burst). The emulator's counter source writes each set's true number into its data,
so every index the reader gives can be checked against the truth.

The old accounting counted only ``since_last × rate − n_read`` at the drain that saw the
overrun: sets lost during a drain and everything before the first drain were not counted
("about 1 sample lost" for hundreds), and the index fell behind the true count for good.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pytest
from avard.daemon.hw import registers as R
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.timebase import TimeBase
from avard.daemon.hw.transport import SpiBus
from avard.daemon.service.acquisition import Acquisition

ODR = 1000.0
PERIOD = 0.016        # half the FIFO at 1 kHz


class Capture:
    """Stands in for the ring: keeps what the reader pushes and marks."""

    capacity = 1 << 22
    consumers: ClassVar[list[Any]] = []

    def __init__(self) -> None:
        self.index: list[np.ndarray] = []
        self.counts: list[np.ndarray] = []
        self.gaps: list[dict] = []

    def push(self, counts: np.ndarray, index: np.ndarray, t_mono: np.ndarray) -> None:
        self.counts.append(np.array(counts))
        self.index.append(np.array(index))

    def mark(self, rec: dict) -> None:
        if rec["kind"] == "gap":
            self.gaps.append(rec)


class LateBus(SpiBus):
    """The SPI bus, with the reader pre-empted just before the next FIFO burst when asked."""

    def __init__(self, dev: FakeSpiDev, clock: VirtualClock) -> None:
        super().__init__(dev)
        self.clock = clock
        self.late_in_burst = 0.0
        self.late_after_burst = 0.0

    def read(self, addr: int, n: int) -> bytes:
        if addr == R.ADDR["FIFO_DATA"] and self.late_in_burst:
            self.clock.advance(self.late_in_burst)
            self.late_in_burst = 0.0
        out = super().read(addr, n)
        if addr == R.ADDR["FIFO_DATA"] and self.late_after_burst:
            # pre-empted after the transfer, before the second STATUS read: the FIFO overruns
            # after this drain's sets were read
            self.clock.advance(self.late_after_burst)
            self.late_after_burst = 0.0
        return out


def _rig() -> tuple[Adxl355, EmulatedAdxl355, VirtualClock, LateBus, Acquisition, Capture]:
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock)
    bus = LateBus(FakeSpiDev(emu), clock)
    dev = Adxl355(bus, clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=2, odr_hz=ODR)
    dev.start()
    cap = Capture()
    acq = Acquisition(dev, cap, TimeBase(ODR), clock, poll_hz=1 / PERIOD)  # type: ignore[arg-type]
    return dev, emu, clock, bus, acq, cap


def _drains(acq: Acquisition, clock: VirtualClock, k: int) -> None:
    for _ in range(k):
        clock.advance(PERIOD)
        acq.poll_once()


def _check(acq: Acquisition, emu: EmulatedAdxl355, cap: Capture) -> tuple[np.ndarray, int]:
    index = np.concatenate(cap.index)
    true = np.concatenate(cap.counts)[:, 0].astype(np.int64)   # the counter: set k is k
    off = index - true
    lost_claimed = sum(g["n"] for g in cap.gaps)
    # every set where it truly belongs (an estimate from time: within one set)
    assert np.max(np.abs(off)) <= 1, (np.unique(off), lost_claimed, emu.lost)
    # every loss a gap of the right size; together they account for what the chip lost
    assert abs(lost_claimed - emu.lost) <= len(cap.gaps), (lost_claimed, emu.lost)
    return off, lost_claimed


@pytest.mark.parametrize("moment", ["before_first_drain", "between_drains", "inside_drain",
                                    "inside_drain_briefly", "after_burst", "all"])
def test_loss_is_counted_from_time_wherever_the_reader_was_late(moment: str) -> None:
    _dev, emu, clock, bus, acq, cap = _rig()
    if moment in ("before_first_drain", "all"):
        clock.advance(0.5)            # a slow start: the FIFO overran before the first drain
        acq.poll_once()
    _drains(acq, clock, 30)
    if moment in ("between_drains", "all"):
        clock.advance(0.3)
        _drains(acq, clock, 20)
    if moment in ("inside_drain", "all"):
        bus.late_in_burst = 0.2       # STATUS saw half a FIFO; the burst came 0.2 s later
        _drains(acq, clock, 20)
    if moment in ("inside_drain_briefly", "all"):
        bus.late_in_burst = 0.025     # 25 sets arrive into 16 free places
        _drains(acq, clock, 20)
    if moment in ("after_burst", "all"):
        bus.late_after_burst = 0.15   # the loss follows this drain's sets: counted at the next
        _drains(acq, clock, 20)
    assert emu.lost > 0
    _check(acq, emu, cap)
    # the index continues from the truth: the next set gets the number the chip gave it
    clock.advance(PERIOD)
    acq.poll_once()
    last_true = int(cap.counts[-1][-1, 0])
    assert acq.next_index in (last_true, last_true + 1, last_true + 2) and \
        abs(acq.next_index - (last_true + 1)) <= 1
    assert acq.unaccounted == 0


def test_a_loss_nobody_reports_becomes_an_unaccounted_gap() -> None:
    _dev, emu, clock, _bus, acq, cap = _rig()
    _drains(acq, clock, 10)
    clock.advance(PERIOD)
    emu._update()
    del emu.fifo[: 3 * 3 * 10]       # ten sets vanish without FIFO_OVR (a chip or bus fault)
    acq.poll_once()
    _drains(acq, clock, 10)
    assert acq.unaccounted == 1
    (gap,) = cap.gaps
    assert gap["reason"] == "unaccounted" and abs(gap["n"] - 10) <= 1
    index = np.concatenate(cap.index)
    true = np.concatenate(cap.counts)[:, 0]
    assert np.max(np.abs(index - true)) <= 1
