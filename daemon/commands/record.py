"""Archive a remote avard stream in the service's own recording format.

Subscribes to every topic of ENDPOINT, fetches the run header from the request socket (or takes
it from the stream), and appends every record to rotating segment files under ``--out`` with
the service's segment writer (daemon/service/recorder.py): ``avard analyze DIR`` reads the
result like
a recording made on the Pi.

Nothing lost passes silently: raw blocks that the network lost (a hole in the sequence numbers
and in the sample indices) are first asked back from the service's ring buffer (request
``recent``); what the ring still holds is written as raw records, the rest as ``gap`` records
with reason ``subscriber_loss`` (``--no-backfill``: gaps only). Other lost messages become an
``event`` naming the topic and count. Gaps the service itself
announced are recorded as it sent them. A restart of the service (new run id) starts a new
segment with the new header; a restart at another output data rate ends the archive (status
2, what was written stays): one recording directory holds one rate, as the service keeps
it. ``--out`` is locked as the service locks its data directory (dirlock.py): one writer.
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

import numpy as np
from avard.core.allan.feed import nominal_of
from avard.core.allan.streaming import AllanSnapshot
from avard.core.errors import ConfigError, FormatError, NetworkError, OutputError
from avard.core.io import frames
from avard.core.io.outputs import check_output_dir
from avard.daemon.commands._options import check_seconds
from avard.daemon.net.subscriber import (
    Message,
    Subscriber,
    add_client_arguments,
    check_stream_sensor,
    subscriber_from_args,
)
from avard.daemon.service import dirlock
from avard.daemon.service.recorder import Recorder, rate_conflict

log = logging.getLogger(__name__)

NAME = "record"
#: INFO lines by default: a long-running command says what it does as it goes
NARRATES = True
HELP = "archive a remote stream (ENDPOINT) into recording segments, with gaps for what was lost"

#: Records kept while waiting for the header (~40 s of the service's ≤ 100 raw blocks/s).
MAX_PENDING = 4096
#: Longest stretch asked back from the service's ring after a loss: the service's default
#: ``[publish] recent_max_s`` (a service that allows less refuses, and the loss stays a gap).
MAX_BACKFILL_S = 10.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_client_arguments(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="recording directory")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="stop after S seconds of wall time (default: until Ctrl-C/SIGTERM)")
    parser.add_argument("--segment", type=float, default=3600.0, metavar="S",
                        help="start a new segment file every S seconds (default 3600)")
    parser.add_argument("--fsync", type=float, default=5.0, metavar="S",
                        help="fsync at most every S seconds (default 5)")
    parser.add_argument("--no-backfill", action="store_true",
                        help="do not ask the service's ring for samples lost in transport "
                             "(they are then only recorded as gaps)")
    parser.add_argument("--wait", type=float, default=10.0, metavar="S",
                        help="give up when nothing arrives within S seconds of the start "
                             "(default 10)")


class StreamArchiver:
    """Turns received messages into recorder writes (header first, gaps for losses)."""

    def __init__(self, sub: Subscriber, out: Path, *, segment_s: float, fsync_s: float,
                 backfill: bool = True) -> None:
        self.sub = sub
        self.backfill = backfill
        self.recovered_samples = 0
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
        #: records of another sensor than the header's (a rig's): refused, counted, said
        self.other_sensor = 0
        self._next_header_try = 0.0

    def _fetch_header(self, run: str) -> None:
        """Ask the request socket for the run's header (at most every 2 s)."""
        now = time.monotonic()
        if now < self._next_header_try or not self.sub.request_endpoint:
            return
        self._next_header_try = now + 2.0
        if self.sub.sensor is None:
            try:       # the service may not have been up when the command started
                self.sub.pick_sensor()
            except NetworkError as exc:
                log.warning("could not ask for the service's sensors: %s", exc)
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
            if self.header is not None and not self._same_sensor(rec):
                return          # another sensor's header never becomes this archive's
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
            self._check_rate(header)
            self.recorder = Recorder(self.out, header["run"], lambda: header,
                                     segment_s=self.segment_s, fsync_interval_s=self.fsync_s)
            waiting, self.pending = self.pending, []
            for m in waiting:
                if m.record["run"] == header["run"]:
                    self._write(m)
                else:  # an earlier run whose header never came
                    self.dropped_waiting += 1
        if rec["kind"] != "header":
            self._write(msg)

    def _check_rate(self, header: dict[str, Any]) -> None:
        """One recording directory holds one output data rate, as the service keeps it
        (``Service._check_recorded_rate``): a run at another ODR in ``--out`` made a record
        that ``avard analyze`` refuses as a whole. Checked before each run's first segment,
        so a service restarted at another rate mid-archive ends the archive (what is written
        stays) with one line, instead of mixing rates."""
        nominal = nominal_of(header)
        got = rate_conflict(self.out, nominal)
        if got is None:
            return
        run, had = got
        raise ConfigError(
            f"--out {str(self.out)!r} holds a recording at a nominal {had:g} Hz (run {run}) "
            f"and the stream's run {header.get('run')} is at {nominal:g} Hz: one recording "
            "directory holds one output data rate; archive this rate into another directory "
            "(--out); nothing of that run was written")

    def _write(self, msg: Message) -> None:
        assert self.recorder is not None
        rec = msg.record
        if not self._same_sensor(rec):
            return
        if msg.missing:
            for i0, n in msg.missing:
                for r in self._recover(msg, i0, n):
                    self.recorder.write(r)
        elif msg.lost:
            self.recorder.write(frames.event_record(
                rec["run"], 0, "subscriber_loss", rec.get("t_mono", 0.0),
                rec.get("t_real", 0.0), detail={"topic": msg.topic, "lost_messages": msg.lost}))
        if rec["kind"] == "avar" and not self._decodes(rec):
            return
        if self.recorder.write(rec):
            self.written += 1

    def _same_sensor(self, rec: dict[str, Any]) -> bool:
        """A rig's record belongs in this archive only when it is the header's sensor's: one
        recording is one sensor's sample index. Another's is refused and counted."""
        name = rec.get("sensor_name")
        if name is None:
            return True
        want = ((self.header or {}).get("sensor") or {}).get("name")
        if name == want:
            return True
        self.other_sensor += 1
        if self.other_sensor == 1:
            log.warning("a record of sensor %s in the stream of %s's header: not archived "
                        "(one recording is one sensor's; pick one with --sensor NAME)",
                        name, want)
        return False

    def _decodes(self, rec: dict[str, Any]) -> bool:
        """An ``avar`` record's snapshot read by the one decoder (as watch and web read it);
        one that does not decode is archived as an ``unreadable_snapshot`` event instead, so
        the recording never holds a snapshot its readers would refuse."""
        try:
            AllanSnapshot.from_dict(rec.get("snapshot"))
            return True
        except FormatError as exc:
            log.warning("an unreadable Allan snapshot was not archived: %s", exc)
            assert self.recorder is not None
            self.recorder.write(frames.event_record(
                rec["run"], 0, "unreadable_snapshot", rec.get("t_mono", 0.0),
                rec.get("t_real", 0.0), detail={"error": str(exc)}))
            return False

    def _recover(self, msg: Message, i0: int, n: int) -> list[dict[str, Any]]:
        """Records for the lost samples ``[i0, i0 + n)``: raw blocks fetched back from the
        service's ring (``recent``) where it still holds them, gap records for the rest."""
        rec = msg.record
        got: list[tuple[int, np.ndarray, float]] = []  # (first index, counts, t_mono)
        if self.backfill and self.sub.request_endpoint:
            got = self._fetch_recent(rec, i0, n)
        out: list[dict[str, Any]] = []
        offset = rec["t_real"] - rec["t_mono"]  # realtime − monotonic, as the block says
        cursor = i0
        for first, counts, t_mono in got:
            if first > cursor:
                out.append(self._gap(rec, msg, cursor, first - cursor))
            out.append(frames.raw_record(rec["run"], 0, first, counts, t_mono,
                                         t_mono + offset, rate_hz=rec.get("rate_hz")))
            self.recovered_samples += counts.shape[0]
            cursor = first + counts.shape[0]
        if cursor < i0 + n:
            out.append(self._gap(rec, msg, cursor, i0 + n - cursor))
        return out

    def _gap(self, rec: dict[str, Any], msg: Message, i0: int, n: int) -> dict[str, Any]:
        self.gaps_written += 1
        self.gap_samples += n
        return frames.gap_record(rec["run"], 0, i0, n, rec["t_mono"], rec["t_real"],
                                 "subscriber_loss", lost_messages=msg.lost, topic=msg.topic)

    def _fetch_recent(self, rec: dict[str, Any], i0: int, n: int
                      ) -> list[tuple[int, np.ndarray, float]]:
        """Contiguous runs of samples inside ``[i0, i0 + n)`` that the ring still holds."""
        rate = float(rec.get("rate_hz") or (self.header or {}).get("rate_hz") or 0.0)
        if rate <= 0:
            return []
        # from the first lost sample to now, with a little margin for what arrived since
        seconds = min((rec["i0"] + rec["n"] - i0) / rate + 0.5, MAX_BACKFILL_S)
        try:
            reply = self.sub.request("recent", {"seconds": seconds})
            index = np.asarray(reply["index"], dtype=np.int64)
            counts = np.asarray(reply["counts"])
            t_mono = np.asarray(reply["t_mono"], dtype=float)
            if counts.ndim != 2 or not index.shape[0] == counts.shape[0] == t_mono.shape[0]:
                raise FormatError("recent: index, counts and t_mono differ in length")
        except (NetworkError, FormatError, KeyError, TypeError, ValueError) as exc:
            log.warning("cannot fetch lost samples [%d, %d) back: %s", i0, i0 + n, exc)
            return []
        sel = np.flatnonzero((index >= i0) & (index < i0 + n))
        if sel.size == 0:
            return []
        # split where the index does not advance by one (the ring's own gaps)
        breaks = np.flatnonzero(np.diff(index[sel]) != 1) + 1
        runs = []
        for part in np.split(sel, breaks):
            runs.append((int(index[part[0]]), np.ascontiguousarray(counts[part]),
                         float(t_mono[part[0]])))
        return runs

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None


#: Suffixes of single files: an --out ending in one is a file name where a folder is needed.
FILE_SUFFIXES = (".npz", ".csv", ".txt", ".avr", ".json", ".h5", ".hdf5", ".bin", ".dat")


def check_out(path: str) -> Path:
    """The recording folder, checked before anything connects: a folder (segments rotate, so
    a recording is several files), writable, or creatable."""
    out = Path(path)
    if not out.exists() and out.suffix.lower() in FILE_SUFFIXES:
        raise OutputError(f"--out {path}: a recording is a folder of segment files, not one "
                          f"{out.suffix} file; give a folder, e.g. --out {out.with_suffix('')}")
    return check_output_dir(out, what=f"--out {path}", create=True)


def run(args: argparse.Namespace) -> int:
    for value, option, zero in ((args.segment, "--segment", False), (args.fsync, "--fsync", True),
                                (args.duration, "--duration", False),
                                (args.wait, "--wait", False),
                                (args.timeout, "--timeout", False)):
        check_seconds(value, option, zero=zero)
    out = check_out(args.out)
    # one writer per recording directory, as the service (dirlock.py): two archives, or an
    # archive beside a service, in one directory wrote the same indices twice
    lock = dirlock.hold(out, what="--out", advice="stop it, or archive into another "
                        "directory (--out)")
    try:
        return _archive(args, out)
    finally:
        dirlock.release(lock)


def _archive(args: argparse.Namespace, out: Path) -> int:
    sub = subscriber_from_args(args)
    # set by SIGTERM, or by an embedding program/test through ``args.stop_event``
    stop: threading.Event = getattr(args, "stop_event", None) or threading.Event()

    def _stop(signum: int, frame: Any) -> None:
        stop.set()

    # SIGTERM ends the archive cleanly (flushed, closed); only the main thread may set it
    in_main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGTERM, _stop) if in_main else None
    check_stream_sensor(sub)
    sub.connect(join=False)
    archiver = StreamArchiver(sub, out, segment_s=args.segment, fsync_s=args.fsync,
                              backfill=not args.no_backfill)
    start = time.monotonic()
    try:
        while not stop.is_set():
            elapsed = time.monotonic() - start
            if args.duration is not None and elapsed >= args.duration:
                break
            if sub.stats.messages_received == 0 and elapsed >= args.wait:
                if sub.stats.bad_messages:
                    raise NetworkError(f"nothing readable from {args.endpoint} within "
                                       f"{args.wait:g} s: {sub.stats.not_avard()}")
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
        f"lost in transport: {s.messages_lost} messages, {s.samples_lost} samples; "
        f"{archiver.recovered_samples} samples fetched back from the service's ring, "
        f"{archiver.gap_samples} recorded as gaps ({archiver.gaps_written} gap records)\n"
        f"service gaps: {s.samples_service_gap} samples; unexplained holes: "
        f"{s.samples_unexplained} samples\n")
    if archiver.other_sensor:
        sys.stdout.write(f"{archiver.other_sensor} records of another sensor than the "
                         "header's were not archived (pick one with --sensor NAME)\n")
    if archiver.dropped_waiting:
        sys.stdout.write(f"{archiver.dropped_waiting} early records were dropped while "
                         "waiting for the run header\n")
    if archiver.header is None:
        sys.stdout.write("no header was obtained: nothing could be written (is the request "
                         "socket reachable? see --request)\n")
        return 1
    return 0
