"""`avard record`: a remote stream archived in the recording format, with gaps for losses.

A fake service (an XPUB socket, so the test knows when the subscription has arrived, and a
real RequestServer answering ``header``) sends records with chosen sequence numbers, so a lost
message is a deliberate hole, over real loopback TCP.
"""

from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zmq
from avard.core.errors import DataError, FormatError
from avard.core.io import frames as F
from avard.core.io.recording import RecordingReader
from avard.daemon import cli
from avard.daemon.commands import record
from avard.daemon.net.publisher import RequestServer

SCALE = 3.9e-6 * 9.80665


def _header(run: str, odr: float = 125.0) -> dict:
    return F.header_record(run, rate_hz=odr, t_mono=0.0, t_real=1.7e9,
                           scale_m_s2_per_count=SCALE, range_g=2.0, software="test",
                           nominal_odr_hz=odr)


class FakeService:
    def __init__(self) -> None:
        self.ctx = zmq.Context()
        self.pub = self.ctx.socket(zmq.XPUB)
        self.pub.setsockopt(zmq.LINGER, 0)
        self.pub.bind("tcp://127.0.0.1:*")
        self.endpoint = self.pub.getsockopt_string(zmq.LAST_ENDPOINT)
        self.run = "run-1"
        self.odr = 125.0
        self.ring: dict[int, tuple[np.ndarray, float]] | None = None  # index → (counts, t)
        handlers = {"header": lambda a: _header(self.run, self.odr), "recent": self._recent}
        self.server = RequestServer("tcp://127.0.0.1:*", handlers).start()

    def _recent(self, args: dict) -> dict:
        """Like the service's ring: the samples it still holds, with their indices."""
        if self.ring is None:
            raise DataError("no ring in this fake service")
        idx = sorted(self.ring)
        return {"index": np.array(idx, dtype=np.int64),
                "counts": np.array([self.ring[i][0] for i in idx], dtype=np.int32).reshape(-1, 3),
                "t_mono": np.array([self.ring[i][1] for i in idx])}

    def keep(self, rec: dict) -> None:
        assert self.ring is not None
        for k in range(rec["n"]):
            self.ring[rec["i0"] + k] = (rec["counts"][k], (rec["i0"] + k) / 125.0)

    def wait_subscribed(self, topics: int = 5) -> None:
        for _ in range(topics):
            assert self.pub.poll(10_000), "the recorder never subscribed"
            assert self.pub.recv()[0] == 1

    def send(self, topic: str, rec: dict) -> None:
        self.pub.send_multipart([topic.encode(), F.encode(rec)])

    def close(self) -> None:
        self.server.stop()
        self.pub.close()
        self.ctx.term()


def _raw(run: str, seq: int, i0: int) -> dict:
    counts = np.full((32, 3), seq, dtype=np.int32)
    return F.raw_record(run, seq, i0, counts, i0 / 125.0, 1.7e9 + i0 / 125.0)


@pytest.fixture
def service():
    s = FakeService()
    yield s
    s.close()


def _read(out: Path) -> list[dict]:
    try:
        return list(RecordingReader(out))
    except FormatError:  # no segment yet
        return []


def _record(service: FakeService, out: Path) -> tuple[threading.Thread, dict]:
    """`avard record` (its run() with the parsed arguments) in a thread, stopped by the test
    through ``args.stop_event`` once the archive holds what was sent: no wall-clock race."""
    parser = argparse.ArgumentParser()
    record.add_arguments(parser)
    args = parser.parse_args([service.endpoint, "--request", service.server.endpoint,
                              "--out", str(out), "--wait", "60"])
    args.stop_event = threading.Event()
    result: dict = {"stop": args.stop_event}

    def go() -> None:
        result["rc"] = record.run(args)

    t = threading.Thread(target=go, daemon=True)
    t.start()
    return t, result


def test_record_archives_stream_with_gaps(service: FakeService, tmp_path: Path,
                                          capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "archive"
    thread, result = _record(service, out)
    service.wait_subscribed()
    i0 = 0
    for seq in range(10):
        if seq == 6:  # the service's own gap: announced, then the next block after it
            service.send("event", F.gap_record("run-1", 0, i0, 50, 0.0, 0.0, "overrun"))
            i0 += 50
        if seq != 4:  # seq 4 "lost in transport"
            service.send("raw", _raw("run-1", seq, i0))
        if seq == 2:
            service.send("temp", F.temp_record("run-1", 0, i0, ["plate"], [21.5], 0.0, 0.0))
        i0 += 32
    # wait until the archive holds run 1 (the header op answers for the current run only)
    while sum(r["kind"] == "raw" for r in _read(out)) < 9:
        assert thread.is_alive(), "record ended early"
        time.sleep(0.02)
    # the service restarts: a new run, a new header, sequences from 0
    service.run = "run-2"
    service.send("raw", _raw("run-2", 0, 0))
    service.send("raw", _raw("run-2", 1, 32))
    while sum(r["run"] == "run-2" for r in _read(out)) < 3:  # header + 2 raw
        assert thread.is_alive(), "record ended early"
        time.sleep(0.02)
    result["stop"].set()
    thread.join(30)
    assert result["rc"] == 0
    text = capsys.readouterr().out
    assert ("lost in transport: 1 messages, 32 samples; 0 samples fetched back from the "
            "service's ring, 32 recorded as gaps (1 gap records)") in text

    recs = list(RecordingReader(out))
    kinds = [(r["run"], r["kind"]) for r in recs]
    assert kinds[0] == ("run-1", "header")
    assert ("run-2", "header") in kinds
    gaps = [r for r in recs if r["kind"] == "gap"]
    assert [(g["i0"], g["n"], g["reason"]) for g in gaps] == [(128, 32, "subscriber_loss"),
                                                              (192, 50, "overrun")]
    raws = [r for r in recs if r["kind"] == "raw"]
    assert [int(r["counts"][0, 0]) for r in raws] == [0, 1, 2, 3, 5, 6, 7, 8, 9, 0, 1]
    assert sum(r["kind"] == "temp" for r in recs) == 1
    headers = [r for r in recs if r["kind"] == "header"]
    assert all(h["scale_m_s2_per_count"] == SCALE for h in headers)


def test_record_without_a_service_fails_clearly(tmp_path: Path,
                                                capsys: pytest.CaptureFixture) -> None:
    rc = cli.main(["record", "tcp://127.0.0.1:9", "--out", str(tmp_path), "--wait", "0.3"])
    assert rc == 2
    assert "nothing received from tcp://127.0.0.1:9" in capsys.readouterr().err


def test_archive_of_the_real_service_equals_its_own_recording(tmp_path: Path) -> None:
    """The service over the emulated sensor; `avard record`'s archiver as a remote subscriber.
    The archive holds the same samples as the service's recording, and its offline Allan
    variance equals the recording's."""
    from avard.core.io.recording import load_recording, replay_allan
    from avard.daemon.commands.record import StreamArchiver
    from avard.daemon.compose import simulated_service
    from avard.daemon.config import load_config
    from avard.daemon.net.subscriber import Subscriber

    cfg = load_config(None, **{
        "recording.data_dir": str(tmp_path / "rec"),
        "publish.endpoint": "tcp://127.0.0.1:0", "publish.request_endpoint": "tcp://127.0.0.1:0",
        "publish.hwm": 1_000_000, "sensor.poll_hz": 1.0, "allan.snapshot_interval_s": 10.0})
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=3, speed=None)
    box: dict = {"stop": threading.Event()}

    def listen() -> None:
        sub = Subscriber(svc.publisher.endpoint,
                         request_endpoint=svc.request_server.endpoint).connect(join=False)
        box["sub"] = sub
        # PUB drops until the subscription has travelled: probe until one arrives, so the
        # archive starts with the first sample however loaded the machine is
        deadline = time.monotonic() + 20.0
        while sub.recv(0.05) is None:
            assert time.monotonic() < deadline, "the archiver never connected"
            svc.publisher.publish("status", F.status_record("", 0, {"probe": 1}, 0.0, 0.0))
        while sub.recv(0.1) is not None:
            pass
        arch = StreamArchiver(sub, tmp_path / "archive", segment_s=3600.0, fsync_s=5.0)
        stop = box["stop"]

        def loop() -> None:
            while not stop.is_set():
                if (m := sub.recv(0.1)) is not None:
                    arch.handle(m)
            while (m := sub.recv(0.3)) is not None:
                arch.handle(m)
            arch.close()
            sub.close()

        box["thread"] = threading.Thread(target=loop, daemon=True)
        box["thread"].start()

    try:
        svc.run(60.0, before_acquisition=listen)
    finally:
        box["stop"].set()
        if "thread" in box:
            box["thread"].join(30)
    stats = box["sub"].stats
    assert stats.messages_lost == 0 and stats.samples_lost == 0 == stats.samples_unexplained

    ours, theirs = load_recording(tmp_path / "archive"), load_recording(tmp_path / "rec")
    assert ours.accel.shape == theirs.accel.shape and ours.accel.shape[0] > 60 * 120
    np.testing.assert_array_equal(ours.accel, theirs.accel)
    a = replay_allan(tmp_path / "archive").snapshot().avar
    b = replay_allan(tmp_path / "rec").snapshot().avar
    np.testing.assert_allclose(a, b, rtol=1e-12)


def test_record_fetches_lost_blocks_back_from_the_ring(service: FakeService,
                                                       tmp_path: Path) -> None:
    """Block 4 lost in transport but still in the ring: recovered as a raw record. Block 7
    lost and half forgotten by the ring: 16 samples recovered, 16 written as a gap."""
    service.ring = {}
    out = tmp_path / "archive"
    thread, result = _record(service, out)
    service.wait_subscribed()
    for seq in range(10):
        rec = _raw("run-1", seq, 32 * seq)
        rec["counts"] = rec["counts"] + np.arange(32, dtype=np.int32)[:, None]
        service.keep(rec)
        if seq == 7:
            for i in range(32 * 7, 32 * 7 + 16):
                del service.ring[i]
        if seq not in (4, 7):
            service.send("raw", rec)
    while sum(r["kind"] == "raw" for r in _read(out)) < 10:
        assert thread.is_alive(), "record ended early"
        time.sleep(0.02)
    result["stop"].set()
    thread.join(30)
    assert result["rc"] == 0
    recs = list(RecordingReader(out))
    raws = [r for r in recs if r["kind"] == "raw"]
    spans = [(r["i0"], r["n"]) for r in raws]
    assert spans == [(0, 32), (32, 32), (64, 32), (96, 32), (128, 32), (160, 32), (192, 32),
                     (240, 16), (256, 32), (288, 32)]
    lost = next(r for r in raws if r["i0"] == 128)
    np.testing.assert_array_equal(lost["counts"][:, 0], 4 + np.arange(32))
    assert lost["t_mono"] == pytest.approx(128 / 125.0)
    assert lost["t_real"] == pytest.approx(1.7e9 + 128 / 125.0)
    half = next(r for r in raws if r["i0"] == 240)
    np.testing.assert_array_equal(half["counts"][:, 1], 7 + np.arange(16, 32))
    gaps = [(g["i0"], g["n"], g["reason"]) for g in recs if g["kind"] == "gap"]
    assert gaps == [(224, 16, "subscriber_loss")]


def test_record_archives_snapshots_its_readers_can_decode_and_says_which_it_could_not(
        service: FakeService, tmp_path: Path) -> None:
    """The avar records go through the one snapshot decoder (AllanSnapshot.from_dict), as in
    watch and web: a good one is archived as is; a ragged one becomes an event, not a record
    that every later reader would refuse."""
    from avard.core.allan.streaming import AllanSnapshot, StreamingAllan

    out = tmp_path / "archive"
    thread, result = _record(service, out)
    service.wait_subscribed()
    acc = StreamingAllan(3, 125.0, names=["x", "y", "z"])
    acc.update(np.random.default_rng(3).normal(size=(4096, 3)))
    good = acc.snapshot().to_dict()
    bad = {**good, "avar": [row[:2] for row in good["avar"]]}
    service.send("raw", _raw("run-1", 0, 0))
    service.send("avar", F.avar_record("run-1", 0, 32, 4096, bad, 0.0, 0.0))
    service.send("avar", F.avar_record("run-1", 1, 32, 4096, good, 0.0, 0.0))
    while sum(r["kind"] in ("avar", "event") for r in _read(out)) < 2:
        assert thread.is_alive(), "record ended early"
        time.sleep(0.02)
    result["stop"].set()
    thread.join(30)
    recs = list(RecordingReader(out))
    avars = [r for r in recs if r["kind"] == "avar"]
    assert len(avars) == 1
    back = AllanSnapshot.from_dict(avars[0]["snapshot"])
    np.testing.assert_array_equal(back.avar, acc.snapshot().avar)
    events = [r for r in recs if r["kind"] == "event"]
    assert [e["name"] for e in events] == ["unreadable_snapshot"]
    assert "avar has shape" in events[0]["detail"]["error"]


def test_record_refuses_a_directory_another_process_records_into(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`avard record --out` wrote through the recorder without the directory lock: an archive
    into a service's data directory (or two archives) wrote the same indices twice. It now
    stops before connecting, with one line naming the holder, status 2."""
    import subprocess
    import sys

    out = tmp_path / "rec"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys\nfrom avard.daemon.service import dirlock\n"
         "dirlock.hold(sys.argv[1]); print('held', flush=True); sys.stdin.read()", str(out)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        rc = cli.main(["record", "tcp://127.0.0.1:9", "--out", str(out), "--wait", "0.3"])
    finally:
        holder.communicate("")
    err = capsys.readouterr().err
    assert rc == 2
    said = [line for line in err.splitlines() if "another avard process" in line]
    assert len(said) == 1 and f"(pid {holder.pid})" in said[0] and "--out" in said[0], err
    assert "nothing received" not in err and "Traceback" not in err
    assert list(out.glob("*.avr")) == []


def test_record_ends_the_archive_when_the_service_restarts_at_another_rate(
        service: FakeService, tmp_path: Path) -> None:
    """One recording directory holds one output data rate (the service refuses a second);
    the archiver wrote a restarted service's run at another ODR into the same directory, a
    record ``avard analyze`` refuses as a whole. It now ends with one line saying so, the
    runs at the first rate archived and readable."""
    from avard.core.errors import ConfigError

    out = tmp_path / "archive"
    parser = argparse.ArgumentParser()
    record.add_arguments(parser)
    args = parser.parse_args([service.endpoint, "--request", service.server.endpoint,
                              "--out", str(out), "--wait", "60"])
    args.stop_event = threading.Event()
    result: dict = {}

    def go() -> None:
        try:
            result["rc"] = record.run(args)
        except ConfigError as exc:
            result["error"] = str(exc)

    thread = threading.Thread(target=go, daemon=True)
    thread.start()
    service.wait_subscribed()
    for seq in range(3):
        service.send("raw", _raw("run-1", seq, 32 * seq))
    while sum(r["kind"] == "raw" for r in _read(out)) < 3:
        assert thread.is_alive(), "record ended early"
        time.sleep(0.02)
    service.run, service.odr = "run-2", 250.0
    service.send("header", _header("run-2", 250.0))
    service.send("raw", _raw("run-2", 0, 0))
    thread.join(30)
    args.stop_event.set()
    assert not thread.is_alive()
    assert "rc" not in result, result
    assert "holds a recording at a nominal 125 Hz (run run-1)" in result["error"]
    assert "run-2 is at 250 Hz" in result["error"]
    assert {r["run"] for r in RecordingReader(out)} == {"run-1"}
    assert sum(r["n"] for r in RecordingReader(out) if r["kind"] == "raw") == 96
