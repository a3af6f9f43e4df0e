"""Archive a remote avard stream in the service's own recording format.

Subscribes to every topic of ENDPOINT, fetches the run header from the request socket (or takes
it from the stream), and appends every record to rotating segment files under ``--out`` with
the service's segment writer (daemon/recorder.py): ``avard analyze DIR`` reads the result like
a recording made on the Pi.

Nothing lost passes silently: raw blocks that the network lost (a hole in the sequence numbers
and in the sample indices) are written as ``gap`` records with reason ``subscriber_loss``;
other lost messages as an ``event`` naming the topic and count. Gaps the service itself
announced are recorded as it sent them. A restart of the service (new run id) starts a new
segment with the new header.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

from avard.core import frames
from avard.core.errors import FormatError, NetworkError
from avard.daemon.recorder import Recorder
from avard.daemon.subscriber import Message, Subscriber, add_client_arguments, subscriber_from_args

log = logging.getLogger(__name__)

NAME = "record"
HELP = "archive a remote stream (ENDPOINT) into recording segments, with gaps for what was lost"

#: Records kept while waiting for the header (about 80 s of raw blocks at 125 Hz).
MAX_PENDING = 4096


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_client_arguments(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="recording directory")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="stop after S seconds of wall time (default: until Ctrl-C/SIGTERM)")
    parser.add_argument("--segment", type=float, default=3600.0, metavar="S",
                        help="start a new segment file every S seconds (default 3600)")
    parser.add_argument("--fsync", type=float, default=5.0, metavar="S",
                        help="fsync at most every S seconds (default 5)")
    parser.add_argument("--wait", type=float, default=10.0, metavar="S",
                        help="give up when nothing arrives within S seconds of the start "
                             "(default 10)")


class StreamArchiver:
    """Turns received messages into recorder writes (header first, gaps for losses)."""

    def __init__(self, sub: Subscriber, out: Path, *, segment_s: float, fsync_s: float) -> None:
        self.sub = sub
        self.out = out
        self.segment_s = segment_s
        self.fsync_s = fsync_s
        self.header: dict[str, Any] | None = None
        self.recorder: Recorder | None = None
        self.pending: list[Message] = []
        self.written = 0
        self.dropped_waiting = 0
        self.gaps_written = 0
        self.gap_samples = 0
        self._next_header_try = 0.0

    def _fetch_header(self, run: str) -> None:
        """Ask the request socket for the run's header (at most every 2 s)."""
        now = time.monotonic()
        if now < self._next_header_try or not self.sub.request_endpoint:
            return
        self._next_header_try = now + 2.0
        try:
            hdr = self.sub.request("header")
        except NetworkError as exc:
            log.warning("no header from the request socket yet: %s", exc)
            return
        try:
            frames.validate(hdr)
        except FormatError as exc:
            log.warning("the service's header is not a valid header record: %s", exc)
            return
        if hdr.get("kind") == "header" and hdr.get("run") == run:
            self.header = hdr

    def handle(self, msg: Message) -> None:
        rec = msg.record
        if msg.new_run and self.recorder is not None:
            log.info("the service restarted (run %s); new segment", rec["run"])
            self.recorder.close()
            self.recorder, self.header = None, None
        if msg.new_run:
            self._next_header_try = 0.0  # ask for the new run's header at once
        if rec["kind"] == "header":
            self.header = rec
        if self.header is None:
            self._fetch_header(rec["run"])
        if self.header is None:
            self.pending.append(msg)
            if len(self.pending) > MAX_PENDING:
                self.pending.pop(0)
                self.dropped_waiting += 1
            return
        if self.recorder is None:
            header = self.header
            self.recorder = Recorder(self.out, header["run"], lambda: header,
                                     segment_s=self.segment_s, fsync_interval_s=self.fsync_s)
            waiting, self.pending = self.pending, []
            for m in waiting:
                if m.record["run"] == header["run"]:
                    self._write(m)
        if rec["kind"] != "header":
            self._write(msg)

    def _write(self, msg: Message) -> None:
        assert self.recorder is not None
        rec = msg.record
        if msg.missing is not None:
            i0, n = msg.missing
            self.recorder.write(frames.gap_record(
                rec["run"], 0, i0, n, rec["t_mono"], rec["t_real"], "subscriber_loss",
                lost_messages=msg.lost, topic=msg.topic))
            self.gaps_written += 1
            self.gap_samples += n
        elif msg.lost:
            self.recorder.write(frames.event_record(
                rec["run"], 0, "subscriber_loss", rec.get("t_mono", 0.0),
                rec.get("t_real", 0.0), detail={"topic": msg.topic, "lost_messages": msg.lost}))
        if self.recorder.write(rec):
            self.written += 1

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    sub = subscriber_from_args(args)
    # set by SIGTERM, or by an embedding program/test through ``args.stop_event``
    stop: threading.Event = getattr(args, "stop_event", None) or threading.Event()

    def _stop(signum: int, frame: Any) -> None:
        stop.set()

    # SIGTERM ends the archive cleanly (flushed, closed); only the main thread may set it
    in_main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGTERM, _stop) if in_main else None
    sub.connect(join=False)
    archiver = StreamArchiver(sub, out, segment_s=args.segment, fsync_s=args.fsync)
    start = time.monotonic()
    try:
        while not stop.is_set():
            elapsed = time.monotonic() - start
            if args.duration is not None and elapsed >= args.duration:
                break
            if sub.stats.messages_received == 0 and elapsed >= args.wait:
                raise NetworkError(
                    f"nothing received from {args.endpoint} within {args.wait:g} s; is "
                    "`avard run` publishing there (and is this client's CURVE key authorised)?")
            msg = sub.recv(0.2)
            if msg is not None:
                archiver.handle(msg)
        # what has already arrived is archived too, so stopping never drops received data
        while (msg := sub.recv(0.05)) is not None:
            archiver.handle(msg)
    except KeyboardInterrupt:
        pass
    finally:
        archiver.close()
        sub.close()
        if in_main:
            signal.signal(signal.SIGTERM, old)
    s = sub.stats
    sys.stdout.write(
        f"recorded {archiver.written} records ({s.samples_received} samples) into {out}\n"
        f"lost in transport: {s.messages_lost} messages, {s.samples_lost} samples "
        f"({archiver.gaps_written} gap records)\n"
        f"service gaps: {s.samples_service_gap} samples; unexplained holes: "
        f"{s.samples_unexplained} samples\n")
    if archiver.header is None:
        sys.stdout.write("no header was obtained: nothing could be written (is the request "
                         "socket reachable? see --request)\n")
        return 1
    return 0
