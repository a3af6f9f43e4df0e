"""The emulator against the datasheet's rules (through the real SpiBus over FakeSpiDev)."""

from __future__ import annotations

import errno
from typing import ClassVar

import numpy as np
import pytest
from avard.core.errors import BusError
from avard.daemon.hw import registers as R
from avard.daemon.hw.adxl355 import decode_counts
from avard.daemon.hw.emulator import (
    EmulatedAdxl355,
    FakeSpiDev,
    VirtualClock,
    array_source,
    constant_source,
    counter_source,
    encode_entries,
)
from avard.daemon.hw.transport import SpiBus

A = R.ADDR


def make(odr_code: int = 0, **kw):
    clock = VirtualClock()
    emu = EmulatedAdxl355(kw.pop("source", counter_source()), clock, **kw)
    bus = SpiBus(FakeSpiDev(emu))
    bus.write(A["FILTER"], odr_code)
    return emu, bus, clock


def start(bus):
    bus.write(A["POWER_CTL"], 0x00)


def entries(bus) -> int:
    return bus.read(A["FIFO_ENTRIES"], 1)[0]


def test_reset_values_are_readable():
    _emu, bus, _ = make()
    for reg in R.REGISTERS.values():
        if reg.access == "w" or reg.name in ("FILTER", "TEMP2", "TEMP1"):  # TEMP is live
            continue
        assert bus.read(reg.address, 1)[0] == reg.reset, reg.name


def test_config_writes_only_in_standby():
    emu, bus, _ = make()
    start(bus)
    bus.write(A["FILTER"], 0x05)
    bus.write(A["RANGE"], 0x83)
    assert bus.read(A["FILTER"], 1)[0] == 0x00  # refused while measuring
    assert bus.read(A["RANGE"], 1)[0] == 0x81
    assert (A["FILTER"], 0x05) in emu.ignored_writes
    bus.write(A["SELF_TEST"], 0x01)  # not a configuration register: allowed
    assert bus.read(A["SELF_TEST"], 1)[0] == 0x01
    bus.write(A["POWER_CTL"], 0x01)
    bus.write(A["FILTER"], 0x05)
    assert bus.read(A["FILTER"], 1)[0] == 0x05


def test_read_only_registers_ignore_writes():
    _, bus, _ = make()
    bus.write(A["DEVID_AD"], 0x00)
    assert bus.read(A["DEVID_AD"], 1)[0] == 0xAD


def test_standby_clears_the_fifo():
    _emu, bus, clock = make()
    start(bus)
    clock.advance(0.004)  # 16 sets at 4 kHz
    assert entries(bus) == 48
    bus.write(A["POWER_CTL"], 0x01)
    assert entries(bus) == 0


def test_reset_restores_defaults_and_sets_nvm_busy_for_a_while():
    emu, bus, clock = make(nvm_busy_s=0.003)
    bus.write(A["FIFO_SAMPLES"], 0x10)
    start(bus)
    clock.advance(0.002)
    bus.write(A["RESET"], 0x12)  # only 0x52 resets
    assert entries(bus) > 0
    bus.write(A["RESET"], R.RESET_CODE)
    assert bus.read(A["STATUS"], 1)[0] & R.STATUS_NVM_BUSY
    assert bus.read(A["FIFO_SAMPLES"], 1)[0] == 0x60
    assert bus.read(A["POWER_CTL"], 1)[0] == 0x01 and not emu.measuring
    assert entries(bus) == 0
    clock.advance(0.004)
    assert not bus.read(A["STATUS"], 1)[0] & R.STATUS_NVM_BUSY


def test_fifo_entries_count_locations_and_markers_mark_x():
    _emu, bus, clock = make()
    start(bus)
    clock.advance(5 / 4000)
    assert entries(bus) == 15
    raw = bus.read(A["FIFO_DATA"], 15 * 3)
    b2 = np.frombuffer(raw, np.uint8)[2::3]
    assert list(b2 & 1) == [1, 0, 0] * 5
    assert not (b2 & 2).any()
    vals = decode_counts(raw).reshape(-1, 3)
    assert vals[:, 0].tolist() == [0, 1, 2, 3, 4]  # oldest first
    assert vals[:, 1].tolist() == [0, -1, -2, -3, -4]


def test_empty_fifo_reads_carry_the_empty_bit():
    _, bus, _ = make()
    raw = bus.read(A["FIFO_DATA"], 6)
    assert raw[2] & R.FIFO_MARK_EMPTY and raw[5] & R.FIFO_MARK_EMPTY


def test_burst_pops_one_entry_on_first_byte_and_every_third_after():
    _emu, bus, clock = make()
    start(bus)
    clock.advance(4 / 4000)  # 12 entries
    bus.read(A["FIFO_DATA"], 1)  # one byte pops a whole entry
    assert entries(bus) == 11
    bus.read(A["FIFO_DATA"], 4)  # bytes 0 and 3 pop: two entries
    assert entries(bus) == 9
    nxt = bus.read(A["FIFO_DATA"], 3)
    assert nxt[2] & R.FIFO_MARK_X  # entry 3 = X of set 1
    assert decode_counts(nxt)[0] == 1


def test_auto_increment_stops_at_fifo_data():
    _emu, bus, clock = make()
    start(bus)
    clock.advance(2 / 4000)
    raw = bus.read(A["XDATA3"], 9 + 6)  # data registers, then FIFO_DATA twice
    assert decode_counts(raw[:9]).tolist() == [1, -1, 8]  # newest sample
    assert decode_counts(raw[9:]).tolist() == [0, 0]  # X and Y of the oldest set
    assert entries(bus) == 4


def test_fifo_full_at_the_watermark():
    _emu, bus, clock = make()
    bus.write(A["FIFO_SAMPLES"], 30)
    start(bus)
    clock.advance(9 / 4000)
    assert not bus.read(A["STATUS"], 1)[0] & R.STATUS_FIFO_FULL
    clock.advance(1 / 4000)
    assert bus.read(A["STATUS"], 1)[0] & R.STATUS_FIFO_FULL


def test_overrun_past_99_locations_newest_overwrite_oldest_cleared_by_status_read():
    emu, bus, clock = make()
    start(bus)
    clock.advance(32 / 4000)
    assert entries(bus) == 96 and not bus.read(A["STATUS"], 1)[0] & R.STATUS_FIFO_OVR
    clock.advance(1 / 4000)  # set 33 goes into the sync buffer: 99 locations, no overrun
    assert entries(bus) == 96 and not bus.read(A["STATUS"], 1)[0] & R.STATUS_FIFO_OVR
    clock.advance(3 / 4000)  # three more sets: past 99
    assert bus.read(A["STATUS"], 1)[0] & R.STATUS_FIFO_OVR
    assert not bus.read(A["STATUS"], 1)[0] & R.STATUS_FIFO_OVR  # cleared by the read
    assert emu.lost == 3
    vals = decode_counts(bus.read(A["FIFO_DATA"], 96 * 3)).reshape(-1, 3)
    assert vals[:, 0].tolist() == list(range(3, 35))  # the oldest three sets are gone
    assert entries(bus) == 3  # the sync buffer moves into the FIFO
    assert decode_counts(bus.read(A["FIFO_DATA"], 9))[0] == 35


def test_a_long_silence_keeps_only_the_newest_sets():
    emu, bus, clock = make(odr_code=2, chunk=1000)
    start(bus)
    clock.advance(10.0)  # 10 000 sets at 1 kHz
    assert entries(bus) == 96  # production is lazy: it happens at the next bus access
    assert emu.produced == 10_000 and emu.lost == 10_000 - 33
    vals = decode_counts(bus.read(A["FIFO_DATA"], 99 * 3)).reshape(-1, 3)
    assert vals[-1, 0] == 9999 and vals[0, 0] == 9999 - 32


@pytest.mark.parametrize("ppm", [-2500.0, 0.0, 3000.0])
def test_odr_error_in_ppm(ppm):
    emu, bus, clock = make(odr_code=3, odr_error_ppm=ppm)  # 500 Hz
    start(bus)
    for _ in range(1000):
        clock.advance(0.05)
        bus.read(A["FIFO_DATA"], 3 * entries(bus))
    expect = 50.0 * 500 * (1 + ppm * 1e-6)
    assert abs(emu.produced - expect) <= 1


def test_temperature_registers_follow_the_source():
    temps = iter([25.0, 35.0])
    _emu, bus, _ = make(temperature=lambda: next(temps), temp_double_buffered=True)
    hi, lo = bus.read(A["TEMP2"], 2)
    assert ((hi << 8) | lo) == 1885
    hi, lo = bus.read(A["TEMP2"], 2)
    assert ((hi & 0x0F) << 8 | lo) == round(1885 - 90.5)


def test_temperature_registers_are_not_double_buffered():
    raws = iter([0x6FF, 0x700])
    _emu, bus, _ = make(temperature=lambda: R.temperature_from_raw(next(raws)))
    hi, lo = bus.read(A["TEMP2"], 2)  # TEMP2 sampled at 0x6FF, TEMP1 at 0x700
    assert (hi << 8 | lo) == 0x600


def test_offsets_are_added_in_units_of_16_counts():
    _emu, bus, clock = make(source=constant_source((100, 200, 300)))
    bus.write(A["OFFSET_X_H"], (-2 & 0xFFFF).to_bytes(2, "big") + (5).to_bytes(2, "big")
              + (0).to_bytes(2, "big"))
    start(bus)
    clock.advance(1 / 4000)
    assert decode_counts(bus.read(A["FIFO_DATA"], 9)).tolist() == [100 - 32, 200 + 80, 300]


def test_self_test_deflection_needs_st1_and_st2():
    _emu, bus, clock = make(source=constant_source((0, 0, 0)))
    bus.write(A["RANGE"], 0x82)  # ±4 g: 128000 LSB/g
    start(bus)
    bus.write(A["SELF_TEST"], R.SELF_TEST_ST2)
    clock.advance(1 / 4000)
    assert decode_counts(bus.read(A["XDATA3"], 9)).tolist() == [0, 0, 0]
    bus.write(A["SELF_TEST"], R.SELF_TEST_ST1 | R.SELF_TEST_ST2)
    clock.advance(1 / 4000)
    assert decode_counts(bus.read(A["XDATA3"], 9)).tolist() == [38400, 38400, 192000]


def test_values_are_clipped_to_20_bits_and_encoded_like_the_datasheet():
    raw = encode_entries(np.array([[524287, -524288, -1]]))
    assert raw == bytes([0x7F, 0xFF, 0xF1, 0x80, 0x00, 0x00, 0xFF, 0xFF, 0xF0])
    _emu, bus, clock = make(source=constant_source((10**7, -(10**7), 0)))
    start(bus)
    clock.advance(1 / 4000)
    assert decode_counts(bus.read(A["FIFO_DATA"], 9)).tolist() == [524287, -524288, 0]


def test_array_source_plays_then_holds_or_loops():
    s = array_source([[1, 2, 3], [4, 5, 6]])
    assert s(3).tolist() == [[1, 2, 3], [4, 5, 6], [4, 5, 6]]
    s = array_source([[1, 2, 3], [4, 5, 6]], loop=True)
    assert s(3)[:, 0].tolist() == [1, 4, 1]


def test_bad_source_shape_is_reported():
    _emu, bus, clock = make(source=lambda n: np.zeros((n, 2)))
    start(bus)
    clock.advance(0.001)
    with pytest.raises(ValueError, match=r"shape"):
        entries(bus)


def test_eio_once_and_always():
    emu, bus, _ = make()
    emu.faults.fail_next()
    with pytest.raises(BusError) as exc:
        bus.read(0, 1)
    assert exc.value.errno == errno.EIO
    assert bus.read(0, 1) == b"\xad"
    emu.faults.fail_always()
    for _ in range(3):
        with pytest.raises(BusError):
            bus.read(0, 1)
    emu.faults.clear()
    assert bus.read(0, 1) == b"\xad"
    assert emu.faults.injected == 4


@pytest.mark.parametrize("level", [0x00, 0xFF])
def test_unplugged_bus_reads_a_level_and_loses_writes_then_comes_back(level):
    emu, bus, _ = make()
    emu.faults.unplug(level)
    assert bus.read(0, 4) == bytes([level] * 4)
    bus.write(A["FIFO_SAMPLES"], 0x10)
    emu.faults.replug()
    assert bus.read(0, 1) == b"\xad"
    assert bus.read(A["FIFO_SAMPLES"], 1)[0] == 0x60


def test_device_stops_producing_and_resumes_without_catching_up():
    emu, bus, clock = make(odr_code=2)
    start(bus)
    clock.advance(0.010)
    emu.stop_producing()
    clock.advance(1.0)
    assert emu.produced == 10
    emu.resume_producing()
    clock.advance(0.005)
    assert entries(bus) == 15 * 3 and emu.produced == 15


def test_the_time_line_counts_what_a_stall_or_a_power_cycle_did_not_make():
    """A gap is sized by time (daemon/service/acquisition.py), so the soak's truth is the
    part's time line: the sets made (those due before a power cycle among them, though no
    bus access asked for them) and the sets due while it made none."""
    emu, bus, clock = make(odr_code=2)          # 1000 Hz
    start(bus)
    clock.advance(0.010)
    emu.stop_producing()
    clock.advance(1.0)
    emu.resume_producing()
    assert emu.produced_total == 10 and emu.missed_total == 1000
    clock.advance(0.020)                        # 20 sets due, no bus access since
    emu.power_cycle()
    assert emu.produced_total == 30             # made, then lost with the power
    clock.advance(0.5)                          # standby: nothing made, the time line goes on
    bus.write(A["FILTER"], 2)
    start(bus)
    assert emu.missed_total == 1500
    clock.advance(0.005)
    assert entries(bus) == 5 * 3 and emu.produced_total == 35


def test_drop_fifo_entries_leaves_the_fifo_mid_set():
    emu, bus, clock = make()
    start(bus)
    clock.advance(3 / 4000)
    emu.drop_fifo_entries(1)
    assert not bus.read(A["FIFO_DATA"], 3)[2] & R.FIFO_MARK_X


def test_wrong_spi_mode_garbles_the_ids():
    emu = EmulatedAdxl355(clock=VirtualClock())
    spi = FakeSpiDev(emu)
    bus = SpiBus(spi)
    spi.mode = 3
    assert bus.read(0, 1)[0] != 0xAD


def test_virtual_clock_manual_and_real_time():
    c = VirtualClock(start=5.0)
    c.sleep(2.5)
    assert c.monotonic() == 7.5
    c.step_realtime(-3600)
    assert c.realtime() - c.monotonic() == pytest.approx(1.7e9 - 3600)
    with pytest.raises(ValueError):
        c.advance(-1)

def test_virtual_clock_at_a_speed_maps_real_time_exactly(monkeypatch):
    # A stand-in for the real clock: what a sleep asks of it and what the virtual clock reads
    # are exact, however loaded the machine (no wall-time measurement).
    import avard.daemon.hw.emulator as emulator

    class RealTime:
        now = 100.0
        slept: ClassVar[list[float]] = []

        @classmethod
        def monotonic(cls) -> float:
            return cls.now

        @classmethod
        def sleep(cls, s: float) -> None:
            cls.slept.append(s)
            cls.now += s

    monkeypatch.setattr(emulator, "time", RealTime)
    fast = VirtualClock(start=0.0, speed=50.0)
    fast.sleep(1.0)  # 1 virtual second = 20 ms of real time
    assert RealTime.slept == [pytest.approx(0.02)]
    assert fast.monotonic() == pytest.approx(1.0)
    RealTime.now += 0.5  # half a real second: 25 virtual ones
    assert fast.monotonic() == pytest.approx(26.0)
    fast.sleep(0.0)
    assert len(RealTime.slept) == 1


def test_odr_error_can_drift_without_a_jump():
    emu, bus, clock = make(odr_code=2)  # 1 kHz
    start(bus)
    clock.advance(1.0)
    entries(bus)
    assert emu.produced == 1000
    emu.set_odr_error_ppm(5000.0)
    clock.advance(2.0)
    entries(bus)
    assert emu.produced == 1000 + 2010


def test_the_simulated_chip_temperature_starts_where_the_simulation_does() -> None:
    """It read 25 °C before the first sample (a spike at the start of every simulated run)."""
    from avard.daemon.config import load_config
    from avard.daemon.hw.simulation import build_simulated

    cfg = load_config(None, **{"recording.data_dir": "/tmp/avard-test-unused"})
    _dev, _clock, sims, _emu = build_simulated(cfg, "quiet-lab", seed=3)
    before = sims.chip_temperature()
    first = sims.source(1)
    assert len(first) == 1
    assert sims.chip_temperature() == pytest.approx(before, abs=1e-6)
    assert abs(before - 25.0) > 0.5  # quiet-lab's chip is not at 25 °C
