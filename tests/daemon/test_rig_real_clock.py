"""A rig on the real clock (issue 28's check "0 overruns at 125 Hz"): its emulated parts make
sets on the host's clock whether read or not and are drained by a reader process (one per bus
on the Pi; the emulated rig's parts share a bed, so one for them all), or, asked for, by a
reader thread per bus whose parts start measuring when it begins (not when the rig is built)
and which asks for SCHED_FIFO. Whether a run overruns depends on the machine's load: that is
measured by ``python -m benchmarks rig`` (docs/service.md), not asserted here; what is
asserted are counts (every set of every part, by its counter, or in a gap)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any, ClassVar

import pytest
from avard.daemon.config import validate_config
from avard.daemon.config_types import Config
from avard.daemon.hw import drain_process as DP
from avard.daemon.hw import rig as rig_mod
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.pacing import FIFO_SETS
from avard.daemon.hw.rig import SensorSpec, bring_up, build_lanes, bus_readers, describe_rig
from avard.daemon.hw.timebase import SystemClock, TimeBase
from avard.daemon.hw.transport import SpiBus
from avard.daemon.service import acquisition
from avard.daemon.service.acquisition import Acquisition, share_reader
from avard.daemon.service.rig_service import RigService

from benchmarks.bench_realtime import CheckingRing

ODR = 125.0
SENSORS = [{"name": "left", "spi_device": 0}, {"name": "right", "spi_device": 1},
           {"name": "i2c", "bus": "i2c", "i2c_address": 0x53}, {"name": "far", "spi_bus": 1}]


def _config(tmp_path: Path, n: int = 4) -> Config:
    return Config.from_dict(validate_config({
        "sensor": [{**s, "odr_hz": ODR} for s in SENSORS[:n]],
        "temperature": {"ds18b20": False},
        "recording": {"data_dir": str(tmp_path / "rec")},
        "publish": {"enabled": False},
    }))


def test_a_real_clock_rig_has_one_reader_per_bus_and_its_parts_wait_for_them(
        tmp_path: Path) -> None:
    config = _config(tmp_path)
    real = build_lanes(describe_rig(config, simulate="quiet-lab", seed=1, real_clock=True),
                       reader_process=False)
    # SPI0's two chip selects share a reader; I2C and SPI1 have their own
    assert real.readers == ((0, 1), (2,), (3,)) == bus_readers(real.spec.sensors)
    assert not real.spec.clock.stepped
    emus = real.parts["emulators"]
    assert isinstance(emus, list)
    assert not any(e.measuring for e in emus)          # configured, not measuring
    assert all(lane.start_measuring is not None for lane in real.lanes)
    # the stepped rig: one reader steps the clock; its parts measure from the start
    stepped = build_lanes(describe_rig(config, simulate="quiet-lab", seed=1, speed=None))
    assert stepped.readers == ((0, 1, 2, 3),)
    assert stepped.spec.clock.stepped
    assert all(e.measuring for e in stepped.parts["emulators"])
    assert all(lane.start_measuring is None for lane in stepped.lanes)


class _Ring:
    capacity = 1 << 20
    consumers: ClassVar[list[Any]] = []

    def __init__(self) -> None:
        self.marks: list[dict[str, Any]] = []
        self.pushed = 0

    def push(self, counts: Any, index: Any, times: Any) -> None:
        self.pushed += len(counts)

    def mark(self, rec: dict[str, Any]) -> None:
        self.marks.append(rec)


def _part(start: bool) -> tuple[Adxl355, EmulatedAdxl355, VirtualClock]:
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock)
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock)
    bring_up(dev, SensorSpec("s", rig_mod.BusSpec("spi", 0), odr_hz=ODR), start=start)
    return dev, emu, clock


def _acq(dev: Adxl355, clock: VirtualClock, **kw: Any) -> tuple[Acquisition, _Ring]:
    ring = _Ring()
    return Acquisition(dev, ring, TimeBase(ODR), clock, poll_hz=4.0, **kw), ring  # type: ignore[arg-type]


def test_a_part_starts_when_its_reader_begins_so_a_slow_service_start_loses_nothing() -> None:
    slow_start = 4 * FIFO_SETS / ODR            # the service's start outlasting the FIFO
    # measuring from bring-up (as before): the first drain finds the FIFO overrun
    dev, emu, clock = _part(start=True)
    acq, ring = _acq(dev, clock)
    clock.advance(slow_start)
    acq.poll_once()
    assert acq.overruns == 1 and emu.lost > 0
    gaps = [m for m in ring.marks if m["kind"] == "gap"]
    assert len(gaps) == 1 and gaps[0]["n"] == acq.lost_estimate > 0
    # left to the reader: nothing is made before it begins, nothing is lost
    dev, emu, clock = _part(start=False)
    acq, ring = _acq(dev, clock, start_measuring=dev.start)
    clock.advance(slow_start)
    assert not emu.measuring
    acq.begin()
    assert emu.measuring
    for _ in range(8):
        clock.advance(0.1)
        acq.poll_once()
    assert acq.overruns == 0 and acq.lost_estimate == 0 and acq.unaccounted == 0
    assert emu.lost == 0 and not [m for m in ring.marks if m["kind"] == "gap"]
    assert ring.pushed == acq.samples > 0
    assert 0 < acq.fifo_high_water < 3 * FIFO_SETS


def test_the_real_clock_rig_readers_ask_for_sched_fifo(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    asked: list[int] = []

    def fake(priority: int = 10) -> bool:
        asked.append(priority)
        return False

    monkeypatch.setattr(acquisition, "raise_thread_priority", fake)
    config = _config(tmp_path, 3)
    built = build_lanes(describe_rig(config, simulate="quiet-lab", seed=1, real_clock=True),
                        reader_process=False)
    svc = RigService(config, built, reader_rt_priority=7)
    svc.run(0.3)
    assert sorted(asked) == [7, 7]                      # SPI0 (two sensors) and I2C
    assert all(not lane.stepped for lane in svc.lanes)  # no waiting for consumers
    # drained by a reader process: its thread here only reads the pipe, and never asks
    asked.clear()
    cfg_p = _config(tmp_path / "p", 3)
    in_process = build_lanes(describe_rig(cfg_p, simulate="quiet-lab", seed=1,
                                          real_clock=True))
    assert in_process.readers == ((0, 1, 2),)
    assert {lane.info["reader"] for lane in in_process.lanes} == {
        f"process {in_process.parts['reader_process'].pid}"}
    svc = RigService(cfg_p, in_process, reader_rt_priority=7)
    svc.run(0.3)
    assert asked == [] and in_process.parts["reader_process"].pid is None   # closed
    # the stepped rig never asks (its reader steps a virtual clock)
    asked.clear()
    stepped = build_lanes(describe_rig(_config(tmp_path / "v", 3), simulate="quiet-lab",
                                       seed=1, speed=None))
    RigService(_config(tmp_path / "v", 3), stepped, reader_rt_priority=7).run(0.5)
    assert asked == []


def test_one_reader_process_drains_several_parts_every_set_accounted_and_restarts_them_all(
        ) -> None:
    rp = DP.ReaderProcess(DP.ReaderSpec("tests.support.chips:open_counter_chips",
                                        {"n": 3, "odr_hz": 500.0}, poll_hz=4.0, chips=3),
                          start_timeout_s=60).start()
    rings = [CheckingRing() for _ in range(3)]
    acqs = [Acquisition(rp.source(k), rings[k], TimeBase(500.0), SystemClock(),  # type: ignore[arg-type]
                        poll_hz=4.0, chip_interval_s=0.1) for k in range(3)]
    reader = share_reader(acqs)
    try:
        assert all(rp.source(k).t_started is not None for k in range(3))
        reader.start()
        deadline = time.monotonic() + 120       # a safety stop, not a measurement
        while min(r.received for r in rings) < 300 and reader.alive \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        for ring, acq in zip(rings, acqs, strict=True):
            assert ring.received >= 300 and acq.error is None and ring.disorder == 0
            claimed = sum(int(g["n"]) for g in ring.gaps)
            # each part's own sets: the index is its counter, every loss a gap (from time)
            assert abs(claimed - ring.true_lost) <= 3 * len(ring.gaps)
            assert ring.max_offset <= 3 * len(ring.gaps)
        assert 10.0 < rp.source(2).read_temperature_c() < 40.0
        # the child killed: it is started again once, and every part's hole is a restart gap
        first_pid, before = rp.pid, [a.next_index for a in acqs]
        assert first_pid is not None
        os.kill(first_pid, signal.SIGKILL)
        while (rp.restarts == 0 or any(a.next_index < b + 400 for a, b in zip(acqs, before,
                                                                             strict=True))) \
                and reader.alive and time.monotonic() < deadline:
            time.sleep(0.05)
        reader.stop()
        assert rp.restarts == 1 and rp.pid not in (None, first_pid)
        for ring, acq, b in zip(rings, acqs, before, strict=True):
            restart = [g for g in ring.gaps if "restart" in g["reason"]]
            assert acq.error is None and len(restart) == 1 and restart[0]["i0"] >= b
            # the new child brought every part up: none is reset once more on top
            assert not [g for g in ring.gaps if "recovered" in g["reason"]]
            assert acq.next_index > restart[0]["i0"] + restart[0]["n"]
    finally:
        reader.stop()
        rp.close()


def test_a_bus_whose_reader_process_fails_to_start_closes_those_started_before(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from avard.core.errors import HardwareError

    closed: list[str] = []

    class Started:
        pid = 1

        def __init__(self, name: str) -> None:
            self.name = name

        def source(self, k: int) -> int:
            return k

        def close(self) -> None:
            closed.append(self.name)

    def bus_process(chips: list[Any], spec: Any) -> Started:
        if chips[0].bus.kind == "i2c":
            raise HardwareError("no ADXL355 at /dev/i2c-1 address 0x53")
        return Started(chips[0].name)

    monkeypatch.setattr(rig_mod, "_bus_process", bus_process)
    monkeypatch.setattr(rig_mod, "_ds18b20_bank", lambda t: None)
    config = Config.from_dict(validate_config({"sensor": SENSORS}))
    with pytest.raises(HardwareError, match="0x53"):
        build_lanes(describe_rig(config))
    assert closed == ["left"]              # SPI0's process, started before I2C's failed


def test_each_part_of_a_reader_process_gets_its_own_drains_errors_and_temperature() -> None:
    import numpy as np
    from avard.core.errors import DeviceStalledError, HardwareError
    from avard.daemon.hw.adxl355 import Drain

    rp = DP.ReaderProcess(DP.ReaderSpec("unused:opener", chips=3))
    counts = np.arange(12, dtype=np.int32).reshape(4, 3)
    for k in (2, 0):
        rp._message(DP.encode_drain(Drain(counts + k, False, 1.0 + k, 2.0, 0), chip=k))
    rp._message(DP.encode_error(DeviceStalledError("part 1 is silent"), 1))
    rp._message(DP._pack(DP._TEMP, chip=2, times=(1.0, 24.5) + (0.0,) * 6))
    a, b, c = (rp.source(k) for k in range(3))
    assert a.ready() and b.ready() and c.ready()
    got_a, got_c = a.drain(), c.drain()
    assert got_a.t_mono == 1.0 and got_c.t_mono == 3.0
    assert np.array_equal(got_a.counts, counts) and np.array_equal(got_c.counts, counts + 2)
    with pytest.raises(DeviceStalledError, match="part 1"):
        b.drain()
    assert not (a.ready() or b.ready() or c.ready())
    assert c.read_temperature_c() == 24.5
    with pytest.raises(HardwareError):
        a.read_temperature_c()           # part 0 has not said its temperature
