"""The ADXL355 driver over the register-level emulator (SPI and I2C)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from avard.core.errors import BusError, ConfigError, DeviceStalledError, HardwareError
from avard.daemon.hw import registers as R
from avard.daemon.hw.adxl355 import Adxl355, decode_counts, decode_counts_naive, decode_fifo
from avard.daemon.hw.emulator import (
    EmulatedAdxl355,
    FakeSMBus,
    FakeSpiDev,
    VirtualClock,
    constant_source,
    counter_source,
    encode_entries,
)
from avard.daemon.hw.transport import I2cBus, SpiBus
from hypothesis import given, settings
from hypothesis import strategies as st


def rig(kind: str = "spi", odr_hz: float = 1000.0, start: bool = True, **kw):
    clock = VirtualClock()
    emu = EmulatedAdxl355(kw.pop("source", counter_source()), clock, **kw)
    bus = SpiBus(FakeSpiDev(emu)) if kind == "spi" else I2cBus(FakeSMBus(emu))
    dev = Adxl355(bus, clock=clock)
    if start:
        dev.probe()
        dev.reset()
        dev.configure(range_g=2, odr_hz=odr_hz)
        dev.start()
    return dev, emu, clock


# -- decoding ---------------------------------------------------------------------------------
def test_decode_test_vectors_from_the_datasheet():
    raw = bytes([0x7F, 0xFF, 0xF0, 0x80, 0x00, 0x00, 0xFF, 0xFF, 0xF0, 0x00, 0x00, 0x10])
    assert decode_counts(raw).tolist() == [524287, -524288, -1, 1]
    assert decode_counts_naive(raw) == [524287, -524288, -1, 1]
    assert decode_counts(raw).dtype == np.int32


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(-(1 << 19), (1 << 19) - 1), min_size=3, max_size=300))
def test_decode_inverts_encode(values):
    vals = np.array(values[: len(values) - len(values) % 3]).reshape(-1, 3)
    out = decode_fifo(encode_entries(vals))
    assert np.array_equal(out.counts, vals) and out.dropped == 0 and out.carry == b""


def test_decode_fifo_realigns_on_the_x_marker_and_carries_an_unfinished_set():
    sets = np.arange(30).reshape(10, 3)
    buf = encode_entries(sets)
    out = decode_fifo(buf[6:-3])  # starts at Z of set 0, ends after Y of set 9
    assert out.counts[:, 0].tolist() == list(range(3, 27, 3))  # sets 1..8
    assert out.dropped == 1  # the lone Z of set 0
    assert out.carry == buf[-9:-3]  # X, Y of set 9: their Z is still in the FIFO
    again = decode_fifo(out.carry + buf[-3:])
    assert again.counts.tolist() == [[27, 28, 29]]


def test_decode_fifo_drops_empty_entries_and_broken_sets():
    sets = np.arange(12).reshape(4, 3)
    buf = bytearray(encode_entries(sets))
    del buf[3:6]  # set 0 lost its Y entry
    buf += bytes([0, 0, R.FIFO_MARK_EMPTY]) * 3
    out = decode_fifo(bytes(buf))
    assert out.counts[:, 0].tolist() == [3, 6, 9]
    assert out.dropped == 2 and out.empty == 3 and out.carry == b""


# -- probe, reset, configure -------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["spi", "i2c"])
def test_probe_reads_ids(kind):
    dev, _, _ = rig(kind, start=False)
    info = dev.probe()
    assert (info.devid_ad, info.devid_mst, info.partid, info.name) == (0xAD, 0x1D, 0xED,
                                                                        "ADXL355")


@pytest.mark.parametrize("level,words", [(0xFF, "all ones"), (0x00, "all zeros")])
def test_probe_on_an_unplugged_bus_says_so(level, words):
    dev, emu, _ = rig(start=False)
    emu.faults.unplug(level)
    with pytest.raises(HardwareError, match=words):
        dev.probe()


def test_probe_wrong_spi_mode_is_recognised_as_a_bit_shift():
    dev, _, _ = rig(start=False)
    dev.bus.spi.mode = 3  # someone changed the mode behind the transport's back
    with pytest.raises(HardwareError, match="shifted by one bit"):
        dev.probe()


def test_probe_wrong_part_and_adxl359(caplog):
    dev, _, _ = rig(start=False, partid=0x42)
    with pytest.raises(HardwareError, match="PARTID reads 0x42"):
        dev.probe()
    dev, _emu, _ = rig(start=False, partid=R.PARTID_ADXL359)
    with caplog.at_level(logging.WARNING):
        assert dev.probe().name == "ADXL359"
    assert "ADXL359" in caplog.text


def test_probe_bus_failure_mentions_another_driver():
    dev, emu, _ = rig(start=False)
    emu.faults.fail_always()
    with pytest.raises(HardwareError, match="another driver"):
        dev.probe()


def test_reset_polls_nvm_busy_and_gives_up_with_advice():
    dev, _, clock = rig(start=False, nvm_busy_s=0.030)
    t0 = clock.monotonic()
    dev.reset()
    assert clock.monotonic() - t0 >= 0.030  # it waited for NVM_BUSY, using the clock
    dev, _emu, clock = rig(start=False, nvm_busy_s=10.0)
    with pytest.raises(HardwareError, match="NVM_BUSY"):
        dev.reset(timeout_s=0.05)


def test_configure_programs_registers_in_standby():
    dev, emu, _ = rig(start=False)
    dev.configure(range_g=8, odr_hz=125, watermark=30)
    assert emu.regs[R.ADDR["FILTER"]] == 0x05
    assert emu.regs[R.ADDR["RANGE"]] == 0x83  # I2C_HS bit kept
    assert emu.regs[R.ADDR["FIFO_SAMPLES"]] == 30
    assert dev.scale_mps2 == pytest.approx(9.80665 / 64000)
    dev.start()
    dev.configure(range_g=2, odr_hz=4000)  # from measurement mode: standby first
    assert emu.regs[R.ADDR["FILTER"]] == 0x00 and not emu.ignored_writes


def test_configure_refuses_rates_ranges_watermarks_the_chip_lacks():
    dev, _, _ = rig(start=False)
    with pytest.raises(ConfigError, match=r"nearest: 125 Hz and 62\.5 Hz"):
        dev.configure(odr_hz=100)
    with pytest.raises(ConfigError):
        dev.configure(range_g=3)
    with pytest.raises(ConfigError, match="watermark"):
        dev.configure(watermark=97)


def test_configure_detects_a_write_that_did_not_stick():
    dev, _emu, _ = rig(start=False)

    class Deaf:
        def __init__(self, bus):
            self.bus = bus

        def read(self, addr, n):
            return self.bus.read(addr, n)

        def write(self, addr, data):
            if addr != R.ADDR["FILTER"]:
                self.bus.write(addr, data)

        def close(self):
            pass

    dev.bus = Deaf(dev.bus)
    with pytest.raises(HardwareError, match="read back"):
        dev.configure(odr_hz=500)


# -- draining -----------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["spi", "i2c"])
def test_drains_deliver_every_set_in_order(kind):
    dev, emu, clock = rig(kind, odr_hz=4000)
    got, idx = [], 0
    rng = np.random.default_rng(1)
    for _ in range(200):
        clock.advance(rng.uniform(0.0005, 0.0075))  # never longer than the FIFO lasts
        d = dev.drain()
        assert not d.overrun and d.index0 == idx and d.counts.dtype == np.int32
        assert d.t_mono <= d.t_mono_end and d.t_real - d.t_mono == pytest.approx(1.7e9)
        idx += d.n_sets
        got.append(d.counts)
    c = np.concatenate(got)
    assert len(c) == emu.produced - emu.fifo_entries // 3
    assert np.array_equal(c[:, 0], np.arange(len(c)))
    assert np.array_equal(c[:, 2], np.arange(len(c)) + 7)


def test_max_sets_leaves_the_rest_for_the_next_drain():
    dev, _emu, clock = rig()
    clock.advance(0.020)
    a = dev.drain(max_sets=5)
    b = dev.drain()
    assert a.n_sets == 5 and b.index0 == 5 and b.n_sets == 15
    assert b.counts[0, 0] == 5


def test_overrun_is_reported_once_as_a_gap_of_unknown_size():
    dev, emu, clock = rig()
    clock.advance(0.010)
    first = dev.drain()
    clock.advance(0.100)  # 100 sets at 1 kHz: the FIFO holds 33
    d = dev.drain()
    assert d.overrun and d.gap_reason == "fifo_overrun"
    assert first.since_last_s is None and d.since_last_s == pytest.approx(0.100)
    # what the gap cost, up to the set still waiting in the sync buffer
    assert round(d.since_last_s * 1000) - d.n_sets - emu.lost in (0, 1)
    assert d.index0 == first.n_sets  # indices count received sets only
    assert d.counts[0, 0] > first.counts[-1, 0] + 1  # the data really jumped
    assert np.all(np.diff(d.counts[:, 0]) == 1)
    clock.advance(0.010)
    assert not dev.drain().overrun and dev.overruns == 1


def test_misaligned_fifo_is_realigned_and_costs_one_set_once():
    dev, emu, clock = rig()
    clock.advance(0.005)
    emu.drop_fifo_entries(1)  # someone popped an X entry
    d = dev.drain()
    assert d.overrun and "realigned" in d.gap_reason
    assert d.counts[0, 0] == 1 and np.all(np.diff(d.counts[:, 0]) == 1)
    for _ in range(5):
        clock.advance(0.0037)
        d2 = dev.drain()
        assert not d2.overrun
        assert d2.counts[0, 0] == d.counts[-1, 0] + 1
        d = d2


def test_partial_set_in_the_fifo_is_carried_not_lost():
    dev, _emu, clock = rig()
    clock.advance(0.004)
    # Read two entries by hand (X, Y of set 0) as a foreign reader would; then the driver's
    # drain starts on a Z entry, drops it, and everything after is intact.
    dev.bus.read(R.ADDR["FIFO_DATA"], 6)
    d = dev.drain()
    assert d.dropped_entries == 1 and d.counts[0, 0] == 1


def test_eio_once_during_a_drain_is_retried_and_flagged():
    dev, emu, clock = rig()
    clock.advance(0.010)
    emu.faults.fail_next(1)
    d = dev.drain()
    # the retry waited 1 ms on the (virtual) clock, so a set may have arrived meanwhile
    assert d.n_sets >= 10 and d.overrun and d.gap_reason == "bus_error"
    assert np.array_equal(d.counts[:, 0], np.arange(d.n_sets))  # nothing was really lost
    assert dev.bus_errors == 1
    clock.advance(0.010)
    assert not dev.drain().overrun


def test_eio_always_raises_bus_error_after_the_retries():
    dev, emu, clock = rig()
    emu.faults.fail_always()
    with pytest.raises(BusError):
        dev.drain()
    assert dev.bus_errors == dev.retries + 1
    emu.faults.clear()
    clock.advance(0.005)
    d = dev.drain()
    assert d.overrun and "bus_error" in d.gap_reason and d.n_sets >= 5


def test_unplugged_all_ones_raises_and_recovers_after_replug():
    dev, emu, clock = rig()
    clock.advance(0.005)
    dev.drain()
    emu.faults.unplug(0xFF)
    clock.advance(0.005)
    with pytest.raises(HardwareError, match="FIFO_ENTRIES reads 127"):
        dev.drain()
    emu.faults.replug()
    emu.power_cycle()  # it came back after losing power: standby, defaults
    dev.recover()
    assert emu.measuring and emu.regs[R.ADDR["FILTER"]] == 0x02
    clock.advance(0.005)
    d = dev.drain()
    assert d.overrun and "recovered" in d.gap_reason and d.n_sets == 5


def test_unplugged_all_zeros_is_found_by_the_stall_check():
    dev, emu, clock = rig()
    emu.faults.unplug(0x00)
    clock.advance(0.1)
    assert dev.drain().n_sets == 0  # zeros look like an empty FIFO at first
    clock.advance(1.0)
    with pytest.raises(HardwareError, match="all zeros"):
        dev.drain()


def test_device_that_stops_producing_raises_stalled_and_recover_restarts_it():
    dev, emu, clock = rig()
    clock.advance(0.01)
    dev.drain()
    emu.stop_producing()
    for _ in range(4):
        clock.advance(0.1)
        assert dev.drain().n_sets == 0
    clock.advance(0.2)
    with pytest.raises(DeviceStalledError, match="no samples"):
        dev.drain()
    emu.resume_producing()
    dev.recover()
    clock.advance(0.01)
    d = dev.drain()
    assert d.n_sets == 10 and d.overrun


def test_reset_by_someone_else_is_reported_as_standby():
    dev, emu, clock = rig()
    emu.power_cycle()
    clock.advance(2.0)
    with pytest.raises(DeviceStalledError, match="standby"):
        dev.drain()


def test_restart_after_standby_is_a_gap_and_indices_continue():
    dev, _emu, clock = rig()
    clock.advance(0.01)
    n = dev.drain().n_sets
    dev.standby()
    dev.start()
    clock.advance(0.01)
    d = dev.drain()
    assert d.overrun and d.index0 == n and "standby" in d.gap_reason


# -- temperature, offsets, self-test -------------------------------------------------------------
def test_temperature_and_intercept():
    dev, _emu, _ = rig(temperature=31.0)
    assert dev.read_temperature_c() == pytest.approx(31.0, abs=0.06)
    dev.temp_intercept_lsb = R.TEMP_INTERCEPT_REV0
    # the same raw value read with the Rev. 0 intercept is 33 LSB / 9.05 LSB/°C cooler
    assert dev.read_temperature_c() == pytest.approx(31.0 - 33 / 9.05, abs=0.06)


def test_temperature_is_reread_when_temp2_changes():
    # raw 0x6FF → 0x700 between the TEMP2 and TEMP1 reads of one burst: the pair tears into
    # 0x600 (28 °C off); TEMP2 read again differs, so the driver reads the pair again.
    first = [0x6FF]  # the first register read sees 0x6FF, every later one 0x700

    def temperature():
        return R.temperature_from_raw(first.pop() if first else 0x700)

    dev, emu, _ = rig(temperature=temperature)
    assert dev.read_temperature_raw() == 0x700
    first.append(0x6FF)
    hi, lo = emu.read(R.ADDR["TEMP2"], 2)
    assert (hi << 8 | lo) == 0x600  # what a driver without the re-read would have used


def test_offsets_round_trip_and_shift_the_output():
    dev, _emu, clock = rig(source=constant_source((1000, -500, 256000)))
    clock.advance(0.002)
    assert dev.drain().n_sets == 2
    assert dev.set_offsets(-1000, 480, -256000) == (-62, 30, -16000)
    assert dev.get_offsets() == (-992, 480, -256000)
    clock.advance(0.003)
    d = dev.drain()
    assert d.overrun  # the restart through standby cleared the FIFO
    assert d.counts[-1].tolist() == [8, -20, 0]
    with pytest.raises(ConfigError):
        dev.set_offsets(1e7, 0, 0)


def test_self_test_passes_on_a_good_part_and_fails_on_a_dead_axis():
    dev, emu, _ = rig(source=constant_source((0, 0, 64000)))  # 1 g on Z at ±8 g
    dev.configure(range_g=8, odr_hz=1000)
    res = dev.self_test()
    assert res.passed and not res.saturated
    assert res.delta_g == pytest.approx((0.3, 0.3, 1.5), abs=1e-4)
    assert emu.regs[R.ADDR["SELF_TEST"]] == 0
    dev, emu, _ = rig(source=constant_source((0, 0, 0)), self_test_g=(0.3, 0.0, 1.5))
    res = dev.self_test()
    assert not res.passed and abs(res.delta_g[1]) < 1e-5


def test_self_test_at_2g_with_gravity_on_z_saturates_and_says_so():
    dev, _emu, _ = rig(source=constant_source((0, 0, 256000)))
    res = dev.self_test()
    assert res.saturated and not res.passed


def test_self_test_from_standby_returns_to_standby():
    dev, emu, _ = rig(start=False)
    dev.probe()
    dev.configure(range_g=4, odr_hz=500)
    assert dev.self_test(n_samples=4).passed
    assert not emu.measuring


class Preempted:
    """A bus that 'loses the CPU' for ``pause_s`` right after the STATUS/FIFO_ENTRIES read,
    as a reader thread on a loaded host does."""

    def __init__(self, bus, clock, pause_s):
        self.bus, self.clock, self.pause_s = bus, clock, pause_s
        self.armed = False

    def read(self, addr, n):
        out = self.bus.read(addr, n)
        if self.armed and addr == R.ADDR["STATUS"] and n == 2:
            self.clock.advance(self.pause_s)
            self.armed = False
        return out

    def write(self, addr, data):
        self.bus.write(addr, data)

    def close(self):
        pass


def test_overrun_between_status_read_and_burst_is_reported_and_voids_the_carry():
    dev, emu, clock = rig()
    dev.bus = Preempted(dev.bus, clock, 0.2)
    clock.advance(0.005)
    emu.drop_fifo_entries(2)  # leaves Z of set 0 first ...
    clock.advance(0.0005)  # ... so the drain carries X (and Y) of the newest, unfinished set
    first = dev.drain()
    assert first.overrun and dev._carry  # realigned, carry pending
    clock.advance(0.004)
    dev.bus.armed = True  # preempted for 200 ms after reading STATUS: the FIFO overruns
    d = dev.drain()
    assert d.overrun and "fifo_overrun" in d.gap_reason
    assert np.all(np.diff(d.counts[:, 0]) == 1)  # the carried X was not glued to a later Y, Z
    assert d.counts[0, 0] > first.counts[-1, 0] + 1
    assert np.array_equal(d.counts[:, 1], -d.counts[:, 0])  # every set is a real set


def test_status_is_read_again_only_when_the_fifo_could_have_overrun():
    """A drain is two transfers (STATUS + FIFO_ENTRIES, the burst) when it took less than
    half the time the FIFO's free room needs to fill; a third (STATUS again) when it was
    preempted that long, which is when an overrun in between is possible."""
    dev, _emu, clock = rig(odr_hz=4000.0)
    bus = dev.bus
    clock.advance(0.004)
    before = bus.transfers
    d = dev.drain()
    assert d.n_sets > 0 and not d.overrun and bus.transfers - before == 2
    dev.bus = Preempted(bus, clock, 0.003)   # 3 ms: 12 sets, over half the free room (16)
    clock.advance(0.004)
    dev.bus.armed = True
    before = bus.transfers
    d = dev.drain()
    assert not d.overrun and bus.transfers - before == 3


def test_a_gap_is_reported_once_even_on_a_drain_without_sets():
    dev, _, clock = rig()
    clock.advance(0.01)
    dev.drain()
    dev.standby()
    dev.start()
    empty = dev.drain()  # no time has passed: no sets, but the gap is said now
    assert empty.n_sets == 0 and empty.overrun
    clock.advance(0.01)
    assert not dev.drain().overrun


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 0.05), st.integers(0, 2), st.booleans()),
                min_size=5, max_size=60))
def test_drains_never_invent_samples_and_report_every_jump(steps):
    """Whatever the timing (overruns included), the FIFO mid-set cuts, and transfer errors:
    every set delivered is a real set, in order, and every jump follows a reported gap.

    Cuts (entries popped by someone else) leave the FIFO mid-set; they are applied only to a
    FIFO that starts on an X entry while the driver holds no unfinished set: popping the rest
    of a set already cut or half read removes a whole set without a trace (the markers only
    mark X), which no driver can see, and no second reader exists in practice."""
    dev, emu, clock = rig(odr_hz=1000)
    last, gap_said = -1, False
    for wait, cut, eio in steps:
        clock.advance(wait)
        if cut and not dev._carry and emu.fifo and emu.fifo[2] & R.FIFO_MARK_X:
            emu.drop_fifo_entries(cut)
        if eio:
            emu.faults.fail_next(1)
        d = dev.drain()
        c = d.counts
        assert np.array_equal(c[:, 1], -c[:, 0]) and np.array_equal(c[:, 2], c[:, 0] + 7)
        assert np.all(np.diff(c[:, 0]) == 1)
        gap_said = gap_said or d.overrun  # a gap may be said on a drain without sets
        if d.n_sets:
            assert c[0, 0] > last
            if c[0, 0] != last + 1:
                assert gap_said
            last = int(c[-1, 0])
            gap_said = False


def test_temperature_intercept_calibration_against_a_reference():
    from avard.daemon.hw.adxl355 import fit_temperature_intercept

    rng = np.random.default_rng(3)
    state = {"t": 25.0}
    # this part's intercept is 1871 LSB, not the datasheet's 1885
    dev, _, _ = rig(temperature=lambda: state["t"], temp_intercept_lsb=1871.0)
    raws, refs = [], []
    for t in rng.uniform(18, 32, 200):
        state["t"] = t
        raws.append(dev.read_temperature_raw())
        refs.append(t + rng.normal(0, 0.03))  # DS18B20 reading
    assert abs(dev.read_temperature_c() - state["t"]) > 1.0  # uncalibrated: off by ~1.5 °C
    refs[::17] = [np.nan] * len(refs[::17])  # DS18B20 dropouts are skipped
    b, u = fit_temperature_intercept(raws, refs)
    assert abs(b - 1871.0) < max(4 * u, 0.05) and u < 0.1
    dev.temp_intercept_lsb = b
    assert abs(dev.read_temperature_c() - state["t"]) < 0.1
    with pytest.raises(ConfigError):
        fit_temperature_intercept([1, 2], [np.nan, 3.0])


def test_drains_with_an_unreliable_stamp_are_not_complete():
    dev, emu, clock = rig()
    clock.advance(0.005)
    assert dev.drain().complete
    clock.advance(0.005)
    emu.faults.fail_next(2)  # two retries wait 2 ms = two periods at 1 kHz after t_mono
    assert not dev.drain().complete
    clock.advance(0.040)  # FIFO full (96 locations): a newer set may sit in the sync buffer
    d = dev.drain()
    assert d.fifo_entries == 96 and not d.complete
    clock.advance(0.005)
    assert not dev.drain(max_sets=2).complete  # sets were left behind


def test_configure_warns_when_the_i2c_bus_cannot_carry_the_rate(caplog):
    dev, _, _ = rig("i2c", start=False)
    assert dev.bus.max_odr_hz() == pytest.approx(0.6 * 100_000 / 81)
    with caplog.at_level(logging.WARNING):
        dev.configure(odr_hz=500)
    assert "expect overruns" not in caplog.text
    with caplog.at_level(logging.WARNING):
        dev.configure(odr_hz=1000)
    assert "expect overruns" in caplog.text


def test_close_puts_the_part_in_standby_and_survives_a_dead_bus():
    dev, emu, _ = rig()
    dev.close()
    assert not emu.measuring and dev.bus.spi.closed
    dev, emu, _ = rig()
    emu.faults.fail_always()
    dev.close()  # logged, not raised
    assert dev.bus.spi.closed


def test_repeated_faults_do_not_flood_the_log(caplog):
    dev, emu, _ = rig()
    emu.faults.fail_always()
    with caplog.at_level(logging.WARNING, logger="avard.daemon.hw.adxl355"):
        for _ in range(200):
            with pytest.raises(BusError):
                dev.drain()
    assert dev.bus_errors == 600
    assert 10 <= len(caplog.records) <= 12


def test_probe_on_i2c_with_no_ack_names_the_address_and_asel():
    clock = VirtualClock()
    emu = EmulatedAdxl355(clock=clock)
    dev = Adxl355(I2cBus(FakeSMBus(emu, address=0x1D), 0x53), clock=clock)
    with pytest.raises(HardwareError, match=r"0x53.*ASEL"):
        dev.probe()
