"""The live separation wired into ``avard run`` (issue 28 item 3; daemon/service/rig_separation.py):
an emulated 3-sensor rig composed as ``avard run --simulate`` composes it, on the virtual clock;
what its lanes publish in their ``avar`` records, against ``avard separate`` on the same
recordings; the pairs' counts across a kill and a restart; the status."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.analysis.separate import (
    PAIRS,
    AlignedRun,
    Separation,
    align,
    aligned_runs,
    read_sensor,
    separate,
    separate_runs,
)
from avard.core.errors import DataError
from avard.daemon.commands.separate import load_and_separate
from avard.daemon.compose import compose_rig
from avard.daemon.config import validate_config
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import describe_rig
from avard.daemon.service.rig_separation import STATE_FILE
from avard.daemon.service.rig_service import RigService
from avard.daemon.service.snapshots import separation_of
from avard.daemon.service.supervisor import ServiceHooks

ODR = 125.0
SENSORS = [{"name": "left", "spi_device": 0}, {"name": "right", "spi_device": 1},
           {"name": "far", "bus": "i2c", "i2c_address": 0x53}]


class Captured:
    """A PUB socket that keeps what it is given (the records every subscriber would get)."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, dict[str, Any]]] = []

    def publish(self, topic: str, record: dict[str, Any]) -> int:
        self.sent.append((topic, record))
        return 1

    def stats(self) -> dict[str, Any]:
        return {"peers": 0, "sent": len(self.sent), "dropped": 0}

    def close(self) -> None:
        pass


class NoRequests:
    def stop(self) -> None:
        pass


def _config(root: Path, sensors: list[dict[str, Any]] = SENSORS) -> Config:
    return Config.from_dict(validate_config({
        "sensor": sensors, "temperature": {"ds18b20": False},
        "recording": {"data_dir": str(root)},
        "allan": {"snapshot_interval_s": 10.0, "checkpoint_interval_s": 10.0}}))


def _rig(config: Config, pub: Captured, *, seed: int = 1) -> RigService:
    """The service ``avard run --simulate quiet-lab`` builds for the config (compose_rig)."""
    svc = compose_rig(config, describe_rig(config, simulate="quiet-lab", seed=seed, speed=None),
                      hooks=ServiceHooks(publisher=lambda _lane: pub,
                                         request_server=lambda _svc: NoRequests()))
    assert isinstance(svc, RigService)
    return svc


def test_every_lane_publishes_the_separation_avard_separate_finds(tmp_path: Path) -> None:
    root = tmp_path / "rec"
    pub = Captured()
    svc = _rig(_config(root), pub)
    svc.run(120.0)
    last = {}
    avars = 0
    for topic, rec in pub.sent:
        if rec["kind"] == "avar":
            avars += 1
            if "separation" in rec:
                last[topic] = rec
    assert sorted(last) == ["avar.far", "avar.left", "avar.right"]
    final = {t: r for t, r in pub.sent if r["kind"] == "avar"}
    assert all(final[t] is last[t] for t in last)          # the run's last: computed at stop
    # only the records after a new computation carry it (every 60 s of 120, and at stop)
    assert sum("separation" in r for _t, r in pub.sent) < avars / 2
    seps = [separation_of(rec) for rec in last.values()]
    assert all(s is not None for s in seps)
    live = seps[0]
    assert live is not None
    maps = [rec["separation"] for rec in last.values()]
    assert all(m == maps[0] for m in maps[1:])            # one rig, one separation
    assert live.sensors == ("left", "right", "far") and live.method == "three-cornered hat"
    # 1. the same rows as avard separate's alignment of the recordings and the cascade's
    #    moments (overlap 8): equal to rounding (the wire carries the ADEV, its interval's
    #    ends and no estimate where there is only an upper limit)
    al = align([read_sensor(root / n) for n in live.sensors])
    cascade = separate(al.accels, al.rate_hz, sensors=live.sensors, axes=al.axes, fit=False,
                       overlap=8)
    assert live.n_samples == cascade.n_samples >= 120 * ODR - 64
    for x, y in zip(live.axes, cascade.axes, strict=True):
        np.testing.assert_array_equal(x.m, y.m)
        for p, q in zip((*x.self_noise, x.common), (*y.self_noise, y.common), strict=True):
            np.testing.assert_array_equal(p.upper_limit, q.upper_limit)
            np.testing.assert_allclose(p.dev, q.dev, rtol=1e-9)       # NaN where limits
            np.testing.assert_allclose(p.hi, q.hi, rtol=1e-9)
    # 2. `avard separate` itself (fully overlapping moments): the two estimators differ by
    #    less than either's 68 % interval is wide, at every τ with ≥ 8 averages
    full = load_and_separate([str(root)])
    assert full.n_samples == live.n_samples
    for x, y in zip(live.axes, full.axes, strict=True):
        k = int(np.searchsorted(y.m, live.n_samples // 8, side="right"))
        for p, q in zip((*x.self_noise, x.common), (*y.self_noise, y.common), strict=True):
            both = ~(p.upper_limit | q.upper_limit)[:k]
            width = (q.hi - q.lo)[:k][both]
            gap = np.abs(np.clip(p.var, 0, None) - np.clip(q.var, 0, None))[:k][both]
            assert np.all(gap <= width), (x.axis, p.var, q.var)
    # the status says what the pairs hold: no slip, one segment each, the invariant held
    st = svc.lanes[0].final_status["separation"]
    assert st["slips"] == {"left": 0, "right": 0, "far": 0}
    assert st["invariant_violations"] == 0
    assert {k: v["segments"] for k, v in st["pairs"].items()} == {
        "left-right": 1, "left-far": 1, "right-far": 1}


def _saved_counts(state: bytes) -> dict[tuple[str, str], int]:
    """Each pair's sample count in a separation state file."""
    import msgpack
    from avard.core.io.recording import scan_frames
    from avard.daemon.service.separation_stage import SeparationStage

    rec = msgpack.unpackb(next(iter(scan_frames(state))).payload, raw=False,
                          strict_map_key=False)
    stage = SeparationStage.from_state(rec["state"])
    return {acc.sensors: acc.n_samples for acc in stage.pairs.values()}


def _offline_rows(runs: list[AlignedRun], names: tuple[str, ...]) -> dict[tuple[str, str], int]:
    """The aligned rows each pair of the recordings holds (both sensors present)."""
    return {(names[i], names[j]): sum(int(np.count_nonzero((r.index[i] >= 0)
                                                          & (r.index[j] >= 0))) for r in runs)
            for i, j in PAIRS[len(names)]}


def _last_published(pub: Captured) -> Separation:
    """The last separation the lanes published."""
    live = [separation_of(r) for _t, r in pub.sent if r["kind"] == "avar"
            and "separation" in r][-1]
    assert live is not None
    return live


def _assert_equal_separations(live: Separation, offline: Separation) -> None:
    assert live.n_samples == offline.n_samples
    for x, y in zip(live.axes, offline.axes, strict=True):
        np.testing.assert_array_equal(x.m, y.m)
        for p, q in zip((*x.self_noise, x.common), (*y.self_noise, y.common), strict=True):
            np.testing.assert_array_equal(p.upper_limit, q.upper_limit)
            np.testing.assert_allclose(p.dev, q.dev, rtol=1e-9)       # NaN where limits
            np.testing.assert_allclose(p.hi, q.hi, rtol=1e-9)
            np.testing.assert_allclose(p.lo, q.lo, rtol=1e-9, atol=0)


@pytest.mark.parametrize("kill", [True, False])
def test_a_restart_replays_the_recordings_and_equals_avard_separate(tmp_path: Path,
                                                                     kill: bool) -> None:
    """``kill``: the worst moment, between the lanes' checkpoints and the separation's — the
    lanes' state and recordings reach the end of the first run, the separation's state file
    is its first checkpoint of it (what a kill right before its next one leaves). The restart
    replays the recordings after that state, so the separation published at the end of the
    second run equals ``avard separate`` on the recordings (run by run: the restart is a
    gap) to 1e-9, and every pair holds exactly the aligned rows the recordings hold."""
    root = tmp_path / "rec"
    svc = _rig(_config(root), Captured())
    saved: dict[str, bytes] = {}
    checkpoint = svc.separation.checkpoint

    def keep_first_checkpoint() -> None:
        checkpoint()
        if svc.separation.checkpoints == 1:
            saved["state"] = (root / STATE_FILE).read_bytes()

    svc.separation.checkpoint = keep_first_checkpoint       # type: ignore[method-assign]
    svc.run(90.0)
    held = _saved_counts((root / STATE_FILE).read_bytes())
    if kill:
        (root / STATE_FILE).write_bytes(saved["state"])      # what the kill leaves
        held = _saved_counts(saved["state"])
        assert all(10 * ODR <= n <= 85 * ODR for n in held.values()), held

    pub = Captured()
    again = _rig(_config(root), pub, seed=2)
    again.run(40.0)
    st = again.lanes[0].final_status["separation"]
    assert st["restored"]["state"] == "restored" and st["restored"]["replayed"] is True
    assert st["restored"]["hole_samples"] == {"left": 0, "right": 0, "far": 0}
    assert st["invariant_violations"] == 0
    names = tuple(again.separation.names)
    runs = aligned_runs([read_sensor(root / n) for n in names])
    assert len(runs) == 2
    rows = _offline_rows(runs, names)
    first_run = _offline_rows(runs[:1], names)
    for acc in again.separation.stage.pairs.values():
        key = f"{acc.sensors[0]}-{acc.sensors[1]}"
        assert acc.n_samples == rows[acc.sensors]                   # what the recordings hold
        assert st["restored"]["replayed_rows"][key] == first_run[acc.sensors] - held[
            acc.sensors]
        assert acc.n_segments >= 2                                  # the restart is a gap
    live = _last_published(pub)
    offline = separate_runs(runs, live.rate_hz, sensors=names, axes=("x", "y", "z"))
    _assert_equal_separations(live, offline)
    # `avard separate DATA_DIR` takes the same way for a recording of several runs
    cli = load_and_separate([str(root)])
    assert any("run by run" in n for n in cli.notes) and len(cli.axes[0].fits) == 3
    _assert_equal_separations(live, cli)


def test_a_run_killed_before_its_first_checkpoint_is_replayed_with_the_next_restart(
        tmp_path: Path) -> None:
    """Two restarts: the second run is killed before its first separation checkpoint (its
    state file is still the first run's last), so the third run's restore replays the whole
    second run from the recordings: three runs, each a segment, equal to avard separate."""
    root = tmp_path / "rec"
    _rig(_config(root), Captured()).run(30.0)
    first_state = (root / STATE_FILE).read_bytes()
    _rig(_config(root), Captured(), seed=2).run(20.0)
    (root / STATE_FILE).write_bytes(first_state)             # the kill of the second run
    pub = Captured()
    third = _rig(_config(root), pub, seed=3)
    third.run(20.0)
    st = third.lanes[0].final_status["separation"]
    names = tuple(third.separation.names)
    runs = aligned_runs([read_sensor(root / n) for n in names])
    assert len(runs) == 3 and st["invariant_violations"] == 0
    second = _offline_rows(runs[1:2], names)
    assert st["restored"]["replayed_rows"] == {f"{a}-{b}": n for (a, b), n in second.items()}
    live = _last_published(pub)
    _assert_equal_separations(live, separate_runs(runs, live.rate_hz, sensors=names,
                                                  axes=("x", "y", "z")))


def test_a_state_file_removed_behind_its_back_is_rebuilt_from_the_recordings(
        tmp_path: Path) -> None:
    root = tmp_path / "rec"
    _rig(_config(root), Captured()).run(30.0)
    (root / STATE_FILE).unlink()
    pub = Captured()
    again = _rig(_config(root), pub, seed=2)
    again.run(20.0)
    st = again.lanes[0].final_status["separation"]
    assert st["restored"]["state"] == "rebuilt"
    assert st["restored"]["hole_samples"] == {"left": 0, "right": 0, "far": 0}
    assert st["invariant_violations"] == 0
    names = tuple(again.separation.names)
    runs = aligned_runs([read_sensor(root / n) for n in names])
    live = _last_published(pub)
    _assert_equal_separations(live, separate_runs(runs, live.rate_hz, sensors=names,
                                                  axes=("x", "y", "z")))


def test_a_recording_that_cannot_be_read_is_a_hole_of_its_size(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from avard.daemon.service import rig_separation

    root = tmp_path / "rec"
    _rig(_config(root), Captured()).run(20.0)
    held = _saved_counts((root / STATE_FILE).read_bytes())

    def unreadable(directory: Path, after: int | None, before: int | None = None) -> None:
        raise OSError(5, "Input/output error", str(directory))

    monkeypatch.setattr(rig_separation, "read_tail", unreadable)
    svc = _rig(_config(root), Captured())
    start = {"left": 2600, "right": 2600, "far": 2600}
    svc.separation.restore(start)
    got = svc.separation.restored
    assert got["state"] == "restored" and "Input/output error" in got["replay_error"]
    assert got["replayed"] is False
    assert all(0 < h <= 2600 for h in got["hole_samples"].values()), got
    assert {acc.sensors: acc.n_samples for acc in svc.separation.stage.pairs.values()} == held
    assert svc.separation.violations == 0


def test_a_state_ahead_of_the_recordings_is_dropped(tmp_path: Path) -> None:
    """A state claiming samples beyond where the lanes restored (a crash lost the
    recordings' tail) is dropped; the pairs are rebuilt from what the recordings hold up to
    there, never beyond."""
    root = tmp_path / "rec"
    _rig(_config(root), Captured()).run(20.0)
    svc = _rig(_config(root), Captured())
    svc.separation.restore({"left": 50, "right": 50, "far": 50})
    assert svc.separation.restored["state"] == "dropped"
    assert 40 <= svc.separation.stage.n_samples <= 50
    assert svc.separation.violations == 0


@pytest.mark.parametrize("garbage", [b"", b"\x00" * 40])
def test_an_unreadable_state_starts_afresh(tmp_path: Path, garbage: bytes) -> None:
    root = tmp_path / "rec"
    root.mkdir()
    (root / STATE_FILE).write_bytes(garbage)
    svc = _rig(_config(root), Captured())
    svc.run(5.0)
    assert svc.separation.restored["state"] == "unusable"


def test_a_rig_of_four_separates_its_first_three_and_says_so(tmp_path: Path) -> None:
    sensors = [*SENSORS, {"name": "spi1", "spi_bus": 1}]
    svc = _rig(_config(tmp_path / "rec", sensors), Captured())
    svc.run(5.0)
    st = svc.lanes[3].final_status["separation"]
    assert st["sensors"] == ["left", "right", "far"] and st["left_out"] == ["spi1"]


def test_a_sensor_added_between_runs_starts_the_pairs_afresh(tmp_path: Path) -> None:
    root = tmp_path / "rec"
    _rig(_config(root, SENSORS[:2]), Captured()).run(5.0)
    pub = Captured()
    svc = _rig(_config(root), pub)
    svc.run(5.0)
    assert svc.separation is not None
    assert svc.separation.restored["state"] == "unusable"
    assert "separates ['left', 'right', 'far']" in svc.separation.restored["detail"]
    # avard separate takes the run the three share, as the live separation does (the first
    # run's samples of left and right are not concatenated with the second's)
    live = _last_published(pub)
    cli = load_and_separate([str(root)])
    assert any("run by run (1 run:" in n for n in cli.notes)
    _assert_equal_separations(live, cli)
    z = load_and_separate([str(root)], channels=["z"])          # one axis: the same numbers
    assert [ax.axis for ax in z.axes] == ["z"]
    _assert_equal_separations(replace(live, axes=live.axes[2:]), z)
    with pytest.raises(DataError, match="--channels q"):
        load_and_separate([str(root)], channels=["q"])


def test_the_snapshot_request_keeps_the_last_separation_beside_later_snapshots() -> None:
    from avard.daemon.service.snapshots import SnapshotBoard

    board = SnapshotBoard(lambda _rec: {})
    board.publish({"kind": "avar", "n": 1, "separation": {"tag": 1}})
    board.publish({"kind": "avar", "n": 2})
    got = board.reply()
    assert got is not None and got["n"] == 2 and got["separation"] == {"tag": 1}
    board.publish({"kind": "avar", "n": 3, "separation": {"tag": 2}})
    got = board.reply()
    assert got is not None and got["separation"] == {"tag": 2}
    board.stop()
