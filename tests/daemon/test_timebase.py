"""Index ↔ CLOCK_MONOTONIC fit: the chip's real rate, per-sample timestamps, gaps, steps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.timebase import SystemClock, TimeBase
from avard.daemon.hw.transport import SpiBus


def run(ppm: float, odr: float = 1000.0, seconds: float = 20.0, overrun_every: int = 0,
        seed: int = 0):
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock, odr_error_ppm=ppm)
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(odr_hz=odr)
    dev.start()
    tb = TimeBase(odr, group_delay_samples=dev.group_delay_samples)
    rng = np.random.default_rng(seed)
    drains = []
    k = 0
    while clock.monotonic() - emu._t_start < seconds:
        k += 1
        # polling every 5–25 ms, as a loaded Raspberry Pi does; now and then far too late
        late = overrun_every and k % overrun_every == 0
        clock.advance(0.2 if late else rng.uniform(0.005, 0.025))
        d = dev.drain()
        tb.add_drain(d)
        if d.n_sets:
            drains.append(d)
    return tb, emu, drains


@pytest.mark.parametrize("ppm", [3000.0, -2200.0])
def test_fit_recovers_the_real_odr_within_50_ppm(ppm):
    tb, emu, _ = run(ppm)
    r = tb.rate()
    assert abs(r.ppm - ppm) < 50
    assert r.odr_hz == pytest.approx(emu.true_odr_hz, rel=50e-6)
    # the quoted uncertainty is honest: error within 5σ, and σ itself small
    assert abs(r.ppm - ppm) < 5 * r.ppm_u and r.ppm_u < 20
    assert 0 < r.jitter_s < 1 / 1000  # stamp lag is U(0, T): RMS T/√12


def test_fit_keeps_the_rate_across_overrun_gaps():
    tb, _emu, drains = run(3000.0, overrun_every=50)
    assert sum(d.overrun for d in drains) >= 5
    assert not all(d.complete for d in drains)  # full-FIFO drains exist and were skipped
    r = tb.rate()
    assert abs(r.ppm - 3000.0) < 50 and abs(r.ppm - 3000.0) < 5 * r.ppm_u


def test_timestamps_match_the_emulated_sampling_instants():
    tb, emu, drains = run(3000.0, seconds=10.0)
    d = drains[-1]
    t = tb.timestamps(d.index0, d.n_sets)
    # the emulator outputs set k (0-based) at t_start + (k + 1) / true_odr
    k = d.counts[:, 0].astype(float)
    t_out = emu._t_start + (k + 1) / emu.true_odr_hz
    t_event = t_out - tb.group_delay_samples / emu.true_odr_hz
    err = (t - t_event) * emu.true_odr_hz  # in sample periods
    assert np.all(np.abs(err) < 0.3)
    assert np.allclose(np.diff(t), 1 / tb.odr_hz)


def test_nominal_rate_until_the_fit_spans_enough_time():
    tb = TimeBase(4000.0, min_span_s=1.0)
    assert tb.odr_hz == 4000.0
    tb.update(100, 10.0)
    tb.update(200, 10.025)
    tb.update(300, 10.05)
    assert tb.odr_hz == 4000.0  # 50 ms of data is not enough to trust a slope
    assert math.isnan(tb.rate().ppm_u)
    with pytest.raises(ValueError):
        TimeBase(4000.0).time_of(0)


def test_large_indices_and_times_keep_full_precision():
    tb = TimeBase(4000.0)
    odr = 4000.0 * (1 + 1234e-6)
    x0 = 10**10  # a month at 4 kHz
    for k in range(0, 400_000, 100):
        tb.update(x0 + k, 1e6 + k / odr)
    assert tb.rate().ppm == pytest.approx(1234.0, abs=0.01)
    assert tb.ppm == pytest.approx(1234.0, abs=0.01)


def test_memory_follows_a_drifting_oscillator():
    short = TimeBase(1000.0, memory_s=2.0)
    long_ = TimeBase(1000.0, memory_s=None)
    t, xf = 0.0, 0.0
    for k in range(4000):
        odr = 1000.0 if k < 2000 else 1001.0  # +1000 ppm after 20 s (a temperature step)
        t += 0.01
        xf += 0.01 * odr
        for tb in (short, long_):
            tb.update(math.floor(xf), t)
    r = short.rate()
    assert abs(r.ppm - 1000.0) < 5 * r.ppm_u and r.ppm_u < 15
    assert 200 < long_.rate().ppm < 800  # an unweighted fit averages both rates


def test_realtime_steps_are_reported():
    tb = TimeBase(1000.0)
    assert tb.realtime_step(1.0, 1e9 + 1.0) is None
    assert tb.realtime_step(2.0, 1e9 + 2.001) is None
    assert tb.realtime_step(3.0, 1e9 + 3.0 - 2.0) == pytest.approx(-2.001)


def test_system_clock():
    c = SystemClock()
    a = c.monotonic()
    c.sleep(0.001)
    assert c.monotonic() > a and c.realtime() > 1.5e9


def test_inexact_points_are_skipped_but_their_gap_is_kept():
    tb = TimeBase(1000.0, min_span_s=0.0)
    assert tb.update(0, 0.0)
    assert tb.update(1000, 1.0)
    assert not tb.update(5000, 3.0, gap=True, exact=False)  # full FIFO: stamp may lag
    assert tb.update(6000, 4.0)  # starts the new segment the skipped point announced
    assert tb.n_points == 3 and tb._old_segments == 1
    assert tb.time_of(6000) == pytest.approx(4.0 - 0.5e-3)


@pytest.mark.slow
def test_ten_virtual_minutes_at_4khz_with_a_drifting_oscillator():
    """2.4 million sets through SPI, a +1500 → −500 ppm oscillator step halfway, occasional
    late polls: every set arrives in order or after a reported gap, and the fit follows."""
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock, odr_error_ppm=1500.0)
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(odr_hz=4000)
    dev.start()
    tb = TimeBase(4000.0, group_delay_samples=dev.group_delay_samples, memory_s=60.0)
    rng = np.random.default_rng(7)
    last, gap_said, changed = -1, False, False
    while clock.monotonic() - 1000.0 < 600.0:
        if not changed and clock.monotonic() - 1000.0 > 300.0:
            emu.set_odr_error_ppm(-500.0)
            changed = True
        clock.advance(0.02 if rng.random() < 0.001 else rng.uniform(0.001, 0.006))
        d = dev.drain()
        tb.add_drain(d)
        gap_said |= d.overrun
        if d.n_sets:
            k = d.counts[:, 0].astype(np.int64)
            assert np.all(np.diff(k) % (1 << 19) == 1)
            assert gap_said or k[0] == (last + 1) % (1 << 19)
            last, gap_said = int(k[-1]), False
    r = tb.rate()
    assert abs(r.ppm + 500.0) < max(5 * r.ppm_u, 20)
