"""Every command that reads a recording or the stream, on a rig of three emulated sensors
(issue 28 item 1): ``--sensor NAME`` picks one, an unknown name is one line with status 2
listing the names, and ``avard separate`` on the rig's recording gives each sensor's
self-noise."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from avard.core.io.source import open_record, rig_sensors
from avard.daemon import cli
from avard.daemon.config import validate_config
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import build_lanes, describe_rig
from avard.daemon.net.subscriber import Subscriber
from avard.daemon.service.rig_service import RigService

from tests.daemon.pubsub import is_probe, wait_until_subscribed

ODR = 125.0
SENSORS = [{"name": "left", "spi_device": 0}, {"name": "right", "spi_device": 1},
           {"name": "far", "bus": "i2c", "i2c_address": 0x53}]
#: long enough for the separation's τ = 1 s to hold a few hundred averages
SECONDS = 300.0


def _rig(data_dir: Path, publish: bool = False, seed: int = 7) -> RigService:
    cfg = validate_config({
        "sensor": SENSORS, "temperature": {"ds18b20": False},
        "recording": {"data_dir": str(data_dir)},
        "publish": {"enabled": publish, "endpoint": "tcp://127.0.0.1:0",
                    "request_endpoint": "tcp://127.0.0.1:0"},
        "allan": {"snapshot_interval_s": 1.0, "checkpoint_interval_s": 60.0}})
    config = Config.from_dict(cfg)
    return RigService(config, build_lanes(describe_rig(config, simulate="quiet-lab",
                                                        seed=seed, speed=None)))


@pytest.fixture(scope="module")
def rig_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("rig") / "rec"
    _rig(root).run(SECONDS)
    return root


def _one_line(err: str, *parts: str) -> None:
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for p in parts:
        assert p in err, err


def test_the_rig_recording_is_one_recording_per_sensor(rig_recording: Path) -> None:
    assert rig_sensors(rig_recording) == ("far", "left", "right")
    assert rig_sensors(rig_recording / "left") == ()
    assert open_record(rig_recording, sensor="far").info.sensor_name == "far"


def test_analyze_takes_one_sensor_and_refuses_the_rest(rig_recording: Path,
                                                       capsys: pytest.CaptureFixture) -> None:
    assert cli.main(["analyze", str(rig_recording), "--sensor", "right", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["sensor"] == "right" and out["source"].endswith("right")
    assert cli.main(["analyze", str(rig_recording)]) == 2
    _one_line(capsys.readouterr().err, "3 sensors (far, left, right)", "--sensor NAME")
    assert cli.main(["analyze", str(rig_recording), "--sensor", "nope"]) == 2
    _one_line(capsys.readouterr().err, "no sensor 'nope'", "far, left, right")
    # a single sensor's recording, named for another sensor
    assert cli.main(["analyze", str(rig_recording / "left"), "--sensor", "far"]) == 2
    _one_line(capsys.readouterr().err, "this record's sensor is left")


def test_explain_takes_one_sensor(rig_recording: Path, capsys: pytest.CaptureFixture) -> None:
    assert cli.main(["explain", str(rig_recording), "--sensor", "nope"]) == 2
    _one_line(capsys.readouterr().err, "far, left, right")


def test_separate_on_the_rig_recording_gives_each_sensors_self_noise(
        rig_recording: Path, capsys: pytest.CaptureFixture) -> None:
    assert cli.main(["separate", str(rig_recording), "--json", "--channels", "z",
                     "--filter-corner", "auto"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["method"] == "three-cornered hat"
    z = d["axes"]["z"]
    assert sorted(z["sensors"]) == ["far", "left", "right"]
    for name in ("far", "left", "right"):
        n_fit = z["sensors"][name]["fit"]["terms"]["velocity_random_walk"]["value"]
        assert n_fit == pytest.approx(1.56e-4, rel=0.15)     # quiet-lab's own N
    # two of them by name: Groslambert's covariance
    assert cli.main(["separate", str(rig_recording), "--sensor", "left", "--sensor", "far",
                     "--json", "--channels", "z"]) == 0
    d2 = json.loads(capsys.readouterr().out)
    assert d2["method"] == "groslambert covariance"
    assert sorted(d2["axes"]["z"]["sensors"]) == ["far", "left"]
    assert cli.main(["separate", str(rig_recording), "--sensor", "nope"]) == 2
    _one_line(capsys.readouterr().err, "--sensor nope", "far, left, right")


def test_web_history_takes_one_sensor(rig_recording: Path, capsys: pytest.CaptureFixture) -> None:
    pytest.importorskip("aiohttp")
    assert cli.main(["web", "tcp://127.0.0.1:5999", "--history", str(rig_recording),
                     "--sensor", "nope"]) == 2
    _one_line(capsys.readouterr().err, "far, left, right")


def test_the_stream_carries_the_sensor_and_record_archives_one(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A subscriber that follows one sensor gets that sensor's records only (topic and field),
    on its own continuous index; `avard record`'s archiver over it writes a recording equal to
    the service's own of that sensor; watch and record refuse an unknown name (status 2)."""
    from avard.core.io.recording import load_recording
    from avard.daemon.commands.record import StreamArchiver

    svc = _rig(tmp_path / "rec", publish=True)
    got: list[Any] = []
    box: dict[str, Any] = {"stop": threading.Event()}

    def before() -> None:
        pub, req = svc.publisher.endpoint, svc.request_server.endpoint
        for cmd in ("watch", "record"):
            extra = ["--once"] if cmd == "watch" else ["--out", str(tmp_path / "x")]
            assert cli.main([cmd, pub, "--request", req, "--sensor", "nope", *extra]) == 2
        said = [ln for ln in capsys.readouterr().err.splitlines() if "--sensor nope" in ln]
        assert len(said) == 2 and all("its sensors are left, right, far" in ln for ln in said)
        sub = Subscriber(pub, request_endpoint=req, sensor="right").connect(join=False)
        box["sub"] = sub
        assert sub.sensors() == ["left", "right", "far"]
        hdr = sub.request("header")                                   # routed by sensor
        assert hdr["sensor"]["name"] == "right" and hdr["sensor_name"] == "right"
        wait_until_subscribed(svc.publisher, sub)
        while sub.recv(0.1) is not None:
            pass
        arch = StreamArchiver(sub, tmp_path / "archive", segment_s=3600.0, fsync_s=5.0)

        def take(m: Any) -> None:
            if not is_probe(m.record):
                got.append(m)
                arch.handle(m)

        def loop() -> None:
            while not box["stop"].is_set():
                if (m := sub.recv(0.1)) is not None:
                    take(m)
            while (m := sub.recv(0.3)) is not None:      # what is still on its way
                take(m)
            arch.close()
            sub.close()

        box["thread"] = threading.Thread(target=loop, daemon=True)
        box["thread"].start()

    try:
        svc.run(20.0, before_acquisition=before)
    finally:
        box["stop"].set()
        if "thread" in box:
            box["thread"].join(60)
    raw = [m for m in got if m.record["kind"] == "raw"]
    assert raw and all(m.topic == "raw.right" for m in raw)
    assert all(m.record["sensor_name"] == "right" for m in got)
    stats = box["sub"].stats
    assert stats.messages_lost == 0 and stats.samples_lost == 0 == stats.samples_unexplained
    # the archive is the sensor's recording, name and samples
    assert open_record(tmp_path / "archive").info.sensor_name == "right"
    ours = load_recording(tmp_path / "archive")
    theirs = load_recording(tmp_path / "rec" / "right")
    assert ours.accel.shape[0] > 15 * ODR
    np.testing.assert_array_equal(ours.accel, theirs.accel[:ours.accel.shape[0]])


def test_a_one_sensor_recording_beside_a_rigs_is_still_read(rig_recording: Path,
                                                            tmp_path: Path) -> None:
    """A data_dir that held a one-sensor recording before the rig was configured: the
    directory is that recording, and --sensor NAME reaches the rig's sensors beside it."""
    import shutil

    root = tmp_path / "data"
    shutil.copytree(rig_recording / "left", root)           # the earlier one-sensor recording
    shutil.copytree(rig_recording / "right", root / "right")
    assert open_record(root).info.sensor_name == "left"
    assert open_record(root, sensor="right").info.sensor_name == "right"
    assert open_record(root, sensor="left").info.sensor_name == "left"
    with pytest.raises(Exception, match="this record's sensor is left"):
        open_record(root, sensor="far")


def test_fleet_by_sensor_takes_a_rigs_sensors(rig_recording: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    from avard.daemon.commands.fleet import _groups
    from avard.daemon.commands.separate import rig_records

    groups = _groups(rig_records([str(rig_recording)], None), "sensor")
    assert {k: [Path(p).name for p in v] for k, v in groups.items()} == {
        "far": ["far"], "left": ["left"], "right": ["right"]}
    some = _groups(rig_records([str(rig_recording)], ["left", "far"]), "sensor")
    assert sorted(some) == ["far", "left"]
    assert cli.main(["fleet", str(rig_recording), "--by", "sensor", "--sensor", "nope"]) == 2
    assert "far, left, right" in capsys.readouterr().err


def test_probe_takes_one_sensor_of_a_rig(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    f = tmp_path / "rig.toml"
    f.write_text('[[sensor]]\nname = "left"\n[[sensor]]\nname = "right"\nspi_device = 1\n')
    assert cli.main(["probe", "--config", str(f), "--emulate", "--no-self-test",
                     "--no-ds18b20", "--seconds", "1", "--sensor", "right"]) == 0
    capsys.readouterr()
    assert cli.main(["probe", "--config", str(f), "--emulate", "--sensor", "nope"]) == 2
    _one_line(capsys.readouterr().err, "--sensor nope", "its sensors are left, right")
    assert cli.main(["probe", "--config", str(f), "--emulate"]) == 2
    _one_line(capsys.readouterr().err, "probe one at a time with --sensor NAME")


def test_watch_says_which_sensor_it_shows() -> None:
    from avard.daemon.commands.watch import WatchView
    from avard.daemon.net.subscriber import Message, StreamStats

    view = WatchView()
    view.update(Message("status.right", {"kind": "status", "run": "r", "seq": 0,
                                         "sensor_name": "right", "status": {}}))
    assert "run r  sensor right  (SI units)" in view.render(StreamStats(), "tcp://h:1")
