"""Checkpoints of the Allan accumulators and the restore at start-up.

The state file (``allan-state.ckpt`` beside the segments) is written atomically; a new run
restores it, replays what the recording holds after it, and continues the sample index from
the last recorded sample. :func:`restore_accumulators` is the one entry point the service
uses; it replays with ``AllanFeed.replay`` (core/io/recording.py), as the offline reader does.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from avard.core.allan.feed import AllanFeed
from avard.core.allan.replay import replay_after
from avard.core.errors import AvardError, FormatError
from avard.core.io import frames
from avard.core.io.recording import frame, scan_frames
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
    feed = AllanFeed.from_state(allan, {"run": ckpt["run"], **ckpt["feed"]})
    # every sample recorded after the checkpoint, whatever run wrote it (runs killed before
    # their first checkpoint included)
    replayed = replay_after(data_dir, feed, int(ckpt["feed"]["next_index"] or ckpt["i_end"]))
    feed.gap()
    log.warning("restored the Allan accumulators of run %s (%d samples, %d replayed from the "
                "recording)", ckpt["run"], allan.n_samples, replayed)
    return Restored(allan, {"run": ckpt["run"], "i_end": ckpt["i_end"],
                            "n_samples": int(allan.n_samples), "replayed": replayed})
