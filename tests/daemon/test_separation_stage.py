"""daemon/service/separation_stage.py: the live separation fed from the emulated rig (several
ADXL355s on one bed, drained through the real driver, each sensor on its own index and fitted
time base), held equal to the offline estimator on the same aligned samples; a loss or a slip
in one sensor is a gap for its pairs only; the aligner's seams."""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np
import pytest
from avard.core.analysis.separate import separate
from avard.core.errors import DataError
from avard.daemon.hw.rig import BusSpec, SensorSpec, bring_up
from avard.daemon.hw.simulation import BedSpec, emulated_rig
from avard.daemon.hw.timebase import TimeBase
from avard.daemon.service.separation_stage import (
    AlignedBlock,
    Aligner,
    SensorBlock,
    SensorClock,
    SeparationStage,
)

ODR = 125.0
SPECS = (SensorSpec("left", BusSpec("spi", 0, device=0), odr_hz=ODR),
         SensorSpec("right", BusSpec("spi", 0, device=1), odr_hz=ODR),
         SensorSpec("i2c", BusSpec("i2c", 1, address=0x53), odr_hz=ODR))
#: each sensor's index starts elsewhere (a sensor added to a running rig, a restart)
ORIGIN = (0, 1000, 77)
#: the bed: white 1e-4 m/s/√s (ADEV 1e-4 m/s² at 1 s) and a slow tilt
BED = BedSpec(white=1e-4, tilt=1e-6, seed=2)


def _bring_up_together(clock: Any, specs: Any, rig: list[tuple[str, Any, Any]]) -> None:
    """Bring-up takes virtual time (5 ms a sensor), so the sensors would start apart: each
    goes to standby the instant it started (before it made a sample), and all start at one
    instant, as an external sync would have them: then every sensor's sample k feels the bed
    (a function of time, daemon/hw/simulation.BedMotion) at one instant, and the indices at
    a tick are each sensor's origin apart (what the test below holds)."""
    for spec, (_n, dev, _e) in zip(specs, rig, strict=True):
        bring_up(dev, spec)
        dev.standby()
    clock.advance(0.1)
    for _n, dev, _e in rig:
        dev.start()


def _drive(n_sensors: int, seconds: float, *, lose: tuple[int, int] | None = None,
           bed: BedSpec = BED
           ) -> tuple[SeparationStage, Aligner, list[AlignedBlock]]:
    """Run the emulated rig; every drain → SensorBlock (+ that sensor's fitted clock) →
    Aligner → SeparationStage. ``lose`` = (sensor, drain number): that drain never arrives."""
    specs = SPECS[:n_sensors]
    clock, rig = emulated_rig(specs, "quiet-lab", bed=bed, seed=3)
    _bring_up_together(clock, specs, rig)
    names = [n for n, _d, _e in rig]
    aligner = Aligner(names)
    stage = SeparationStage(names, ODR)
    timebases = [TimeBase(ODR) for _ in rig]
    blocks = []
    for k in range(int(seconds / 0.2)):
        clock.advance(0.2)
        for s, (name, dev, _e) in enumerate(rig):
            d = dev.drain()
            assert not d.overrun
            i0 = d.index0 + ORIGIN[s]
            tb = timebases[s]
            tb.update(i0 + len(d.counts) - 1, d.t_mono)
            if lose == (s, k):
                continue
            aligner.push(SensorBlock(name, i0, d.counts * dev.scale_mps2),
                         SensorClock.of(tb, i0))
        while (blk := aligner.pop()) is not None:
            stage.feed(blk)
            blocks.append(blk)
    stage.flush()
    return stage, aligner, blocks


@pytest.mark.parametrize("n_sensors", [2, 3])
def test_live_separation_equals_offline_on_the_emulated_rig(n_sensors: int) -> None:
    stage, aligner, blocks = _drive(n_sensors, 240.0)
    index = np.concatenate([b.index for b in blocks], axis=1)
    accel = np.concatenate([b.accel for b in blocks], axis=1)
    assert np.all(index >= 0)                      # nothing lost, nothing slipped
    assert aligner.slips == dict.fromkeys(aligner.names, 0)
    # aligned by time base: each sensor's own index, its origin apart
    for s in range(1, n_sensors):
        np.testing.assert_array_equal(index[s] - ORIGIN[s], index[0] - ORIGIN[0])
    assert index.shape[1] >= 240 * ODR - 64
    live = stage.separation()
    assert live is not None
    offline = separate(list(accel), ODR, sensors=stage.sensors, axes=("x", "y", "z"),
                       fit=False, overlap=8)
    assert live.n_samples == offline.n_samples
    for x, y in zip(live.axes, offline.axes, strict=True):
        np.testing.assert_array_equal(x.m, y.m)
        scale = np.max([p.hi for p in (*y.self_noise, y.common)], axis=0)
        for p, q in zip((*x.self_noise, x.common), (*y.self_noise, y.common), strict=True):
            np.testing.assert_array_equal(p.upper_limit, q.upper_limit)
            np.testing.assert_array_less(np.abs(p.var - q.var), 1e-12 * scale)
            np.testing.assert_allclose(p.hi, q.hi, rtol=1e-12)
            # lo is found by bisection to 2⁻⁴⁰ of its bracket (up to the upper end): the
            # moments' 1e-13 rounding can move it by one step, so held as var is, to the scale
            np.testing.assert_array_less(np.abs(p.lo - q.lo), 1e-12 * (np.abs(q.lo) + scale))
    # the bed is found: white 1e-4 m/s/√s, ADEV 1e-4 m/s² at τ = 1 s
    z = live.axes[2]
    k = int(np.argmin(np.abs(z.tau - 1.0)))
    assert np.sqrt(z.common.var[k]) == pytest.approx(1e-4, rel=0.25)


@pytest.mark.parametrize("who", [1, 0])
def test_a_lost_block_is_a_gap_for_that_sensors_pairs_only(who: int) -> None:
    """"right" (or "left", whose index is the ticks) loses one drain, 0.2 s."""
    stage, _aligner, blocks = _drive(3, 60.0, lose=(who, 100))
    segments = {acc.sensors: acc.n_segments for acc in stage.pairs.values()}
    names = ("left", "right", "i2c")
    assert segments == {pair: 2 if names[who] in pair else 1 for pair in segments}
    index = np.concatenate([b.index for b in blocks], axis=1)
    missing = int(np.sum(index[who] < 0))
    assert 24 <= missing <= 26                                   # 0.2 s at 125 Hz
    assert int(np.sum(index < 0)) == missing                     # the others lost nothing
    n = {acc.sensors: acc.n_samples for acc in stage.pairs.values()}
    whole = [p for p in n if names[who] not in p]
    for p in n:
        assert n[whole[0]] - n[p] == (missing if names[who] in p else 0)


def test_clocks_that_drift_apart_slip_and_each_slip_is_a_gap() -> None:
    """Sensor b runs 200 ppm fast: its index gains a sample on a's every 5000 samples; the
    aligner follows by time base and every slip ends the pair's segment."""
    rate = 100.0
    ppm = 200e-6
    a_clock = SensorClock(0, 0.0, 1 / rate)
    b_clock = SensorClock(0, 0.0021, 1 / (rate * (1 + ppm)))
    aligner = Aligner(["a", "b"])
    stage = SeparationStage(["a", "b"], rate, axes=("z",))
    rng = np.random.default_rng(1)
    n = 20_000
    for i0 in range(0, n, 250):
        aligner.push(SensorBlock("a", i0, rng.normal(size=(250, 1))), a_clock)
        aligner.push(SensorBlock("b", i0, rng.normal(size=(250, 1))), b_clock)
        while (blk := aligner.pop()) is not None:
            stage.feed(blk)
    stage.flush()
    # 20 000 samples × 200 ppm = 4 samples gained; a slip each
    assert aligner.slips["b"] == 4
    (acc,) = stage.pairs.values()
    assert acc.n_segments == 5
    assert n - 2 <= acc.n_samples + 4 <= n


def test_a_silent_sensor_does_not_hold_the_others_forever() -> None:
    aligner = Aligner(["a", "b"], max_wait_s=1.0)
    clock = SensorClock(0, 0.0, 0.01)
    aligner.push(SensorBlock("a", 0, np.zeros((500, 3))), clock)
    blk = aligner.pop()
    assert blk is not None and blk.index.shape[1] == 400        # 5 s waited, 1 s kept back
    assert np.all(blk.index[1] == -1)


def test_state_round_trip_and_refusals() -> None:
    stage, _a, _b = _drive(2, 30.0)
    again = SeparationStage.from_state(msgpack.unpackb(msgpack.packb(stage.state())))
    x, y = stage.separation(), again.separation()
    assert x is not None and y is not None
    np.testing.assert_array_equal(x.axes[0].common.var, y.axes[0].common.var)
    with pytest.raises(DataError, match="2 or 3"):
        SeparationStage(["a", "b", "c", "d"], ODR)
    with pytest.raises(DataError, match="repeats"):
        al = Aligner(["a", "b"])
        al.push(SensorBlock("a", 10, np.zeros((5, 3))), SensorClock(0, 0.0, 0.01))
        al.push(SensorBlock("a", 12, np.zeros((5, 3))), SensorClock(0, 0.0, 0.01))
    with pytest.raises(DataError, match="lacks"):
        stage.feed(AlignedBlock(("x", "y"), np.zeros((2, 1), np.int64), np.zeros((2, 1, 3))))


def test_the_separation_is_computed_once_per_interval_of_samples_then_per_growth() -> None:
    rng = np.random.default_rng(2)
    stage = SeparationStage(["a", "b"], 100.0, axes=("z",), interval_s=60.0)
    names = ("a", "b")

    def feed(n: int, start: int) -> None:
        idx = np.tile(np.arange(start, start + n, dtype=np.int64), (2, 1))
        stage.feed(AlignedBlock(names, idx, rng.normal(size=(2, n, 1))))

    assert stage.record_fields() == {}                # nothing yet: no separation
    feed(3000, 0)
    first = stage.record_fields()
    assert stage.computed == 1 and first["separation"]["n_samples"] == 3000
    feed(3000, 3000)                                  # 30 s more: the last one again
    assert stage.record_fields() == first and stage.computed == 1
    feed(3000, 6000)                                  # 60 s since: a new one
    again = stage.record_fields()
    assert stage.computed == 2 and again["separation"]["n_samples"] == 9000
    # a long run: again when it grew by a tenth (here 2 h: 720 s), at most every 600 s
    feed(720_000 - 9000, 9000)
    assert stage.record_fields()["separation"]["n_samples"] == 720_000
    feed(59_000, 720_000)                             # 590 s: not yet
    assert stage.record_fields()["separation"]["n_samples"] == 720_000
    feed(1_000, 779_000)                              # 600 s: the cap
    assert stage.record_fields()["separation"]["n_samples"] == 780_000
    # the run's last record: whatever came in since, now
    feed(10, 780_000)
    assert stage.record_fields(force=True)["separation"]["n_samples"] == 780_010


def test_readers_push_from_their_threads_while_one_consumer_pops() -> None:
    import threading

    n, b = 20_000, 50
    rng = np.random.default_rng(4)
    data = rng.normal(size=(3, n, 3))
    names = ("a", "b", "c")
    # unpaced threads run apart by more than the 30 s a silent sensor is waited for (in
    # samples); a real-time reader that far behind is stuck, these are only unscheduled
    aligner = Aligner(names, max_wait_s=1e6)
    clock = SensorClock(0, 0.0, 0.01)
    got: list[AlignedBlock] = []
    pushed = threading.Barrier(4)

    def reader(s: int) -> None:
        pushed.wait()
        for i0 in range(0, n, b):
            aligner.push(SensorBlock(names[s], i0, data[s, i0:i0 + b]), clock)

    def consumer() -> None:
        pushed.wait()
        rows = 0
        while rows < n - 1:      # the last tick waits for a sample after it (SLIP margin)
            blk = aligner.pop()
            if blk is None:
                continue
            got.append(blk)
            rows += blk.index.shape[1]

    threads = [threading.Thread(target=reader, args=(s,)) for s in range(3)]
    threads.append(threading.Thread(target=consumer))
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not any(t.is_alive() for t in threads)
    index = np.concatenate([g.index for g in got], axis=1)
    accel = np.concatenate([g.accel for g in got], axis=1)
    k = index.shape[1]
    np.testing.assert_array_equal(index, np.tile(np.arange(k), (3, 1)))
    np.testing.assert_array_equal(accel, data[:, :k])
