"""A client of a rig's stream never mixes its sensors (issue 28 item 1's review):
with no sensor chosen it follows one, and the archiver refuses another sensor's record."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from avard.core.io import frames
from avard.core.io.recording import RecordingReader
from avard.daemon.net.subscriber import Message

# -- 1. a client with no sensor chosen never mixes a rig's sensors -----------------------------

def test_a_subscriber_with_no_sensor_follows_the_first_one_seen_never_a_mix() -> None:
    """The request socket was not up when the client started (so no sensor was picked): the
    stream is still one sensor's, the first whose topic arrived, and that choice is kept."""
    from avard.daemon.net.publisher import Publisher
    from avard.daemon.net.subscriber import Subscriber, check_stream_sensor
    from avard.daemon.service.rig_service import SensorPublisher

    from tests.daemon.pubsub import is_probe, wait_until_subscribed

    pub = Publisher("tcp://127.0.0.1:0", "run1", hwm=1000)
    sub = Subscriber(pub.endpoint, request_endpoint="tcp://127.0.0.1:1", request_timeout_s=0.2)
    try:
        check_stream_sensor(sub)
        assert sub.sensor is None
        sub.connect(join=False)
        wait_until_subscribed(pub, sub)
        for name in ("right", "left", "right", "left"):
            SensorPublisher(pub, name).publish(None, frames.event_record(
                "run1", 0, "mark", 0.0, 0.0, i0=0, detail={}))
        got = []
        while (m := sub.recv(0.5)) is not None:
            if not is_probe(m.record):
                got.append((m.topic, m.record["sensor_name"]))
        assert got == [("event.right", "right")] * 2
        assert sub.sensor == "right"
    finally:
        sub.close()
        pub.close()


def _rig_header(run: str, name: str) -> dict[str, Any]:
    return {**frames.header_record(run, rate_hz=125.0, t_mono=0.0, t_real=1.7e9,
                                   scale_m_s2_per_count=3.8e-5, range_g=2.0,
                                   sensor={"name": name}, software="test"),
            "sensor_name": name}


def _rig_raw(run: str, seq: int, i0: int, name: str) -> dict[str, Any]:
    rec = frames.raw_record(run, seq, i0, np.full((32, 3), seq, dtype=np.int32),
                            i0 / 125.0, 1.7e9 + i0 / 125.0)
    return {**rec, "sensor_name": name}


def test_the_archiver_refuses_another_sensors_record_and_counts_it(tmp_path: Path) -> None:
    """One recording is one sensor's index: a record whose sensor_name is not the header's
    sensor is not written (counted and said), whatever let it through."""
    from avard.daemon.commands.record import StreamArchiver

    sub: Any = SimpleNamespace(request_endpoint=None, sensor="left")
    out = tmp_path / "archive"
    arch = StreamArchiver(sub, out, segment_s=3600.0, fsync_s=5.0)
    arch.handle(Message("header.left", _rig_header("r1", "left"), new_run=True))
    arch.handle(Message("raw.left", _rig_raw("r1", 0, 0, "left")))
    arch.handle(Message("raw.right", _rig_raw("r1", 0, 0, "right")))
    arch.handle(Message("header.right", _rig_header("r1", "right")))
    arch.handle(Message("raw.left", _rig_raw("r1", 1, 32, "left")))
    arch.close()
    raws = [r for r in RecordingReader(out) if r["kind"] == "raw"]
    assert [(r["i0"], r["sensor_name"]) for r in raws] == [(0, "left"), (32, "left")]
    assert arch.other_sensor == 2
    assert arch.written == 2
    assert arch.header is not None and arch.header["sensor"]["name"] == "left"


def test_the_archiver_asks_for_the_sensors_again_when_it_fetches_the_header(
        tmp_path: Path) -> None:
    """The service came up after the command started: the header fetch picks the sensor first,
    so the header asked for is that sensor's."""
    from avard.daemon.commands.record import StreamArchiver

    asked: list[tuple[str, str | None]] = []

    class Sub:
        request_endpoint = "tcp://127.0.0.1:1"
        sensor: str | None = None

        def pick_sensor(self) -> None:
            asked.append(("pick", self.sensor))
            self.sensor = "left"

        def request(self, op: str, args: Any = None) -> dict[str, Any]:
            asked.append((op, self.sensor))
            return _rig_header("r1", str(self.sensor))

    arch = StreamArchiver(Sub(), tmp_path / "archive", segment_s=3600.0,  # type: ignore[arg-type]
                          fsync_s=5.0)
    arch.handle(Message("raw.left", _rig_raw("r1", 0, 0, "left"), new_run=True))
    arch.close()
    assert asked == [("pick", None), ("header", "left")]
    assert arch.written == 1
