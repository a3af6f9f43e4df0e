"""Checkpoints of the Allan accumulators and the restore at start-up.

The state file (``allan-state.ckpt`` beside the segments) is written atomically; a new run
restores it, replays what the recording holds after the index its accumulators account for
(the feed's ``covered``), and continues the sample index from the end of the recording. When
the state file is missing, damaged or says nothing usable, the recording's own ``checkpoint``
records stand in for it. :func:`restore_accumulators` is the one entry point the service
uses; it replays with ``replay_after`` (core/allan/replay.py), through the same walk and
``AllanFeed`` as the offline reader.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from avard.core.allan.feed import AllanFeed
from avard.core.allan.replay import ReplayExtent, replay_after, replay_extent
from avard.core.errors import AvardError, FormatError
from avard.core.io import frames
from avard.core.io.recording import (
    NO_INDEX,
    SEGMENT_SUFFIX,
    frame,
    keyed_segments,
    records_backwards,
    scan_frames,
    segment_files,
)
from avard.daemon.service.recorder import write_atomic

log = logging.getLogger("avard.daemon.service")

STATE_FILE = "allan-state.ckpt"


def save_state(data_dir: Path, rec: dict[str, Any]) -> None:
    """Write a checkpoint record as the state file, atomically (recorder.write_atomic: tmp,
    fsync, rename; the tmp is removed again when the disk is full)."""
    path = data_dir / STATE_FILE
    try:
        write_atomic(path, frame(frames.encode(dict(rec, seq=0))))
    except OSError as exc:
        log.error("cannot save the Allan checkpoint to %s: %s", path, exc)


@dataclass(frozen=True)
class StateFile:
    """What ``allan-state.ckpt`` held: its checkpoint record, or why there is none."""

    record: dict[str, Any] | None
    problem: str | None          # "missing", or what is wrong with it; None when readable


def read_state(data_dir: Path) -> StateFile:
    """The state file's checkpoint record, or why there is none (missing, damaged)."""
    path = data_dir / STATE_FILE
    if not path.exists():
        return StateFile(None, "missing")
    probs: list[Any] = []
    try:
        frs = list(scan_frames(path.read_bytes(), str(path), problems=probs))
        if not frs:
            raise FormatError(f"no valid frame ({'; '.join(map(str, probs))})")
        rec = frames.decode(frs[0].payload)
        if rec.get("kind") != "checkpoint":
            raise FormatError(f"holds a {rec.get('kind')!r} record, not a checkpoint")
        return StateFile(rec, None)
    except (OSError, FormatError) as exc:
        return StateFile(None, f"damaged ({exc})")


@dataclass(frozen=True)
class Restored:
    """The accumulators a run continues from, the index after the last sample they account
    for (``covered``: the new run's feed continues from it), and what the header and the
    start event say about them (``info``: where they came from, and any problem met)."""

    allan: Any
    info: dict[str, Any]
    covered: int
    origin: int | None          # the index the accumulators started from, when known


def held_index(ckpt: dict[str, Any]) -> int | None:
    """The index after the last sample a checkpoint's accumulators account for, or None when
    the checkpoint does not say (one written before ``covered`` existed, at an early stop or
    just after a gap, said ``i_end = 0`` while holding samples: replaying after 0 counted the
    recording twice)."""
    feed = ckpt.get("feed") or {}
    covered = feed.get("covered")
    if covered is not None:
        return int(covered)
    legacy = feed.get("next_index") or ckpt.get("i_end")
    if not legacy and int(ckpt.get("n_samples", 0)) > 0:
        return None
    return int(legacy or 0)


@dataclass(frozen=True)
class Refused:
    """Why a checkpoint cannot be continued; ``other_config``: it is of another channel set
    or rate (older ones will be too: the service starts afresh instead of searching)."""

    reason: str
    other_config: bool = False


def _usable(ckpt: dict[str, Any], streaming_cls: Any, names: list[str],
            rate_hz: float) -> tuple[AllanFeed, int] | Refused:
    """The feed (over the accumulators) of ``ckpt`` and the index they hold up to, or why
    they cannot be used."""
    after = held_index(ckpt)
    if after is None:
        return Refused(f"it holds {ckpt.get('n_samples')} samples but does not say up to "
                       "which index (written at an early stop by an older version)")
    try:
        allan = streaming_cls.from_state(ckpt["state"])
        feed = AllanFeed.from_state(allan, {"run": ckpt["run"], **ckpt["feed"]})
    except (AvardError, KeyError, ValueError, TypeError) as exc:
        return Refused(f"its state does not load ({type(exc).__name__}: {exc})")
    if list(allan.names) != list(names) or float(allan.rate_hz) != float(rate_hz):
        return Refused(f"its channels/rate ({allan.names} at {allan.rate_hz:g} Hz) differ from "
                       "this configuration", other_config=True)
    feed.nominal_hz = float(rate_hz)       # a run recorded after it at another ODR is refused
    return feed, after


def _recorded_checkpoints(data_dir: Path) -> Iterator[dict[str, Any]]:
    """The recording's ``checkpoint`` records, newest first (segments in data order, each
    read from its end)."""
    try:
        files = segment_files(data_dir)
    except FormatError:
        return
    for seg in reversed(files):
        try:
            for rec in records_backwards(seg):
                if rec["kind"] == "checkpoint":
                    yield rec
        except (OSError, FormatError) as exc:
            log.warning("cannot read %s for a checkpoint record: %s", seg, exc)


def _first_index(data_dir: Path) -> int | None:
    """The first sample index the recording names (its first segment in data order)."""
    keyed = keyed_segments(f for f in data_dir.glob("*" + SEGMENT_SUFFIX) if f.is_file())
    return keyed[0][0].i0 if keyed and keyed[0][0].i0 != NO_INDEX else None


def _announce_whole_replay(ext: ReplayExtent, rate_hz: float) -> None:
    """The one restore whose length has no bound but the recording's: said before it starts,
    so a journal that ends there (systemd's start timeout) explains itself."""
    span = ext.end_index - ext.first_index
    log.warning("the recording holds no usable checkpoint record: replaying all of it into "
                "new accumulators before READY (%d segments, %.1f MB, sample indices %d to %d: "
                "%d samples, %.0f s at %g Hz, gaps included). Start-up waits for it; if it "
                "runs past TimeoutStartSec systemd stops the service: raise TimeoutStartSec "
                "in a drop-in, or move old segments out of the data directory",
                ext.segments, ext.bytes / 1e6, ext.first_index, ext.end_index, span,
                span / rate_hz if rate_hz > 0 else float("nan"), rate_hz)


def restore_accumulators(data_dir: Path, streaming_cls: Any, names: list[str],
                         rate_hz: float, *,
                         fresh: Callable[[], Any] | None = None) -> Restored | None:
    """The accumulators of the last checkpoint with everything recorded after it replayed,
    ended by a gap (the restart); None when there is nothing to restore (no recording, or a
    checkpoint of another configuration: the service then starts afresh).

    The checkpoint is the state file; when that is missing, damaged or does not say which
    samples it holds, the recording's newest usable ``checkpoint`` record (written every
    ``checkpoint_interval_s``: the replay reads from the segment holding it, at most one
    ``segment_s`` of recording before it plus what was recorded after); when the recording has
    none, ``fresh()`` (new empty accumulators of this configuration) fed the whole recording,
    synchronously before READY, with no bound but the recording's length: announced at
    WARNING with its extent before it starts (TimeoutStartSec can stop it). Every such
    rebuild is logged at WARNING with what was done. Then the invariant: the accumulators
    cannot hold more samples than the recording has indices up to ``covered``; if they do,
    they are dropped (ERROR, and the start event says so) rather than continued wrong."""
    state = read_state(data_dir)
    ckpt, problem = state.record, state.problem
    source = STATE_FILE
    got: tuple[AllanFeed, int] | Refused | None = None
    if ckpt is not None:
        got = _usable(ckpt, streaming_cls, names, rate_hz)
        if isinstance(got, Refused) and got.other_config:
            log.warning("the Allan checkpoint %s: %s; starting the accumulators afresh",
                        STATE_FILE, got.reason)
            return None
        if isinstance(got, Refused):
            problem, got = f"unusable: {got.reason}", None
    if got is None:
        if problem == "missing" and not any(data_dir.glob("*" + SEGMENT_SUFFIX)):
            return None                          # a new recording: nothing to restore
        for rec in _recorded_checkpoints(data_dir):
            use = _usable(rec, streaming_cls, names, rate_hz)
            if isinstance(use, Refused):
                log.warning("skipping the checkpoint record of run %s at index %s: %s",
                            rec.get("run"), rec.get("i_end"), use.reason)
                if use.other_config:
                    return None                  # as for the state file: start afresh
                continue
            ckpt, got, source = rec, use, f"the recording's checkpoint record of run {rec['run']}"
            break
    info: dict[str, Any] = {}
    if problem is not None:
        info["state_file"] = problem
    run: str | None = None
    if isinstance(got, tuple):
        assert ckpt is not None
        feed, after = got
        run = ckpt["run"]
    elif fresh is not None:
        feed, after = AllanFeed(fresh(), 1.0, list(names[3:])), None  # headers set the scale
        feed.nominal_hz = float(rate_hz)
        feed.origin = _first_index(data_dir)
        source = "the whole recording (it holds no usable checkpoint record)"
    else:
        return None
    allan = feed.sink
    base_n = int(allan.n_samples)
    if after is None:
        _announce_whole_replay(replay_extent(data_dir, None), rate_hz)
    try:
        replayed = replay_after(data_dir, feed, after)
    except (AvardError, ValueError) as exc:
        # e.g. a run of the recording with other temperature channels than this one
        log.error("cannot rebuild the Allan accumulators from %s: %s; starting afresh",
                  source, exc)
        return None
    feed.gap()
    covered = feed.covered if feed.covered is not None else (after or 0)
    info.update(run=run, source=source, i_end=covered, n_samples=int(allan.n_samples),
                replayed=replayed)
    if problem is not None:
        log.warning("the Allan checkpoint %s is %s; rebuilt the accumulators from %s and the "
                    "samples recorded after it: %d samples, %d replayed, up to index %d",
                    STATE_FILE, problem, source, allan.n_samples, replayed, covered)
    else:
        log.warning("restored the Allan accumulators of run %s (%d samples, %d replayed from "
                    "the recording)", run, allan.n_samples, replayed)
    span = covered - feed.origin if feed.origin is not None else None
    if span is not None and int(allan.n_samples) > span:
        msg = (f"the restored accumulators hold {int(allan.n_samples)} samples but only "
               f"{span} sample indices lie between where they started ({feed.origin}) and "
               f"{covered} (checkpoint {base_n} + replayed {replayed}); they are dropped and "
               "this run starts afresh")
        log.error("invariant violated: %s", msg)
        return Restored(None, {"invariant_violated": msg, **info}, covered, None)
    return Restored(allan, info, covered, feed.origin)
