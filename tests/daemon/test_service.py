"""The service end to end over real loopback sockets, on the emulated sensor.

Checked: every sample published and recorded exactly once (sequence numbers and sample index
continuity, seen by a real SUB socket), the recording's offline Allan variance equals the
service's streamed snapshot to 1e-12 relative, and injected faults (bus errors, a FIFO
overrun, a DS18B20 dropping out) appear as gap and event records.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.errors import NetworkError
from avard.core.io.recording import RecordingReader, load_recording, replay_allan
from avard.daemon.compose import compose, simulated_service
from avard.daemon.config import load_config
from avard.daemon.config_types import as_config
from avard.daemon.hw.simulation import build_simulated
from avard.daemon.net.subscriber import Subscriber
from avard.daemon.service.supervisor import Service, ServiceHooks

from tests.support.rigs import rig_from_parts

from .pubsub import is_probe, wait_until_subscribed


def _cfg(data_dir: Path, **extra: Any) -> dict:
    return load_config(None, **{
        "recording.data_dir": str(data_dir),
        "publish.endpoint": "tcp://127.0.0.1:0", "publish.request_endpoint": "tcp://127.0.0.1:0",
        "publish.hwm": 1_000_000, "sensor.poll_hz": 1.0, "allan.snapshot_interval_s": 10.0,
        "allan.checkpoint_interval_s": 30.0, "recording.segment_s": 60.0, **extra})


class Listener:
    """A real subscriber in a thread, keeping every record it gets."""

    def __init__(self, svc: Service) -> None:
        self.sub = Subscriber(svc.publisher.endpoint,
                              request_endpoint=svc.request_server.endpoint).connect(join=False)
        # before acquisition starts: from here on the subscriber gets every message
        self.records: list[tuple[str, dict]] = wait_until_subscribed(svc.publisher, self.sub)
        self.stop_evt = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _keep(self, msg: Any) -> None:
        if not is_probe(msg.record):
            self.records.append((msg.topic, msg.record))

    def _run(self) -> None:
        while not self.stop_evt.is_set():
            msg = self.sub.recv(timeout_s=0.1)
            if msg is not None:
                self._keep(msg)

    def finish(self) -> None:
        self.stop_evt.set()
        self.thread.join(5)
        while (msg := self.sub.recv(timeout_s=0.3)) is not None:
            self._keep(msg)
        self.sub.close()


def _run(tmp_path: Path, seconds: float, *, inject: Callable[[Any, float], None] | None = None,
         **cfg_extra: Any) -> tuple[Service, Listener, Any]:
    cfg = _cfg(tmp_path / "rec", **cfg_extra)
    def tick(t: float) -> None:
        inject(ctx, t - svc.t_start)

    svc, sims, emu = simulated_service(cfg, "quiet-lab", seed=7, speed=None,
                                       after_tick=None if inject is None else tick)
    ctx = {"svc": svc, "sims": sims, "emu": emu, "clock": svc.clock}
    box: dict[str, Listener] = {}
    svc.run(seconds, before_acquisition=lambda: box.setdefault("l", Listener(svc)))
    box["l"].finish()
    return svc, box["l"], ctx


def _snapshot_avar(rec: dict) -> np.ndarray:
    return np.asarray(rec["snapshot"]["avar"], dtype=float)


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    assert a.shape == b.shape
    scale = np.where(b == 0, 1.0, np.abs(b))
    return float(np.max(np.abs(a - b) / scale))


def test_every_sample_published_and_recorded_once_and_allan_matches(tmp_path: Path) -> None:
    svc, lst, _ = _run(tmp_path, 150.0)
    st = svc.final_status
    assert st["overruns"] == 0 and st["samples"] > 150 * 120
    # Subscriber: contiguous sequence numbers per topic and contiguous sample indices.
    raw = [r for t, r in lst.records if t == "raw"]
    assert [r["seq"] for r in raw] == list(range(len(raw)))
    idx = np.concatenate([r["i0"] + np.arange(r["n"]) for r in raw])
    np.testing.assert_array_equal(idx, np.arange(idx[0], idx[0] + st["samples"]))
    assert lst.sub.stats.messages_lost == 0
    # Recording: the same samples, once each, with identical counts.
    recs = list(RecordingReader(tmp_path / "rec"))
    rraw = [r for r in recs if r["kind"] == "raw"]
    ridx = np.concatenate([r["i0"] + np.arange(r["n"]) for r in rraw])
    np.testing.assert_array_equal(ridx, idx)
    np.testing.assert_array_equal(np.concatenate([r["counts"] for r in rraw]),
                                  np.concatenate([r["counts"] for r in raw]))
    assert len(list((tmp_path / "rec").glob("*.avr"))) >= 3     # rotated every 60 s
    # Allan: the last streamed snapshot (as the subscriber got it) equals the offline replay.
    avars = [r for t, r in lst.records if t == "avar"]
    # how many come depends on how the threads were scheduled (at most one per chunk the
    # Allan stage takes): each before the stop's own comes at a sample time past a new
    # deadline t0 + k·10 s, and 150 s of samples pass more than one
    t0 = raw[0]["t_mono"]
    due = [math.floor((r["t_mono"] - t0) / 10.0 + 1e-9) for r in avars[:-1]]
    assert due and due[0] >= 1 and all(a < b for a, b in itertools.pairwise(due)), due
    offline = replay_allan(tmp_path / "rec").snapshot()
    assert avars[-1]["n_samples"] == offline.n_samples
    assert _rel(_snapshot_avar(avars[-1]), offline.avar) < 1e-12
    assert _rel(np.asarray(avars[-1]["snapshot"]["cov"]), offline.cov) < 1e-12
    # The header travels on the status topic (first, then when the fitted rate moves), the
    # same record the recording holds; status maps carry every documented field.
    on_status = [r for t, r in lst.records if t == "status"]
    headers = [r for r in on_status if r["kind"] == "header"]
    assert headers and headers[0]["run"] == svc.run_id
    recorded = {r["rate_hz"] for r in recs if r["kind"] == "header"}
    assert {h["rate_hz"] for h in headers} <= recorded
    status = [r["status"] for r in on_status if r["kind"] == "status"][-1]
    assert {"run", "samples", "index", "rate_hz", "overruns", "lost_samples_estimate", "gaps",
            "bus_errors", "clock_steps", "stalled", "allan_samples", "consumers_lost",
            "sim_time_s", "disk", "subscribers", "published", "publish_dropped"} <= set(status)
    # And the SI conversion of the whole recording.
    record = load_recording(tmp_path / "rec")
    assert record.accel.shape == (st["samples"], 3)
    assert abs(np.mean(record.accel[:, 2]) - 9.80665) < 0.05
    # one range for the whole run: its LSB, for the analysis's rounding term (±2 g, 20 bit)
    assert record.meta["lsb_mps2"] == pytest.approx(9.80665 / 256000, rel=0.02)
    assert record.temperature_names == ["chip", *svc.temp_names[1:]]


def test_injected_faults_become_gap_and_event_records(tmp_path: Path) -> None:
    done: set[str] = set()

    def inject(ctx: dict, t: float) -> None:
        if t > 20 and "bus" not in done:
            done.add("bus")
            ctx["emu"].faults.fail_next(3)          # more than the driver's retries
        if t > 40 and "overrun" not in done:
            done.add("overrun")
            ctx["clock"].advance(3.0)               # the reader stalls 3 s: FIFO overruns
        if t > 60 and "ds" not in done:
            done.add("ds")
            ctx["sims"].fail.add(ctx["sims"].names[0])
        if t > 80 and "back" not in done:
            done.add("back")
            ctx["sims"].fail.clear()
        if t > 90 and "ntp" not in done:
            done.add("ntp")
            ctx["clock"].step_realtime(100.0)       # NTP steps the wall clock

    svc, lst, _ = _run(tmp_path, 110.0, inject=inject)
    recs = list(RecordingReader(tmp_path / "rec"))
    events = [r["name"] for r in recs if r["kind"] == "event"]
    gaps = [r for r in recs if r["kind"] == "gap"]
    assert "bus_error" in events
    assert "sensor_lost" in events and "sensor_back" in events
    step = next(r for r in recs if r["kind"] == "event" and r["name"] == "clock_step")
    assert abs(step["detail"]["step_s"] - 100.0) < 0.01
    # Records after the step carry the new wall time; order stays on the monotonic clock.
    offsets = [r["t_real"] - r["t_mono"] for r in recs if r["kind"] == "raw"]
    assert abs((offsets[-1] - offsets[0]) - 100.0) < 0.01
    assert any("overrun" in g["reason"] for g in gaps)
    # The overrun gap's size is estimated from elapsed time × rate: about 3 s of samples.
    # (A failed drain at the simulation's tight poll margin may overrun a little too.)
    g = max((g for g in gaps if "overrun" in g["reason"]), key=lambda g: g["n"])
    assert 2.5 * 125 < g["n"] < 3.5 * 125
    # The raw index jumps exactly over the announced gap.
    rraw = [r for r in recs if r["kind"] == "raw"]
    jumps = [(a["i0"] + a["n"], b["i0"]) for a, b in itertools.pairwise(rraw)
             if b["i0"] != a["i0"] + a["n"]]
    assert [(g["i0"], g["i0"] + g["n"]) for g in gaps if g["n"]] == jumps
    # The DS18B20 drop-out is recorded as missing readings, never as a made-up value.
    temps = [r for r in recs if r["kind"] == "temp" and svc.temp_names[1] in r["names"]]
    assert any(v is None for r in temps for v in r["values_c"])
    # The subscriber saw the gap as a service gap, nothing unexplained.
    st = lst.sub.stats
    assert st.samples_unexplained == 0
    assert st.samples_service_gap == sum(g["n"] for g in gaps)
    # Allan accumulators broke their segment at the gap: offline replay still agrees.
    avars = [r for t, r in lst.records if t == "avar"]
    assert _rel(_snapshot_avar(avars[-1]), replay_allan(tmp_path / "rec").snapshot().avar) \
        < 1e-12


def test_request_socket_answers_status_snapshot_recent(tmp_path: Path) -> None:
    # A snapshot every 60 s of virtual time (3 s real at speed 20).
    cfg = _cfg(tmp_path / "rec", **{"allan.snapshot_interval_s": 60.0})
    svc, _sims, emu = simulated_service(cfg, "quiet-lab", seed=3, speed=20.0)
    answers: dict[str, Any] = {}

    def ask() -> None:
        try:
            _ask()
        finally:  # a failure above leaves the answers missing, never the service running
            svc.stop_requested.set()

    def _ask() -> None:
        sub = Subscriber(svc.publisher.endpoint, request_endpoint=svc.request_server.endpoint,
                         request_timeout_s=30.0)
        # until the 2 s asked for below exist (a count, not a guess at how fast the service
        # runs on this machine)
        while (status := sub.request("status"))["samples"] < 2 * 125:
            time.sleep(0.05)
        answers["status"] = status
        answers["recent"] = sub.request("recent", {"seconds": 2.0})
        hang = time.monotonic() + 300  # a bound on a hang only
        while "first_snapshot" not in answers:  # none before the first snapshot interval
            try:
                answers["first_snapshot"] = sub.request("snapshot")
            except NetworkError:
                assert time.monotonic() < hang
                time.sleep(0.05)
        # The fit is computed off the request thread. The sensor stops, so no newer snapshot
        # replaces this one before its fit is done, however slow the machine: ask until it is.
        emu.stop_producing()
        while (snap := sub.request("snapshot"))["fit_pending"]:
            assert time.monotonic() < hang
            time.sleep(0.05)
        answers["snapshot"] = snap
        with pytest.raises(Exception, match="seconds"):
            sub.request("recent", {"seconds": 1e9})
        sub.close()

    threading.Timer(0.1, ask).start()
    svc.run(None)
    assert answers["status"]["samples"] > 0
    assert answers["recent"]["n"] == 250 and answers["recent"]["counts"].shape == (250, 3)
    assert np.all(np.diff(answers["recent"]["index"]) == 1)
    assert answers["snapshot"]["kind"] == "avar"
    assert answers["first_snapshot"]["kind"] == "avar"
    fit = answers["snapshot"]["fit"]
    assert set(fit) == {"x", "y", "z"}
    vrw = fit["x"]["terms"]["velocity_random_walk"]
    assert vrw["unit"] == "m/s/sqrt(s)" and vrw["lo"] <= vrw["value"] <= vrw["hi"]
    # the fit's ADEV bars (analyze's EDF rule) per τ of that snapshot, and the LSB it used
    snap = answers["snapshot"]["snapshot"]
    assert len(fit["x"]["hi"]) == len(fit["x"]["edf"]) == len(snap["tau"])
    assert np.all(np.asarray(fit["x"]["edf"]) >= np.asarray(snap["edf"])[:, 0])
    assert snap["lsb_mps2"] > 0


def test_ds18b20_through_w1thermsensor_drops_out_and_returns(tmp_path: Path) -> None:
    """Real w1thermsensor over a fake sysfs tree, in the bank's own threads."""
    from avard.daemon.hw.ds18b20 import Ds18b20Bank
    from avard.daemon.hw.w1_sysfs import SysfsTree

    tree = SysfsTree(tmp_path / "w1")
    sid = tree.add("0316a2797cff", 21.5)
    bank = Ds18b20Bank({"plate": sid}, interval_s=0.05, base_directory=tree.base)
    cfg = _cfg(tmp_path / "rec", **{"publish.enabled": False})
    dev, clock, _sims, _emu = build_simulated(cfg, "quiet-lab", seed=5)
    svc = compose(as_config(cfg), rig_from_parts(as_config(cfg), dev, clock, simulate="quiet-lab",
                                                 speed=20.0, bank=bank))
    timers = [threading.Timer(1.0, tree.remove, args=(sid,)),
              threading.Timer(1.6, tree.restore, args=(sid,)),
              threading.Timer(2.4, svc.stop_requested.set)]
    for t in timers:
        t.start()
    svc.run(None)
    recs = list(RecordingReader(tmp_path / "rec"))
    assert svc.temp_names == ["chip", "plate"]
    events = [(r["name"], r["detail"].get("sensor")) for r in recs if r["kind"] == "event"]
    assert ("sensor_lost", "plate") in events and ("sensor_back", "plate") in events
    values = [v for r in recs if r["kind"] == "temp" and r["names"] == ["plate"]
              for v in r["values_c"]]
    assert None in values
    assert {v for v in values if v is not None} == {21.5}
    # The Allan feed held 21.5 °C through the drop-out instead of inventing a value.
    rec = load_recording(tmp_path / "rec")
    col = rec.temperature_c[:, rec.temperature_names.index("plate")]
    assert set(np.unique(col[~np.isnan(col)])) == {21.5}


def test_sd_notify_ready_once_samples_flow_and_watchdog_only_while_they_advance(
        tmp_path: Path) -> None:
    import socket

    from avard.daemon.service.sdnotify import Notifier

    path = str(tmp_path / "notify.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(path)
    sock.settimeout(0.05)
    notifier = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "100000"})  # ping every 50 ms
    cfg = _cfg(tmp_path / "rec", **{"publish.enabled": False})
    svc, _sims, emu = simulated_service(cfg, "quiet-lab", seed=9, speed=20.0, notifier=notifier)
    text: list[str] = []
    done = threading.Event()
    # Driven by the messages, not by how far the service got in a wall-clock interval: the
    # sensor stops after 5 watchdog pings; the service is stopped once 5 STATUS= followed the
    # last ping after that. If pings never stopped, the hang guard stops it and the
    # assertions below say so.
    hang_guard = threading.Timer(120.0, svc.stop_requested.set)
    hang_guard.start()

    def receive() -> None:  # like systemd: read as they come (the queue is short)
        stalled = False
        since_ping = 0
        while not done.is_set():
            try:
                m = sock.recv(4096).decode()
            except TimeoutError:
                continue
            text.append(m)
            if m.startswith("WATCHDOG=1"):
                since_ping = 0
            elif m.startswith("STATUS="):
                since_ping += 1
            if not stalled and sum(t.startswith("WATCHDOG=1") for t in text) >= 5:
                stalled = True
                emu.stop_producing()
                since_ping = 0
            if stalled and since_ping >= 5:
                svc.stop_requested.set()
            if m.startswith("STOPPING=1"):
                return

    rx = threading.Thread(target=receive)
    rx.start()
    svc.run(None)
    rx.join(120.0)
    done.set()
    hang_guard.cancel()
    sock.close()
    assert text[0].startswith("READY=1")
    assert sum(m.startswith("READY=1") for m in text) == 1
    watchdogs = [i for i, m in enumerate(text) if m.startswith("WATCHDOG=1")]
    assert len(watchdogs) >= 5                           # fed while samples advanced
    assert any("samples" in m and "Hz" in m for m in text if m.startswith("STATUS="))
    assert text[-1].startswith("STOPPING=1")
    # After the sensor stopped producing, no more WATCHDOG=1: systemd would restart us.
    tail = text[watchdogs[-1] + 1:]
    assert sum(m.startswith("STATUS=") for m in tail) >= 5
    assert svc.final_status["stalled"]


def test_disk_full_keeps_acquiring_and_publishing_and_records_the_gap(tmp_path: Path) -> None:
    import errno

    from avard.daemon.service.recorder import FileOps, Recorder

    class Disk(FileOps):
        full = False

        def write(self, f, data: bytes) -> None:  # type: ignore[no-untyped-def]
            if self.full:
                raise OSError(errno.ENOSPC, "No space left on device")
            super().write(f, data)

        def free_bytes(self, directory: Path) -> int:
            return 0 if self.full else 10**12

    disk = Disk()
    seen_full: list[str] = []

    class DataTimedRecorder(Recorder):
        """The disk is full while the records of samples 20 s..40 s arrive (by sample index,
        not by the reader's clock: the recorder thread may lag it by many seconds)."""

        def write(self, record: dict) -> bool:
            if record["kind"] == "raw":   # the only records in strict index order
                disk.full = 20 * 125 < record["i0"] < 40 * 125
            ok = super().write(record)
            if self.disk_full:
                seen_full.append(svc.status()["disk"]["state"])
            return ok

    def recorder(svc: Service) -> Recorder:
        return DataTimedRecorder(svc.data_dir, svc.run_id, svc.header,
                                 clock=svc.clock.monotonic, realtime=svc.clock.realtime,
                                 fileops=disk, retry_s=0.0)

    def inject(ctx: dict, t: float) -> None:
        return None

    cfg = _cfg(tmp_path / "rec")
    def tick(t: float) -> None:
        inject(ctx, t - svc.t_start)

    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=11, speed=None, after_tick=tick,
                                         hooks=ServiceHooks(recorder=recorder))
    ctx = {"svc": svc}
    box: dict[str, Listener] = {}
    svc.run(60.0, before_acquisition=lambda: box.setdefault("l", Listener(svc)))
    box["l"].finish()
    assert "disk_full" in seen_full
    # Publishing never stopped: the subscriber has every sample.
    raw = [r for t, r in box["l"].records if t == "raw"]
    assert sum(r["n"] for r in raw) == svc.final_status["samples"]
    # The recording has a disk_full gap exactly over what it is missing.
    recs = list(RecordingReader(tmp_path / "rec"))
    gap = next(r for r in recs if r["kind"] == "gap")
    assert gap["reason"] == "disk_full" and 15 * 125 < gap["n"] < 25 * 125
    rraw = [r for r in recs if r["kind"] == "raw"]
    ends = [(a["i0"] + a["n"], b["i0"]) for a, b in itertools.pairwise(rraw)
            if b["i0"] != a["i0"] + a["n"]]
    assert ends == [(gap["i0"], gap["i0"] + gap["n"])]


def test_curve_section_secures_both_sockets_of_the_service(tmp_path: Path) -> None:
    from avard.daemon.net.curve import CurveClientConfig, make_keypair

    server_pub, server_sec = make_keypair(tmp_path / "server", "server")
    auth = tmp_path / "authorized"
    auth.mkdir()
    client_pub, client_sec = make_keypair(tmp_path / "client", "client")
    (auth / "client.key").write_text(client_pub.read_text())
    cfg = _cfg(tmp_path / "rec", **{"curve.enabled": True,
                                    "curve.server_secret_key_file": str(server_sec),
                                    "curve.authorized_keys_dir": str(auth)})
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=4, speed=20.0)
    got: dict[str, Any] = {}

    def clients() -> None:
        try:
            _clients()
        except Exception as exc:  # reported by the assertions below
            got["error"] = repr(exc)
        finally:
            svc.stop_requested.set()

    def _clients() -> None:
        client = CurveClientConfig(server_pub, client_sec)
        good = Subscriber(svc.publisher.endpoint, request_endpoint=svc.request_server.endpoint,
                          curve=client, request_timeout_s=10.0).connect(join=False)
        plain = Subscriber(svc.publisher.endpoint).connect(join=False)
        deadline = time.monotonic() + 20
        while "raw" not in got and time.monotonic() < deadline:
            m = good.recv(0.2)
            if m is not None and m.topic == "raw":
                got["raw"] = m.record
        got["status"] = good.request("status")
        got["plain"] = plain.recv(0.5)
        good.close()
        plain.close()

    th = threading.Thread(target=clients)
    svc.run(None, before_acquisition=th.start)
    th.join()
    assert "error" not in got, got.get("error")
    assert got["raw"]["counts"].shape[1] == 3
    assert got["status"]["samples"] > 0
    assert got["plain"] is None


def test_service_takes_the_typed_config_only(tmp_path: Path) -> None:
    """The Service's contract is typed: a checked dict is turned into a Config at the edge
    (config_types.as_config), never inside the service."""
    cfg = _cfg(tmp_path / "rec", **{"publish.enabled": False})
    dev, clock, _sims, _emu = build_simulated(cfg, "quiet-lab", seed=5)
    rig = rig_from_parts(as_config(cfg), dev, clock)
    with pytest.raises(TypeError, match="Config"):
        Service(cfg, rig)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="Rig"):
        Service(as_config(cfg), dev)  # type: ignore[arg-type]
    assert Service(as_config(cfg), rig).config.sensor.odr_hz == cfg["sensor"]["odr_hz"]
