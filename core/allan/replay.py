"""Replaying a recording into the service's accumulators (the restore at start-up)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from avard.core.allan.feed import AllanFeed
from avard.core.io.recording import (
    NO_INDEX,
    SEGMENT_SUFFIX,
    RecordingReader,
    keyed_segments,
    segment_end,
    segment_key,
    walk,
)


@dataclass(frozen=True)
class ReplayExtent:
    """What :func:`replay_after` will read: segment files, their bytes, and the sample
    indices they span (from the first segment's key to the last one's last raw block: an
    estimate of the samples to replay, gaps included)."""

    segments: int
    bytes: int
    first_index: int
    end_index: int


def segments_to_read(directory: str | Path, after: int | None) -> list[Path]:
    """The segments holding the samples from index ``after`` on (all when None): from the
    newest whose first sample index is at or before ``after``, in data order (also the live
    separation's replay after a restart, daemon/service/rig_separation.read_tail)."""
    d = Path(directory)
    keyed = keyed_segments(f for f in d.glob("*" + SEGMENT_SUFFIX) if f.is_file())
    keep = 0
    if after is not None:
        for k, (key, _seg) in enumerate(keyed):
            if key.i0 <= after:
                keep = k
    return [seg for _, seg in keyed[keep:]]


def replay_extent(directory: str | Path, after: int | None) -> ReplayExtent:
    """How much :func:`replay_after` would read, from the segments' keys and ends (a few
    small reads per file), so a long replay can be announced before it starts."""
    segs = segments_to_read(directory, after)
    if not segs:
        return ReplayExtent(0, 0, 0, 0)
    first = segment_key(segs[0]).i0 if after is None else after
    ends = [e for e in (segment_end(s) for s in segs) if e != NO_INDEX]
    end = max(ends) if ends else first
    return ReplayExtent(len(segs), sum(s.stat().st_size for s in segs),
                        first if first != NO_INDEX else end, end)


def replay_after(directory: str | Path, feed: AllanFeed, after: int | None) -> int:
    """Feed ``feed`` every sample a recording holds from index ``after`` on (all of them when
    None), whatever run wrote it (the service's restore: a checkpoint, then everything
    recorded after it, also by runs killed before their first checkpoint). Reads only from
    the newest segment whose first sample index is at or before ``after`` (segments in data
    order, from their frames), so a long recording is not read again at every restart.
    Returns the number of samples fed."""
    segs = segments_to_read(directory, after)
    if not segs:
        return 0
    reader = RecordingReader(segs[0])               # one file: not ordered a second time
    reader.files = segs
    return feed.replay(walk(reader), after=after)
