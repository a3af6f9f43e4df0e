"""The recording scan's fast reader of one segment file: frames checked and raw blocks read in
C (core/io/_framescan.c), in stretches instead of one Python object per frame.

Opening a recording (``source.RecordingSource``) must check every frame and learn every raw
block's run, first index and size; done one frame at a time in Python that cost several
times the whole analysis of the same samples in an ``.npz``. Here a chunk of the file goes
to the C loop, which checks each frame's length and CRC, skips the records the scan never
decodes (temp, avar, checkpoint, status: by their kind, as the Python scan skips them) and
reads raw records laid out exactly as ``frames.raw_record`` writes them. Consecutive such
blocks of one run that continue each other's sample index come back as one
:class:`Stretch`; every other record (headers, gaps, events, a raw record laid out any other
way) comes back as a :class:`Frame` for the general decoder.

The C loop stops at the first frame that does not check. What follows is the general
reader's (``recording.scan_frames``: reported, resynchronised), so damage reads exactly as
it does for every reader. The walk (``recording.walk``) takes a stretch as one raw block
where that is the same as taking its blocks one by one (its run's header read, its indices
all new) and otherwise decodes its frames with the general decoder
(:meth:`Stretch.records`). tests/core/test_recording_fastscan.py holds the scan equal to
the general one on clean and damaged recordings.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from avard.core.errors import FormatError
from avard.core.io.crc import FRAMESCAN_API, load_framescan
from avard.core.io.recording import FRAME_HEADER, Frame
from numpy.typing import NDArray

#: The compiled frame loop, or None (core/io/crc.py loads it for both of its users)
_load = load_framescan
_framescan: Any = _load()

#: The interface this module calls: a module built from another ``_framescan.c`` is not used.
API = FRAMESCAN_API
#: Bytes of a segment handed to the C loop at once (a frame longer than this is read whole).
CHUNK = 1 << 20


def available() -> bool:
    """Whether the compiled frame loop is built (else the scan takes the general path)."""
    return _framescan is not None and getattr(_framescan, "API", None) == API


@dataclass(frozen=True)
class Stretch:
    """Raw blocks of one run in one file, each continuing the last one's sample index, whose
    frames checked and whose records are laid out as ``frames.raw_record`` writes them; with
    the header records between them (the service's copies every minute), kept in place."""

    file: str
    number: int                       # the file's place in the recording's file list
    data: bytes                       # the chunk of the file they were read from
    base: int                         # file offset of data[0]
    offsets: NDArray[np.int64]        # file offset of each frame
    lengths: NDArray[np.int64]        # payload bytes of each frame
    i0: NDArray[np.int64]             # first sample index of each block
    n: NDArray[np.int64]              # samples of each block
    counts: NDArray[np.int64]         # file offset of each block's counts (<i4, (n, 3))
    # header frames between the blocks: (blocks before it, frame), in file order
    headers: tuple[tuple[int, Frame], ...] = ()

    def copies(self, run: str, max_bytes: int) -> list[dict[str, Any]] | None:
        """The header records between the blocks when every one decodes and is of ``run``
        (copies of a header the walk knows, which only renew its newest header: the walk
        may take them after the blocks), else None."""
        from avard.core.io import frames as wire

        out = []
        for _, fr in self.headers:
            try:
                rec = wire.decode(fr.payload, max_bytes=max_bytes)
            except FormatError:
                return None
            if rec["kind"] != "header" or rec["run"] != run:
                return None
            out.append(rec)
        return out

    def records(self, decoded: Callable[[Frame], dict[str, Any] | None], max_bytes: int
                ) -> Iterator[dict[str, Any]]:
        """The blocks as the general decoder reads them (``frames.decode``), each tagged with
        ``_at`` as the scan tags a raw record, and the headers between them in place (through
        ``decoded``, the reader's decode-or-report): what the walk takes where the stretch
        cannot be taken whole (a run without its header yet, indices met before, a header
        between that is not a readable copy)."""
        from avard.core.io import frames as wire

        hdr = FRAME_HEADER.size
        heads = iter(self.headers)
        nxt = next(heads, None)
        for k, (off, size, at) in enumerate(zip(self.offsets.tolist(), self.lengths.tolist(),
                                                self.counts.tolist(), strict=True)):
            while nxt is not None and nxt[0] == k:
                got = decoded(nxt[1])
                if got is not None:
                    yield got
                nxt = next(heads, None)
            rel = off - self.base + hdr
            rec = wire.decode(self.data[rel:rel + size], max_bytes=max_bytes)
            rec["_at"] = (self.number, at, int(rec["i0"]))
            yield rec


def stretch_record(run: str, stretch: Stretch) -> dict[str, Any]:
    """A stretch as the walk sees one raw record: its run, first index and samples."""
    return {"kind": "raw", "v": 1, "run": run, "i0": int(stretch.i0[0]),
            "n": int(stretch.n.sum()), "_stretch": stretch}


def scan_file(fh: BinaryIO, name: str, number: int, max_bytes: int, limit: int | None
              ) -> Generator[Frame | tuple[str, Stretch], None, tuple[int, bool]]:
    """The frames of one open segment file from its start, until the first frame that does not
    check or the end (``limit`` bytes when given): a :class:`Frame` for each record the scan
    decodes, ``(run, Stretch)`` for raw blocks read here. Returns (as the generator's value)
    the file offset where it stopped and whether that is the file's clean end."""
    assert _framescan is not None
    fields = int(_framescan.ENTRY_FIELDS)
    base = 0                         # file offset of the chunk
    while True:
        # each chunk starts at a frame: the frame the last one cut is read again whole
        # (cheaper than copying the chunk's tail onto the next read)
        fh.seek(base)
        want = CHUNK if limit is None else min(CHUNK, limit - base)
        data = fh.read(want) if want > 0 else b""
        consumed, status, raw = _framescan.scan(data, base, max_bytes)
        if not consumed and not status and len(data) == want >= 8:
            # one frame longer than a chunk (its length checked by the C loop): read whole
            whole = 8 + int.from_bytes(data[:4], "little")
            want = whole if limit is None else min(whole, limit - base)
            if want > len(data):
                fh.seek(base)
                data = fh.read(want)
                consumed, status, raw = _framescan.scan(data, base, max_bytes)
        e = np.frombuffer(raw, dtype=np.int64).reshape(-1, fields)
        yield from _entries(e, data, base, name, number)
        base += consumed
        if status != 0:
            return base, False
        if len(data) < want or not consumed:
            # the end of the file (or of ``limit``): clean when no bytes are left over
            return base, consumed == len(data)


def spans(cont: NDArray[np.bool_]) -> Iterator[tuple[int, int]]:
    """``[a, b)`` of each run of items where ``cont`` says an item continues the one before
    (``cont[0]`` is never looked at: the first item starts a run)."""
    starts = np.flatnonzero(~cont[1:]) + 1
    return itertools.pairwise([0, *starts.tolist(), len(cont)]) if len(cont) else iter(())


def _entries(e: NDArray[np.int64], data: bytes, base: int, name: str, number: int
             ) -> Iterator[Frame | tuple[str, Stretch]]:
    """The C loop's entries as frames to decode and stretches of raw blocks (a stretch goes
    on across header records, which it carries in place)."""
    if not len(e):
        return
    hdr = FRAME_HEADER.size
    off, size, code, i0, n, counts = (e[:, k] for k in range(6))

    def frame_at(k: int) -> Frame:
        rel = int(off[k]) - base + hdr
        return Frame(name, int(off[k]), data[rel:rel + int(size[k])])

    raws = np.flatnonzero(code == 1)
    heads = np.cumsum(code == 3)
    # a raw entry continues the raw entry before it: the same run (the C loop's flag), the
    # next index, and only header records between them
    cont = np.zeros(len(raws), dtype=bool)
    if len(raws) > 1:
        a, b = raws[:-1], raws[1:]
        cont[1:] = ((e[b, 8] == 1) & (i0[b] == i0[a] + n[a])
                    & (heads[b] - heads[a] == b - a - 1))
    at = 0                                   # the next entry not yielded
    for p, q in spans(cont):
        first, last = int(raws[p]), int(raws[q - 1])
        for k in range(at, first):
            yield frame_at(k)
        inside = raws[p:q]
        hk = np.flatnonzero(code[first + 1:last] == 3) + first + 1
        between = [(int(j), frame_at(int(k)))
                   for j, k in zip(np.searchsorted(inside, hk), hk, strict=True)]
        r0 = int(e[first, 6]) - base
        run = data[r0:r0 + int(e[first, 7])].decode("ascii")
        yield run, Stretch(name, number, data, base, off[inside], size[inside], i0[inside],
                           n[inside], counts[inside], tuple(between))
        at = last + 1
    for k in range(at, len(e)):
        yield frame_at(k)
