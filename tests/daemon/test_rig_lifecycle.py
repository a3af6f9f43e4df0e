"""A rig's start, READY, watchdog and thread deaths (issue 28 item 1's review): READY
with one sensor silent from the start, the watchdog fed only when every lane advanced, a
failed start that leaves no lane running, the sensor that raised blamed with its bus."""

from __future__ import annotations

import threading
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from avard.core.io.recording import RecordingReader
from avard.daemon.hw.rig import build_lanes, describe_rig
from avard.daemon.service.rig_service import RigService

from tests.daemon.test_rig_service import LEFT, RIGHT, _config

# -- 2. READY with one sensor silent from the start; 6. the watchdog per lane -------------------

class _Notifier:
    """sd_notify's calls, counted (the watchdog interval short so it is asked every tick)."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.statuses: list[str] = []

    def watchdog_interval_s(self) -> float:
        return 0.01

    def status(self, text: str) -> None:
        self.calls.append("status")
        self.statuses.append(text)

    def __getattr__(self, name: str) -> Any:
        return lambda *a: self.calls.append(name)


def test_a_rig_with_a_sensor_silent_from_the_start_is_ready_and_status_names_it(
        tmp_path: Path) -> None:
    config = _config(tmp_path, [LEFT, RIGHT])
    built = build_lanes(describe_rig(config, simulate="quiet-lab", seed=1, speed=None))
    built.parts["emulators"][1].stop_producing()         # "right" never makes a sample
    n = _Notifier()
    svc = RigService(config, built, notifier=n)
    svc.run(20.0)
    assert svc.lanes[1].acq is not None and svc.lanes[1].acq.samples == 0
    assert svc.lanes[1].acq.stalled
    assert svc.ready and "ready" in n.calls
    assert any("right: STALLED (no samples yet)" in s for s in n.statuses)
    assert not any("left: STALLED" in s for s in n.statuses)


def _progress_of(counts: list[tuple[int, bool]], svc: Any) -> Any:
    from avard.daemon.service.supervisor import Progress

    ps = [Progress(n > 0, n, stalled, False) for n, stalled in counts]
    svc.lanes = [SimpleNamespace(progress=lambda p=p: p) for p in ps]
    return RigService.progress(svc)


def test_the_watchdog_count_advances_only_when_every_lane_did_or_is_stalled() -> None:
    """A reader hung inside a transfer raises no stall: its frozen count alone must stop the
    watchdog, however fast the other lanes go (r8: the sum kept advancing)."""
    svc: Any = SimpleNamespace(_seen=[0, 0], _advances=0)
    first = _progress_of([(1000, False), (500, False)], svc)
    hung = _progress_of([(1250, False), (500, False)], svc)       # "far" frozen
    assert hung.samples == first.samples and not hung.stalled
    both = _progress_of([(1500, False), (510, False)], svc)
    assert both.samples == first.samples + 1
    marked = _progress_of([(1750, False), (510, True)], svc)     # frozen, but said stalled
    assert marked.samples == both.samples + 1
    assert marked.first_samples


# -- 3. a later lane failing to start leaves nothing running ------------------------------------

def test_a_lane_whose_directory_is_unusable_is_refused_before_any_lane_starts(
        tmp_path: Path) -> None:
    from avard.core.errors import ConfigError

    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "right").write_text("not a directory")
    config = _config(tmp_path, [LEFT, RIGHT])
    svc = RigService(config, build_lanes(describe_rig(config, simulate="quiet-lab", seed=1,
                                                      speed=None)))
    before = set(threading.enumerate())
    with pytest.raises(ConfigError, match="right"):
        svc.run(5.0)
    assert [t.name for t in set(threading.enumerate()) - before if t.is_alive()] == []
    assert not any((tmp_path / "rec" / "left").glob("*.avr"))     # no lane had started


def test_a_start_failing_after_a_lane_started_stops_and_flushes_that_lane(
        tmp_path: Path) -> None:
    """A failure the directory check cannot see (here: the second lane's recorder cannot be
    made): the first lane's threads are stopped and its recording closed, not left running."""
    from avard.daemon.service.supervisor import Service

    config = _config(tmp_path, [LEFT, RIGHT])
    svc = RigService(config, build_lanes(describe_rig(config, simulate="quiet-lab", seed=1,
                                                      speed=None)))
    real_start = Service.start

    def start(lane: Service, before: Any = None, *, stop_at: float | None = None) -> None:
        if lane.sensor_name == "right":
            raise OSError(28, "No space left on device")
        real_start(lane, before, stop_at=stop_at)

    before = set(threading.enumerate())
    Service.start = start                    # type: ignore[method-assign]
    try:
        with pytest.raises(OSError):
            svc.run(5.0)
    finally:
        Service.start = real_start           # type: ignore[method-assign]
    assert [t.name for t in set(threading.enumerate()) - before if t.is_alive()] == []
    left = svc.lanes[0]
    assert left.workers and all(not w._thread.is_alive() for w in left.workers)  # type: ignore[attr-defined]
    assert [r["name"] for r in RecordingReader(tmp_path / "rec" / "left")
            if r["kind"] == "event"][:1] == ["start"]


# -- 8. the sensor whose drain raised is blamed, with its bus ------------------------------------

def test_the_sensor_that_raised_is_blamed_not_the_first_of_its_bus(tmp_path: Path) -> None:
    from avard.core.errors import ServiceFault
    from avard.daemon.service.acquisition import StoppedWithBus

    config = _config(tmp_path, [LEFT, RIGHT])
    built = build_lanes(describe_rig(config, simulate="quiet-lab", seed=1, speed=None))
    dev = built.lanes[1].sensor
    clock = built.clock
    t0 = clock.monotonic()
    real_drain = dev.drain

    def drain(*a: Any, **k: Any) -> Any:
        if clock.monotonic() - t0 > 5.0:
            raise RuntimeError("driver bug in right")
        return real_drain(*a, **k)

    dev.drain = drain                               # type: ignore[method-assign]
    svc = RigService(config, built)
    with pytest.raises(ServiceFault) as err:
        svc.run(20.0)
    assert str(err.value).startswith("sensor right (/dev/spidev0.1): ")
    assert "driver bug in right" in str(err.value)
    left, right = (lane.acq for lane in svc.lanes)
    assert isinstance(right.error, RuntimeError)             # type: ignore[union-attr]
    assert isinstance(left.error, StoppedWithBus)            # type: ignore[union-attr]


# -- 7. a stalled sensor's outage is one gap, sized by time ------------------------------------

def _gaps(path: Path) -> list[dict[str, Any]]:
    from avard.core.io.source import RecordingSource

    return [r for r in RecordingSource(path).records() if r["kind"] == "gap"]


def test_a_sensor_silent_for_the_whole_run_records_no_invented_loss(tmp_path: Path) -> None:
    """It made nothing, so nothing was lost: the stall is an event, not 16 samples per
    recovery (r3: 928 'lost' over 60 s of a part that made none)."""
    config = _config(tmp_path, [LEFT, RIGHT])
    built = build_lanes(describe_rig(config, simulate="quiet-lab", seed=1, speed=None))
    built.parts["emulators"][1].stop_producing()
    svc = RigService(config, built)
    svc.run(30.0)
    right = svc.lanes[1].acq
    assert right is not None and right.samples == 0 and right.stalled
    assert right.lost_estimate == 0 and right.next_index == 0
    assert _gaps(tmp_path / "rec" / "right") == []


def test_a_stall_then_resume_is_one_gap_the_size_of_the_outage(tmp_path: Path) -> None:
    config = _config(tmp_path, [LEFT, RIGHT])
    built = build_lanes(describe_rig(config, simulate="quiet-lab", seed=1, speed=None))
    emu = built.parts["emulators"][1]
    t0: list[float] = []

    def tick(t: float) -> None:          # "right" makes nothing from 10 s to 20 s
        t0.append(t) if not t0 else None
        if 10.0 <= t - t0[0] < 20.0 and not emu.stalled:
            emu.stop_producing()
        elif t - t0[0] >= 20.0 and emu.stalled:
            emu.resume_producing()

    import dataclasses

    lanes = list(built.lanes)
    lanes[0] = dataclasses.replace(lanes[0], on_tick=tick)
    svc = RigService(config, dataclasses.replace(built, lanes=tuple(lanes)))
    svc.run(40.0)
    gaps = _gaps(tmp_path / "rec" / "right")
    assert len(gaps) == 1 and "stall" in gaps[0]["reason"]
    left, right = (lane.acq for lane in svc.lanes)
    assert left is not None and right is not None
    assert right.samples == pytest.approx(30 * 125, abs=64)
    # the gap is what time says was not made: the index stays on the time line, beside left's
    assert gaps[0]["n"] == pytest.approx(10 * 125, abs=64)
    assert right.next_index == pytest.approx(left.next_index, abs=3)
    assert right.lost_estimate == gaps[0]["n"]
