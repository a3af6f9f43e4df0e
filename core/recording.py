"""Crash-safe recordings: CRC-framed msgpack records in segment files, and their reader.

On disk every record is one frame::

    u32 length (little endian) | u32 crc32 of the payload (little endian) | payload

where the payload is the same msgpack record that goes on the wire (``avard.core.frames``).
A segment file is a sequence of frames that starts with a ``header`` record; a recording is a
file or a directory of segment files, read in name order (names start with the UTC start time).

Why this framing: a power cut can only leave a *truncated* last frame (appends are the only
writes), which the reader detects from the length and drops, saying how many bytes it dropped.
A flipped bit anywhere else fails the CRC; the reader reports that frame by file and byte
offset, resynchronises on the next valid frame and goes on, so one bad sector never costs the
rest of a 60-hour run and never passes silently.

This module never touches hardware or sockets (it is part of ``avard.core``).
"""

from __future__ import annotations

import logging
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import FormatError

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


def scan_frames(data: bytes, name: str = "<bytes>", *, max_bytes: int = MAX_FRAME_BYTES,
                problems: list[Problem] | None = None) -> Iterator[Frame]:
    """Yield the valid frames of one segment's bytes, recording what had to be skipped.

    A frame whose length runs past the end of the data and after which no valid frame follows
    is a truncated tail (the normal result of a power cut): it ends the scan. A frame that
    fails its CRC in the middle is reported as corrupt; the scan resynchronises by searching
    byte by byte for the next offset where a frame with a valid CRC starts.
    """
    problems = problems if problems is not None else []
    buf = memoryview(data)
    pos = 0
    size = len(buf)
    hdr = FRAME_HEADER.size
    while pos < size:
        n = _valid_at(buf, pos, max_bytes)
        if n is not None:
            yield Frame(name, pos, bytes(buf[pos + hdr:pos + hdr + n]))
            pos += hdr + n
            continue
        # Not a valid frame here. Find where the next valid one starts, if any.
        nxt = _resync(buf, pos + 1, max_bytes)
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


def _resync(buf: memoryview, start: int, max_bytes: int) -> int | None:
    """Offset of the next position at or after ``start`` where a valid frame begins."""
    pos = start
    while pos + FRAME_HEADER.size <= len(buf):
        if _valid_at(buf, pos, max_bytes) is not None:
            return pos
        pos += 1
    return None


def segment_files(path: str | Path) -> list[Path]:
    """The segment files of a recording: the file itself, or a directory's ``*.avr`` files in
    name order (names are ``RUN_NNNN_STAMP.avr`` and a run id begins with the run's UTC start
    time, so name order is data order)."""
    p = Path(path)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix == SEGMENT_SUFFIX and f.is_file())
        if not files:
            raise FormatError(f"{p}: no {SEGMENT_SUFFIX} segment files in this directory; "
                              "point at a recording directory written by `avard run`")
        return files
    if not p.exists():
        raise FormatError(f"{p}: no such recording file or directory")
    return [p]


def frame_offsets(path: str | Path, *, max_bytes: int = MAX_FRAME_BYTES) -> list[int] | None:
    """Byte offsets of the frames of a segment from their length fields alone (no CRC, no
    decoding): fast for finding the tail of an hour-long segment at start-up. A truncated
    last frame is left out. None when a length field is implausible (damage): then read the
    file with :class:`RecordingReader`."""
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
            if end > size:
                break
            offsets.append(pos)
            pos = end
    return offsets


def read_frame_at(path: str | Path, offset: int) -> dict[str, Any] | None:
    """Decode the frame at ``offset`` if its CRC and record are valid, else None."""
    from . import frames as wire

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


def last_record(path: str | Path, kind: str) -> dict[str, Any] | None:
    """The last valid record of ``kind`` in one segment file, reading from the end."""
    offsets = frame_offsets(path)
    if offsets is None:
        found = None
        for rec in RecordingReader(path):
            if rec["kind"] == kind:
                found = rec
        return found
    for off in reversed(offsets):
        rec = read_frame_at(path, off)
        if rec is not None and rec["kind"] == kind:
            return rec
    return None


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

    def frames(self) -> Iterator[Frame]:
        for f in self.files:
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
        from . import frames as wire  # the record schema shared with the wire

        for fr in self.frames():
            try:
                rec = wire.decode(fr.payload, max_bytes=self.max_bytes)
            except FormatError as exc:
                size = FRAME_HEADER.size + len(fr.payload)  # the whole frame is lost
                self._report([Problem(fr.file, fr.offset, "undecodable", size, str(exc))])
                continue
            yield rec

    @property
    def dropped_bytes(self) -> int:
        return sum(p.dropped_bytes for p in self.problems)


# --------------------------------------------------------------------------------------------
# the Allan feed: one definition of "what the accumulators saw", shared by service and replay


class AllanFeed:
    """Builds the (n, 3 + k) blocks the streaming Allan accumulators see, from raw and
    temperature records, identically in the service and in an offline replay.

    Channels are the three axes in m/s² (counts × the header's scale) followed by the
    temperature channels in °C, each held at its last reading (zero-order hold) from the
    sample index the reading was stamped with. Feeding starts only once every temperature
    channel has a first reading (a hold needs a value to hold); samples before that are
    counted in ``skipped``. A jump in the sample index or an explicit gap ends the segment
    (``StreamingAllan.gap()``), so no Allan cluster straddles lost samples.

    ``sink`` is anything with ``update(block)`` and ``gap()`` (a StreamingAllan).
    """

    def __init__(self, sink: Any, scale_m_s2_per_count: float, temp_names: list[str]) -> None:
        self.sink = sink
        self.scale = float(scale_m_s2_per_count)
        self.temp_names = list(temp_names)
        self._col = {name: 3 + i for i, name in enumerate(self.temp_names)}
        self._held = np.full(len(self.temp_names), np.nan)
        self._pending: list[tuple[int, np.ndarray]] = []   # (i0, held values from i0 on)
        self.next_index: int | None = None
        self.fed = 0
        self.skipped = 0
        self._open = False          # samples fed since the last gap()

    @property
    def channels(self) -> list[str]:
        return ["x", "y", "z", *self.temp_names]

    def temp(self, i0: int, names: list[str], values_c: list[float | None]) -> None:
        """A temperature reading valid from sample index ``i0`` on (None = failed read)."""
        held = self._pending[-1][1].copy() if self._pending else self._held.copy()
        for name, value in zip(names, values_c, strict=True):
            col = self._col.get(name)
            if col is not None and value is not None:
                held[col - 3] = float(value)
        self._pending.append((int(i0), held))

    def gap(self) -> None:
        """Samples are missing here: end the accumulators' segment."""
        if self._open:
            self.sink.gap()
            self._open = False
        self.next_index = None

    def raw(self, i0: int, counts: np.ndarray) -> None:
        """A block of raw counts (n, 3) for samples ``[i0, i0 + n)``."""
        n = int(counts.shape[0])
        if n == 0:
            return
        if self.next_index is not None and i0 != self.next_index:
            self.gap()
        self.next_index = i0 + n
        block = np.empty((n, 3 + len(self.temp_names)))
        block[:, :3] = np.asarray(counts, dtype=np.float64) * self.scale
        # Piecewise-constant temperature columns: apply the pending readings in order.
        start = 0
        held = self._held
        while self._pending and self._pending[0][0] < i0 + n:
            at, values = self._pending.pop(0)
            cut = max(0, at - i0)
            block[start:cut, 3:] = held
            start = max(start, cut)
            held = values
        block[start:, 3:] = held
        self._held = held
        if len(self.temp_names):
            known = ~np.isnan(block[:, 3:]).any(axis=1)
            if not known.all():
                first = int(np.argmax(known)) if known.any() else n
                self.skipped += first
                block = block[first:]
        if block.shape[0]:
            self.sink.update(block)
            self.fed += block.shape[0]
            self._open = True


# --------------------------------------------------------------------------------------------
# streaming iteration and the whole-record loader


@dataclass
class _FallbackRecord:
    """The fields of ``avard.core.readers.Record`` (used only if readers is unavailable)."""

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


def _scale_of(header: dict[str, Any]) -> float:
    scale = header.get("scale_m_s2_per_count")
    if not isinstance(scale, int | float) or not scale > 0:
        raise FormatError(f"header of run {header.get('run')!r} has no positive "
                          "scale_m_s2_per_count; this recording cannot be converted to m/s²")
    return float(scale)


def iter_records(path: str | Path, *, strict: bool = False,
                 reader: RecordingReader | None = None) -> Iterator[dict[str, Any]]:
    """Every decoded record of a recording in order (see :class:`RecordingReader`)."""
    yield from (reader or RecordingReader(path, strict=strict))


def replay_allan(path: str | Path, *, streaming_cls: Any = None,
                 reader: RecordingReader | None = None) -> Any:
    """Recompute the service's streaming Allan accumulators offline from a recording.

    Feeds exactly what the service fed (:class:`AllanFeed`), with a segment break at every
    gap record, index jump and run change, so the result equals the service's own snapshot.
    Returns the StreamingAllan.
    """
    if streaming_cls is None:
        from .streaming import StreamingAllan as streaming_cls
    allan = None
    feed: AllanFeed | None = None
    run = None
    for rec in reader or RecordingReader(path):
        kind = rec["kind"]
        if kind == "header":
            names = list(rec.get("temperature_channels", []))
            if allan is None:
                allan = streaming_cls(3 + len(names), float(rec["rate_hz"]),
                                      names=["x", "y", "z", *names])
            if rec["run"] != run or feed is None:
                # A new run (a restart) is a segment break; a new file of the same run is not.
                if feed is not None:
                    feed.gap()
                feed = AllanFeed(allan, _scale_of(rec), names)
            run = rec["run"]
        elif feed is None:
            continue
        elif kind == "raw":
            feed.raw(rec["i0"], rec["counts"])
        elif kind == "temp":
            feed.temp(rec["i0"], rec["names"], rec["values_c"])
        elif kind == "gap":
            feed.gap()
    if allan is None:
        raise FormatError(f"{path}: no header record found; not an avard recording")
    return allan


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
    """Load a whole recording as an :class:`avard.core.readers.Record` in SI units.

    ``accel`` is (N, 3) m/s² (raw counts × the header's ``scale_m_s2_per_count``) of every
    recorded sample in index order; ``temperature_c`` holds the temperature channels held at
    their last reading on the sample grid (NaN before a channel's first reading). The sample
    indices, gaps (``meta["gaps"]``: first index, count, reason), events, headers and every
    skipped or truncated frame (``meta["problems"]``) are in ``meta``; nothing lost passes
    silently.
    """
    try:
        from .readers import Record
    except ImportError:  # readers.py not present (partial install): same fields, plain class
        Record = _FallbackRecord

    reader = RecordingReader(path, strict=strict)
    headers: list[dict[str, Any]] = []
    blocks: list[np.ndarray] = []
    index: list[np.ndarray] = []
    temps: list[tuple[int, list[str], list[Any]]] = []
    gaps: list[dict[str, Any]] = []
    events: list[dict[str, Any]] = []
    scale = None
    last_avar = None
    for rec in reader:
        kind = rec["kind"]
        if kind == "header":
            headers.append(rec)
            scale = _scale_of(rec)
        elif scale is None:
            continue
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
        raise FormatError(f"{path}: no header record found; not an avard recording")
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
    rates = [float(h["rate_hz"]) for h in headers]
    scales = {_scale_of(h) for h in headers}
    meta = {
        "format": "avard-recording",
        "files": [str(f) for f in reader.files],
        "index": idx,
        "gaps": gaps,
        "events": events,
        "headers": [{k: v for k, v in h.items() if k != "config"} for h in headers],
        "config": headers[0].get("config", {}),
        "problems": [str(p) for p in reader.problems],
        "dropped_bytes": reader.dropped_bytes,
        "rates_hz": rates,
        # one LSB for the whole record (m/s²), or None when runs used different ranges
        "lsb_mps2": scales.pop() if len(scales) == 1 else None,
        "last_avar": last_avar,
        "units": {"accel": "m/s^2", "temperature": "degC", "rate": "Hz"},
    }
    # Each run's newest header carries its best fit of the output rate (the service rewrites
    # the header as the fit improves); runs are averaged.
    fitted = {h["run"]: float(h["rate_hz"]) for h in headers}
    return Record(accel=accel, rate_hz=float(np.mean(list(fitted.values()))),
                  names=["x", "y", "z"],
                  temperature_c=temperature, temperature_names=tnames,
                  source=str(path), gyro=None, meta=meta)
