"""Crash-safe recordings: CRC-framed msgpack records in segment files, and their reader.

On disk every record is one frame::

    u32 length (little endian) | u32 crc32 of the payload (little endian) | payload

where the payload is the same msgpack record that goes on the wire (``avard.core.io.frames``).
A segment file is a sequence of frames that starts with a ``header`` record; a recording is a
file or a directory of segment files, read in data order: by run (the run id starts with a run
sequence number, daemon/service/recorder.py ``new_run_id``) and sample index, both read from
the frames (:func:`order_segments`), never from the file names.

Why this framing: a power cut can only leave a *truncated* last frame (appends are the only
writes), which the reader detects from the length and drops, saying how many bytes it dropped.
A flipped bit anywhere else fails the CRC; the reader reports that frame by file and byte
offset, resynchronises on the next valid frame and goes on, so one bad sector never costs the
rest of a 60-hour run and never passes silently.

This module never touches hardware or sockets (it is part of ``avard.core``).
"""

from __future__ import annotations

import logging
import mmap
import re
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from avard.core.allan.feed import AllanFeed, Segmenter, nominal_of, scale_of
from avard.core.errors import DataError, FormatError

log = logging.getLogger(__name__)

FRAME_HEADER = struct.Struct("<II")
#: Largest frame the reader accepts (bytes of payload). A 4 kHz raw block of one second is
#: 48 kB; anything near this cap is a corrupt length field, not data.
MAX_FRAME_BYTES = 16 * 1024 * 1024
SEGMENT_SUFFIX = ".avr"


def frame(payload: bytes) -> bytes:
    """One on-disk frame for an encoded record: ``u32 len | u32 crc32 | payload``."""
    if len(payload) > MAX_FRAME_BYTES:
        raise FormatError(
            f"record of {len(payload)} bytes exceeds the frame limit of {MAX_FRAME_BYTES} bytes;"
            " write smaller raw blocks (lower block_s in the [recording] config)"
        )
    return FRAME_HEADER.pack(len(payload), zlib.crc32(payload) & 0xFFFFFFFF) + payload


@dataclass(frozen=True)
class Problem:
    """Something the reader had to skip: where it is and how much it cost."""

    file: str
    offset: int           # byte offset of the frame (or garbage) in the file
    kind: str             # "truncated" (tail) | "corrupt" (middle) | "undecodable"
    dropped_bytes: int
    detail: str

    def __str__(self) -> str:
        return (f"{self.file}: {self.kind} record at byte {self.offset} "
                f"({self.dropped_bytes} bytes dropped): {self.detail}")


@dataclass(frozen=True)
class Frame:
    """One valid frame: where it sits and its payload bytes."""

    file: str
    offset: int
    payload: bytes


def _valid_at(buf: memoryview, pos: int, max_bytes: int) -> int | None:
    """Payload length if a frame with a matching CRC starts at ``pos``, else None."""
    if pos + FRAME_HEADER.size > len(buf):
        return None
    n, crc = FRAME_HEADER.unpack_from(buf, pos)
    end = pos + FRAME_HEADER.size + n
    # n == 0 is never a record (the smallest is a msgpack map of a dozen bytes), but eight zero
    # bytes have a matching CRC: without this a zero-filled tail (ext4 after a power cut) would
    # read as thousands of "valid" empty frames instead of one truncated tail.
    if n == 0 or n > max_bytes or end > len(buf):
        return None
    if zlib.crc32(buf[pos + FRAME_HEADER.size:end]) & 0xFFFFFFFF != crc:
        return None
    return n


def scan_frames(data: bytes | memoryview, name: str = "<bytes>", *,
                max_bytes: int = MAX_FRAME_BYTES,
                problems: list[Problem] | None = None) -> Iterator[Frame]:
    """Yield the valid frames of one segment's bytes, recording what had to be skipped.

    A frame whose length runs past the end of the data and after which no valid frame follows
    is a truncated tail (the normal result of a power cut): it ends the scan. A frame that
    fails its CRC in the middle is reported as corrupt; the scan resynchronises on the next
    offset where a frame with a valid CRC starts (every offset is a candidate; the search is
    linear in the bytes searched, see ``_resync``).
    """
    problems = problems if problems is not None else []
    buf = memoryview(data)
    pos = 0
    size = len(buf)
    hdr = FRAME_HEADER.size
    prefix: _PrefixCrc | None = None      # built at the first damage, kept for the file
    while pos < size:
        n = _valid_at(buf, pos, max_bytes)
        if n is not None:
            yield Frame(name, pos, bytes(buf[pos + hdr:pos + hdr + n]))
            pos += hdr + n
            continue
        # Not a valid frame here. Find where the next valid one starts, if any.
        prefix = prefix or _PrefixCrc(buf)
        nxt = _resync(buf, pos + 1, max_bytes, prefix)
        if nxt is None:
            claimed = FRAME_HEADER.unpack_from(buf, pos)[0] if pos + hdr <= size else None
            if claimed is not None and claimed <= max_bytes and pos + hdr + claimed > size:
                detail = f"frame claims {claimed} payload bytes, only {size - pos - hdr} present"
            elif claimed is None:
                detail = f"{size - pos} bytes, shorter than a frame header"
            else:
                detail = "bytes at the end do not form a valid frame"
            problems.append(Problem(name, pos, "truncated", size - pos, detail))
            return
        problems.append(Problem(name, pos, "corrupt", nxt - pos,
                                "CRC32 mismatch or bad length; resynchronised on the next frame"))
        pos = nxt


# --------------------------------------------------------------------------------------------
# resynchronisation in time linear in the file size
#
# Checking one candidate frame costs its claimed length (a CRC over the payload), so trying
# every byte offset in turn is quadratic on a crafted file where every offset claims a frame to
# the end of the file. Instead the CRC of any byte range comes from two prefix CRCs:
#
#     crc32(buf[a:b]) = P(b) XOR Z_{b-a}(P(a)),     P(k) = crc32(buf[base:k])
#
# where Z_L is the GF(2)-linear map "append L zero bytes to the raw CRC register" (the
# operator of zlib's crc32_combine). Z_L is applied with one 4 × 256 lookup table per bit of L,
# vectorised over all candidates of a window, and the prefix CRCs are taken in one forward
# pass over the sorted candidate ends: bounded work per byte of the file.

_CRC_BITS = 25                  # Z_{2^j} for j < 25 covers payload lengths up to 2^25 - 1
_ZERO_TABLES: np.ndarray | None = None
_WINDOW_MAX = 1 << 20           # largest resync window (candidate offsets): bounded memory


def _zero_byte_tables() -> np.ndarray:
    """(25, 4, 256) uint32: entry [j, k, v] is Z_{2^j} applied to the register ``v << 8k``."""
    global _ZERO_TABLES
    if _ZERO_TABLES is None:
        crc_table = [zlib.crc32(bytes([b]), 0xFFFFFFFF) ^ 0xFFFFFFFF for b in range(256)]
        # raw register update by one zero byte, on each of the 32 basis vectors
        cols = [((1 << i) >> 8) ^ crc_table[(1 << i) & 0xFF] for i in range(32)]
        tables = np.zeros((_CRC_BITS, 4, 256), dtype=np.uint32)
        for j in range(_CRC_BITS):
            for k in range(4):
                for bit in range(8):
                    step = 1 << bit
                    # entries v with this bit set get the image of basis vector 8k + bit
                    tables[j, k, step:2 * step] = tables[j, k, :step] ^ np.uint32(cols[8 * k
                                                                                  + bit])
            # cols[i] = Z_{2^j}(e_i), so Z_{2^j}(cols[i]) = Z_{2^(j+1)}(e_i)
            cols = [_apply_zero(tables[j], c) for c in cols]
        _ZERO_TABLES = tables
    return _ZERO_TABLES


def _apply_zero(t: np.ndarray, v: Any) -> Any:
    """Z (given as its (4, 256) byte tables) applied to a uint32 register or array of them."""
    if isinstance(v, np.ndarray):
        return t[0][v & 0xFF] ^ t[1][(v >> 8) & 0xFF] ^ t[2][(v >> 16) & 0xFF] ^ t[3][v >> 24]
    return int(t[0][v & 0xFF] ^ t[1][(v >> 8) & 0xFF] ^ t[2][(v >> 16) & 0xFF]
               ^ t[3][v >> 24])


_CRC_TABLE: np.ndarray | None = None
_STRIDE = 16                    # prefix CRCs are kept at every 16th byte


def _crc_table() -> np.ndarray:
    """The reflected CRC-32 byte table (256 uint32): raw register update by one byte."""
    global _CRC_TABLE
    if _CRC_TABLE is None:
        _CRC_TABLE = np.array([zlib.crc32(bytes([b]), 0xFFFFFFFF) ^ 0xFFFFFFFF
                               for b in range(256)], dtype=np.uint32)
    return _CRC_TABLE


class _PrefixCrc:
    """``crc32(buf[:q])`` for arrays of offsets q, with work linear in the bytes covered.

    Keeps the prefix CRC at every ``_STRIDE``-th byte (filled by zlib as far as asked, once per
    buffer); an arbitrary q steps on from the stride point before it, at most ``_STRIDE - 1``
    bytes, vectorised over all q at once."""

    def __init__(self, buf: memoryview) -> None:
        self.buf = buf
        self.bytes = np.frombuffer(buf, dtype=np.uint8)
        self.stride = np.zeros(1, dtype=np.uint32)      # crc32(buf[:k * _STRIDE])

    def _extend(self, upto: int) -> np.ndarray:
        """The stride CRCs up to offset ``upto`` (computed once, then kept)."""
        k = self.stride.size - 1
        if k * _STRIDE >= upto:
            return self.stride
        buf, crc32 = self.buf, zlib.crc32
        crc = int(self.stride[-1])
        more: list[int] = []
        append = more.append
        while k * _STRIDE < upto:
            crc = crc32(buf[k * _STRIDE:(k + 1) * _STRIDE], crc)
            append(crc)
            k += 1
        self.stride = np.concatenate([self.stride, np.array(more, dtype=np.uint32)])
        return self.stride

    def at(self, q: np.ndarray) -> np.ndarray:
        top = int(q.max())
        strides = self._extend(top - top % _STRIDE)
        k0 = q // _STRIDE
        reg = ~strides[k0]                     # the raw register (zlib inverts in and out)
        rest = q - k0 * _STRIDE
        table = _crc_table()
        for t in range(int(rest.max()) if rest.size else 0):
            live = rest > t
            byte = self.bytes[np.minimum(k0 * _STRIDE + t, len(self.bytes) - 1)]
            step = (reg >> np.uint32(8)) ^ table[(reg ^ byte) & np.uint32(0xFF)]
            reg = np.where(live, step, reg)
        return ~reg


def _crc_of_ranges(prefix: _PrefixCrc, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """crc32(buf[s:e]) for every pair, from the prefix CRCs at both ends."""
    p_start, p_end = prefix.at(starts), prefix.at(ends)
    length = ends - starts
    tables = _zero_byte_tables()
    v = p_start
    for j in range(int(length.max()).bit_length()):
        sel = ((length >> j) & 1).astype(bool)
        if sel.any():
            v[sel] = _apply_zero(tables[j], v[sel])
    return p_end ^ v


def _valid_in(buf: memoryview, lo: int, hi: int, max_bytes: int,
              prefix: _PrefixCrc) -> np.ndarray:
    """Offsets in ``[lo, hi)`` where a frame with a matching CRC starts (as ``_valid_at``)."""
    size = len(buf)
    hdr = FRAME_HEADER.size
    hi = min(hi, size - hdr + 1)
    if hi <= lo:
        return np.zeros(0, dtype=np.int64)
    raw = np.frombuffer(buf, dtype=np.uint8, count=hi - lo + hdr - 1, offset=lo)
    m = hi - lo
    b = [raw[i:i + m].astype(np.int64) for i in range(4)]
    n = b[0] | (b[1] << 8) | (b[2] << 16) | (b[3] << 24)
    pos = np.arange(lo, hi, dtype=np.int64)
    end = pos + hdr + n
    ok = np.flatnonzero((n > 0) & (n <= max_bytes) & (end <= size))
    if not ok.size:
        return np.zeros(0, dtype=np.int64)
    pos, end = pos[ok], end[ok]
    c = [raw[ok + i].astype(np.uint32) for i in range(4, 8)]
    crc = c[0] | (c[1] << 8) | (c[2] << 16) | (c[3] << 24)
    good = _crc_of_ranges(prefix, pos + hdr, end) == crc
    return pos[good]


#: Candidate offsets right after the damage that are checked one at a time (parsing the
#: length, and a zlib CRC when the claimed payload is short) before the windowed search: on a
#: densely damaged segment the next frame is usually a few bytes away, and a fixed window of
#: 16 384 vectorised candidates per resync cost ~140 CPU-s per MB (#26 item 10).
_NEAR = 64
#: Payload bytes those one-at-a-time CRCs may cover per resync (longer claims are left to the
#: windowed search, whose cost per candidate does not grow with the claimed length), so a
#: crafted file cannot make the near search quadratic.
_NEAR_CRC_BYTES = 1 << 12
_WINDOW_NEAR = 1 << 8           # first window of the search after that, doubled up to
                                # _WINDOW_MAX


def _resync(buf: memoryview, start: int, max_bytes: int,
            prefix: _PrefixCrc | None = None) -> int | None:
    """Offset of the next position at or after ``start`` where a valid frame begins.

    Same answer as trying ``_valid_at`` at every offset in turn. Work grows with the distance
    to that frame, not with a fixed window: the first ``_NEAR`` offsets are tried one at a
    time (a frame claiming a long payload there is deferred), then windows of candidates that
    double from ``_WINDOW_NEAR``, each checked with prefix CRCs in time independent of the
    claimed lengths (linear in the bytes searched overall)."""
    size = len(buf)
    hdr = FRAME_HEADER.size
    deferred: int | None = None          # first near offset whose long claim was not checked
    budget = _NEAR_CRC_BYTES
    stop = min(start + _NEAR, size - hdr + 1)
    for q in range(start, stop):
        n = int.from_bytes(buf[q:q + 4], "little")
        if n == 0 or n > max_bytes or q + hdr + n > size:
            continue
        if n > budget:
            deferred = q if deferred is None else deferred
            continue
        budget -= n
        if _valid_at(buf, q, max_bytes) is not None:
            if deferred is None:
                return q
            prefix = prefix or _PrefixCrc(buf)
            found = _valid_in(buf, deferred, q, max_bytes, prefix)
            return int(found[0]) if found.size else q
    prefix = prefix or _PrefixCrc(buf)
    pos = deferred if deferred is not None else max(stop, start)
    window = _WINDOW_NEAR
    while pos + hdr <= size:
        found = _valid_in(buf, pos, pos + window, max_bytes, prefix)
        if found.size:
            return int(found[0])
        pos += window
        window = min(2 * window, _WINDOW_MAX)
    return None


def segment_files(path: str | Path) -> list[Path]:
    """The segment files of a recording: the file itself, or a directory's ``*.avr`` files in
    data order (:func:`order_segments`: read from their frames, never from their names)."""
    p = Path(path)
    if p.is_dir():
        files = [f for f in p.iterdir() if f.suffix == SEGMENT_SUFFIX and f.is_file()]
        if not files:
            raise FormatError(f"{p}: no {SEGMENT_SUFFIX} segment files in this directory; "
                              "point at a recording directory written by `avard run`")
        return order_segments(files)
    if not p.exists():
        raise FormatError(f"{p}: no such recording file or directory")
    return [p]


#: A run id begins with its run sequence number, ``nSSSSSSSS-`` (daemon/service/recorder.py
#: ``new_run_id``); ids written before that begin with a UTC stamp and sort before them.
_RUN_SEQ = re.compile(r"n(\d+)-")


@dataclass(frozen=True, order=True)
class SegmentKey:
    """Where a segment sits in its recording, read from its frames: the run (by its sequence
    number), then the first sample index its sample records name (raw, gap: the recorder
    writes them in sample order; a segment without one in its first records takes its first
    ``temp`` or ``event`` index, which can be a drain early: those are stamped in another
    thread before they are queued), then the sequence number of its first header
    (segments of one run that start at the same index), then the name (only to make the
    order total). Names are not trusted: ``_9999_`` sorted after ``_10000_`` while the field
    was four digits wide, and a file can be renamed."""

    run_seq: int            # -1 for an old stamp-first run id, then ordered by ``run``
    run: str
    i0: int                 # NO_INDEX when no record of the file names an index
    header_seq: int         # -1 when the file holds no readable header
    name: str


#: ``SegmentKey.i0`` of a file with no readable record: after its run's readable segments.
NO_INDEX = 1 << 62
#: Records read from a segment's start to find its first sample index (the recorder writes
#: the header, perhaps a gap or event, then the first raw block).
_HEAD_RECORDS = 64


def run_order(run: str) -> tuple[int, str]:
    """Sort key of a run id: its run sequence number, or -1 then the id for old ids."""
    m = _RUN_SEQ.match(run)
    return (int(m.group(1)) if m else -1, run)


def _head_records(path: Path) -> Iterator[dict[str, Any] | None]:
    """The first records of a segment, read frame by frame from its start (a few small
    reads, not the file); yields None and stops at the first frame that does not check."""
    from avard.core.io import frames as wire

    with open(path, "rb") as f:
        for _ in range(_HEAD_RECORDS):
            head = f.read(FRAME_HEADER.size)
            if len(head) < FRAME_HEADER.size:
                return
            n, crc = FRAME_HEADER.unpack(head)
            if n == 0 or n > MAX_FRAME_BYTES:
                yield None
                return
            payload = f.read(n)
            if len(payload) != n or zlib.crc32(payload) & 0xFFFFFFFF != crc:
                yield None
                return
            try:
                yield wire.decode(payload)
            except FormatError:
                yield None
                return


#: Keys already read, by (path, inode, size, mtime): the service orders its recording at
#: every start (restore, last_recorded, retention) and a weekend at segment_s = 10 s makes
#: 21 600 files; a file that changed in any way is read again.
_KEYS: dict[tuple[str, int, int, int], SegmentKey] = {}
_KEYS_MAX = 1 << 17


_ENDS: dict[tuple[str, int, int, int], int] = {}


def _stamp(p: Path) -> tuple[str, int, int, int] | None:
    try:
        st = p.stat()
    except OSError:
        return None
    return (str(p), st.st_ino, st.st_size, st.st_mtime_ns)


def _cached(cache: dict[tuple[str, int, int, int], Any], p: Path, read: Any) -> Any:
    stamp = _stamp(p)
    if stamp is not None and stamp in cache:
        return cache[stamp]
    value = read(p)
    if stamp is not None:
        if len(cache) >= _KEYS_MAX:
            cache.clear()
        cache[stamp] = value
    return value


def segment_key(path: str | Path) -> SegmentKey:
    """A segment's :class:`SegmentKey`, from the records at its start; after damage there,
    from a scan of the whole file (resynchronising). A file with no record naming an index
    takes its header's; with no readable record at all, its name's run id and NO_INDEX."""
    key: SegmentKey = _cached(_KEYS, Path(path), _read_segment_key)
    return key


def segment_end(path: str | Path) -> int:
    """The index after the last sample of a segment's last readable raw block; NO_INDEX
    when it holds none (read from the file's end, kept while the file is unchanged)."""
    def read(p: Path) -> int:
        try:
            rec = last_record(p, "raw")
        except (OSError, FormatError):
            rec = None
        return NO_INDEX if rec is None else int(rec["i0"]) + int(rec["n"])

    end: int = _cached(_ENDS, Path(path), read)
    return end


#: Records that carry samples' indices in sample order. ``temp`` and ``event`` records are
#: stamped with the ring's index in another thread before they are queued, so one can land
#: at a segment's start naming an index the previous segment's samples still cover.
_SAMPLE_KINDS = ("raw", "gap")


def _read_segment_key(p: Path) -> SegmentKey:
    header: dict[str, Any] | None = None
    first: dict[str, Any] | None = None       # the first sample record (raw or gap)
    other: dict[str, Any] | None = None       # else the first record naming an index

    def take(rec: dict[str, Any]) -> None:
        nonlocal header, first, other
        if rec["kind"] == "header":
            header = header or rec
        elif rec["kind"] in _SAMPLE_KINDS:
            first = first or rec
        elif "i0" in rec and rec["i0"] is not None:
            other = other or rec

    damaged = False
    try:
        for rec in _head_records(p):
            if rec is None:
                damaged = True
                break
            take(rec)
            if first is not None:
                break
        if first is None and damaged:
            for rec in RecordingReader(p):
                take(rec)
                if first is not None:
                    break
    except (OSError, FormatError):
        pass
    ref = first or other or header
    if ref is None:
        return SegmentKey(*run_order(p.name.split("_", 1)[0]), NO_INDEX, -1, p.name)
    seq = int(header["seq"]) if header is not None and header["run"] == ref["run"] else -1
    return SegmentKey(*run_order(str(ref["run"])), int(ref["i0"]), seq, p.name)


def keyed_segments(paths: Iterable[str | Path]) -> list[tuple[SegmentKey, Path]]:
    """Segment files with their :func:`segment_key`, in data order (a few small reads per
    file). The one ordering every reader of a recording uses: the walk, the service's
    restore and ``last_recorded``, retention's "oldest first"."""
    return sorted((segment_key(p), Path(p)) for p in paths)


def order_segments(paths: Iterable[str | Path]) -> list[Path]:
    """Segment files in data order (:func:`keyed_segments` without the keys)."""
    return [p for _, p in keyed_segments(paths)]


def _listed_frames(path: str | Path, max_bytes: int) -> tuple[list[int], int, int] | None:
    """Frame offsets from the length fields alone, the byte where the listing stopped (a
    length of 0 or one past the end of the file) and the file size; None when a length
    field is implausible."""
    offsets = []
    with open(path, "rb") as f:
        size = f.seek(0, 2)
        pos = 0
        while pos + FRAME_HEADER.size <= size:
            f.seek(pos)
            n, _crc = FRAME_HEADER.unpack(f.read(FRAME_HEADER.size))
            if n > max_bytes:
                return None
            end = pos + FRAME_HEADER.size + n
            # n == 0 is never a record (see _valid_at): a zero-filled tail, also ended here
            if n == 0 or end > size:
                break
            offsets.append(pos)
            pos = end
    return offsets, pos, size


def frame_offsets(path: str | Path, *, max_bytes: int = MAX_FRAME_BYTES) -> list[int] | None:
    """Byte offsets of the frames of a segment from their length fields alone (no CRC, no
    decoding): fast for finding the tail of an hour-long segment at start-up. A length of 0
    (a zero-filled tail) or one running past the end of the file ends the listing (a torn
    tail, or a flipped bit in a length: :func:`records_backwards` tells them apart). None
    when a length field is implausible (damage): then the file must be scanned."""
    listed = _listed_frames(path, max_bytes)
    return None if listed is None else listed[0]


def _scanned_offsets(path: str | Path, start: int = 0) -> list[int]:
    """Offsets of the valid frames of a segment from byte ``start`` on, read forwards,
    resynchronising; the file is mapped, not read into memory, and only the offsets are
    kept (an hour-long segment at 4 kHz is ~170 MB)."""
    with open(path, "rb") as f:
        if f.seek(0, 2) <= start:
            return []
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mapped:
            view = memoryview(mapped)
            problems: list[Problem] = []
            try:
                return [start + fr.offset
                        for fr in scan_frames(view[start:], str(path), problems=problems)]
            finally:
                view.release()
                for prob in problems:         # damage is never silent (a torn tail is
                    if prob.kind != "truncated":  # what a power cut leaves: not news)
                        log.warning("%s", replace(prob, offset=start + prob.offset))


def _checked_offsets(path: str | Path) -> list[int]:
    """Offsets of the valid frames of a segment, from the length fields where they can be
    trusted, else from a forward scan (resynchronising).

    A power cut leaves only a torn last frame, which the listing never includes. So a last
    listed frame that fails its CRC is damage (a wrong length led the walk astray): the file
    is scanned. A listing that stops on a length past the end of the file is either that torn
    tail or a flipped bit in a length field: the bytes from there are scanned (a torn tail is
    shorter than one frame, so this costs nothing after a power cut), and any valid frame
    found there is damage's survivor, kept."""
    listed = _listed_frames(path, MAX_FRAME_BYTES)
    if listed is None:
        return _scanned_offsets(path)
    offsets, stop, size = listed
    if offsets and read_frame_at(path, offsets[-1]) is None:
        return _scanned_offsets(path)
    if stop < size:
        offsets += _scanned_offsets(path, stop)
    return offsets


def read_frame_at(path: str | Path, offset: int) -> dict[str, Any] | None:
    """Decode the frame at ``offset`` if its CRC and record are valid, else None."""
    from avard.core.io import frames as wire

    with open(path, "rb") as f:
        f.seek(offset)
        head = f.read(FRAME_HEADER.size)
        if len(head) < FRAME_HEADER.size:
            return None
        n, crc = FRAME_HEADER.unpack(head)
        if n > MAX_FRAME_BYTES:
            return None
        payload = f.read(n)
    if len(payload) != n or zlib.crc32(payload) & 0xFFFFFFFF != crc:
        return None
    try:
        return wire.decode(payload)
    except FormatError:
        return None


def records_backwards(path: str | Path) -> Iterator[dict[str, Any]]:
    """The valid records of one segment file, newest first, read from the end (frame offsets
    from the length fields, checked: :func:`_checked_offsets`); a damaged file is scanned
    forwards once (resynchronising) for its frame offsets alone, so what is held is one
    offset per frame and the records being looked at, never the file or all its records."""
    for off in reversed(_checked_offsets(path)):
        hit = read_frame_at(path, off)
        if hit is not None:
            yield hit


def last_record(path: str | Path, kind: str) -> dict[str, Any] | None:
    """The last valid record of ``kind`` in one segment file, reading from the end."""
    return next((rec for rec in records_backwards(path) if rec["kind"] == kind), None)


def first_record(path: str | Path) -> dict[str, Any] | None:
    """The first record of a segment (its header), or None if it is unreadable."""
    return read_frame_at(path, 0)


@dataclass
class RecordingReader:
    """Iterate over the decoded records of a recording (a segment file or a directory).

    ``problems`` lists every truncated tail and corrupt frame met so far, by file and byte
    offset. With ``strict=True`` a corrupt frame in the middle raises :class:`FormatError`
    naming its position instead (a truncated tail never raises: it is what a power cut leaves).
    """

    path: str | Path
    strict: bool = False
    max_bytes: int = MAX_FRAME_BYTES
    problems: list[Problem] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.files = segment_files(self.path)
        self.current: Path | None = None   # the segment file being read

    def frames(self) -> Iterator[Frame]:
        for f in self.files:
            self.current = f
            data = f.read_bytes()
            local: list[Problem] = []
            for fr in scan_frames(data, str(f), max_bytes=self.max_bytes, problems=local):
                self._report(local)
                yield fr
            self._report(local)

    def _report(self, local: list[Problem]) -> None:
        while local:
            prob = local.pop(0)
            if self.strict and prob.kind != "truncated":
                raise FormatError(f"{prob}; read with strict=False to skip it and go on")
            log.warning("%s", prob)
            self.problems.append(prob)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        for fr in self.frames():
            rec = self.decoded(fr)
            if rec is not None:
                yield rec

    def decoded(self, fr: Frame) -> dict[str, Any] | None:
        """A frame's record, or None when it does not decode (reported as undecodable)."""
        from avard.core.io import frames as wire  # the record schema shared with the wire

        try:
            return wire.decode(fr.payload, max_bytes=self.max_bytes)
        except FormatError as exc:
            size = FRAME_HEADER.size + len(fr.payload)  # the whole frame is lost
            self._report([Problem(fr.file, fr.offset, "undecodable", size, str(exc))])
            return None

    @property
    def dropped_bytes(self) -> int:
        return sum(p.dropped_bytes for p in self.problems)


# --------------------------------------------------------------------------------------------
# one walk over a recording: headers recovered, losses in samples, duplicates counted once


@dataclass(frozen=True)
class Loss:
    """Samples ``[i0, i0 + n)`` of run ``run`` that the recording lacks because of damage (a
    corrupt or truncated frame, or no surviving header): not a recorded gap."""

    run: str
    i0: int
    n: int
    cause: str

    def __str__(self) -> str:
        return f"samples [{self.i0}, {self.i0 + self.n}) of run {self.run} lost: {self.cause}"


@dataclass
class WalkReport:
    """What :func:`walk` had to repair or drop, in samples: losses (damage), duplicates (index
    ranges met more than once: counted once, reported here), header copies used in place of a
    damaged header."""

    losses: list[Loss] = field(default_factory=list)
    duplicates: list[tuple[int, int]] = field(default_factory=list)   # (i0, n) dropped
    # the file each duplicate was read in (the walk drops it there, before the next record)
    duplicate_files: list[str] = field(default_factory=list)
    recovered_headers: list[str] = field(default_factory=list)        # runs
    # each run's newest readable header: the service rewrites it as its fit of the output
    # rate improves, so this one carries the run's best rate (copies are not yielded again)
    newest_header: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def samples_lost(self) -> int:
        return sum(loss.n for loss in self.losses)

    @property
    def samples_duplicated(self) -> int:
        return sum(n for _, n in self.duplicates)


class _IndexSet:
    """Disjoint sorted ``[lo, hi)`` ranges of sample indices already seen (merged as they
    grow), so a duplicated or overlapping raw block is found in O(log ranges)."""

    def __init__(self) -> None:
        self.lo: list[int] = []
        self.hi: list[int] = []

    def unseen(self, i0: int, i1: int) -> list[tuple[int, int]]:
        """The parts of ``[i0, i1)`` not seen yet (and marks all of it seen)."""
        import bisect

        if self.in_order(i0):                         # the common case: data in order
            self._add(i0, i1)
            return [(i0, i1)]
        out, at = [], i0
        k = bisect.bisect_right(self.hi, i0)
        while at < i1 and k < len(self.lo):
            if self.lo[k] > at:
                out.append((at, min(i1, self.lo[k])))
            at = max(at, self.hi[k])
            k += 1
        if at < i1:
            out.append((at, i1))
        for a, b in out:
            self._add(a, b)
        return out

    def in_order(self, i0: int) -> bool:
        """Whether every index from ``i0`` on is unseen and after all seen (data in order)."""
        return not self.hi or i0 >= self.hi[-1]

    def _add(self, a: int, b: int) -> None:
        import bisect

        k = bisect.bisect_left(self.lo, a)
        self.lo.insert(k, a)
        self.hi.insert(k, b)
        # merge with neighbours that touch
        if k + 1 < len(self.lo) and self.lo[k + 1] <= self.hi[k]:
            self.hi[k] = max(self.hi[k], self.hi.pop(k + 1))
            self.lo.pop(k + 1)
        if k > 0 and self.hi[k - 1] >= self.lo[k]:
            self.hi[k - 1] = max(self.hi[k - 1], self.hi.pop(k))
            self.lo.pop(k)


#: Samples of one run held while waiting for a readable header of that run (the recorder
#: repeats the header every 60 s of data: 240 000 samples at 4 kHz); older ones are reported
#: lost beyond this, so memory stays bounded (about 50 MB of counts).
MAX_HEADERLESS_SAMPLES = 1 << 22


def _taken(rec: dict[str, Any], headers: dict[str, dict[str, Any]], seen: _IndexSet,
           reader: RecordingReader) -> Iterable[dict[str, Any]]:
    """The records one item of the reader stands for. A stretch (``_stretch``: consecutive
    raw blocks of one run, each continuing the last one's index, from the scan's C loop,
    core/io/rawscan.py, with the header records between them) is taken as one raw block when
    its run's header is known, its indices are all new and every header between is a
    readable copy of that run's header: the walk then does for it what it does for its blocks
    one by one (one range seen, the run's next index after its last block, damage before it
    charged to its first), and the copies after it, which only renew the run's newest header,
    in their order. Otherwise its blocks and headers are decoded one by one, in place."""
    stretch = rec.get("_stretch")
    if stretch is None:
        return (rec,)
    run = rec["run"]
    if run in headers and seen.in_order(int(rec["i0"])):
        copies = stretch.copies(run, reader.max_bytes)
        if copies is not None:
            return (rec, *copies)
    return stretch.records(reader.decoded, reader.max_bytes)  # type: ignore[no-any-return]


def walk(reader: RecordingReader, report: WalkReport | None = None
         ) -> Iterator[dict[str, Any]]:
    """The records of a recording as its readers should see them: the one walk used by the
    offline Allan replay, the service's restore, ``load_recording`` and so ``avard analyze``.

    - Every record follows a header of its own run: a header is yielded once per run change
      (a header copy of the same run is not repeated). Records whose segment header is damaged
      wait for the run's header from another segment or a later copy in the same segment; if
      none survives their samples are reported lost.
    - Raw samples whose indices were met before (a segment copied twice, overlapping runs) are
      dropped and reported in ``report.duplicates``: every sample index counts once. Other
      records met twice (same run, kind and sequence number) are dropped too.
    - A jump in a run's sample index after a corrupt or truncated frame is reported in
      ``report.losses`` as the index range it cost.
    """
    report = report if report is not None else WalkReport()
    headers: dict[str, dict[str, Any]] = {}
    # records waiting for their run's header, each with the damage read just before it
    pending: dict[str, list[tuple[dict[str, Any], str | None]]] = {}
    held: dict[str, int] = {}                # samples waiting in ``pending``, per run
    seen_idx = _IndexSet()
    # (run, kind) -> the sequence numbers met, as ranges: a set of every (run, kind, seq) grew
    # by ~200 bytes a record (120 MB over 60 h of temperature records), this by a range per
    # gap in the numbering
    seen_seq: dict[tuple[str, str], _IndexSet] = {}
    expect: dict[str, int] = {}              # next sample index of each run
    started: set[str] = set()                # runs whose first raw block was read
    run_now: str | None = None
    n_problems = 0
    damage: dict[str, str] = {}              # per run: the first problem since its last block

    def emit(rec: dict[str, Any], dmg: str | None) -> Iterator[dict[str, Any]]:
        nonlocal run_now
        run = rec["run"]
        if dmg is not None:
            damage.setdefault(run, dmg)
        if run != run_now:
            run_now = run
            yield headers[run]
        kind = rec["kind"]
        if kind != "raw":
            seq = int(rec["seq"])
            if not seen_seq.setdefault((run, kind), _IndexSet()).unseen(seq, seq + 1):
                return
            if kind == "gap" and run in expect:
                # a recorded gap explains its samples: they are not a loss to damage
                expect[run] = max(expect[run], int(rec["i0"]) + int(rec["n"]))
            elif (kind == "event" and rec["name"] == "start" and "i0" in rec
                  and run not in started):
                expect[run] = int(rec["i0"])     # the run's first sample index, exactly
            yield rec
            return
        started.add(run)
        i0, n = int(rec["i0"]), int(rec["n"])
        why = damage.pop(run, None)
        if why is not None and run in expect and i0 > expect[run]:
            report.losses.append(Loss(run, expect[run], i0 - expect[run], why))
            log.warning("%s", report.losses[-1])
        expect[run] = max(expect.get(run, 0), i0 + n)
        parts = seen_idx.unseen(i0, i0 + n)
        if parts == [(i0, i0 + n)]:
            yield rec
            return
        kept = sum(b - a for a, b in parts)
        if kept < n:
            report.duplicates.append((i0, n - kept))
            report.duplicate_files.append(str(reader.current or ""))
            # one line per block would be 3600 an hour of a copied segment: the readers
            # summarise report.duplicates (core/io/source.py: one WARNING per run)
            log.debug("samples [%d, %d) of run %s were already read; counted once",
                      i0, i0 + n, run)
        for a, b in parts:
            yield dict(rec, i0=a, n=b - a, counts=rec["counts"][a - i0:b - i0])

    carry: str | None = None                 # a problem read since the last record used
    for item in reader:
        # a stretch of raw blocks read by the scan's C loop (core/io/rawscan.py) is one
        # block where that is the same as its blocks one by one, else its blocks
        for rec in _taken(item, headers, seen_idx, reader):
            if len(reader.problems) > n_problems:
                carry = carry or str(reader.problems[n_problems])
                n_problems = len(reader.problems)
            run = rec["run"]
            if rec["kind"] == "header":
                report.newest_header[run] = rec
                if run in headers:
                    continue                      # a header copy: the run is already known
                headers[run] = rec
                # where the run's samples start (the service's header may be a little ahead of
                # its first block; the start event, when there is one, is exact)
                expect.setdefault(run, int(rec["i0"]))
                if run in pending:
                    report.recovered_headers.append(run)
                held.pop(run, None)
                for late, dmg in pending.pop(run, []):
                    yield from emit(late, dmg)
                if run_now is None or run_now != run:
                    run_now = run
                    yield rec
                continue
            if run not in headers:
                waiting = pending.setdefault(run, [])
                waiting.append((rec, carry))
                carry = None
                held[run] = held.get(run, 0) + int(rec.get("n", 0))
                while held[run] > MAX_HEADERLESS_SAMPLES and waiting:
                    # memory stays bounded however long a run goes without a readable header
                    old, _ = waiting.pop(0)
                    if old["kind"] == "raw":
                        held[run] -= int(old["n"])
                        expect[run] = max(expect.get(run, 0), int(old["i0"]) + int(old["n"]))
                        report.losses.append(Loss(run, int(old["i0"]), int(old["n"]),
                                                  f"no header of run {run} within "
                                                  f"{MAX_HEADERLESS_SAMPLES} samples"))
                        log.warning("%s", report.losses[-1])
                continue
            yield from emit(rec, carry)
            carry = None
    for run, recs in pending.items():
        for rec, _ in recs:
            if rec["kind"] == "raw":
                report.losses.append(Loss(run, int(rec["i0"]), int(rec["n"]),
                                          f"no header of run {run} survived"))
                log.warning("%s", report.losses[-1])


# --------------------------------------------------------------------------------------------
# streaming iteration and the whole-record loader


@dataclass
class _FallbackRecord:
    """The fields of ``avard.core.io.readers.Record`` (used only if readers is unavailable)."""

    accel: np.ndarray
    rate_hz: float
    names: list[str]
    temperature_c: np.ndarray | None
    temperature_names: list[str]
    source: str
    gyro: np.ndarray | None
    meta: dict[str, Any]


@dataclass
class Block:
    """Consecutive raw samples of one raw record, converted to SI units."""

    i0: int
    counts: np.ndarray        # (n, 3) int32
    accel: np.ndarray         # (n, 3) float64 m/s²
    t_mono: float             # CLOCK_MONOTONIC s of the first sample
    t_real: float             # CLOCK_REALTIME s of the first sample


def iter_records(path: str | Path, *, strict: bool = False,
                 reader: RecordingReader | None = None) -> Iterator[dict[str, Any]]:
    """Every decoded record of a recording in order (see :class:`RecordingReader`)."""
    yield from (reader or RecordingReader(path, strict=strict))


def replay_allan(path: str | Path, *, streaming_cls: Any = None,
                 reader: RecordingReader | None = None,
                 report: WalkReport | None = None) -> Any:
    """Recompute the service's streaming Allan accumulators offline from a recording.

    Feeds exactly what the service fed (:meth:`AllanFeed.replay` over :func:`walk`), with a
    segment break at every gap record, index jump and run change, so the result equals the
    service's own snapshot. Returns the StreamingAllan.
    """
    if streaming_cls is None:
        from avard.core.allan.streaming import StreamingAllan

        streaming_cls = StreamingAllan
    records = walk(reader or RecordingReader(path), report)
    for first in records:
        names = list(first.get("temperature_channels", []))
        allan = streaming_cls(3 + len(names), float(first["rate_hz"]),
                              names=["x", "y", "z", *names])
        feed = AllanFeed(allan, scale_of(first), names)
        feed.apply(first)
        feed.replay(records)
        return allan
    raise FormatError(f"{path}: no header record found; not an avard recording")


def _hold_on_grid(idx: np.ndarray, tnames: list[str],
                  temps: list[tuple[int, list[str], list[Any]]]) -> np.ndarray:
    """Temperature channels on the sample grid: each reading held from its index on
    (zero-order hold, NaN before a channel's first reading); O(N log R), not O(N·R)."""
    out = np.full((idx.shape[0], len(tnames)), np.nan)
    col = {n: i for i, n in enumerate(tnames)}
    per: list[tuple[list[int], list[float]]] = [([], []) for _ in tnames]
    for i0, names, values in temps:
        for name, value in zip(names, values, strict=True):
            if name in col and value is not None:
                per[col[name]][0].append(int(i0))
                per[col[name]][1].append(float(value))
    for c, (starts, vals) in enumerate(per):
        if not starts:
            continue
        st = np.asarray(starts, dtype=np.int64)
        order = np.argsort(st, kind="stable")      # later records win at equal index
        st, v = st[order], np.asarray(vals)[order]
        k = np.searchsorted(st, idx, side="right") - 1
        have = k >= 0
        out[have, c] = v[k[have]]
    return out


def load_recording(path: str | Path, *, strict: bool = False) -> Any:
    """Load a whole recording as an :class:`avard.core.io.readers.Record` in SI units.

    ``accel`` is (N, 3) m/s² (raw counts × the header's ``scale_m_s2_per_count``) of every
    recorded sample in recording order (each sample index once); ``temperature_c`` holds the
    temperature channels held at their last reading on the sample grid (NaN before a
    channel's first reading). In ``meta``: the sample indices, gaps (first index, count,
    reason), events, headers, every skipped or truncated frame (``problems``), the samples
    damage cost (``losses``: index ranges), duplicated index ranges counted once
    (``duplicates``), and ``segment_bounds``: where the service's accumulators broke their
    segments (every gap record, run change and index jump); nothing lost passes silently.
    """
    record_cls: Any
    try:
        from avard.core.io.readers import Record

        record_cls = Record
    except ImportError:  # readers.py not present (partial install): same fields, plain class
        record_cls = _FallbackRecord

    reader = RecordingReader(path, strict=strict)
    report = WalkReport()
    cuts = Segmenter()
    headers: list[dict[str, Any]] = []
    blocks: list[np.ndarray] = []
    index: list[np.ndarray] = []
    temps: list[tuple[int, list[str], list[Any]]] = []
    gaps: list[dict[str, Any]] = []
    events: list[dict[str, Any]] = []
    scale = 0.0
    last_avar = None
    for rec in walk(reader, report):
        kind = rec["kind"]
        cuts.starts_segment(rec)
        if kind == "header":
            headers.append(rec)
            scale = scale_of(rec)
        elif kind == "raw":
            blocks.append(np.asarray(rec["counts"], dtype=np.float64) * scale)
            index.append(rec["i0"] + np.arange(rec["n"], dtype=np.int64))
        elif kind == "temp":
            temps.append((rec["i0"], rec["names"], rec["values_c"]))
        elif kind == "gap":
            gaps.append({k: rec[k] for k in ("i0", "n", "reason", "run", "t_real")})
        elif kind == "event":
            events.append({k: rec.get(k) for k in ("name", "i0", "t_real", "detail", "run")})
        elif kind == "avar":
            last_avar = rec
    if not headers:
        lost = f" ({report.samples_lost} samples without a header)" if report.losses else ""
        raise FormatError(f"{path}: no header record found{lost}; not an avard recording, or "
                          "every header copy of it is damaged")
    accel = np.concatenate(blocks) if blocks else np.zeros((0, 3))
    idx = np.concatenate(index) if index else np.zeros(0, dtype=np.int64)
    tnames: list[str] = []
    for h in headers:
        for name in h.get("temperature_channels", []):
            if name not in tnames:
                tnames.append(name)
    temperature = None
    if tnames:
        temperature = _hold_on_grid(idx, tnames, temps)
    # runs at another ODR setting are another record (their samples are not these τ): the
    # record source refuses them the same way, by its rate rule
    nominals = {run: nominal_of(h) for run, h in report.newest_header.items()}
    if len({v for v in nominals.values() if v is not None}) > 1:
        listed = "; ".join(f"run {run} at {v:g} Hz" for run, v in nominals.items()
                           if v is not None)
        raise DataError(f"{path}: runs at different output data rates ({listed}); they are "
                        "not one record: analyse each separately with --run RUN")
    # each run's newest header carries its best fit of the output rate; runs are averaged
    fitted = {run: float(h["rate_hz"]) for run, h in report.newest_header.items()}
    rates = list(fitted.values())
    scales = {scale_of(h) for h in headers}
    meta = {
        "format": "avard-recording",
        "files": [str(f) for f in reader.files],
        "index": idx,
        "segment_bounds": cuts.segment_bounds(),
        "gaps": gaps,
        "events": events,
        "headers": [{k: v for k, v in h.items() if k != "config"} for h in headers],
        "config": headers[0].get("config", {}),
        "problems": [str(p) for p in reader.problems],
        "dropped_bytes": reader.dropped_bytes,
        "losses": [{"run": x.run, "i0": x.i0, "n": x.n, "cause": x.cause}
                   for x in report.losses],
        "samples_lost": report.samples_lost,
        "duplicates": [{"i0": a, "n": n} for a, n in report.duplicates],
        "samples_duplicated": report.samples_duplicated,
        "rates_hz": rates,
        # one LSB for the whole record (m/s²), or None when runs used different ranges
        "lsb_mps2": scales.pop() if len(scales) == 1 else None,
        "last_avar": last_avar,
        "units": {"accel": "m/s^2", "temperature": "degC", "rate": "Hz"},
    }
    return record_cls(accel=accel, rate_hz=float(np.mean(rates)),
                  names=["x", "y", "z"],
                  temperature_c=temperature, temperature_names=tnames,
                  source=str(path), gyro=None, meta=meta)
