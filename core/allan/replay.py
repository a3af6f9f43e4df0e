"""Replaying a recording into the service's accumulators (the restore at start-up)."""

from __future__ import annotations

from pathlib import Path

from avard.core.allan.feed import AllanFeed
from avard.core.io.recording import SEGMENT_SUFFIX, RecordingReader, keyed_segments, walk


def replay_after(directory: str | Path, feed: AllanFeed, after: int | None) -> int:
    """Feed ``feed`` every sample a recording holds from index ``after`` on (all of them when
    None), whatever run wrote it (the service's restore: a checkpoint, then everything
    recorded after it, also by runs killed before their first checkpoint). Reads only from
    the newest segment whose first sample index is at or before ``after`` (segments in data
    order, from their frames), so a long recording is not read again at every restart.
    Returns the number of samples fed."""
    d = Path(directory)
    keyed = keyed_segments(f for f in d.glob("*" + SEGMENT_SUFFIX) if f.is_file())
    if not keyed:
        return 0
    keep = 0
    if after is not None:
        for k, (key, _seg) in enumerate(keyed):
            if key.i0 <= after:
                keep = k
    reader = RecordingReader(keyed[keep][1])        # one file: not ordered a second time
    reader.files = [seg for _, seg in keyed[keep:]]
    return feed.replay(walk(reader), after=after)
