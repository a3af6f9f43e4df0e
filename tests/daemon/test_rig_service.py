"""Several sensors in one service (issue 28 item 1): ``[[sensor]]`` entries, one lane per
sensor recording into DATA_DIR/NAME, one reader per bus, the alignment recorded; and the
adversary's cases: two sensors with one name or one chip select, a sensor that stops answering
while the others run, a restart with a sensor added and one removed."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.errors import ConfigError
from avard.core.io.source import RecordingSource, open_record
from avard.daemon.commands.check_config import to_toml
from avard.daemon.config import load_config, validate_config
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import build_lanes, describe_rig
from avard.daemon.service.rig_service import RigService

ODR = 125.0
LEFT = {"name": "left", "spi_device": 0}
RIGHT = {"name": "right", "spi_device": 1}
FAR = {"name": "far", "bus": "i2c", "i2c_address": 0x53}
SPI1 = {"name": "spi1", "spi_bus": 1}


def _config(tmp_path: Path, sensors: list[dict[str, Any]]) -> Config:
    return Config.from_dict(validate_config({
        "sensor": sensors,
        "temperature": {"ds18b20": False},
        "recording": {"data_dir": str(tmp_path / "rec")},
        "publish": {"enabled": False},
        "allan": {"snapshot_interval_s": 5.0, "checkpoint_interval_s": 10.0},
    }))


def _rig(config: Config, *, seed: int = 1, tick: Any = None) -> RigService:
    spec = describe_rig(config, simulate="quiet-lab", seed=seed, speed=None)
    built = build_lanes(spec)
    if tick is not None:
        lanes = list(built.lanes)
        lanes[0] = dataclasses.replace(lanes[0], on_tick=tick)
        built = dataclasses.replace(built, lanes=tuple(lanes))
    return RigService(config, built)


def _events(path: Path, name: str) -> list[dict[str, Any]]:
    return [r for r in RecordingSource(path).records()
            if r["kind"] == "event" and r.get("name") == name]


# -- the config ---------------------------------------------------------------------------------

def test_sensor_entries_are_checked_like_the_sensor_table(tmp_path: Path) -> None:
    cfg = validate_config({"sensor": [LEFT, RIGHT, FAR, SPI1]})
    c = Config.from_dict(cfg)
    assert [s.name for s in c.rig_sensors] == ["left", "right", "far", "spi1"]
    assert c.sensor.name == "left" and c.rig_sensors[2].i2c_address == 0x53
    assert c.rig_sensors[3].spi_bus == 1 and c.rig_sensors[1].odr_hz == ODR
    # --show prints [[sensor]] tables that read back to the same config
    again = tmp_path / "again.toml"
    again.write_text(to_toml(cfg))
    assert "[[sensor]]" in again.read_text()
    assert load_config(again) == cfg


def test_one_sensor_entry_is_todays_sensor_table() -> None:
    one = Config.from_dict(validate_config({"sensor": [{"name": "a", "odr_hz": 250}]}))
    table = Config.from_dict(validate_config({"sensor": {"name": "a", "odr_hz": 250}}))
    assert one.sensor == table.sensor and one.rig_sensors == table.rig_sensors
    assert "sensors" not in table.as_dict()      # today's form stores what it stored


@pytest.mark.parametrize(("sensors", "said"), [
    ([LEFT, {**RIGHT, "name": "left"}], "left is used twice"),
    ([LEFT, {**RIGHT, "spi_device": 0}], r"left and right are both on /dev/spidev0\.0"),
    ([FAR, {**LEFT, "bus": "i2c", "i2c_address": 0x53}],
     r"far and left are both on /dev/i2c-1 address 0x53"),
    ([LEFT, {"spi_device": 1}], "several sensors need a name each"),
    ([LEFT, {**RIGHT, "name": ".."}], "not '.' or '..'"),
    ([LEFT, {**RIGHT, "odr": 125}], r"sensor #2\.odr: unknown key"),
    ([LEFT, {**RIGHT, "range_g": 3}], r"sensor #2\.range_g = 3: out of range"),
])
def test_a_bad_rig_is_refused_at_config_check(sensors: list[dict[str, Any]], said: str) -> None:
    with pytest.raises(ConfigError, match=said):
        validate_config({"sensor": sensors})


def test_a_rig_config_file_reads(tmp_path: Path) -> None:
    f = tmp_path / "rig.toml"
    f.write_text('[[sensor]]\nname = "left"\n[[sensor]]\nname = "right"\nspi_device = 1\n'
                 'sync = "external"\n')
    raw = tomllib.loads(f.read_text())
    assert isinstance(raw["sensor"], list)
    c = Config.from_dict(load_config(f))
    assert [s.sync for s in c.rig_sensors] == ["none", "external"]


# -- the service --------------------------------------------------------------------------------

def test_three_sensors_each_on_its_own_index_and_recording(tmp_path: Path) -> None:
    config = _config(tmp_path, [LEFT, RIGHT, FAR])
    svc = _rig(config)
    assert len(svc.readers) == 0 and len(svc.built.readers) == 1   # a virtual clock: one
    svc.run(30.0)
    root = tmp_path / "rec"
    assert sorted(p.name for p in root.iterdir() if p.is_dir()) == ["far", "left", "right"]
    assert (root / "separation-state.ckpt").is_file()      # the live separation's state
    runs = set()
    for lane in svc.lanes:
        info = open_record(root / lane.sensor_name).info
        assert info.sensor_name == lane.sensor_name
        assert info.recording is not None and not info.recording.losses
        (run,) = info.recording.runs
        runs.add(run.run)
        assert abs(run.n_samples - 30 * ODR) <= 64 and run.samples_lost == 0
        hdr = next(r for r in RecordingSource(root / lane.sensor_name).records()
                   if r["kind"] == "header")
        assert hdr["rig"]["sensors"] == ["left", "right", "far"]
        assert hdr["rig"]["index"] == svc.names.index(lane.sensor_name)
        # the alignment is each sensor's own record of where it stands against the reference
        al = _events(root / lane.sensor_name, "alignment")
        assert al, lane.sensor_name
        detail = al[-1]["detail"]
        assert detail["reference"] == "left" and detail["sync"] == "none"
        # one virtual clock, no rate error: the parts started measuring a few ms apart
        # (each bring-up's reset waits on the clock): the fitted offsets hold that truth
        # within their stated uncertainty
        starts = [e._t_start for e in svc.built.parts["emulators"]]
        for s, t in zip(detail["sensors"], starts, strict=True):
            truth = -(t - starts[0]) * ODR
            assert abs(s["index_offset"] - truth) <= s["offset_u_samples"], (s, truth)
            assert s["offset_u_samples"] < 1.0
    assert len(runs) == 1                                   # one run id for the rig


def test_a_sensor_that_stops_answering_is_its_own_gap(tmp_path: Path) -> None:
    config = _config(tmp_path, [LEFT, RIGHT, FAR])
    emus: list[Any] = []
    t0: list[float] = []

    def tick(t: float) -> None:       # the reader's tick: "right" stalls for 10 s of 40
        if not t0:
            t0.append(t)
        emu = emus[0]
        if 10.0 <= t - t0[0] < 20.0 and not emu.stalled:
            emu.stop_producing()
        elif t - t0[0] >= 20.0 and emu.stalled:
            emu.resume_producing()

    svc = _rig(config, tick=tick)
    emus.append(svc.built.parts["emulators"][1])         # the emulator of "right"
    svc.run(40.0)
    root = tmp_path / "rec"
    runs = {lane.sensor_name: open_record(root / lane.sensor_name).info.recording
            for lane in svc.lanes}
    for name in ("left", "far"):                       # the others went on, whole
        rec = runs[name]
        assert rec is not None and not rec.gaps and not rec.losses
        assert abs(rec.runs[0].n_samples - 40 * ODR) <= 64
        assert not _events(root / name, "stalled")
    right = runs["right"]
    assert right is not None and not right.losses
    assert _events(root / "right", "stalled") and _events(root / "right", "resumed")
    # its loss is its own: gaps in its recording only (segment ends for its accumulators)
    assert right.gaps
    have, counted = right.runs[0].n_samples, sum(g.n for g in right.gaps)
    assert have == pytest.approx(30 * ODR, abs=64)
    # the stall is one gap sized by time once it resumes, so the index stays beside the
    # others'; whatever it is off by, the alignment (fitted time bases) says so
    behind = runs["left"].runs[0].n_samples - (have + counted)   # type: ignore[union-attr]
    offset = _events(root / "left", "alignment")[-1]["detail"]["sensors"][1]
    assert offset["name"] == "right"
    assert offset["index_offset"] == pytest.approx(-behind, abs=3)
    assert abs(offset["odr_hz"] - ODR) < 0.1      # its rate fit survived the stall


def test_a_sensor_added_then_one_removed_keeps_each_sensors_record(tmp_path: Path) -> None:
    root = tmp_path / "rec"
    first = _rig(_config(tmp_path, [LEFT, RIGHT]), seed=1)
    first.run(20.0)
    second = _rig(_config(tmp_path, [LEFT, RIGHT, FAR]), seed=2)
    second.run(20.0)
    third = _rig(_config(tmp_path, [LEFT, FAR]), seed=3)
    third.run(20.0)
    assert first.run_id < second.run_id < third.run_id
    expect_runs = {"left": 3, "right": 2, "far": 2}
    for name, n_runs in expect_runs.items():
        rec = open_record(root / name).info.recording
        assert rec is not None and len(rec.runs) == n_runs, name
        assert not rec.losses
        assert not _events(root / name, "invariant_violated")
    # the accumulators of a sensor that went on were restored, of the new one started afresh
    # (the service checks at every checkpoint that they hold what the recording holds: no
    # invariant_violated event above)
    lanes = {lane.sensor_name: lane for lane in third.lanes}
    assert lanes["left"].restored is not None and lanes["far"].restored is not None
    assert lanes["left"].start_index > 2 * 20 * ODR - 64     # its index went on from run 2
    far = {lane.sensor_name: lane for lane in second.lanes}["far"]
    assert far.restored is None
    # a removed sensor's recording is left as it was
    right_files = sorted((root / "right").glob("*.avr"))
    assert len({f.name.split("_")[0] for f in right_files}) == 2
    assert np.all([f.stat().st_size > 0 for f in right_files])


def test_sighup_reopens_every_sensors_recording(tmp_path: Path) -> None:
    import signal

    svc = _rig(_config(tmp_path, [LEFT, RIGHT]))
    svc._handle_signals([signal.SIGHUP])
    assert all(lane.reopen_requested.is_set() for lane in svc.lanes)
    assert not svc.stop_requested.is_set()
    svc._handle_signals([signal.SIGTERM])
    assert svc.stop_requested.is_set()


def test_a_subscriber_of_one_sensor_never_gets_a_sensor_whose_name_it_prefixes() -> None:
    """ZeroMQ subscribes by prefix: raw.left would also match raw.left2."""
    from avard.core.io import frames
    from avard.daemon.net.publisher import Publisher
    from avard.daemon.net.subscriber import Subscriber
    from avard.daemon.service.rig_service import SensorPublisher

    from tests.daemon.pubsub import is_probe, wait_until_subscribed

    pub = Publisher("tcp://127.0.0.1:0", "run1", hwm=1000)
    sub = Subscriber(pub.endpoint, sensor="left").connect(join=False)
    try:
        wait_until_subscribed(pub, sub)
        for name in ("left2", "left", "lef", "left2", "left"):
            SensorPublisher(pub, name).publish(None, frames.event_record(
                "run1", 0, "mark", 0.0, 0.0, i0=0, detail={"from": name}))
        got = []
        while (m := sub.recv(0.5)) is not None:
            if not is_probe(m.record):
                got.append((m.topic, m.record["sensor_name"], m.record["detail"]["from"]))
        assert got == [("event.left", "left", "left")] * 2
        assert sub.stats.topics["event.left"].lost == 0      # seq counts per sensor's topic
    finally:
        sub.close()
        pub.close()


def test_one_reader_per_bus_on_hardware(monkeypatch: pytest.MonkeyPatch) -> None:
    """SPI0's two chip selects share a reader; SPI1 and I2C have their own (the parts here are
    emulated behind the hardware path's opener: only the grouping is under test)."""
    from avard.daemon.hw import rig as rig_mod

    monkeypatch.setattr(rig_mod, "_open_hardware", lambda s: rig_mod._still(s, 0.0))
    monkeypatch.setattr(rig_mod, "_ds18b20_bank", lambda t: None)
    config = Config.from_dict(validate_config({"sensor": [LEFT, RIGHT, SPI1, FAR]}))
    built = build_lanes(describe_rig(config), reader_process=False)
    assert built.readers == ((0, 1), (2,), (3,))
    assert [lane.info["wiring"] for lane in built.lanes] == [
        "/dev/spidev0.0", "/dev/spidev0.1", "/dev/spidev1.0", "/dev/i2c-1 address 0x53"]
    # by default each bus is drained by a reader process of its own, its parts in turn
    procs: list[Any] = []

    class FakeProcess:
        pid = 4242

        def __init__(self, chips: list[Any]) -> None:
            self.chips = [c.name for c in chips]
            procs.append(self)

        def source(self, k: int) -> tuple[str, int]:
            return ("source", k)

        def close(self) -> None:
            pass

    monkeypatch.setattr(rig_mod, "_bus_process", lambda chips, spec: FakeProcess(chips))
    built = build_lanes(describe_rig(config))
    assert [p.chips for p in procs] == [["left", "right"], ["spi1"], ["far"]]
    assert built.readers == ((0, 1), (2,), (3,))
    assert [lane.sensor for lane in built.lanes] == [("source", 0), ("source", 1),
                                                      ("source", 0), ("source", 0)]
    assert all(lane.info["reader"] == "process 4242" for lane in built.lanes)


def test_one_sensor_entry_runs_todays_service_in_data_dir_itself(tmp_path: Path) -> None:
    from avard.daemon.compose import compose_rig
    from avard.daemon.service.supervisor import Service

    config = _config(tmp_path, [{**RIGHT}])
    svc = compose_rig(config, describe_rig(config, simulate="quiet-lab", seed=1, speed=None))
    assert type(svc) is Service
    svc.run(10.0)
    root = tmp_path / "rec"
    assert list(root.glob("*.avr")) and not [p for p in root.iterdir() if p.is_dir()]
    assert open_record(root).info.sensor_name == "right"


def test_a_lane_refused_at_start_leaves_no_run_in_the_other_lanes(tmp_path: Path) -> None:
    """Lanes started one after another, each checking its own recorded rate: with ``right``
    holding a 250 Hz recording, the rig at 125 Hz was refused only once ``left`` had started
    and written a run. Every lane's lock and rate are now checked before any lane starts;
    nothing is left held."""
    from avard.core.io.recording import RecordingReader
    from avard.daemon.service import dirlock

    rec = tmp_path / "rec"
    _rig(_config(tmp_path, [{**LEFT, "odr_hz": 250}, {**RIGHT, "odr_hz": 250}])).run(2.0)
    (rec / "right").rename(tmp_path / "right250")
    for p in (rec / "left").iterdir():
        p.unlink()
    _rig(_config(tmp_path, [LEFT, RIGHT])).run(2.0)       # left now at 125 Hz
    for p in (rec / "right").iterdir():
        p.unlink()
    (rec / "right").rmdir()
    (tmp_path / "right250").rename(rec / "right")
    before = sorted(p.name for p in (rec / "left").iterdir())
    runs = {r["run"] for r in RecordingReader(rec / "left")}
    with pytest.raises(ConfigError, match=r"/right' holds a recording at a nominal 250 Hz"):
        _rig(_config(tmp_path, [LEFT, RIGHT])).run(2.0)
    assert sorted(p.name for p in (rec / "left").iterdir()) == before
    assert {r["run"] for r in RecordingReader(rec / "left")} == runs
    assert dirlock._held == {}


def test_avard_run_of_a_rig_beside_a_service_on_one_lane_stops_before_opening_a_sensor(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """``avard run`` locked only ``data_dir`` before building the rig; each lane's
    ``data_dir/NAME`` was locked when the lane started, after every sensor had been opened
    and reset: a rig started beside a one-sensor service on ``data_dir/left`` reset that
    service's sensor before it was refused. Every lane's directory is now locked first."""
    import subprocess
    import sys

    from avard.daemon import cli
    from avard.daemon.commands import run as run_cmd

    rec = tmp_path / "rec"
    conf = tmp_path / "rig.toml"
    conf.write_text(
        '[[sensor]]\nname = "left"\nspi_device = 0\n'
        '[[sensor]]\nname = "right"\nspi_device = 1\n'
        f'[temperature]\nds18b20 = false\n[recording]\ndata_dir = "{rec}"\n'
        '[publish]\nenabled = false\n')
    built: list[object] = []
    build = run_cmd.build
    monkeypatch.setattr(run_cmd, "build", lambda *a, **k: built.append(a) or build(*a, **k))
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys\nfrom avard.daemon.service import dirlock\n"
         "dirlock.hold(sys.argv[1]); print('held', flush=True); sys.stdin.read()",
         str(rec / "left")], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        status = cli.main(["run", "--config", str(conf), "--simulate", "quiet-lab",
                           "--speed", "0", "--duration", "2"])
    finally:
        holder.communicate("")
    err = capsys.readouterr().err
    assert status == 2, err
    assert built == []                       # no sensor was opened
    said = [line for line in err.splitlines() if "another avard process" in line]
    assert len(said) == 1 and f"(pid {holder.pid})" in said[0] and "/left'" in said[0], err
    assert "Traceback" not in err
