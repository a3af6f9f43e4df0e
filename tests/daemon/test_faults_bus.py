"""Faults of the SPI/I2C bus, injected into the whole service running over the emulator.

A single EIO costs nothing (the FIFO keeps filling); a burst and an unplugged bus (MISO stuck
at 0xFF or 0x00) make the service re-probe, reset, reconfigure and restart the part once the
bus answers again, and the samples lost meanwhile become one gap record whose bounds are
exactly the jump of the sample index. Checked in the recording and by a real subscriber.

This module also holds the harness the other test_faults_* modules use (``run_rig``).
"""

from __future__ import annotations

import dataclasses
import itertools
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.io.recording import RecordingReader, replay_allan
from avard.daemon.compose import compose
from avard.daemon.config import load_config
from avard.daemon.config_types import as_config
from avard.daemon.hw import registers as R
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSMBus, VirtualClock, counter_source
from avard.daemon.hw.simulation import build_simulated
from avard.daemon.hw.transport import I2cBus
from avard.daemon.net.subscriber import Subscriber
from avard.daemon.service.supervisor import Service, ServiceHooks

from tests.support.rigs import rig_from_parts

from .pubsub import is_probe, wait_until_subscribed

RATE = 125.0

# ------------------------------------------------------------------------------ the harness


def rig_config(data_dir: Path, **extra: Any) -> dict:
    return load_config(None, **{
        "recording.data_dir": str(data_dir),
        "publish.endpoint": "tcp://127.0.0.1:0", "publish.request_endpoint": "tcp://127.0.0.1:0",
        "publish.hwm": 1_000_000, "sensor.poll_hz": 4.0, "allan.snapshot_interval_s": 10.0,
        "allan.checkpoint_interval_s": 20.0, "recording.segment_s": 600.0, **extra})


class Listener:
    """A real SUB socket in a thread, keeping every record it gets."""

    def __init__(self, svc: Service) -> None:
        self.sub = Subscriber(svc.publisher.endpoint,
                              request_endpoint=svc.request_server.endpoint).connect(join=False)
        # before acquisition starts: from here on the subscriber gets every message
        self.records: list[tuple[str, dict]] = wait_until_subscribed(svc.publisher, self.sub)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _keep(self, msg: Any) -> None:
        if not is_probe(msg.record):
            self.records.append((msg.topic, msg.record))

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.sub.recv(timeout_s=0.1)
            if msg is not None:
                self._keep(msg)

    def finish(self) -> None:
        self._stop.set()
        self._thread.join(5)
        while (msg := self.sub.recv(timeout_s=0.3)) is not None:
            self._keep(msg)
        self.sub.close()

    def raw(self) -> list[dict]:
        return [r for t, r in self.records if t == "raw"]


@dataclass
class Rig:
    """One finished run: the service, what a subscriber got, the recording, the fault log."""

    svc: Service
    listener: Listener
    data_dir: Path
    ctx: dict[str, Any]
    injected: list[tuple[float, str]] = field(default_factory=list)

    def records(self) -> list[dict]:
        return list(RecordingReader(self.data_dir))

    def kinds(self, kind: str) -> list[dict]:
        return [r for r in self.records() if r["kind"] == kind]


Inject = Callable[[dict[str, Any], float], None]


def run_rig(tmp_path: Path, seconds: float, *, inject: Inject | None = None, seed: int = 7,
            speed: float | None = None, bank: Any = None, recorder_factory: Any = None,
            listener_factory: Callable[[Service], Any] | None = None,
            notifier: Any = None, **cfg_extra: Any) -> Rig:
    """Run the service over the emulator for ``seconds`` of virtual time with a subscriber.

    ``inject(ctx, t)`` is called by the reader thread before every drain with the time since
    start; ``ctx`` holds svc, sims, emu (EmulatedAdxl355), clock (VirtualClock), dev, and a
    ``once(name)`` helper that is True the first time it is asked for ``name``. ``speed``
    caps virtual time at that many times real time (a bank of real DS18B20 threads needs real
    time to pass); None runs as fast as the CPU allows.
    """
    data_dir = tmp_path / "rec"
    cfg = rig_config(data_dir, **cfg_extra)
    dev, clock, sims, emu = build_simulated(cfg, "quiet-lab", seed=seed)
    done: set[str] = set()
    injected: list[tuple[float, str]] = []

    def once(name: str) -> bool:
        if name in done:
            return False
        done.add(name)
        injected.append((ctx["clock"].monotonic(), name))
        return True

    if inject is not None:
        # Before every drain (also while the bus fails, when the reader's on_tick hook is not
        # called), so a fault can both start and end on schedule.
        drain = dev.drain

        def faulty_drain(*args: Any, **kwargs: Any) -> Any:
            inject(ctx, clock.monotonic() - svc.t_start)
            return drain(*args, **kwargs)

        dev.drain = faulty_drain  # type: ignore[method-assign]

    config = as_config(cfg)
    parts = rig_from_parts(config, dev, clock, simulate="quiet-lab", speed=speed, sims=sims,
                           bank=bank)
    if bank is not None:     # the bank replaces the simulated DS18B20s; the ticks stay
        parts = dataclasses.replace(parts, extra_temperature_names=(), temperature_feed=None)
    svc = compose(config, parts, notifier=notifier,
                  hooks=ServiceHooks(recorder=recorder_factory))
    ctx: dict[str, Any] = {"svc": svc, "sims": sims, "emu": emu, "clock": clock, "dev": dev,
                           "once": once}
    box: dict[str, Any] = {}
    make = listener_factory or Listener
    svc.run(seconds, before_acquisition=lambda: box.setdefault("l", make(svc)))
    box["l"].finish()
    return Rig(svc, box["l"], data_dir, ctx, injected)


def assert_index_jumps_match_gaps(recs: list[dict]) -> list[dict]:
    """The raw index is continuous except exactly over the announced gaps; returns the gaps."""
    raw = [r for r in recs if r["kind"] == "raw"]
    gaps = [r for r in recs if r["kind"] == "gap"]
    jumps = [(a["i0"] + a["n"], b["i0"]) for a, b in itertools.pairwise(raw)
             if b["i0"] != a["i0"] + a["n"]]
    assert [(g["i0"], g["i0"] + g["n"]) for g in gaps if g["n"]] == jumps
    return gaps


def assert_subscriber_saw_everything(rig: Rig) -> None:
    """Every recorded sample reached the subscriber once; holes only where gaps say."""
    st = rig.listener.sub.stats
    assert st.samples_unexplained == 0 and st.samples_repeated == 0
    assert st.messages_lost == 0
    raw_sub = rig.listener.raw()
    raw_rec = rig.kinds("raw")
    idx_sub = np.concatenate([r["i0"] + np.arange(r["n"]) for r in raw_sub])
    idx_rec = np.concatenate([r["i0"] + np.arange(r["n"]) for r in raw_rec])
    np.testing.assert_array_equal(idx_sub, idx_rec)


def assert_allan_stream_equals_recording(rig: Rig) -> None:
    avars = [r for t, r in rig.listener.records if t == "avar"]
    streamed = np.asarray(avars[-1]["snapshot"]["avar"], dtype=float)
    offline = replay_allan(rig.data_dir).snapshot().avar
    scale = np.where(offline == 0, 1.0, np.abs(offline))
    assert float(np.max(np.abs(streamed - offline) / scale)) < 1e-12


# ------------------------------------------------------------------------------ the tests


def test_single_eio_costs_nothing(tmp_path):
    def inject(ctx: dict, t: float) -> None:
        if t > 15 and ctx["once"]("eio"):
            ctx["emu"].faults.fail_next(1)

    rig = run_rig(tmp_path, 40.0, inject=inject)
    recs = rig.records()
    # The driver retried the transfer; the FIFO kept the samples. Continuity cannot be proven
    # across a failed transfer, so the Allan segment may end there (a gap of n = 0), but not
    # one sample is missing.
    gaps = assert_index_jumps_match_gaps(recs)
    assert rig.ctx["emu"].faults.injected == 1
    assert rig.ctx["dev"].bus_errors == 1
    # Nothing was lost: every set the emulator produced is in the recording (bar the last
    # poll's worth still in its FIFO at stop).
    recorded = sum(r["n"] for r in recs if r["kind"] == "raw")
    produced = rig.ctx["emu"].produced_total
    assert 0 <= produced - recorded <= RATE / 4.0 + 1
    # The gap's size is an estimate from elapsed time (drain timing against the sample
    # phase): it may claim one sample that was never lost, never more.
    # KNOWN LIMITATION (reported): such a phantom sample shifts the index by one.
    assert all(g["n"] <= 1 for g in gaps)
    assert_subscriber_saw_everything(rig)


@pytest.mark.parametrize(("fault", "reason"), [
    ("burst", "bus_error"),        # EIO in 4 drains in a row: the FIFO overran meanwhile
    ("unplug-ff", "recovered"),    # unplugged (MISO high), lost power, plugged back in
    ("unplug-00", "recovered"),    # the same with MISO pulled low
    ("glitch-ff", "overrun"),      # MISO stuck high for 4 s without a power loss
])
def test_burst_or_unplug_then_recover_with_one_gap(tmp_path, fault, reason):
    def inject(ctx: dict, t: float) -> None:
        emu, faults = ctx["emu"], ctx["emu"].faults
        if t > 15 and ctx["once"]("start"):
            if fault == "burst":
                faults.fail_next(12)  # 4 drains of 3 tries fail: the part is reset
            else:
                faults.unplug(0xFF if fault.endswith("ff") else 0x00)
        if t > 19 and fault != "burst" and ctx["once"]("replug"):
            if fault.startswith("unplug"):
                emu.power_cycle()  # back with every register at reset: standby, ±2 g, 4 kHz
            faults.replug()

    # ±4 g, so that a part left at its reset range (±2 g) would be noticed
    rig = run_rig(tmp_path, 45.0, inject=inject, **{"sensor.range_g": 4})
    recs = rig.records()
    gaps = assert_index_jumps_match_gaps(recs)
    lossy = [g for g in gaps if g["n"]]
    assert len(lossy) == 1, gaps
    gap = lossy[0]
    assert reason in gap["reason"], gap
    # The gap's bounds: it starts where the recorded samples stop and spans about the outage.
    t_fault = rig.injected[0][0] - rig.svc.t_start
    outage_s = 4.0 if fault != "burst" else 0.0
    assert gap["n"] <= (outage_s + 4.0) * RATE
    raw = [r for r in recs if r["kind"] == "raw"]
    before = [r for r in raw if r["i0"] < gap["i0"]]
    assert before[-1]["i0"] + before[-1]["n"] == gap["i0"]
    assert abs(gap["i0"] / RATE - t_fault) < 2.0
    # Re-probed and reprogrammed: measuring again at the configured range and ODR ...
    emu: EmulatedAdxl355 = rig.ctx["emu"]
    assert emu.measuring and emu.range_g() == 4 and emu.odr_hz == RATE
    # ... and samples continued to the end of the run.
    t_end = rig.svc.final_status["sim_time_s"]
    after = sum(r["n"] for r in raw if r["i0"] >= gap["i0"])
    assert after >= (t_end - t_fault - outage_s - 4.0) * RATE
    events = [r["name"] for r in recs if r["kind"] == "event"]
    assert "bus_error" in events or "stalled" in events
    assert_subscriber_saw_everything(rig)
    assert rig.listener.sub.stats.samples_service_gap == sum(g["n"] for g in gaps)
    assert_allan_stream_equals_recording(rig)


@pytest.mark.parametrize("level", [0xFF, 0x00])
def test_i2c_unplugged_and_back_is_reprobed(level):
    # The I2C path of the same driver: nothing acks while unplugged (EREMOTEIO); after the
    # sensor is back, recover() probes, resets and reprograms, and the next drain is a gap.
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock)
    dev = Adxl355(I2cBus(FakeSMBus(emu)), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=4, odr_hz=RATE)
    dev.start()
    clock.advance(0.2)
    first = dev.drain()
    assert first.counts.shape[0] > 0
    emu.faults.unplug(level)
    clock.advance(0.2)
    with pytest.raises(Exception) as info:
        dev.drain()
    assert "ADXL355" in str(info.value) or "bus" in str(info.value).lower()
    emu.faults.replug()
    emu.power_cycle()  # it lost power while unplugged: registers at reset, standby
    dev.recover()
    assert emu.range_g() == 4 and emu.odr_hz == RATE and emu.measuring
    assert emu.regs[R.ADDR["POWER_CTL"]] & 0x01 == 0
    clock.advance(0.3)
    after = dev.drain()
    assert after.counts.shape[0] > 0
    assert after.gap_reason is not None and "recovered" in after.gap_reason
