"""The reader process (daemon/hw/drain_process.py): the drain loop in a child process of its
own, its drains handed to the service's reader through a pipe, whole, in order and with every
field the loss accounting uses; its errors raised as their type; a child that dies started
again with a restart gap; a service that stops reading costs drains only after the backlog,
and says so.

No assertion here depends on how fast anything ran: the real-clock runs wait for a count of
sets, and what they check (index = the counter, every loss a gap) holds whether or not the
machine was late.
"""

from __future__ import annotations

import configparser
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from avard.core.errors import AvardError, DeviceStalledError, HardwareError
from avard.daemon.config_types import TemperatureConfig
from avard.daemon.hw import drain_process as DP
from avard.daemon.hw.adxl355 import Drain
from avard.daemon.hw.source import GapReason
from avard.daemon.hw.timebase import SystemClock, TimeBase
from avard.daemon.service.acquisition import Acquisition

from benchmarks.bench_realtime import CheckingRing

EMULATED = "avard.daemon.hw.drain_process:open_emulated"


def _drain(**kw: object) -> Drain:
    base: dict[str, object] = dict(
        counts=np.arange(96, dtype=np.int32).reshape(32, 3) - 40, overrun=True, t_mono=12.5,
        t_real=1.7e9 + 0.25, index0=123_456_789, gap_reason="fifo_overrun,bus_error",
        status=0x06, fifo_entries=96, dropped_entries=3, t_mono_end=12.5004,
        complete=False, since_last_s=0.0123, t_burst=12.5001, t_burst_end=12.5003,
        t_real_u=2e-6, overrun_in_drain=True, t_post=12.5003, post_entries=12)
    base.update(kw)
    return Drain(**base)  # type: ignore[arg-type]


def _roundtrip(msg: bytes) -> Drain:
    head = DP._HEAD.unpack_from(msg)
    assert head[0] == len(msg) <= DP.PIPE_BUF
    return DP._decode_drain(head, msg[DP._HEAD.size:])


def test_a_drain_crosses_the_pipe_with_every_field() -> None:
    for d in (_drain(), _drain(since_last_s=None, overrun=False, gap_reason=None,
                               complete=True, overrun_in_drain=False, post_entries=-1,
                               counts=np.empty((0, 3), np.int32))):
        back = _roundtrip(DP.encode_drain(d))
        assert np.array_equal(back.counts, d.counts) and back.counts.dtype == np.int32
        assert back.gap_reasons == tuple(r for r in GapReason if r in d.gap_reasons)
        for f in ("overrun", "t_mono", "t_real", "index0", "status", "fifo_entries",
                  "dropped_entries", "t_mono_end", "complete", "since_last_s", "t_burst",
                  "t_burst_end", "t_real_u", "overrun_in_drain", "t_post", "post_entries"):
            assert getattr(back, f) == getattr(d, f), f


def test_a_drain_the_child_adds_a_reason_to_is_a_gap() -> None:
    d = _drain(overrun=False, gap_reason=None)
    back = _roundtrip(DP.encode_drain(d, (GapReason.READER_BACKLOG,)))
    assert back.overrun and back.gap_reasons == (GapReason.READER_BACKLOG,)


def test_errors_keep_their_type() -> None:
    for exc in (DeviceStalledError("no samples for 2 s"), HardwareError("x" * 10_000)):
        msg = DP.encode_error(exc)
        assert len(msg) <= DP.PIPE_BUF
        rp = DP.ReaderProcess(DP.ReaderSpec(EMULATED))
        rp._message(msg)
        with pytest.raises(type(exc)) as got:
            rp.drain()
        assert type(got.value) is type(exc) and str(exc).startswith(str(got.value))


def test_the_child_never_blocks_on_a_service_that_does_not_read() -> None:
    """The pipe fills; the writer keeps `limit` messages, drops the oldest and counts them."""
    r, w = os.pipe()
    try:
        os.set_blocking(w, False)
        writer = DP._Writer(w, limit=50)
        msg = DP.encode_drain(_drain())
        sent = 0
        while writer.dropped < 10:          # fills the pipe, then the backlog, then drops
            writer.send(msg)
            sent += 1
        in_pipe = 0
        os.set_blocking(r, False)
        buf = b""
        while True:
            try:
                buf += os.read(r, 1 << 16)
            except BlockingIOError:
                break
        in_pipe = len(buf) // len(msg)
        assert len(buf) % len(msg) == 0          # whole messages only
        assert len(writer.pending) == 50
        assert in_pipe + len(writer.pending) + writer.dropped == sent
        writer.flush()                           # room again: the backlog goes out in order
        assert len(writer.pending) < 50
    finally:
        os.close(r)
        os.close(w)


def test_an_opener_that_fails_is_raised_by_start() -> None:
    spec = DP.ReaderSpec("avard.daemon.hw.drain_process:open_hardware",
                         {"kind": "spi", "number": 99})
    with pytest.raises(HardwareError) as got:
        DP.ReaderProcess(spec, start_timeout_s=60).start()
    assert "spidev" in str(got.value)


def _run_until(acq: Acquisition, ring: CheckingRing, sets: int, limit_s: float = 60.0) -> None:
    acq.start()
    deadline = time.monotonic() + limit_s       # a safety stop, not a measurement
    while ring.received < sets and acq.alive and time.monotonic() < deadline:
        time.sleep(0.05)
    acq.stop()


def _accounted(ring: CheckingRing, acq: Acquisition) -> None:
    """Every set the counter says is missing lies in a gap, and the index is the counter's."""
    assert acq.error is None and ring.disorder == 0
    claimed = sum(int(g["n"]) for g in ring.gaps)
    if ring.true_lost == 0:
        assert ring.max_offset == 0
    else:            # a loaded machine made the child late: the gaps say how much, from time
        assert ring.gaps and abs(claimed - ring.true_lost) <= 3 * len(ring.gaps)
        assert ring.max_offset <= 3 * len(ring.gaps)


def test_the_reader_process_feeds_the_service_reader_on_the_real_clock() -> None:
    rp = DP.ReaderProcess(DP.ReaderSpec(EMULATED, {"odr_hz": 1000.0}, poll_hz=4.0),
                          start_timeout_s=60).start()
    try:
        assert rp.odr_hz == 1000.0 and rp.scale_mps2 > 0 and rp.t_started is not None
        ring = CheckingRing()
        acq = Acquisition(rp, ring, TimeBase(1000.0), SystemClock(),  # type: ignore[arg-type]
                          poll_hz=4.0, chip_interval_s=0.1)
        _run_until(acq, ring, 300)
        assert ring.received >= 300 and ring.first is not None
        _accounted(ring, acq)
        assert 10.0 < rp.read_temperature_c() < 40.0      # the child reads TEMP
    finally:
        rp.close()
    assert rp.pid is None


def test_a_killed_child_is_started_again_and_the_hole_is_a_restart_gap() -> None:
    rp = DP.ReaderProcess(DP.ReaderSpec(EMULATED, {"odr_hz": 500.0}, poll_hz=4.0),
                          start_timeout_s=60).start()
    ring = CheckingRing()
    acq = Acquisition(rp, ring, TimeBase(500.0), SystemClock(),  # type: ignore[arg-type]
                      poll_hz=4.0)
    try:
        acq.start()
        deadline = time.monotonic() + 120       # a safety stop, not a measurement
        while ring.received < 200 and acq.alive and time.monotonic() < deadline:
            time.sleep(0.05)
        first_pid, before = rp.pid, acq.next_index
        assert first_pid is not None and before >= 200
        os.kill(first_pid, signal.SIGKILL)
        while (rp.restarts == 0 or acq.next_index < before + 400) and acq.alive \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        acq.stop()
        assert rp.restarts == 1 and rp.pid not in (None, first_pid)
        assert acq.error is None and acq.bus_errors >= 1     # the dead child was reported
        restart = [g for g in ring.gaps if "restart" in g["reason"]]
        assert len(restart) == 1
        assert restart[0]["i0"] >= before and restart[0]["n"] >= 1
        assert acq.next_index > restart[0]["i0"] + restart[0]["n"]   # samples flow again
    finally:
        rp.close()


def test_the_realtime_drop_in_allows_the_priority_the_reader_asks_for() -> None:
    text = (Path(__file__).parents[2] / "systemd" / "realtime.conf").read_text()
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.optionxform = str  # type: ignore[assignment,method-assign]
    unit.read_string(text)
    assert dict(unit["Service"]) == {"RestrictRealtime": "no", "LimitRTPRIO": "10"}
    assert 1 <= DP.READER_RT_PRIORITY <= int(unit["Service"]["LimitRTPRIO"])


def test_the_hardware_is_drained_by_a_process_unless_int1_is_used(monkeypatch) -> None:
    from avard.daemon.hw import rig as RIG

    started: list[DP.ReaderSpec] = []

    class Fake(DP.ReaderProcess):
        def start(self) -> DP.ReaderProcess:
            started.append(self.spec)
            return self

    def thread_path(_s: object) -> None:
        raise HardwareError("thread path")

    monkeypatch.setattr(DP, "ReaderProcess", Fake)
    monkeypatch.setattr(RIG, "_open_hardware", thread_path)
    bus = RIG.BusSpec("spi", 0, device=1, speed_hz=8_000_000)
    fast = RIG.RigSpec((RIG.SensorSpec("a", bus, odr_hz=4000.0, poll_hz=5.0),),
                       temperature=TemperatureConfig(ds18b20=False, chip_interval_s=2.0))
    rig = RIG.build_rig(fast)
    assert isinstance(rig.sensor, Fake) and len(started) == 1
    spec = started[0]
    assert spec.opener == "avard.daemon.hw.drain_process:open_hardware"
    assert spec.params["odr_hz"] == 4000.0 and spec.params["device"] == 1
    assert spec.params["speed_hz"] == 8_000_000 and spec.poll_hz == 5.0
    assert spec.rt_priority == DP.READER_RT_PRIORITY and spec.chip_interval_s == 2.0
    for odr in (125.0, 4000.0):                   # an INT1 pin keeps the thread
        slow = RIG.RigSpec((RIG.SensorSpec("a", bus, odr_hz=odr, int1_gpio="gpiochip0:25"),))
        with pytest.raises(AvardError):     # the thread path (or the missing GPIO binding)
            RIG.build_rig(slow)
    RIG.build_rig(RIG.RigSpec((RIG.SensorSpec("a", bus, odr_hz=125.0),),
                              temperature=TemperatureConfig(ds18b20=False)))
    assert started[-1].params["odr_hz"] == 125.0
    started.pop()
    assert len(started) == 1


def test_messages_split_anywhere_by_the_reads_arrive_whole_and_in_order() -> None:
    rng = np.random.default_rng(7)
    drains = [_drain(index0=i, counts=np.full((i % 33, 3), i, np.int32)) for i in range(40)]
    stream = b"".join(DP.encode_drain(d) for d in drains)
    rp = DP.ReaderProcess(DP.ReaderSpec(EMULATED))
    cuts = np.sort(rng.choice(np.arange(1, len(stream)), size=200, replace=False))
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(stream)], strict=True):
        rp._feed(stream[a:b])
    got = [rp.drain() for _ in drains]
    assert [d.index0 for d in got] == list(range(40))
    assert all(np.array_equal(g.counts, d.counts) for g, d in zip(got, drains, strict=True))
    with pytest.raises(HardwareError):            # nothing more: said, not invented
        rp.drain()


def test_the_child_ends_when_the_service_goes_away_without_a_word() -> None:
    """The parent killed: its end of the command pipe closes, and the child stops (it must not
    drain a part nobody reads for ever)."""
    rp = DP.ReaderProcess(DP.ReaderSpec(EMULATED, {"odr_hz": 125.0}),
                          start_timeout_s=60).start()
    proc = rp._proc
    assert proc is not None
    os.close(rp._cmd)                 # what the kernel does when the service dies
    rp._cmd = -1
    assert proc.wait(timeout=60) == 0
    rp.close()


def test_the_services_stop_ends_the_reader_process(tmp_path: Path, monkeypatch) -> None:
    import argparse

    from avard.daemon.commands import run as run_cmd
    from avard.daemon.config import load_config
    from avard.daemon.config_types import Config
    from avard.daemon.hw import rig

    monkeypatch.setattr(rig, "HARDWARE_OPENER", EMULATED)
    cfg = load_config(None, **{"recording.enabled": False, "publish.enabled": False,
                               "temperature.ds18b20": False})
    svc = run_cmd.build(argparse.Namespace(simulate=None, speed=None, seed=None),
                        Config.from_dict(cfg))
    reader = svc.rig.sensor
    assert isinstance(reader, DP.ReaderProcess)
    proc = reader._proc
    assert proc is not None and proc.poll() is None
    assert svc.run(0.5) == 0
    assert proc.poll() == 0 and reader.pid is None      # ended, and in standby (exit 0)
