"""The live separation wired into a running rig (RigService): what each lane records goes to the
aligner, one thread feeds the pair accumulators, every lane's ``avar`` record carries the result.

::

    lane ring ──▶ SeparationFeed (one per lane: a ring consumer, its own thread)
                    SensorBlock(name, recorded index, counts × scale) + SensorClock
                    ──▶ Aligner ──(notify)──▶ separation thread: pop → SeparationStage.feed
                                                    every interval_s of samples: separation()
    every lane's AllanStage: avar record ∪ {"separation": the latest one computed}

The index pushed is the one the lane records (the ring's, which jumps over an overrun, a
restart gap or samples this consumer lost from the ring), so a loss is an index jump the pair
accumulators turn into a gap. The separation is computed on the separation thread, never on an
Allan stage's (about a second of CPU for three sensors); the Allan stages only copy the latest
map. At stop, :meth:`RigSeparation.drain` (called after the readers stopped and before the
lanes flush) feeds everything the rings still hold and computes the separation afresh, so each
lane's final ``avar`` record covers every aligned sample.

Checkpoint: every ``checkpoint_interval_s`` of the reference sensor's samples (and at stop)
``separation-state.ckpt`` in the rig's ``data_dir`` holds the pairs' state and each sensor's
next index. A restart restores it and replays what each sensor's recording (``data_dir/NAME``)
holds after it, up to the index the lane restored to, aligned run by run by the offline rule
(core/analysis/separate.aligned_runs: the one ``avard separate`` applies to recordings of
several runs), each pair after its last fed row; then every pair's segment ends (the
restart). So a kill between the lanes' checkpoints and this one loses nothing, and the
published separation equals ``avard separate`` on the recordings. With no usable state (none,
unreadable, or claiming samples a recording no longer holds: a crash lost its tail) the pairs
are rebuilt from the recordings' newest :data:`MAX_REPLAY_S` of samples. The run-time check
holds each pair to grow by exactly the rows replayed or fed into it; recorded samples that
could not be replayed are counted per sensor in the status (``restored.hole_samples``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import msgpack
import numpy as np
from avard.core.allan.feed import scale_of
from avard.core.allan.replay import segments_to_read
from avard.core.analysis.separate import AlignedRun, SensorRecord, aligned_runs
from avard.core.errors import AvardError, FormatError
from avard.core.io.recording import (
    SEGMENT_SUFFIX,
    RecordingReader,
    frame,
    keyed_segments,
    scan_frames,
    walk,
)
from avard.daemon.service.recorder import write_atomic
from avard.daemon.service.ring import Chunk, Consumer
from avard.daemon.service.separation_stage import (
    AlignedBlock,
    Aligner,
    SensorBlock,
    SensorClock,
    SeparationStage,
)
from avard.daemon.service.stage import Stage, split_chunk
from numpy.typing import NDArray

log = logging.getLogger("avard.daemon.service")

STATE_FILE = "separation-state.ckpt"
#: Sensors the live separation takes (the three-cornered hat's); a larger rig separates its
#: first three and says so.
MAX_SENSORS = 3
#: Seconds of samples a SeparationFeed lets accumulate between ring reads (as the Allan stage).
FEED_BATCH_S = 0.25
#: The most of each sensor's newest recorded samples a restart replays into the pairs (in
#: memory: three axes of float64, about 10 MB per sensor at 125 Hz); older samples the
#: state does not hold are a hole, counted in the status.
MAX_REPLAY_S = 3 * 3600.0


def _first_recorded(directory: Path) -> int | None:
    keyed = keyed_segments(f for f in directory.glob("*" + SEGMENT_SUFFIX) if f.is_file())
    return int(keyed[0][0].i0) if keyed else None


def _run_at(tail: SensorRecord, index: int) -> str | None:
    """The run of a recording's tail that sample ``index`` belongs to (the last header at or
    before it), None when the tail does not reach back to it."""
    before = [h for h in tail.meta.get("headers", []) if int(h["i0"]) <= index]
    return str(max(before, key=lambda h: int(h["i0"]))["run"]) if before else None


def read_tail(directory: Path, after: int | None, before: int | None = None) -> SensorRecord:
    """A sensor's recording from sample index ``after`` on (all when None) up to ``before``
    (the index the lane's run starts at: what a restart's lanes restored), through the one
    walk (core/io/recording.walk): its samples in m/s², their indices and every run's header
    (what core/analysis/separate.aligned_runs needs)."""
    segs = segments_to_read(directory, after)
    headers: list[dict[str, Any]] = []
    blocks: list[NDArray[np.float64]] = []
    index: list[NDArray[np.int64]] = []
    scale = 0.0
    rate = 0.0
    if segs:
        reader = RecordingReader(segs[0])
        reader.files = segs
        for rec in walk(reader):
            kind = rec["kind"]
            if kind == "header":
                headers.append({k: v for k, v in rec.items() if k != "config"})
                scale = scale_of(rec)
                rate = float(rec.get("rate_hz", rate) or rate)
            elif kind == "raw":
                i0, n = int(rec["i0"]), int(rec["n"])
                skip = 0 if after is None else max(0, min(n, after - i0))
                stop = n if before is None else max(skip, min(n, before - i0))
                if skip < stop:
                    counts = np.asarray(rec["counts"], dtype=np.float64)[skip:stop, :3]
                    blocks.append(counts * scale)
                    index.append(i0 + skip + np.arange(stop - skip, dtype=np.int64))
    accel = np.concatenate(blocks) if blocks else np.zeros((0, 3))
    idx = np.concatenate(index) if index else np.zeros(0, dtype=np.int64)
    return SensorRecord(accel, ("x", "y", "z"), rate if rate > 0 else 1.0, source=str(directory),
                        meta={"index": idx, "headers": headers})


class FittedRate(Protocol):
    """A lane's fitted time base, as far as the separation needs it."""

    @property
    def odr_hz(self) -> float: ...

    @property
    def period_s(self) -> float: ...


@dataclass(frozen=True)
class SeparatedLane:
    """One sensor of the separation: its name, ring consumer, scale (m/s² per count),
    fitted time base and the index its run starts at (after any restart gap)."""

    name: str
    consumer: Consumer
    scale: float
    timebase: FittedRate
    start_index: int


class SeparationFeed(Stage):
    """One lane's samples, in ring order, pushed into the aligner with the recorded index."""

    def __init__(self, lane: SeparatedLane, owner: RigSeparation, *,
                 batch_samples: int) -> None:
        super().__init__(lane.consumer, batch_samples=batch_samples)
        self.name = f"separation-feed-{lane.name}"
        self.lane = lane
        self.owner = owner

    def handle(self, chunk: Chunk) -> None:
        for kind, val in split_chunk(chunk):
            if kind != "samples":
                continue
            a, b = val
            self.owner.push(self.lane, chunk, a, b)
        self.owner.wake()


class RigSeparation:
    """The live separation of a rig's first 2–3 sensors (see the module docstring)."""

    def __init__(self, names: Sequence[str], nominal_odr: float, *,
                 data_dir: Path | None, checkpoint_interval_s: float,
                 interval_s: float | None = None, batch_s: float = FEED_BATCH_S) -> None:
        self.names = tuple(names[:MAX_SENSORS])
        self.left_out = tuple(names[MAX_SENSORS:])
        self.nominal_odr = float(nominal_odr)
        self.data_dir = data_dir
        self.checkpoint_interval_s = float(checkpoint_interval_s)
        self.batch_s = batch_s
        kw = {} if interval_s is None else {"interval_s": interval_s}
        self.stage = SeparationStage(self.names, self.nominal_odr, **kw)
        self.aligner = Aligner(self.names)
        self.lanes: dict[str, SeparatedLane] = {}
        self.feeds: list[SeparationFeed] = []
        #: each sensor's index after the last sample fed to the pairs (the checkpoint's
        #: "next"; what the aligner still holds is not in the state, so a hole after it)
        self.next_index: dict[str, int] = {}
        self.restored: dict[str, Any] = {}
        self._fields: dict[str, Any] = {}
        self._version = 0                         # separations computed and kept so far
        self._given: dict[str, int] = {}          # the version each lane's avar carried
        self._fields_lock = threading.Lock()
        self._work = threading.Condition()
        self._pending = False
        self._stopping = False
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self._rows_since = {p: 0 for p in self.stage.pairs}     # rows fed per pair
        self.rows_fed = {p: 0 for p in self.stage.pairs}        # ... in this run
        self._n_since = {p: acc.n_samples for p, acc in self.stage.pairs.items()}
        self._next_ckpt_rows: int | None = None
        self._rows_total = 0
        self.violations = 0
        self.checkpoints = 0
        #: CPU seconds of the separation thread: aligning and feeding the pairs, computing
        #: the separation (the benchmark's split of the live separation's cost)
        self.cpu_s = {"feed": 0.0, "separation": 0.0}

    # -- restore and checkpoint ----------------------------------------------------------
    def restore(self, start_index: dict[str, int]) -> None:
        """Continue from the state file, then replay what the sensors' recordings hold after
        it (module docstring); with no usable state, replay the recordings whole (up to
        :data:`MAX_REPLAY_S` of the newest samples; older ones are a hole, said with its
        size)."""
        if self.data_dir is None:
            return
        path = self.data_dir / STATE_FILE
        saved: dict[str, int] | None = None
        problem: dict[str, Any] = {}
        if path.exists():
            try:
                frs = list(scan_frames(path.read_bytes(), str(path)))
                if not frs:
                    raise FormatError("no valid frame in it")
                rec = msgpack.unpackb(frs[0].payload, raw=False, strict_map_key=False)
                if rec.get("kind") != "separation_checkpoint" or rec.get("v") != 1:
                    raise FormatError("not a version-1 separation checkpoint")
                if list(rec.get("sensors", [])) != list(self.names):
                    raise FormatError(f"it is of sensors {rec.get('sensors')}, this rig "
                                      f"separates {list(self.names)}")
                stage = SeparationStage.from_state(rec["state"])
                saved = {str(k): int(v) for k, v in rec["next"].items()}
            except (AvardError, OSError, KeyError, TypeError, ValueError,
                    msgpack.UnpackException) as exc:
                log.warning("the live separation's checkpoint %s is not usable (%s): the "
                            "pairs are rebuilt from the recordings", path, exc)
                problem = {"state": "unusable", "detail": str(exc)}
                saved = None
            if saved is not None:
                ahead = {n: saved[n] - start_index[n] for n in self.names
                         if saved.get(n, 0) > start_index[n]}
                if ahead:
                    log.warning("the live separation's checkpoint holds samples the "
                                "recordings no longer do (%s): the pairs are rebuilt from "
                                "the recordings", ahead)
                    problem = {"state": "dropped", "ahead": ahead}
                    saved = None
            if saved is not None:
                stage.interval_s = self.stage.interval_s
                self.stage = stage
        self._replay(saved, start_index, problem)

    def _replay(self, saved: dict[str, int] | None, start_index: dict[str, int],
                problem: dict[str, Any]) -> None:
        """Feed the pairs every aligned row the recordings hold after what the state holds
        (each pair after its last fed row), aligned run by run by the one offline rule
        (core/analysis/separate.aligned_runs), then end every pair's segment (the restart).
        The run-time check: each pair grew by exactly the rows replayed into it; what the
        recordings hold that could not be replayed is a hole, counted per sensor."""
        assert self.data_dir is not None
        base = {p: acc.n_samples for p, acc in self.stage.pairs.items()}
        after = dict(saved) if saved is not None else {}
        for (i, j), acc in self.stage.pairs.items():
            last = acc.last_fed
            if last is not None:
                for name, v in ((self.names[i], last[0] + 1), (self.names[j], last[1] + 1)):
                    after[name] = min(after.get(name, v), v)
        cap = int(MAX_REPLAY_S * self.nominal_odr)
        hole: dict[str, int] = {}
        replayed = {f"{a.sensors[0]}-{a.sensors[1]}": 0 for a in self.stage.pairs.values()}
        runs: list[AlignedRun] = []
        try:
            tails = []
            for name in self.names:
                first = after.get(name)
                floor = start_index[name] - cap
                oldest = first if first is not None else _first_recorded(self.data_dir / name)
                if oldest is not None and oldest < floor:
                    hole[name] = floor - oldest
                    first = floor
                # from the last sample the state holds: the run it belongs to is read too
                tails.append(read_tail(self.data_dir / name, None if first is None
                                       else max(0, first - 1), start_index[name]))
            if saved is None and not problem and not any(len(t.accel) for t in tails):
                return                                 # a new rig: nothing to restore
            if all(len(t.accel) for t in tails):
                runs = aligned_runs(tails)
        except (AvardError, OSError) as exc:
            log.error("the live separation cannot replay the recordings (%s): what they hold "
                      "after its checkpoint is a gap for the pairs", exc)
            runs = []
            hole = {n: max(0, start_index[n] - after.get(n, 0)) for n in self.names}
            problem = {**problem, "replay_error": str(exc)}
        for run in runs:
            for (i, j), acc in self.stage.pairs.items():
                last = acc.last_fed
                if last is not None and run.run != _run_at(tails[i], last[0]):
                    acc.gap()      # a later run than the state's last row: a restart between
                lim_a = last[0] if last is not None else after.get(self.names[i], 0) - 1
                lim_b = last[1] if last is not None else after.get(self.names[j], 0) - 1
                rows = (run.index[i] > lim_a) & (run.index[j] > lim_b)
                got = acc.feed(run.index[i][rows], run.index[j][rows],
                               run.accel[i][rows], run.accel[j][rows])
                replayed[f"{acc.sensors[0]}-{acc.sensors[1]}"] += got
        for p, acc in self.stage.pairs.items():
            acc.gap()                                  # the restart: no difference across it
            key = f"{acc.sensors[0]}-{acc.sensors[1]}"
            if acc.n_samples != base[p] + replayed[key]:
                self.violations += 1
                log.error("invariant violated: the live separation's pair %s grew by %d "
                          "samples in the replay while %d rows were replayed", key,
                          acc.n_samples - base[p], replayed[key])
        self._n_since = {p: acc.n_samples for p, acc in self.stage.pairs.items()}
        state = "restored" if saved is not None else problem.get("state", "rebuilt")
        self.restored = {**problem, "state": state, "n_samples": self.stage.n_samples,
                         "replayed": "replay_error" not in problem, "replayed_rows": replayed,
                         "hole_samples": {n: hole.get(n, 0) for n in self.names}}
        log.info("live separation %s: %d aligned samples, %s rows replayed from the "
                 "recordings, hole %s", self.restored["state"], self.stage.n_samples,
                 replayed, self.restored["hole_samples"])

    def checkpoint(self) -> None:
        """Save the pairs' state and each sensor's next index; check the pairs' counts."""
        self._check()
        if self.data_dir is None:
            return
        rec = {"kind": "separation_checkpoint", "v": 1, "sensors": list(self.names),
               "state": self.stage.state(), "next": dict(self.next_index)}
        try:
            self.data_dir.mkdir(parents=True, exist_ok=True)
            write_atomic(self.data_dir / STATE_FILE, frame(msgpack.packb(rec)))
            self.checkpoints += 1
        except OSError as exc:
            log.error("cannot save the live separation's checkpoint: %s", exc)

    def _check(self) -> None:
        """Run-time invariant: each pair's sample count grew by exactly the rows fed to it
        (rows where both sensors have a sample) since the last check."""
        self.stage.flush()
        for p, acc in self.stage.pairs.items():
            grew = acc.n_samples - self._n_since[p]
            if grew != self._rows_since[p]:
                self.violations += 1
                log.error("invariant violated: the live separation's pair %s-%s grew by %d "
                          "samples while it was fed %d aligned rows", *acc.sensors, grew,
                          self._rows_since[p])
            self._n_since[p] = acc.n_samples
            self._rows_since[p] = 0

    # -- the data path -------------------------------------------------------------------
    def attach(self, lanes: Sequence[SeparatedLane]) -> None:
        """The lanes to follow (their ring consumers made before the readers start)."""
        for lane in lanes:
            self.lanes[lane.name] = lane
            self.next_index[lane.name] = lane.start_index
            self.feeds.append(SeparationFeed(
                lane, self, batch_samples=max(1, int(self.batch_s * self.nominal_odr))))

    def push(self, lane: SeparatedLane, chunk: Chunk, a: int, b: int) -> None:
        """Samples [a, b) of a chunk (index-contiguous) into the aligner, with the lane's
        clock at the block's last sample (its recorded time)."""
        i0 = int(chunk.index[a])
        last = b - 1
        clock = SensorClock(int(chunk.index[last]), float(chunk.t_mono[last]),
                            float(lane.timebase.period_s))
        self.aligner.push(SensorBlock(lane.name, i0, chunk.counts[a:b, :3] * lane.scale),
                          clock)

    def wake(self) -> None:
        with self._work:
            self._pending = True
            self._work.notify()

    def start(self) -> None:
        for f in self.feeds:
            f.start()
        self._thread = threading.Thread(target=self._run, name="avard-separation",
                                        daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            while True:
                with self._work:
                    self._work.wait_for(lambda: self._pending or self._stopping)
                    if self._stopping and not self._pending:
                        return
                    self._pending = False
                self._take()
        except BaseException as exc:
            log.exception("the separation thread died")
            self.error = exc

    def _take(self, *, final: bool = False) -> None:
        """Feed every aligned tick; compute the separation and checkpoint when due."""
        c0 = time.thread_time()
        while (blk := self.aligner.pop(final=final)) is not None:
            self._feed(blk)
        c1 = time.thread_time()
        fields = self.stage.record_fields(self._rate(), force=final)
        self.cpu_s["feed"] += c1 - c0
        self.cpu_s["separation"] += time.thread_time() - c1
        with self._fields_lock:
            if fields != self._fields:
                self._fields = fields
                self._version += 1
        ckpt_rows = int(self.checkpoint_interval_s * self.nominal_odr)
        if self._next_ckpt_rows is None:
            self._next_ckpt_rows = self._rows_total + ckpt_rows
        if final or self._rows_total >= self._next_ckpt_rows:
            self._next_ckpt_rows = self._rows_total + ckpt_rows
            self.checkpoint()

    def _feed(self, blk: AlignedBlock) -> None:
        rows = [blk.names.index(n) for n in self.stage.sensors]
        for (i, j) in self._rows_since:
            ok = (blk.index[rows[i]] >= 0) & (blk.index[rows[j]] >= 0)
            got = int(np.count_nonzero(ok))
            self._rows_since[(i, j)] += got
            self.rows_fed[(i, j)] += got
        self._rows_total += blk.index.shape[1]
        for s, name in enumerate(blk.names):
            have = blk.index[s][blk.index[s] >= 0]
            if len(have):
                self.next_index[name] = max(self.next_index[name], int(have[-1]) + 1)
        self.stage.feed(blk)

    def _rate(self) -> float:
        """The reference sensor's fitted rate (τ = m / it)."""
        ref = self.lanes.get(self.names[0])
        return float(ref.timebase.odr_hz) if ref is not None else self.nominal_odr

    def drain(self) -> None:
        """At stop, after the readers stopped: the feeds read what their rings still hold,
        the separation thread ends, and the last aligned rows are fed, the separation
        computed afresh and checkpointed (before the lanes write their last ``avar``)."""
        for f in self.feeds:
            f.stop()
        with self._work:
            self._stopping = True
            self._work.notify()
        if self._thread is not None:
            self._thread.join(30.0)
            if self._thread.is_alive():     # never feed the pairs from two threads
                log.error("the separation thread did not finish; its last separation and "
                          "checkpoint are not written")
                return
        if self.error is None:
            self._take(final=True)

    def fields_for(self, lane: str) -> Callable[[], dict[str, Any]]:
        """What ``lane``'s next ``avar`` record carries (its Allan stage's thread calls it):
        the separation once after each computation, {} in between (a map of ~10 kB in every
        record of every sensor would grow each recording by a third; the ``snapshot``
        request and avard web keep the last one seen, snapshots.SnapshotBoard)."""
        def fields() -> dict[str, Any]:
            with self._fields_lock:
                if self._given.get(lane) == self._version:
                    return {}
                self._given[lane] = self._version
                return dict(self._fields)
        return fields

    def error_of_threads(self) -> BaseException | None:
        if self.error is not None:
            return self.error
        return next((f.error for f in self.feeds if f.error is not None), None)

    def status(self) -> dict[str, Any]:
        """Slips, each pair's segments and samples, the restore and any sensors left out."""
        pairs = {f"{acc.sensors[0]}-{acc.sensors[1]}": {
            "segments": acc.n_segments, "samples": acc.n_samples,
            "fed_this_run": self.rows_fed[p]} for p, acc in self.stage.pairs.items()}
        st: dict[str, Any] = {"sensors": list(self.names), "slips": dict(self.aligner.slips),
                              "pairs": pairs, "computed": self.stage.computed,
                              "invariant_violations": self.violations}
        if self.restored:
            st["restored"] = self.restored
        if self.left_out:
            st["left_out"] = list(self.left_out)
        return st
