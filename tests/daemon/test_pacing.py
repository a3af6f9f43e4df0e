"""The reader drains when the FIFO is due half full at the fitted rate, and stages wake on
work: the ring's condition."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.pacing import FIFO_SETS, drain_period_s
from avard.daemon.hw.timebase import TimeBase
from avard.daemon.hw.transport import SpiBus
from avard.daemon.service.acquisition import Acquisition
from avard.daemon.service.ring import Ring


def test_drain_period_is_half_the_fifo_or_the_least_rate() -> None:
    assert FIFO_SETS == 32
    assert drain_period_s(125.0, 4.0) == pytest.approx(16 / 125.0)
    assert drain_period_s(4000.0, 4.0) == pytest.approx(16 / 4000.0)
    assert drain_period_s(7.8125, 4.0) == pytest.approx(0.25)      # the least rate wins


@pytest.mark.parametrize("ppm", [3000.0, -2200.0])
def test_reader_follows_the_fitted_rate_and_never_overruns(ppm: float) -> None:
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock, odr_error_ppm=ppm)
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=2, odr_hz=4000.0)
    dev.start()
    drains = {"n": 0}
    real_drain = dev.drain

    def counting_drain(max_sets: int | None = None):  # type: ignore[no-untyped-def]
        drains["n"] += 1
        return real_drain(max_sets)

    dev.drain = counting_drain  # type: ignore[method-assign]
    tb = TimeBase(4000.0)
    acq = Acquisition(dev, Ring(40000), tb, clock, poll_hz=4.0)
    t0 = clock.monotonic()
    acq.start()
    while clock.monotonic() - t0 < 20.0 and acq.error is None:
        threading.Event().wait(0.01)
    acq.stop()
    assert acq.error is None and acq.overruns == 0
    true_rate = 4000.0 * (1 + ppm * 1e-6)
    assert tb.odr_hz == pytest.approx(true_rate, rel=50e-6)
    assert acq.period == pytest.approx(16 / true_rate, rel=50e-6)
    elapsed = clock.monotonic() - t0
    # one drain per half FIFO at the real rate: 250 × (1 + ppm) a second
    assert drains["n"] / elapsed == pytest.approx(true_rate / 16, rel=0.02)
    assert acq.max_drain_interval_s < 32 / true_rate


def _push(ring: Ring, i0: int, n: int) -> None:
    idx = np.arange(i0, i0 + n, dtype=np.int64)
    ring.push(np.zeros((n, 3), np.int32), idx, idx / 125.0)


def test_consumer_wait_wakes_on_push_mark_and_wake_and_times_out_otherwise() -> None:
    ring = Ring(100)
    c = ring.consumer("c")
    assert c.wait(0.01) is False                       # nothing: times out
    woke: list[bool] = []
    t = threading.Thread(target=lambda: woke.append(c.wait(10.0)))
    t.start()
    _push(ring, 0, 5)
    t.join(5)
    assert woke == [True] and c.read().n == 5
    ring.mark({"kind": "event"})
    assert c.wait(0.0) is True and c.read().marks      # a mark is work too
    t = threading.Thread(target=lambda: woke.append(c.wait(30.0)))
    t.start()
    for _ in range(100):                               # shutdown: wake() ends the wait
        ring.wake()
        t.join(0.05)
        if not t.is_alive():
            break
    assert not t.is_alive() and woke[-1] is True and c.read().n == 0
