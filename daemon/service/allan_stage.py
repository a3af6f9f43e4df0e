"""The Allan stage: feeds the streaming accumulators, emits snapshots and checkpoints.

Snapshots (``avar`` records) and checkpoints go out through ``emit`` (the ring's mark channel,
so the recorder and the publisher see them in sample order, after every sample they cover).
The stage never reads what it emits: marks are skipped by kind.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from avard.core.allan.feed import AllanFeed
from avard.core.io import frames
from avard.daemon.service.ring import Chunk, Consumer
from avard.daemon.service.stage import Stage, offset_after_mark, split_chunk

Record = dict[str, Any]
log = logging.getLogger("avard.daemon.service")


def relabel_tau(snap: dict[str, Any], odr_hz: float) -> None:
    """τ = m / ODR with the *fitted* ODR (docs/architecture.md: τ0 = 1/fitted ODR).

    The accumulators count in samples and were built with the nominal rate, which only labels
    τ; the variances themselves (of sample averages) do not depend on the rate. ``rate_hz``
    becomes the fitted rate too, so a client computing τ = m / rate_hz agrees."""
    snap["tau"] = [float(m) / odr_hz for m in snap["m"]]
    snap["rate_hz"] = float(odr_hz)


def _next_deadline(deadline: float, interval: float, now: float) -> float:
    """The first ``deadline + k·interval`` (k ≥ 1) after ``now``."""
    return deadline + interval * (1 + int((now - deadline) // interval))


class AllanStage(Stage):
    """Feeds ``feed`` (and so ``allan``) in sample order; every ``snapshot_interval_s`` of
    sample time emits an ``avar`` record, every ``checkpoint_interval_s`` a ``checkpoint``
    (handed to ``on_checkpoint`` too when nothing records it)."""

    name = "allan"

    def __init__(self, consumer: Consumer, allan: Any, feed: AllanFeed, *, run_id: str,
                 real_offset: float, rate_hz: Callable[[], float],
                 emit: Callable[[Record], None],
                 on_checkpoint: Callable[[Record], None] | None,
                 snapshot_interval_s: float, checkpoint_interval_s: float,
                 batch_samples: int = 1,
                 record_fields: Callable[[], Record] | None = None) -> None:
        super().__init__(consumer, batch_samples=batch_samples)
        #: optional fields of every ``avar`` record (a rig's live ``separation``)
        self.record_fields = record_fields
        self.allan = allan
        self.feed = feed
        self.run_id = run_id
        self.real_offset = real_offset
        self.rate_hz = rate_hz
        self.emit = emit
        self.on_checkpoint = on_checkpoint
        self.snapshot_interval_s = snapshot_interval_s
        self.checkpoint_interval_s = checkpoint_interval_s
        self._next_snap: float | None = None   # set by the first sample (see handle)
        self._next_ckpt: float | None = None
        self._t = 0.0
        self.ring_lost = 0                      # samples this stage lost from the ring
        # counts at the last checkpoint, or before the first chunk (see _check)
        self._since: dict[str, int] | None = None

    def _counts(self) -> dict[str, int]:
        # a sink without a sample count (a test double that only records calls) counts 0
        return {"i_end": self.i_end(), "n": int(getattr(self.allan, "n_samples", 0)),
                "seen": self.feed.fed + self.feed.skipped, "fed": self.feed.fed,
                "lost": self.ring_lost}

    def handle(self, chunk: Chunk) -> None:
        if self._since is None:
            self._since = self._counts()
        if chunk.lost_samples or chunk.lost_marks:
            self.feed.gap()
            self.ring_lost += chunk.lost_samples
        for kind, val in split_chunk(chunk):
            if kind == "samples":
                a, b = val
                self.feed.raw(int(chunk.index[a]), chunk.counts[a:b])
                continue
            self.real_offset = offset_after_mark(val, self.real_offset)
            if val["kind"] == "temp":
                self.feed.temp(val["i0"], val["names"], val["values_c"])
            elif val["kind"] == "gap":
                self.feed.gap()
        if chunk.n:
            self._t = float(chunk.t_mono[-1])
        # The timers start with the first sample, deliberately: the first snapshot and
        # checkpoint come one interval into the run (the restore replays every run recorded
        # after a checkpoint, so an early one is not needed; docs/recording.md).
        if self._next_snap is None or self._next_ckpt is None:
            if not chunk.n:
                return
            first = float(chunk.t_mono[0])
            self._next_snap = first + self.snapshot_interval_s
            self._next_ckpt = first + self.checkpoint_interval_s
        # Fixed deadlines from the first sample (not re-armed from a late chunk): a stage that
        # reads in batches would otherwise drift one batch later at every interval.
        if self._t >= self._next_snap:
            self._next_snap = _next_deadline(self._next_snap, self.snapshot_interval_s, self._t)
            rec = self.snapshot_record()
            if rec is not None:
                self.emit(rec)
        if self._t >= self._next_ckpt:
            self._next_ckpt = _next_deadline(self._next_ckpt, self.checkpoint_interval_s,
                                             self._t)
            self.checkpoint()

    def snapshot_record(self) -> Record | None:
        """The ``avar`` record of everything fed so far; None before the first τ point (a
        snapshot without one would carry (0, C) arrays whose shape msgpack lists lose)."""
        snap = self.allan.snapshot().to_dict()
        if not snap["m"]:
            return None
        relabel_tau(snap, float(self.rate_hz()))
        snap.update(channels=self.feed.channels,
                    units=["m/s^2"] * 3 + ["degC"] * len(self.feed.temp_names),
                    allan_rate_hz=float(self.allan.rate_hz), fitted_rate_hz=snap["rate_hz"],
                    lsb_mps2=float(self.feed.scale))  # the fit's rounding term, as analyze's
        rec = frames.avar_record(self.run_id, 0, self.i_end(),
                                 int(self.allan.n_samples), snap, self._t,
                                 self._t + self.real_offset)
        if self.record_fields is not None:
            rec.update(self.record_fields())
        return rec

    def i_end(self) -> int:
        """The index after the last sample the accumulators account for: the feed's
        ``covered``, which a gap or a run that fed nothing leaves where it was (the feed's
        ``next_index`` is None then, and a checkpoint that said 0 made the next start replay
        the whole recording onto accumulators that already held it)."""
        return self.feed.covered if self.feed.covered is not None else 0

    def checkpoint(self) -> None:
        rec = frames.checkpoint_record(self.run_id, 0, self.i_end(),
                                       int(self.allan.n_samples), self.allan.state(),
                                       self._t, self._t + self.real_offset)
        rec["feed"] = self.feed.state()
        rec["check"] = self._check()
        self.emit(rec)
        if self.on_checkpoint is not None:
            self.on_checkpoint(rec)
        # With a recording, the recorder saves the state file once the checkpoint record
        # (and every sample before it) is written and fsynced: a checkpoint never covers
        # samples the recording lost in a crash, so restore + replay equals the recording.

    def _check(self) -> dict[str, int]:
        """What the accumulators took since the last checkpoint, for the run-time invariant
        the recorder checks (RecorderStage): samples of indices [from, to) seen by the feed
        (fed, or skipped before every temperature channel had a reading), lost from the ring,
        and the growth of the accumulators' sample count, which must equal the samples fed."""
        now = self._counts()
        was, self._since = self._since or now, now
        check = {"from": was["i_end"], "to": now["i_end"], "seen": now["seen"] - was["seen"],
                 "lost": now["lost"] - was["lost"], "n_added": now["n"] - was["n"],
                 "fed": now["fed"] - was["fed"]}
        if check["n_added"] != check["fed"]:
            log.error("invariant violated: the Allan accumulators grew by %d samples while "
                      "the feed gave them %d (indices [%d, %d))", check["n_added"],
                      check["fed"], check["from"], check["to"])
        return check

    def finish(self) -> None:
        rec = self.snapshot_record()
        if rec is not None:
            self.emit(rec)
        self.checkpoint()
