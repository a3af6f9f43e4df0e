"""The service and its files, adversarially (daemon23g): what a simulated service leaves behind,
and a segment changed behind the recorder's back while it writes into it.

Each case runs the simulated service on its virtual clock (as fast as it can) and acts from
the reader's tick at a chosen simulated time, so what happens depends on the data clock only.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest
from avard.core.io.recording import RecordingReader
from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config
from avard.daemon.hw.simulation import W1_DIR
from avard.daemon.service.recorder import Recorder
from avard.daemon.service.supervisor import Service


def _config(data: Path, **over: object):
    settings: dict[str, object] = {
        "recording.data_dir": str(data), "publish.enabled": False, "sensor.poll_hz": 2.0,
        "allan.checkpoint_interval_s": 4.0, "allan.snapshot_interval_s": 4.0}
    settings.update(over)
    return load_config(None, **settings)


# -- the simulated 1-Wire tree ------------------------------------------------------------------


def test_the_simulated_one_wire_tree_lives_in_the_recording_directory_never_in_tmp(
        tmp_path, monkeypatch):
    """The tree was a TemporaryDirectory in /tmp: removed by a finalizer that a killed
    process never runs, so every killed service or test left an ``avard-sim-w1-*`` folder.
    It now lives in the recording directory the service owns; a killed run's folder is
    replaced at the next start and removed at a clean stop."""
    data = tmp_path / "rec"
    data.mkdir()
    cfg = _config(data)
    tmp = tmp_path / "tmp"                       # the process's temporary directory
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    stale = data / W1_DIR / "devices" / "28-00000000dead"
    stale.mkdir(parents=True)                    # what a killed run left
    (stale / "w1_slave").write_text("junk\n")
    seen: list[set[str]] = []

    def look(t_mono: float) -> None:
        if not seen and (data / W1_DIR / "devices").is_dir() and \
                not (data / W1_DIR / "devices" / stale.name).exists():
            seen.append({p.name for p in (data / W1_DIR / "devices").iterdir()})
            seen.append({p.name for p in tmp.iterdir()})

    svc, sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, after_tick=look)
    svc.run(6.0)
    # while it ran (as a SIGKILL would find it): the sensors' folders in the recording
    # directory, the stale one gone, nothing in the temporary directory
    assert seen, "the 1-Wire tree was never made in the recording directory"
    assert {f"28-{sid}" for sid in sims.ids} <= seen[0]
    assert seen[1] == set()
    # the simulated DS18B20s were read through it
    read = {n for r in RecordingReader(data) if r["kind"] == "temp"
            for n, v in zip(r["names"], r["values_c"], strict=True) if v is not None}
    assert set(sims.names) <= read
    # a clean stop removes it
    assert not (data / W1_DIR).exists()
    assert list(tmp.iterdir()) == []



@pytest.mark.parametrize("left", ["a_file", "a_link_to_a_directory"])
def test_what_stands_in_the_one_wire_folders_place_is_replaced_and_never_followed(tmp_path,
                                                                                  left):
    data = tmp_path / "rec"
    data.mkdir()
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep").write_text("not the service's\n")
    if left == "a_file":
        (data / W1_DIR).write_text("junk\n")
    else:
        (data / W1_DIR).symlink_to(outside, target_is_directory=True)
    svc, sims, _emu = simulated_service(_config(data), "quiet-lab", seed=1)
    svc.run(4.0)
    read = {n for r in RecordingReader(data) if r["kind"] == "temp"
            for n, v in zip(r["names"], r["values_c"], strict=True) if v is not None}
    assert set(sims.names) <= read
    assert not (data / W1_DIR).exists() and not (data / W1_DIR).is_symlink()
    assert [p.name for p in outside.iterdir()] == ["keep"]


def _sensor_events(data: Path) -> list[tuple[str, str, str]]:
    return [(r["name"], r["detail"]["sensor"], r["detail"]["status"])
            for r in RecordingReader(data)
            if r["kind"] == "event" and r["name"] in ("sensor_lost", "sensor_back")]


def test_a_full_disk_under_the_simulated_one_wire_tree_fails_its_readings_not_the_reader(
        tmp_path, monkeypatch):
    """The tree now shares the recording's disk: a write refused with ENOSPC ended the
    reader thread (ServiceFault, exit 70). Now each refused sensor reads as failed for that
    round (never as the value its file held before), and comes back when the disk does."""
    import errno

    from avard.daemon.hw.w1_sysfs import SysfsTree

    data = tmp_path / "rec"
    full = {"on": False}
    write = SysfsTree._write

    def refused(self: SysfsTree, sensor_id: str, text: str) -> None:
        if full["on"]:
            raise OSError(errno.ENOSPC, "No space left on device (injected)")
        write(self, sensor_id, text)

    monkeypatch.setattr(SysfsTree, "_write", refused)
    box: dict[str, Service] = {}

    def disk(t_mono: float) -> None:
        full["on"] = 5.0 <= t_mono - box["svc"].t_start < 9.0

    svc, sims, _emu = simulated_service(_config(data), "quiet-lab", seed=1, after_tick=disk)
    box["svc"] = svc
    svc.run(14.0)
    events = _sensor_events(data)
    assert sorted(events) == sorted(
        [("sensor_lost", n, "error") for n in sims.names]
        + [("sensor_back", n, "ok") for n in sims.names]), events
    temps = [r for r in RecordingReader(data) if r["kind"] == "temp"]
    values = {n: [v for r in temps for m, v in zip(r["names"], r["values_c"], strict=True)
                  if m == n] for n in sims.names}
    for name, vs in values.items():
        assert vs[-1] is not None and None in vs, (name, vs)


def test_a_full_fd_table_under_the_simulated_service_is_ridden_through(tmp_path):
    """Every descriptor of the process taken for a while (``RLIMIT_NOFILE`` reached): the
    simulated DS18B20 files could not be written and the reader thread died of it. Now the
    service rides through: the DS18B20s read as failed with the host's error (not as a
    missing sensor), the checkpoint that could not be saved is saved at the next one, and
    what the accumulators hold equals what the recording holds."""
    import resource

    from avard.core.allan.streaming import StreamingAllan
    from avard.core.io import frames
    from avard.core.io.recording import replay_allan, scan_frames
    from avard.daemon.service.checkpoint import STATE_FILE

    data = tmp_path / "rec"
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    taken: list[int] = []
    box: dict[str, Service] = {}

    def fds(t_mono: float) -> None:
        t = t_mono - box["svc"].t_start
        if 5.0 <= t < 13.0 and not taken:
            # a lower soft limit, so that filling it costs a few hundred opens
            in_use = len(os.listdir("/proc/self/fd"))
            resource.setrlimit(resource.RLIMIT_NOFILE, (min(soft, in_use + 64), hard))
            try:
                while True:
                    taken.append(os.open(os.devnull, os.O_RDONLY))
            except OSError:
                pass
        elif t >= 13.0 and taken:
            while taken:
                os.close(taken.pop())
            resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))

    cfg = _config(data, **{"recording.segment_s": 3600.0})
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, after_tick=fds)
    box["svc"] = svc
    try:
        svc.run(20.0)
    finally:
        while taken:
            os.close(taken.pop())
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    lost = [e for e in _sensor_events(data) if e[0] == "sensor_lost"]
    assert lost and {e[2] for e in lost} == {"error"}, lost
    state = frames.decode(next(scan_frames((data / STATE_FILE).read_bytes())).payload)
    final = StreamingAllan.from_state(state["state"]).snapshot()
    offline = replay_allan(data).snapshot()
    assert final.n_samples == offline.n_samples == int(svc.allan.n_samples)
    raw = [(r["i0"], r["i0"] + r["n"]) for r in RecordingReader(data) if r["kind"] == "raw"]
    assert _tiles(raw) == [(0, svc.final_status["samples"])]

def _run(data: Path, seconds: float, seed: int, **over: object) -> Service:
    svc, _sims, _emu = simulated_service(_config(data, **over), "quiet-lab", seed=seed)
    svc.run(seconds)
    return svc


def _run_with_recorder(data: Path, recorder_cls: type[Recorder]) -> Service:
    """30 s of a simulated service whose recorder is ``recorder_cls`` (hour-long segments,
    so nothing rotates the acted-on segment away)."""
    from avard.daemon.service.supervisor import ServiceHooks

    def recorder(svc: Service) -> Recorder:
        r = svc.config.recording
        return recorder_cls(svc.data_dir, svc.run_id, svc.run_header.for_segment,
                            segment_s=r.segment_s, clock=svc.clock.monotonic,
                            realtime=svc.clock.realtime)

    cfg = _config(data, **{"recording.segment_s": 3600.0})
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=3,
                                         hooks=ServiceHooks(recorder=recorder))
    svc.run(30.0)
    return svc


# -- the open segment deleted, emptied, cut short or replaced behind the recorder's back -------

RATE = 125.0
ACT_AT = int(14 * RATE)          # the first raw block at or after this index finds it done


def _act(path: Path, how: str) -> None:
    if how == "deleted":
        path.unlink()
    elif how == "emptied":                       # `: > segment`, logrotate's copytruncate
        with open(path, "r+b") as f:
            f.truncate(0)
    elif how == "cut_in_half":
        with open(path, "r+b") as f:
            f.truncate(path.stat().st_size // 2)
    elif how == "replaced_by_a_directory":
        path.unlink()
        path.mkdir()
    elif how == "recording_directory_removed":
        # moved out of its place first: the simulated 1-Wire files are written into it from
        # another thread, and rmtree in place races with them
        gone = path.parent.with_name(path.parent.name + ".gone")
        path.parent.rename(gone)
        while gone.exists():
            shutil.rmtree(gone, ignore_errors=True)
    else:
        raise ValueError(how)


def _tiles(spans: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Sorted [i0, i1) spans merged where they touch; overlaps fail."""
    out: list[tuple[int, int]] = []
    for i0, i1 in sorted(spans):
        if out and i0 < out[-1][1]:
            raise AssertionError(f"[{i0}, {i1}) overlaps [{out[-1][0]}, {out[-1][1]})")
        if out and i0 == out[-1][1]:
            out[-1] = (out[-1][0], i1)
        else:
            out.append((i0, i1))
    return out


@pytest.mark.parametrize("how", ["deleted", "emptied", "cut_in_half",
                                 "replaced_by_a_directory", "recording_directory_removed"])
def test_an_open_segment_changed_behind_the_recorders_back_becomes_a_recorded_gap(tmp_path,
                                                                                  how):
    """The recorder wrote on into a deleted (or emptied) segment until its next rotation,
    up to ``segment_s`` (an hour by default) later: every record of that time went nowhere,
    no gap said so, the status said "writing". It now notices at its next write, records
    what the segment took as a ``segment_removed`` gap at the start of a new segment, and
    goes on recording there: the recording's blocks and gaps tile every acquired index."""
    from avard.daemon.service.recorder import Recorder

    data = tmp_path / "rec"
    done: dict[str, object] = {}

    class ChangedBehindItsBack(Recorder):
        """Acts on its own open segment just before the first raw block at or after
        ACT_AT: in the recorder's thread, so which records it takes depends on the data."""

        def write(self, record: dict) -> bool:
            if (not done and record.get("kind") == "raw" and record["i0"] >= ACT_AT
                    and self.path is not None):
                done["path"], done["i0"] = self.path, record["i0"]
                _act(self.path, how)
            return super().write(record)

    svc = _run_with_recorder(data, ChangedBehindItsBack)
    assert done, "the segment was never acted on"
    recs = list(RecordingReader(data))
    gaps = [r for r in recs if r["kind"] == "gap"]
    assert [g["reason"] for g in gaps] == ["segment_removed"]
    gap = gaps[0]
    # the samples the segment took, up to the block that found it: nothing else is missing
    # and nothing is claimed twice
    assert gap["i0"] + gap["n"] == done["i0"] and gap["n"] > 0
    raw = [(r["i0"], r["i0"] + r["n"]) for r in recs if r["kind"] == "raw"]
    assert _tiles([*raw, (gap["i0"], gap["i0"] + gap["n"])]) == [(0, svc.final_status["samples"])]
    if how == "cut_in_half":
        assert any(i1 <= gap["i0"] for _, i1 in raw)      # the kept half is still read
    # it went on recording, in a new segment that starts with the gap
    assert raw[-1][1] == svc.final_status["samples"]
    segs = [p for p in data.glob("*.avr") if p.is_file()]
    assert len(segs) >= 2 if how == "cut_in_half" else len(segs) >= 1
    assert svc.final_status["disk"]["state"] == "writing"
    assert svc.final_status["disk"]["segments_removed"] == 1
    # the checkpoint at the stop was saved (into a recreated directory too)
    from avard.daemon.service.checkpoint import read_state

    state = read_state(data).record
    assert state is not None and state["n_samples"] == int(svc.allan.n_samples)


# -- two services, one recording directory ------------------------------------------------------


def test_a_second_avard_run_on_a_recording_directory_in_use_stops_with_one_line(tmp_path):
    """Two services on one directory both took the next run sequence number, both continued
    the index from the recording's end and wrote the same indices with different samples
    (the reader kept one stream and dropped the other as duplicates), replaced each other's
    state file, and on hardware the second one's start-up reset the first one's sensor. The
    second ``avard run`` now stops before it opens the sensor: one line, exit status 2; the
    first is not disturbed."""
    data = tmp_path / "rec"
    _run(data, 6.0, 1)
    first, _s, _e = simulated_service(_config(data), "quiet-lab", seed=2)
    second: dict[str, object] = {}

    def another_run_meanwhile() -> None:
        # the first holds the directory (its restore is done, it is about to record)
        out = subprocess.run(
            [sys.executable, "-m", "avard.daemon.cli", "run", "--simulate", "quiet-lab",
             "--speed", "0", "--duration", "2", "--data-dir", str(data)],
            capture_output=True, text=True, timeout=120, cwd=tmp_path)
        second["status"], second["stderr"] = out.returncode, out.stderr

    first.run(6.0, before_acquisition=another_run_meanwhile)
    assert second["status"] == 2, second
    said = [line for line in str(second["stderr"]).splitlines()
            if "another avard process" in line]
    assert len(said) == 1 and f"(pid {os.getpid()})" in said[0], second["stderr"]
    assert "Traceback" not in str(second["stderr"])
    # the first run alone wrote after the first: one restart gap, every index once
    recs = list(RecordingReader(data))
    assert [g["reason"] for g in recs if g["kind"] == "gap"] == ["restart"]
    raw = [(r["i0"], r["i0"] + r["n"]) for r in recs if r["kind"] == "raw"]
    assert _tiles(raw)[-1][1] == raw[-1][1]
    assert len({r["run"] for r in recs if r["kind"] == "raw"}) == 2


def test_a_service_refused_by_the_lock_never_opens_a_segment_and_a_killed_holder_frees_it(
        tmp_path):
    """The lock is the kernel's, on an open file: it goes with its process however the
    process ends, so a SIGKILLed service never keeps its restart out."""
    from avard.core.errors import ConfigError

    data = tmp_path / "rec"
    _run(data, 3.0, 1)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom avard.daemon.service import dirlock\n"
         "dirlock.hold(sys.argv[1]); print('held', flush=True); time.sleep(120)", str(data)],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        before = sorted(p.name for p in data.iterdir())
        svc, _s, _e = simulated_service(_config(data), "quiet-lab", seed=2)
        with pytest.raises(ConfigError, match=rf"another avard process \(pid {holder.pid}\)"):
            svc.run(3.0)
        assert sorted(p.name for p in data.iterdir()) == before
    finally:
        holder.kill()
        holder.wait()
    svc = _run(data, 3.0, 3)
    assert svc.final_status["samples"] > 0



def test_a_temporary_state_file_left_in_place_is_replaced_never_written_through(tmp_path):
    """A process killed inside a checkpoint write leaves ``allan-state.tmp``; a link in its
    place was followed, and the checkpoint overwrote whatever it pointed at."""
    from avard.daemon.service.checkpoint import STATE_FILE, read_state

    data = tmp_path / "rec"
    data.mkdir()
    outside = tmp_path / "not-the-services"
    outside.write_bytes(b"keep me\n")
    (data / STATE_FILE).with_suffix(".tmp").symlink_to(outside)
    svc = _run(data, 6.0, 1)
    assert outside.read_bytes() == b"keep me\n"
    state = read_state(data)
    assert state.problem is None and state.record is not None
    assert state.record["n_samples"] == int(svc.allan.n_samples) > 0
    assert not (data / STATE_FILE).with_suffix(".tmp").exists()
    assert not (data / STATE_FILE).with_suffix(".tmp").is_symlink()



def test_a_directory_in_a_closed_segments_place_is_neither_read_nor_deleted(tmp_path, caplog):
    """Between runs a segment replaced by a directory: the next runs restore, record and
    rotate as before; no warning that names do not sort (the directory was sorted among the
    segments), and retention never tries to delete it."""
    over: dict[str, object] = {"recording.segment_s": 10.0}
    data = tmp_path / "rec"
    _run(data, 25.0, 1, **over)
    # the last records are written at 25 s of service time or later: past one rotation
    segs = sorted(data.glob("*.avr"))
    assert len(segs) >= 2
    segs[1].unlink()
    segs[1].mkdir()
    caplog.set_level("INFO", logger="avard.daemon.service")
    # retention that wants every closed segment gone
    svc = _run(data, 25.0, 2, **over, **{"recording.retention_max_bytes": 1})
    said = [r.getMessage() for r in caplog.records]
    assert not [m for m in said if "do not sort" in m or "cannot delete" in m], said
    assert segs[1].is_dir() and svc.restored is not None
    assert not segs[0].exists()
    assert svc.final_status["disk"]["state"] == "writing"


def test_a_killed_avard_run_leaves_nothing_in_tmp_and_the_next_run_cleans_up(tmp_path):
    """The real process, SIGKILLed once its simulated DS18B20s have been read: its temporary
    directory stays empty (before, an ``avard-sim-w1-*`` folder stayed there for good); what
    it left in its own recording directory the next run replaces and removes at its stop."""
    import signal
    import time

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    data = tmp_path / "rec"
    env = dict(os.environ, TMPDIR=str(tmp))
    args = [sys.executable, "-m", "avard.daemon.cli", "run", "--simulate", "quiet-lab",
            "--data-dir", str(data)]
    proc = subprocess.Popen([*args, "--speed", "20"], env=env, cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120.0          # a bound on a hang, not a measurement
        while not list((data / W1_DIR / "devices").glob("28-*/w1_slave")):
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert list(tmp.iterdir()) == []
    assert (data / W1_DIR).is_dir()
    done = subprocess.run([*args, "--speed", "0", "--duration", "3"], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert not (data / W1_DIR).exists()
    assert list(tmp.iterdir()) == []


@pytest.mark.parametrize("then", ["sighup", "stop"])
def test_a_segment_deleted_just_before_a_reopen_or_the_stop_is_still_a_recorded_gap(tmp_path,
                                                                                   then):
    """``rm segment; systemctl reload avard``: the reopen closed the deleted segment before
    any write could notice, and its samples went without a gap; deleted just before the
    stop, the same. The reopen and the stop now look first, and the gap goes into the next
    segment (at the stop, a last one made for it)."""
    from avard.daemon.service.recorder import Recorder

    data = tmp_path / "rec"
    done: dict[str, object] = {}

    class DeletedThen(Recorder):
        def write(self, record: dict) -> bool:
            if (then == "sighup" and not done and record.get("kind") == "raw"
                    and record["i0"] >= ACT_AT and self.path is not None):
                done["i0"] = record["i0"]
                self.path.unlink()
                self.reopen()                # what SIGHUP does, from the recorder's thread
            return super().write(record)

        def close(self) -> None:
            if then == "stop" and self.path is not None and self.path.exists():
                done["i0"] = None
                self.path.unlink()
            super().close()

    svc = _run_with_recorder(data, DeletedThen)
    assert done
    recs = list(RecordingReader(data))
    gaps = [r for r in recs if r["kind"] == "gap"]
    assert [g["reason"] for g in gaps] == ["segment_removed"]
    gap = gaps[0]
    samples = svc.final_status["samples"]
    assert gap["i0"] == 0                       # the only segment until then
    assert gap["i0"] + gap["n"] == (done["i0"] if then == "sighup" else samples)
    raw = [(r["i0"], r["i0"] + r["n"]) for r in recs if r["kind"] == "raw"]
    assert _tiles([*raw, (gap["i0"], gap["i0"] + gap["n"])]) == [(0, samples)]


@pytest.mark.slow
def test_a_slow_disk_on_the_real_clock_costs_recorder_behind_gaps_of_the_right_size(tmp_path):
    """A slow disk (each block's write takes longer than the ring holds) on the real clock,
    where the reader does not wait for the recorder: the recorder's cursor falls off the
    ring, and every sample it lost is in a ``recorder_behind`` gap: blocks and gaps tile
    every acquired index, and it records again once the disk is fast. (Slow: real time.)"""
    import time

    from avard.daemon.compose import compose
    from avard.daemon.config_types import Config
    from avard.daemon.hw.rig import ClockSpec, Rig, RigSpec, SensorSpec, bring_up
    from avard.daemon.hw.simulation import emulated_rig
    from avard.daemon.hw.timebase import SystemClock
    from avard.daemon.service.recorder import Recorder
    from avard.daemon.service.supervisor import ServiceHooks

    data = tmp_path / "rec"
    cfg = Config.from_dict(load_config(None, **{
        "recording.data_dir": str(data), "publish.enabled": False, "service.ring_s": 1.0,
        "temperature.ds18b20": False}))
    sensor = SensorSpec.from_config(cfg.sensor)
    clock, parts = emulated_rig([sensor], "quiet-lab", seed=1, clock=SystemClock())
    _name, dev, _emu = parts[0]
    bring_up(dev, sensor)
    rig = Rig(RigSpec((sensor,), ClockSpec("system", "quiet-lab"), cfg.temperature), dev,
              clock, {"device": "ADXL355 (emulated, real clock)"})
    slow_from, slow_to = int(2 * RATE), int(6 * RATE)     # the disk is slow for these blocks

    class SlowDisk(Recorder):
        def write(self, record: dict) -> bool:
            if record.get("kind") == "raw" and slow_from <= record["i0"] < slow_to:
                time.sleep(1.5)                           # longer than the 1 s ring
            return super().write(record)

    def recorder(svc: Service) -> Recorder:
        return SlowDisk(svc.data_dir, svc.run_id, svc.run_header.for_segment,
                        clock=svc.clock.monotonic, realtime=svc.clock.realtime)

    svc = compose(cfg, rig, hooks=ServiceHooks(recorder=recorder))
    svc.run(12.0)
    recs = list(RecordingReader(data))
    gaps = [r for r in recs if r["kind"] == "gap"]
    assert "recorder_behind" in {g["reason"] for g in gaps}
    raw = [(r["i0"], r["i0"] + r["n"]) for r in recs if r["kind"] == "raw"]
    end = svc.final_status["index"]       # an overrun on a loaded machine is a gap as well
    assert _tiles([*raw, *((g["i0"], g["i0"] + g["n"]) for g in gaps)]) == [(0, end)]
    assert raw[-1][1] == end and raw[-1][0] >= slow_to


def test_a_checkpoint_names_the_rate_of_the_samples_it_holds(tmp_path):
    """The live feed never saw a header, so its ``nominal_hz`` stayed None and every
    checkpoint stored ``"nominal_hz": null``: whoever read it back knew no rate to refuse a
    run at another one by. Both the fresh feed and the one a restart restores carry it."""
    from avard.daemon.service.checkpoint import read_state

    data = tmp_path / "rec"
    for seed in (1, 2):                 # the second run restores the first one's feed
        svc = _run(data, 9.0, seed)
        state = read_state(data)
        assert state.record is not None
        assert state.record["feed"]["nominal_hz"] == float(svc.odr) == 125.0
    assert svc.restored is not None


def test_a_lock_file_this_user_may_not_write_is_locked_read_only(tmp_path, monkeypatch):
    """After a manual ``sudo avard run`` the lock file is root's, 0644: the unit (User=avard)
    could not open it read-write, stopped with exit status 2, and RestartPreventExitStatus=2
    kept it down for good. flock needs no write access: the service now locks it read-only
    and records; a second process is still refused, naming the holder the kernel knows
    (the file still names the old root run's pid, which this one could not replace).

    The tests run as root, whom a 0444 mode does not stop: the refusal of a read-write open
    is injected at os.open instead."""
    import errno

    from avard.daemon.service import dirlock

    data = tmp_path / "rec"
    data.mkdir()
    (data / dirlock.LOCK_FILE).write_text("1\n")        # the sudo run's note
    (data / dirlock.LOCK_FILE).chmod(0o444)
    real_open = os.open

    def as_another_user(path, flags, *args, **kwargs):
        if str(path).endswith(dirlock.LOCK_FILE) and flags & (os.O_RDWR | os.O_WRONLY):
            raise PermissionError(errno.EACCES, "Permission denied (injected)", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", as_another_user)
    probe = ("import sys\nfrom avard.daemon.service import dirlock\n"
             "try:\n    dirlock.hold(sys.argv[1])\nexcept Exception as e:\n    print(e)\n")
    seen: dict[str, str] = {}

    def another_process_meanwhile() -> None:
        seen["said"] = subprocess.run([sys.executable, "-c", probe, str(data)],
                                      capture_output=True, text=True, timeout=60).stdout

    svc, _s, _e = simulated_service(_config(data), "quiet-lab", seed=1)
    svc.run(4.0, before_acquisition=another_process_meanwhile)
    assert svc.final_status["samples"] > 0
    assert f"another avard process (pid {os.getpid()})" in seen["said"], seen
    assert (data / dirlock.LOCK_FILE).read_text() == "1\n"


def test_without_recording_the_simulated_one_wire_tree_stays_out_of_the_data_directory(
        tmp_path, monkeypatch):
    """A service that does not record holds no lock on ``recording.data_dir``: its tree went
    there all the same, where the service that does record there keeps its own (and one's
    start removed the other's). It is now a private temporary folder, removed at the stop."""
    data = tmp_path / "rec"
    data.mkdir()
    theirs = data / W1_DIR / "devices" / "28-00000000a001"
    theirs.mkdir(parents=True)                   # the recording service's tree
    (theirs / "w1_slave").write_text("theirs\n")
    cfg = _config(data, **{"recording.enabled": False})
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    seen: list[list[str]] = []

    def look(t_mono: float) -> None:
        if not seen and any(tmp.iterdir()):
            seen.append(sorted(p.name for p in tmp.iterdir()))

    svc, sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, after_tick=look)
    got: list[str] = []
    handler = svc.temperature_reading
    sims.deliver = lambda r: (got.append(r.status), handler(r))[1]
    svc.run(6.0)
    assert seen and seen[0][0].startswith("avard-sim-w1-"), seen
    assert got and set(got) == {"ok"}, got
    assert (theirs / "w1_slave").read_text() == "theirs\n"
    assert sorted(p.name for p in data.iterdir()) == [W1_DIR]
    assert list(tmp.iterdir()) == []                 # removed at the stop


def test_a_simulated_one_wire_tree_that_cannot_be_made_fails_every_reading(tmp_path,
                                                                          monkeypatch):
    """The tree made at the first conversion on a full disk raised, and the tick returned
    before delivering anything: no reading, no ``sensor_lost``, the DS18B20 channels just
    stopped. Each sensor now reads as failed until the tree can be made."""
    import errno

    from avard.daemon.hw.simulation import SimulatedSensors

    data = tmp_path / "rec"
    full = {"on": True}
    make = SimulatedSensors._w1_root

    def refused(self: SimulatedSensors) -> Path:
        if full["on"]:
            raise OSError(errno.ENOSPC, "No space left on device (injected)")
        return make(self)

    monkeypatch.setattr(SimulatedSensors, "_w1_root", refused)
    box: dict[str, Service] = {}

    def disk(t_mono: float) -> None:
        full["on"] = t_mono - box["svc"].t_start < 6.0

    svc, sims, _emu = simulated_service(_config(data), "quiet-lab", seed=1, after_tick=disk)
    box["svc"] = svc
    svc.run(12.0)
    events = _sensor_events(data)
    assert sorted(events) == sorted(
        [("sensor_lost", n, "error") for n in sims.names]
        + [("sensor_back", n, "ok") for n in sims.names]), events


def _remove(data: Path) -> None:
    """``rm -r`` while the service's other writers (snapshots) may add files in it."""
    while data.exists():
        shutil.rmtree(data, ignore_errors=True)


def _until(done: Any) -> None:
    """Wait for another thread of the service to have done something (the bound is for a
    hang, not a measurement)."""
    import time

    deadline = time.monotonic() + 60.0
    while not done():
        assert time.monotonic() < deadline
        time.sleep(0.01)


_PROBE = ("import sys\nfrom avard.daemon.service import dirlock\n"
          "try:\n    dirlock.hold(sys.argv[1])\nexcept Exception as e:\n    print(e)\n"
          "else:\n    print('locked', flush=True)\n    sys.stdin.read()\n")


def test_a_recording_directory_removed_under_the_service_is_locked_again(tmp_path):
    """``rm -r DIR`` under a running service: the recorder makes DIR again and records on,
    but its lock stayed on the deleted file, and a second service locked the new one and
    recorded beside it. The recorder now locks the new file when it opens its next segment,
    and the second process is refused."""
    data = tmp_path / "rec"
    box: dict[str, Service] = {}
    said: list[str] = []

    def act(t_mono: float) -> None:
        svc = box["svc"]
        t = t_mono - svc.t_start
        if t >= 5.0 and not (tmp_path / "removed").exists():
            (tmp_path / "removed").touch()
            # the recorder's thread lags the reader's by however the threads were scheduled:
            # the segment must hold samples when it goes (else nothing is segment_removed,
            # and the test failed now and then); removed between two of its records
            _until(lambda: len(svc.recorder._marks.at) > 0)
            with svc.recorder._lock:
                _remove(data)
        elif t >= 8.0 and not said:
            _until(lambda: box["svc"].recorder.segments_written > 1)   # it wrote again
            said.append(subprocess.run([sys.executable, "-c", _PROBE, str(data)],
                                       capture_output=True, text=True, timeout=60,
                                       stdin=subprocess.DEVNULL).stdout)

    svc, _s, _e = simulated_service(_config(data), "quiet-lab", seed=1, after_tick=act)
    box["svc"] = svc
    svc.run(12.0)
    assert said and f"another avard process (pid {os.getpid()})" in said[0], said
    gaps = [g["reason"] for g in RecordingReader(data) if g["kind"] == "gap"]
    assert gaps == ["segment_removed"], gaps
    assert svc.final_status["disk"]["state"] == "writing"


def test_a_directory_made_again_while_its_holder_writes_nothing_is_checked_at_its_next_hold(
        tmp_path):
    """The lock is the directory's as it is: removed and made again by hand while the process
    that held it writes nothing (``avard run`` between its own hold and the service's start,
    a long start-up replay), the new directory is free and the first process to lock it
    records there (the old holder holds a deleted file; nothing can tell another process
    about it). The old holder finds out before it writes (the recorder's recheck, tested
    above) and now also when it takes the lock again, as the service's start does after
    ``avard run``'s: refused with one line naming the process there, where it used to count
    one more hold of a lock it no longer had. Once that process has gone, it locks the new
    directory again."""
    from avard.core.errors import ConfigError
    from avard.daemon.service import dirlock

    data = tmp_path / "rec"

    def probe() -> str:
        return subprocess.run([sys.executable, "-c", _PROBE, str(data)], capture_output=True,
                              text=True, timeout=60, stdin=subprocess.DEVNULL).stdout

    key = dirlock.hold(data)
    holder = None
    try:
        assert f"another avard process (pid {os.getpid()})" in probe()
        shutil.rmtree(data)
        data.mkdir()                                    # by hand
        holder = subprocess.Popen([sys.executable, "-c", _PROBE, str(data)],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        with pytest.raises(ConfigError, match=rf"another avard process \(pid {holder.pid}\)"):
            dirlock.hold(data)
        lost = dirlock.recheck(data)
        assert lost is not None and f"pid {holder.pid}" in lost
        holder.communicate("")                          # it ends; the kernel drops its lock
        again = dirlock.hold(data)                      # the new directory's lock, now ours
        dirlock.release(again)
        assert f"another avard process (pid {os.getpid()})" in probe()
    finally:
        if holder is not None and holder.poll() is None:
            holder.kill()
            holder.wait()
        dirlock.release(key)
    assert probe().startswith("locked")                 # released for good


def test_a_recording_directory_moved_away_and_made_again_is_recorded_in_from_then_on(tmp_path):
    """``mv rec rec.old; mkdir rec`` under a running service: its open segment moved with
    the old directory and stays whole, so nothing rotated: the service locked the new
    directory (the recheck) but went on writing into rec.old for up to ``segment_s``, while
    its state file went into rec, naming checkpoints recorded in rec.old. A lock taken again
    now also starts a new segment in the directory at the path: the old one keeps what was
    written before the move, the new one everything after, with nothing lost between."""
    data, moved = tmp_path / "rec", tmp_path / "rec.old"
    box: dict[str, Service] = {}

    def act(t_mono: float) -> None:
        svc = box["svc"]
        if t_mono - svc.t_start >= 5.0 and not moved.exists():
            _until(lambda: len(svc.recorder._marks.at) > 0)
            with svc.recorder._lock:              # between two of its records
                data.rename(moved)
                data.mkdir()

    svc, _s, _e = simulated_service(_config(data), "quiet-lab", seed=1, after_tick=act)
    box["svc"] = svc
    svc.run(12.0)
    old = [r for r in RecordingReader(moved) if r["kind"] == "raw"]
    new = [r for r in RecordingReader(data) if r["kind"] == "raw"]
    assert old and new, (len(old), len(new))
    spans = [(r["i0"], r["i0"] + r["n"]) for r in old + new]
    assert _tiles(spans) == [(old[0]["i0"], new[-1]["i0"] + new[-1]["n"])], _tiles(spans)
    assert max(r["i0"] for r in old) < min(r["i0"] for r in new)    # before, then after
    assert not [g for g in RecordingReader(data) if g["kind"] == "gap"]
    # the state file beside the new segments names a checkpoint recorded among them
    from avard.core.io import frames
    from avard.core.io.recording import scan_frames
    from avard.daemon.service.checkpoint import STATE_FILE

    state = frames.decode(next(scan_frames((data / STATE_FILE).read_bytes())).payload)
    ckpts = {(c["run"], c["i_end"]) for c in RecordingReader(data) if c["kind"] == "checkpoint"}
    assert (state["run"], state["i_end"]) in ckpts


def test_a_service_whose_removed_directory_another_locked_meanwhile_pauses(tmp_path):
    """The directory removed and, before this service's next segment, another process
    locked the new one: this service pauses (a write error saying so) instead of recording
    beside it, and resumes once that process has gone, with a gap over what it missed."""
    from avard.daemon.service.recorder import Recorder
    from avard.daemon.service.supervisor import ServiceHooks

    data = tmp_path / "rec"
    box: dict[str, Any] = {}
    paused: list[str] = []

    def act(t_mono: float) -> None:
        svc = box["svc"]
        t = t_mono - svc.t_start
        if t >= 5.0 and "holder" not in box:
            # the recorder's thread lags the reader's by however the threads were scheduled:
            # the segment must hold samples when it goes (else nothing is segment_removed)
            _until(lambda: len(svc.recorder._marks.at) > 0)
            with svc.recorder._lock:          # between two of its records
                _remove(data)
                box["before"] = (svc.recorder.records_lost, svc.recorder.segments_written)
                holder = box["holder"] = subprocess.Popen(
                    [sys.executable, "-c", _PROBE, str(data)], stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE, text=True)
                assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        elif t >= 9.0 and "gone" not in box:
            box["gone"] = True
            # it has tried to write since: lost the records, or opened a segment
            _until(lambda: (svc.recorder.records_lost, svc.recorder.segments_written)
                   > box["before"])
            st = svc.recorder.status()
            paused.append(f"{st['state']}: {st['error']}")
            paused.append(" ".join(sorted(p.name for p in data.glob("*.avr"))))
            box["holder"].communicate("")       # it ends; the kernel drops its lock

    def recorder(svc: Service) -> Recorder:
        # retried on the virtual clock: the run takes less real time than one retry_s
        return Recorder(svc.data_dir, svc.run_id, svc.run_header.for_segment,
                        clock=svc.clock.monotonic, wall=svc.clock.monotonic,
                        realtime=svc.clock.realtime, retry_s=1.0)

    svc, _s, _e = simulated_service(_config(data), "quiet-lab", seed=1, after_tick=act,
                                    hooks=ServiceHooks(recorder=recorder))
    box["svc"] = svc
    try:
        svc.run(16.0)
    finally:
        if "holder" in box and box["holder"].poll() is None:
            box["holder"].kill()
            box["holder"].wait()
    assert paused and paused[0].startswith("write_error: ") and \
        "another avard process" in paused[0], paused
    assert paused[1] == "", paused                  # nothing written beside the other
    recs = list(RecordingReader(data))
    gaps = {g["reason"]: (g["i0"], g["n"]) for g in recs if g["kind"] == "gap"}
    assert set(gaps) == {"segment_removed", "write_error"}, gaps
    raw = sorted((r["i0"], r["i0"] + r["n"]) for r in recs if r["kind"] == "raw")
    # what was lost (the removed segment, then the pause) and what was written after it
    # tile the indices from the removed segment's first sample on
    spans = sorted([*raw, *((i0, i0 + n) for i0, n in gaps.values())])
    assert _tiles(spans) == [(spans[0][0], spans[-1][1])], _tiles(spans)
    assert svc.final_status["disk"]["state"] == "writing"


def test_a_lock_file_removed_alone_is_locked_again_within_a_second_of_data(tmp_path):
    """``rm DIR/.avard.lock`` leaves the open segment as it is, so nothing rotates: the
    service held the deleted file for up to ``segment_s`` while a second one could lock a
    new one. The recorder checks the lock once a second of data time. Acted on from the
    recorder's own writes (at sample 5 s, then 8 s), so it depends on the data clock only."""
    from avard.daemon.service import dirlock
    from avard.daemon.service.recorder import Recorder
    from avard.daemon.service.supervisor import ServiceHooks

    data = tmp_path / "rec"
    said: list[str] = []
    removed: list[int] = []

    class Acting(Recorder):
        def write(self, record: dict[str, Any]) -> bool:
            i0 = record.get("i0", 0) if record.get("kind") == "raw" else 0
            if i0 >= 5 * RATE and not removed:
                removed.append(i0)
                (data / dirlock.LOCK_FILE).unlink()
            elif i0 >= 8 * RATE and not said:
                said.append(subprocess.run([sys.executable, "-c", _PROBE, str(data)],
                                           capture_output=True, text=True, timeout=60,
                                           stdin=subprocess.DEVNULL).stdout)
            return super().write(record)

    def recorder(svc: Service) -> Recorder:
        return Acting(svc.data_dir, svc.run_id, svc.run_header.for_segment,
                      clock=svc.clock.monotonic, realtime=svc.clock.realtime)

    svc, _s, _e = simulated_service(_config(data), "quiet-lab", seed=1,
                                    hooks=ServiceHooks(recorder=recorder))
    svc.run(12.0)
    assert said and f"another avard process (pid {os.getpid()})" in said[0], said
    assert [g for g in RecordingReader(data) if g["kind"] == "gap"] == []
    assert svc.final_status["disk"]["state"] == "writing"
