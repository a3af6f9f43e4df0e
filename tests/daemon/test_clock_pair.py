"""CLOCK_MONOTONIC and CLOCK_REALTIME read as a tight pair (issue 26, item 11): a reader
pre-empted between the two reads made the realtime offset look 0.1 s off for one drain, and
the service recorded a spurious ``clock_step`` of +0.1 s and one of −0.1 s at the next drain.
A real step is still seen, once."""

from __future__ import annotations

from typing import Any, ClassVar

from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.timebase import TimeBase, read_clock_pair
from avard.daemon.hw.transport import SpiBus
from avard.daemon.service.acquisition import Acquisition

ODR = 125.0


class PreemptedClock(VirtualClock):
    """A virtual clock whose reader is pre-empted for ``stall_s`` just before the next
    ``preempt`` CLOCK_REALTIME reads."""

    def __init__(self) -> None:
        super().__init__()
        self.preempt = 0
        self.stall_s = 0.1

    def realtime(self) -> float:
        if self.preempt:
            self.preempt -= 1
            self.advance(self.stall_s)
        return super().realtime()


class Marks:
    capacity = 1 << 20
    consumers: ClassVar[list[Any]] = []

    def __init__(self) -> None:
        self.events: list[dict] = []

    def push(self, *_a: Any) -> None:
        pass

    def mark(self, rec: dict) -> None:
        if rec["kind"] == "event":
            self.events.append(rec)


def test_a_preempted_clock_read_is_no_clock_step_and_a_real_step_is_one() -> None:
    clock = PreemptedClock()
    emu = EmulatedAdxl355(counter_source(), clock)
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=2, odr_hz=ODR)
    dev.start()
    marks = Marks()
    acq = Acquisition(dev, marks, TimeBase(ODR), clock, poll_hz=4.0)  # type: ignore[arg-type]
    for k in range(60):
        clock.advance(0.125)
        if k in (10, 20, 30):
            clock.preempt = 1          # one pre-empted pair read: the retry is tight
        if k == 40:
            clock.preempt = 2          # two in a row: the third read is tight
        acq.poll_once()
    assert [e["name"] for e in marks.events] == []
    clock.step_realtime(1.25)          # NTP steps the wall clock
    for _ in range(5):
        clock.advance(0.125)
        acq.poll_once()
    steps = [e for e in marks.events if e["name"] == "clock_step"]
    assert len(steps) == 1 and abs(steps[0]["detail"]["step_s"] - 1.25) < 1e-6


def test_every_read_preempted_widens_the_threshold_instead_of_inventing_steps() -> None:
    clock = PreemptedClock()
    tb = TimeBase(ODR)
    seen = []
    for k in range(20):
        clock.advance(0.125)
        clock.preempt = 3 if k % 2 else 0     # every other read: all three tries pre-empted
        t_mono, t_real, u = read_clock_pair(clock)
        assert (u >= 0.05) == bool(k % 2)
        seen.append(tb.realtime_step(t_mono, t_real, u_s=u))
    assert seen == [None] * 20
