"""Replaying a recording into the service's accumulators (the restore at start-up)."""

from __future__ import annotations

from pathlib import Path

from avard.core.allan.feed import AllanFeed
from avard.core.errors import FormatError
from avard.core.io.recording import RecordingReader, first_record, segment_files, walk


def replay_after(directory: str | Path, feed: AllanFeed, after: int) -> int:
    """Feed ``feed`` every sample a recording holds from index ``after`` on, whatever run
    wrote it (the service's restore: a checkpoint, then everything recorded after it, also by
    runs killed before their first checkpoint). Reads only from the newest segment whose
    header starts at or before ``after``, so a long recording is not read again at every
    restart. Returns the number of samples fed."""
    try:
        files = segment_files(directory)
    except FormatError:
        return 0
    keep = 0
    for k, seg in enumerate(files):
        head = first_record(seg)
        if head is not None and head.get("kind") == "header" and int(head["i0"]) <= after:
            keep = k
    reader = RecordingReader(directory)
    reader.files = files[keep:]
    return feed.replay(walk(reader), after=after)
