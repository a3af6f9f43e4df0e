"""A run stopped before its first sample reaches the Allan stage must not make the next start
count the recording twice (#26 item 1).

The old checkpoint said ``i_end = 0`` / ``next_index = null`` when the feed had seen nothing
(an early stop, a sensor that produced nothing before SIGTERM, SIGTERM during the start-up
replay), and the next restore replayed the whole recording on top of accumulators that
already held it. The checkpoint now says which samples the accumulators account for
(``covered``), and after every sequence of runs the accumulators equal the offline Allan
variance of the recording (same samples, same AVAR).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan.streaming import StreamingAllan
from avard.core.io import frames
from avard.core.io.recording import RecordingReader, replay_allan, scan_frames
from avard.core.io.recording import frame as frame_bytes
from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config
from avard.daemon.hw.adxl355 import Drain
from avard.daemon.service.checkpoint import STATE_FILE
from avard.daemon.service.recorder import Recorder, last_recorded, restart_gap
from avard.daemon.service.supervisor import Service


def _service(data: Path, seed: int) -> Service:
    cfg = load_config(None, **{"recording.data_dir": str(data), "publish.enabled": False,
                               "sensor.poll_hz": 2.0, "allan.checkpoint_interval_s": 4.0,
                               "allan.snapshot_interval_s": 4.0})
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=seed)
    return svc


def _run(data: Path, seconds: float, seed: int, *, stop_first: bool = False) -> Service:
    svc = _service(data, seed)
    if stop_first:
        # a sensor that produces nothing, stopped by SIGTERM (under the unit READY never
        # comes and TimeoutStartSec sends it); the same as SIGTERM during the start-up replay
        def nothing() -> Drain:
            return Drain(np.zeros((0, 3), np.int32), False, svc.clock.monotonic(),
                         svc.clock.realtime(), 0)

        svc.sensor.drain = nothing
        svc.run(None, before_acquisition=svc.stop_requested.set)
        assert svc.final_status["samples"] == 0
    else:
        svc.run(seconds)
    return svc


def _state(data: Path) -> dict:
    return frames.decode(next(scan_frames((data / STATE_FILE).read_bytes())).payload)


def _assert_accumulators_equal_the_recording(data: Path) -> None:
    final = StreamingAllan.from_state(_state(data)["state"]).snapshot()
    offline = replay_allan(data).snapshot()
    recorded = sum(r["n"] for r in RecordingReader(data) if r["kind"] == "raw")
    assert final.n_samples == offline.n_samples, (final.n_samples, offline.n_samples, recorded)
    assert final.n_samples <= recorded
    np.testing.assert_allclose(final.avar, offline.avar, rtol=1e-12, atol=0)


@pytest.mark.parametrize("early", ["duration", "stopped_before_samples"])
def test_an_early_stop_between_two_runs_does_not_count_the_recording_twice(tmp_path, early):
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    if early == "duration":
        _run(data, 0.05, 2)                           # `avard run … --duration 0.05`
    else:
        _run(data, 0.0, 2, stop_first=True)
    ckpt = _state(data)
    assert ckpt["i_end"] > 0                          # says which samples it holds
    _run(data, 6.0, 3)
    _assert_accumulators_equal_the_recording(data)


def test_two_early_stops_in_a_row_then_a_run(tmp_path):
    """Restarts in quick succession: each early stop keeps what the last checkpoint said."""
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    _run(data, 0.0, 2, stop_first=True)
    _run(data, 0.05, 3)
    _run(data, 6.0, 4)
    _assert_accumulators_equal_the_recording(data)


def test_a_checkpoint_after_a_gap_still_says_what_it_holds(tmp_path):
    """A gap just before the checkpoint (the feed's next index is unknown there) must not
    turn the checkpoint's index into 0 either."""
    data = tmp_path / "rec"
    svc = _run(data, 9.0, 1)
    held = svc.feed.covered
    svc.feed.gap()
    assert svc.feed.covered == held and held is not None and held > 0


# -- a damaged or deleted state file (#26 item 3) ---------------------------------------------


def _damage(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x10
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("fault", ["deleted", "damaged", "emptied"])
def test_a_lost_state_file_is_rebuilt_from_the_recordings_checkpoint_records(tmp_path, caplog,
                                                                              fault):
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    _run(data, 5.0, 2)
    state = data / STATE_FILE
    if fault == "deleted":
        state.unlink()
    elif fault == "damaged":
        _damage(state)
    else:
        state.write_bytes(b"")
    caplog.set_level("WARNING", logger="avard.daemon.service")
    svc = _run(data, 6.0, 3)
    # the history the recording holds is kept: the accumulators equal its offline Allan
    _assert_accumulators_equal_the_recording(data)
    assert svc.restored is not None and svc.restored["state_file"].startswith(
        "missing" if fault == "deleted" else "damaged")
    # rebuilt from the newest checkpoint record (the previous run's final one): nothing after
    # it to replay, so the start-up does not read the recording again
    assert svc.restored["replayed"] == 0 and svc.restored["run"] == _runs(data)[1]
    said = [r for r in caplog.records if r.levelname == "WARNING" and STATE_FILE in r.message]
    assert said and "rebuilt the accumulators from the recording's checkpoint record" in \
        said[0].getMessage()


def _runs(data: Path) -> list[str]:
    out: list[str] = []
    for r in RecordingReader(data):
        if r["kind"] == "header" and r["run"] not in out:
            out.append(r["run"])
    return out


def _strip_checkpoints(data: Path, run: str) -> None:
    for seg in data.glob(f"{run}_*.avr"):
        kept = [f for f in scan_frames(seg.read_bytes())
                if frames.decode(f.payload)["kind"] not in ("checkpoint", "avar")]
        seg.write_bytes(b"".join(frame_bytes(f.payload) for f in kept))


def _two_runs_without_checkpoints(tmp_path: Path) -> Path:
    """Two runs whose checkpoint records are stripped and whose state file is gone."""
    data = tmp_path / "rec"
    _run(data, 6.0, 1)
    _run(data, 4.0, 2)
    for run in _runs(data):
        _strip_checkpoints(data, run)
    (data / STATE_FILE).unlink()
    return data


def test_a_lost_state_file_and_no_checkpoint_record_rebuilds_from_the_whole_recording(
        tmp_path, caplog):
    data = _two_runs_without_checkpoints(tmp_path)
    caplog.set_level("WARNING", logger="avard.daemon.service")
    svc = _run(data, 3.0, 3)
    assert svc.restored is not None and svc.restored["source"].startswith("the whole recording")
    _assert_accumulators_equal_the_recording(data)
    assert any("rebuilt the accumulators from the whole recording" in r.getMessage()
               for r in caplog.records)


def test_a_lost_state_file_and_a_killed_run_replays_what_came_after_the_checkpoint(tmp_path):
    """The newest checkpoint record is the previous run's last; a later run killed before its
    first checkpoint (no final checkpoint either) is replayed after it."""
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    svc = _service(data, 2)
    svc.run(3.0)
    # a SIGKILL: the run's samples are recorded, its checkpoints are not
    _strip_checkpoints(data, _runs(data)[-1])
    (data / STATE_FILE).unlink()
    svc = _run(data, 5.0, 3)
    assert svc.restored is not None and svc.restored["replayed"] > 0
    _assert_accumulators_equal_the_recording(data)


# -- the run-time invariant (#26: checked while running, not only in tests) --------------------


def test_every_checkpoint_checks_the_accumulators_against_what_was_recorded(tmp_path):
    data = tmp_path / "rec"
    svc = _run(data, 13.0, 1)
    ckpts = [r for r in RecordingReader(data) if r["kind"] == "checkpoint"]
    # How many checkpoints a run makes depends on how the threads were scheduled (at most
    # one per chunk the Allan stage takes, and a lagging stage takes long chunks), so the
    # test asks what does not: together the checks cover every recorded sample, each taking
    # up where the last one ended, and each agrees with the recording.
    raw = [(r["i0"], r["i0"] + r["n"]) for r in RecordingReader(data) if r["kind"] == "raw"]
    spans = [(c["check"]["from"], c["check"]["to"]) for c in ckpts]
    assert spans and spans[0][0] == raw[0][0] and spans[-1][1] == raw[-1][1], spans
    assert all(a[1] == b[0] for a, b in itertools.pairwise(spans)), spans
    for c in ckpts:
        check = c["check"]
        recorded = sum(max(0, min(r["i0"] + r["n"], check["to"]) - max(r["i0"], check["from"]))
                       for r in RecordingReader(data) if r["kind"] == "raw")
        assert check["seen"] == recorded and check["n_added"] == check["fed"]
    assert not [r for r in RecordingReader(data)
                if r["kind"] == "event" and r["name"] == "invariant_violated"]
    assert svc.workers[1].violations == 0


def test_a_violation_is_logged_and_recorded_as_an_event(tmp_path, caplog):
    """A feed that counts a block twice (the kind of fault the early stop caused) is caught at
    the next checkpoint, loudly, and the recording says so."""
    data = tmp_path / "rec"
    svc = _service(data, 1)
    feed = svc.feed
    real_raw = feed.raw
    doubled = []

    def raw_twice(i0, counts):
        real_raw(i0, counts)
        if not doubled and feed.fed > 500:
            doubled.append(i0)
            real_raw(i0, counts)                 # the same samples again
    feed.raw = raw_twice
    caplog.set_level("ERROR", logger="avard.daemon.service")
    svc.run(9.0)
    events = [r for r in RecordingReader(data)
              if r["kind"] == "event" and r["name"] == "invariant_violated"]
    assert len(events) == 1 and events[0]["detail"]["accumulators_took"] > \
        events[0]["detail"]["recorded"]
    assert any("invariant violated" in r.getMessage() for r in caplog.records)


# -- restarts in quick succession: one hole, one gap of the right size (#26 item 11) ---------


def _run_segment(d: Path, run: str, i0: int, n: int, t_mono: float, *,
                 restart: tuple[int, int] | None = None) -> None:
    """A run as the service writes it: header, its restart gap, its start event at index
    ``i0`` and time ``t_mono`` (one boot), then ``n`` samples."""
    def header() -> dict:
        return frames.header_record(run, rate_hz=125.0, t_mono=t_mono, t_real=1.7e9 + t_mono,
                                    i0=i0, scale_m_s2_per_count=3.9e-5, boot_id="boot")

    rec = Recorder(d, run, header)
    if restart is not None:
        rec.write(frames.gap_record(run, 0, restart[0], restart[1], t_mono, 1.7e9 + t_mono,
                                    "restart", estimated=True, clock="monotonic"))
    rec.write(frames.event_record(run, 0, "start", t_mono, 1.7e9 + t_mono, i0=i0))
    if n:
        rec.write(frames.raw_record(run, 0, i0, np.zeros((n, 3), np.int32), t_mono,
                                    1.7e9 + t_mono, rate_hz=125.0))
    rec.close()


def _restart(d: Path, run: str, t_mono: float, n: int) -> tuple[int, int]:
    """The service's start: the gap from the recording's end, then the run."""
    last = last_recorded(d, 125.0)
    assert last is not None
    g = restart_gap(last, boot_id="boot", t_mono=t_mono, t_real=1.7e9 + t_mono,
                    rate_hz=125.0)
    _run_segment(d, run, g.i0 + g.n, n, t_mono, restart=(g.i0, g.n))
    return g.i0, g.n


def test_restarts_that_record_no_sample_do_not_write_overlapping_restart_gaps(tmp_path):
    """Runs that started and stopped without recording a sample each measured their restart
    gap from the last *sample*, so one hole became [2494, +481), [2494, +811), [2494, +1101).
    A run's start event ends the recording too: the gaps tile the hole exactly."""
    _run_segment(tmp_path, "n00000001-a", 0, 2494, 0.0)           # samples end at 19.952 s
    gaps = [_restart(tmp_path, "n00000002-b", 19.952 + 481 / 125, 0),
            _restart(tmp_path, "n00000003-c", 19.952 + 811 / 125, 0),
            _restart(tmp_path, "n00000004-d", 19.952 + 1101 / 125, 250)]
    assert gaps == [(2494, 481), (2975, 330), (3305, 290)]
    last = last_recorded(tmp_path, 125.0)
    assert last is not None and last.i_end == 2494 + 1101 + 250


def test_segments_deleted_by_retention_do_not_look_like_double_counting(tmp_path, caplog):
    """The accumulators legitimately hold more than what is left of the recording once
    retention deleted old segments: the restore's invariant counts from where they started."""
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    second = _run(data, 5.0, 2)
    first_run = _runs(data)[0]
    for seg in data.glob(f"{first_run}_*.avr"):
        seg.unlink()
    caplog.set_level("ERROR", logger="avard.daemon.service")
    svc = _run(data, 2.0, 3)
    assert svc.restored is not None and "invariant_violated" not in svc.restored
    assert svc.restored["n_samples"] == int(second.allan.n_samples)
    assert not [r for r in caplog.records if "invariant" in r.getMessage()]


def test_accumulators_holding_more_samples_than_indices_are_dropped_loudly(tmp_path, caplog):
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    ckpt = _state(data)
    ckpt["feed"]["origin"] = ckpt["feed"]["covered"] - 10     # claims to have started late
    (data / STATE_FILE).write_bytes(frame_bytes(frames.encode(ckpt)))
    caplog.set_level("ERROR", logger="avard.daemon.service")
    svc = _run(data, 2.0, 2)
    assert svc.restored is not None and "invariant_violated" in svc.restored
    assert any("invariant violated" in r.getMessage() for r in caplog.records)
    # this run starts afresh: its accumulators hold only its own samples
    assert int(svc.allan.n_samples) <= svc.final_status["samples"]


def test_a_checkpoint_left_by_the_old_early_stop_bug_is_not_trusted(tmp_path, caplog):
    """Upgrading over a state file the old code wrote at an early stop (``i_end = 0``,
    ``next_index = null``, samples held, no ``covered``): it is recognised, not replayed onto,
    and the recording's checkpoint record stands in for it."""
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    ckpt = _state(data)
    ckpt["i_end"] = 0
    ckpt["feed"] = {k: v for k, v in ckpt["feed"].items() if k not in ("covered", "origin")}
    ckpt["feed"]["next_index"] = None
    (data / STATE_FILE).write_bytes(frame_bytes(frames.encode(ckpt)))
    caplog.set_level("WARNING", logger="avard.daemon.service")
    svc = _run(data, 4.0, 2)
    assert svc.restored is not None and svc.restored["state_file"].startswith("unusable")
    _assert_accumulators_equal_the_recording(data)


def test_a_lost_tail_and_an_unknown_restart_gap_never_reuse_indices_the_accumulators_hold(
        tmp_path, caplog):
    """The state file says the accumulators cover the second run, whose segment is gone (a
    lost or damaged tail), and the wall clock is behind the recording (a Pi without RTC
    after a power cut: restart gap "unknown", 0 samples). The third run must start where the
    accumulators end, not where the recording does: the indices between are a recorded loss,
    never fed twice."""
    data = tmp_path / "rec"
    _run(data, 9.0, 1)
    second = _run(data, 9.0, 2)
    covered = _state(data)["feed"]["covered"]
    for seg in data.glob(f"{second.run_id}_*.avr"):
        seg.unlink()
    first_end = max(r["i0"] + r["n"] for r in RecordingReader(data) if r["kind"] == "raw")
    assert first_end < covered
    caplog.set_level("ERROR", logger="avard.daemon.service")
    svc = _service(data, 3)
    svc.clock.step_realtime(-3600.0)
    svc.run(5.0)
    assert svc.start_index == covered
    assert not [r for r in caplog.records if "invariant" in r.getMessage()]
    recs = [r for r in RecordingReader(data) if r["run"] == svc.run_id]
    (gap,) = [r for r in recs if r["kind"] == "gap" and r["reason"] == "restart"]
    assert (gap["i0"], gap["n"], gap["clock"]) == (first_end, covered - first_end, "unknown")
    assert not [r for r in recs if r["kind"] == "event" and r["name"] == "invariant_violated"]
    alone = tmp_path / "third"                  # the third run's samples, taken once
    alone.mkdir()
    for seg in data.glob(f"{svc.run_id}_*.avr"):
        (alone / seg.name).write_bytes(seg.read_bytes())
    third = replay_allan(alone).snapshot().n_samples
    assert int(_state(data)["state"]["n_samples"]) == int(second.allan.n_samples) + third


def test_a_whole_recording_rebuild_is_announced_with_its_length_before_it_starts(
        tmp_path, caplog, monkeypatch):
    """Without a usable checkpoint record the restore replays the whole recording before
    READY, which TimeoutStartSec bounds: a WARNING says so, with how much will be replayed,
    before the replay starts (so a journal that ends there explains the timeout)."""
    from avard.core.allan import replay

    data = _two_runs_without_checkpoints(tmp_path)
    recorded = sum(r["n"] for r in RecordingReader(data) if r["kind"] == "raw")
    first = min(r["i0"] for r in RecordingReader(data) if r["kind"] == "raw")
    end = max(r["i0"] + r["n"] for r in RecordingReader(data) if r["kind"] == "raw")
    size = sum(f.stat().st_size for f in data.glob("*.avr"))
    said_before: list[str] = []
    real = replay.replay_after

    def replay_after(*a, **kw):  # type: ignore[no-untyped-def]
        said_before.extend(r.getMessage() for r in caplog.records if r.levelname == "WARNING")
        return real(*a, **kw)

    monkeypatch.setattr("avard.daemon.service.checkpoint.replay_after", replay_after)
    caplog.set_level("WARNING", logger="avard.daemon.service")
    _run(data, 2.0, 3)
    (msg,) = [m for m in said_before if "TimeoutStartSec" in m]
    assert f"indices {first} to {end}" in msg and f"{end - first} samples" in msg
    assert f"{size / 1e6:.1f} MB" in msg and "2 segments" in msg
    assert recorded <= end - first
