"""Checkpoints of the Allan accumulators and the restore at start-up.

The state file (``allan-state.ckpt`` beside the segments) is written atomically; a new run
restores it, replays what the recording holds after it, and continues the sample index from
the last recorded sample. :func:`restore_accumulators` is the one entry point the service
uses, so the restore can move to ``AllanFeed``'s own state/replay API (issue #16) in one place.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from avard.core import frames
from avard.core.errors import AvardError, FormatError
from avard.core.recording import (
    AllanFeed,
    RecordingReader,
    first_record,
    frame,
    last_record,
    scan_frames,
)

log = logging.getLogger("avard.daemon.service")

STATE_FILE = "allan-state.ckpt"


def feed_state(feed: AllanFeed) -> dict[str, Any]:
    """What an AllanFeed needs to continue exactly: held temperatures, pending readings."""
    return {"next_index": feed.next_index, "held": [float(v) for v in feed._held],
            "pending": [[int(i), [float(v) for v in h]] for i, h in feed._pending],
            "temp_names": feed.temp_names, "scale": feed.scale, "open": feed._open}


def restore_feed(feed: AllanFeed, state: dict[str, Any]) -> None:
    feed.next_index = state["next_index"]
    feed._held = np.array(state["held"], dtype=float)
    feed._pending = [(int(i), np.array(h, dtype=float)) for i, h in state["pending"]]
    feed._open = bool(state.get("open", False))


def save_state(data_dir: Path, rec: dict[str, Any]) -> None:
    """Write a checkpoint record as the state file, atomically (tmp, fsync, rename)."""
    path = data_dir / STATE_FILE
    tmp = path.with_suffix(".tmp")
    try:
        data = frame(frames.encode(dict(rec, seq=0)))
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        log.error("cannot save the Allan checkpoint to %s: %s", path, exc)


def load_state(data_dir: Path) -> dict[str, Any] | None:
    path = data_dir / STATE_FILE
    if not path.exists():
        return None
    probs: list[Any] = []
    try:
        frs = list(scan_frames(path.read_bytes(), str(path), problems=probs))
        if not frs:
            raise FormatError(f"{path}: no valid frame ({'; '.join(map(str, probs))})")
        return frames.decode(frs[0].payload)
    except (OSError, FormatError) as exc:
        log.error("ignoring the Allan checkpoint %s: %s; starting the accumulators afresh",
                  path, exc)
        return None


def last_recorded(data_dir: Path, nominal_odr_hz: float) -> tuple[int, float] | None:
    """(index after the last recorded sample, its CLOCK_REALTIME) of the newest segment
    that holds samples; read from the file's end, so an hour-long segment costs little."""
    if not data_dir.is_dir():
        return None
    for seg in reversed(sorted(data_dir.glob("*.avr"))):
        try:
            rec = last_record(seg, "raw")
        except (OSError, FormatError):
            continue
        if rec is not None:
            rate = float(rec.get("rate_hz") or nominal_odr_hz)
            return rec["i0"] + rec["n"], rec["t_real"] + rec["n"] / rate
    return None


def _replay_after(data_dir: Path, ckpt: dict[str, Any], feed: AllanFeed) -> int:
    """Feed what run ``ckpt['run']`` recorded after the checkpoint (crash window)."""
    run = ckpt["run"]
    start = int(ckpt["feed"]["next_index"] or ckpt["i_end"])
    n0 = feed.fed
    segs = [s for s in sorted(data_dir.glob("*.avr")) if s.name.startswith(f"{run}_")]
    # Only the segment the checkpoint falls in and the later ones (headers carry the
    # index their segment starts at): a 60-hour run is not read again at every restart.
    keep = 0
    for k, seg in enumerate(segs):
        head = first_record(seg)
        if head is not None and head.get("kind") == "header" and head["i0"] <= start:
            keep = k
    for seg in segs[keep:]:
        for rec in RecordingReader(seg):
            kind = rec["kind"]
            if kind == "raw" and rec["i0"] + rec["n"] > start:
                cut = max(0, start - rec["i0"])
                feed.raw(rec["i0"] + cut, np.asarray(rec["counts"])[cut:])
                start = rec["i0"] + rec["n"]
            elif kind == "temp" and rec["i0"] >= start:
                feed.temp(rec["i0"], rec["names"], rec["values_c"])
            elif kind == "gap" and rec["i0"] >= start:
                feed.gap()
    return feed.fed - n0


@dataclass(frozen=True)
class Restored:
    """The accumulators a run continues from, and what the header says about them."""

    allan: Any
    info: dict[str, Any]


def restore_accumulators(data_dir: Path, streaming_cls: Any, names: list[str],
                         rate_hz: float) -> Restored | None:
    """The accumulators of the last checkpoint with everything recorded after it replayed,
    ended by a gap (the restart); None when there is no usable checkpoint."""
    ckpt = load_state(data_dir)
    if ckpt is None:
        return None
    try:
        allan = streaming_cls.from_state(ckpt["state"])
    except (AvardError, KeyError, ValueError, TypeError) as exc:
        log.error("cannot restore the Allan checkpoint: %s; starting afresh", exc)
        return None
    if list(allan.names) != list(names) or float(allan.rate_hz) != float(rate_hz):
        log.warning("the checkpoint's channels/rate (%s at %g Hz) differ from this "
                    "configuration; starting the accumulators afresh", allan.names,
                    allan.rate_hz)
        return None
    feed = AllanFeed(allan, ckpt["feed"]["scale"], ckpt["feed"]["temp_names"])
    restore_feed(feed, ckpt["feed"])
    replayed = _replay_after(data_dir, ckpt, feed)
    feed.gap()
    log.warning("restored the Allan accumulators of run %s (%d samples, %d replayed from the "
                "recording)", ckpt["run"], allan.n_samples, replayed)
    return Restored(allan, {"run": ckpt["run"], "i_end": ckpt["i_end"],
                            "n_samples": int(allan.n_samples), "replayed": replayed})
