"""Every command that reads a recording or the stream, on a rig of three emulated sensors
(issue 28 item 1): ``--sensor NAME`` picks one, an unknown name is one line with status 2
listing the names, and ``avard separate`` on the rig's recording gives each sensor's
self-noise."""

from __future__ import annotations

import itertools
import json
import threading
from pathlib import Path
from typing import Any

import pytest
from avard.core.errors import ConfigError
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


def test_the_stream_carries_the_sensor_and_a_subscriber_follows_one(tmp_path: Path) -> None:
    svc = _rig(tmp_path / "rec", publish=True)
    got: list[Any] = []
    sub: Subscriber | None = None
    ready = threading.Event()

    def before() -> None:
        nonlocal sub
        pub, req = svc.publisher.endpoint, svc.request_server.endpoint
        sub = Subscriber(pub, request_endpoint=req, sensor="right").connect(join=False)
        assert sub.sensors() == ["left", "right", "far"]
        with pytest.raises(ConfigError, match="its sensors are left, right, far"):
            Subscriber(pub, request_endpoint=req, sensor="nope").pick_sensor()
        hdr = sub.request("header")                                   # routed by sensor
        assert hdr["sensor"]["name"] == "right" and hdr["sensor_name"] == "right"
        wait_until_subscribed(svc.publisher, sub)
        ready.set()

    worker = threading.Thread(target=svc.run, args=(20.0,),
                              kwargs={"before_acquisition": before})
    worker.start()
    assert ready.wait(60)
    worker.join(120)
    assert sub is not None
    while (m := sub.recv(1.0)) is not None:
        if not is_probe(m.record):
            got.append(m)
    raw = [m for m in got if m.record["kind"] == "raw"]
    assert raw and all(m.topic == "raw.right" for m in raw)
    assert all(m.record["sensor_name"] == "right" for m in got)
    # one sensor's own index: continuous, nothing counted lost or unexplained
    assert sub.stats.samples_unexplained == 0
    idx = [(m.record["i0"], m.record["n"]) for m in raw]
    assert all(a + n == b for (a, n), (b, _) in itertools.pairwise(idx))
    sub.close()


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
