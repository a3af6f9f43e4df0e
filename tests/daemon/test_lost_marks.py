"""Marks the ring dropped before a worker read them (its mark queue overflowed) are no longer
only counted: the recorder writes a ``marks_lost`` event and a zero-length ``marks_lost`` gap
before the next sample, and the Allan feed ends its segment there, so the live accumulators
and every reader of the recording break at the same place (#16 item 9)."""

from __future__ import annotations

import threading
from types import SimpleNamespace
from typing import Any

import numpy as np
from avard.core.allan.feed import AllanFeed
from avard.core.io import frames
from avard.daemon.service.allan_stage import AllanStage
from avard.daemon.service.header import RunHeader
from avard.daemon.service.recorder_stage import RecorderStage
from avard.daemon.service.ring import Ring


class Sink:
    def __init__(self) -> None:
        self.gaps = 0
        self.n = 0

    def update(self, block: np.ndarray) -> None:
        self.n += len(block)

    def gap(self) -> None:
        self.gaps += 1


class Written:
    def __init__(self) -> None:
        self.records: list[dict[str, Any]] = []

    def write(self, rec: dict[str, Any]) -> bool:
        self.records.append(rec)
        return True

    def flush(self) -> bool:
        return True


def _header() -> RunHeader:
    return RunHeader(lambda: {"kind": "header", "run": "run"},
                     SimpleNamespace(odr_hz=125.0), lambda: 0.0,  # type: ignore[arg-type]
                     lambda: 0, lambda: 0.0)


def _fill(ring: Ring) -> None:
    ring.push(np.ones((10, 3), np.int32), np.arange(10), np.arange(10) / 125.0)
    for k in range(6):      # more marks than the queue holds: the first two are dropped
        ring.mark(frames.temp_record("run", 0, 10, ["chip"], [20.0 + k], 0.0, 0.0))
    ring.push(np.ones((10, 3), np.int32), np.arange(10, 20), np.arange(10, 20) / 125.0)


def test_the_recorder_writes_an_event_and_a_gap_note_for_lost_marks() -> None:
    ring = Ring(100, mark_capacity=4)
    consumer = ring.consumer("recorder")
    out = Written()
    worker = RecorderStage(consumer, out, run_id="run", real_offset=0.0,
                           rate_hz=lambda: 125.0, real_now=lambda: 1.0, header=_header(),
                           checkpoint_written=lambda rec: None, reopen=threading.Event(),
                           block_samples=1000)
    _fill(ring)
    chunk = consumer.read()
    assert chunk.lost_marks == 2
    worker.handle(chunk)
    worker._flush()
    kinds = [(r["kind"], r.get("name") or r.get("reason")) for r in out.records]
    assert kinds[:2] == [("event", "marks_lost"), ("gap", "marks_lost")]
    assert out.records[0]["detail"] == {"count": 2, "consumer": "recorder"}
    assert out.records[1]["i0"] == 0 and out.records[1]["n"] == 0
    assert sum(r["kind"] == "temp" for r in out.records) == 4


def test_the_allan_feed_ends_its_segment_at_lost_marks() -> None:
    ring = Ring(100, mark_capacity=4)
    consumer = ring.consumer("allan")
    sink = Sink()
    feed = AllanFeed(sink, 1.0, [])
    ring.push(np.ones((10, 3), np.int32), np.arange(10), np.arange(10) / 125.0)
    worker = AllanStage(consumer, sink, feed, run_id="run", real_offset=0.0,
                        rate_hz=lambda: 125.0, emit=ring.mark, on_checkpoint=None,
                        snapshot_interval_s=1e9, checkpoint_interval_s=1e9)
    worker.handle(consumer.read())
    assert sink.n == 10 and sink.gaps == 0
    for k in range(6):
        ring.mark(frames.temp_record("run", 0, 10, ["chip"], [20.0 + k], 0.0, 0.0))
    ring.push(np.ones((10, 3), np.int32), np.arange(10, 20), np.arange(10, 20) / 125.0)
    chunk = consumer.read()
    assert chunk.lost_marks == 2
    worker.handle(chunk)
    assert sink.n == 20 and sink.gaps == 1
