"""A recording's temperature records read in bulk from the byte ranges the scan skipped
(``source._TempPlaces``): the frames in those ranges found, checked and decoded with array
operations instead of one msgpack decode and a dozen Python steps a record (~2.7 µs each:
0.7 CPU-s for the ~250 000 records of 24 h of three channels, what explain paid on a
recording beyond analyze's read).

The service writes every temperature record in one layout (``frames.temp_record``: a map of
ten keys in a fixed order, one reading). A frame laid out exactly so, byte for byte, is
decoded here; every other frame whose kind is ``temp`` (another key order, several readings,
a float32, an odd string) is handed back for the general decode (``source._temp_record``),
so what is read is what that decode gives for every frame, in frame order."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["FrameSet", "TempReadings", "frames_in", "service_readings"]

#: A temperature record's first bytes after its map's header (``source._peek_kind``'s layout)
TEMP_KIND = b"\xa4kind\xa4temp"
#: The service's layout: a map of ten entries, the keys in this order
_LEAD = 0x8A
_K_V, _K_RUN, _K_SEQ, _K_I0 = b"\xa1v", b"\xa3run", b"\xa3seq", b"\xa2i0"
_K_TMONO, _K_TREAL = b"\xa6t_mono", b"\xa6t_real"
_K_NAMES, _K_VALUES, _K_SOURCE = b"\xa5names\x91", b"\xa8values_c\x91", b"\xa6source"
_HEADER = 8   # recording.FRAME_HEADER: length and CRC, little-endian uint32 each


@dataclass(frozen=True)
class FrameSet:
    """Frames found in a buffer: each payload's offset and length, and the CRC its header
    states, in buffer order."""

    body: NDArray[np.int64]
    n: NDArray[np.int64]
    crc: NDArray[np.int64]


@dataclass(frozen=True)
class TempReadings:
    """Readings decoded from frames of the service's layout, in frame order: the frame
    (its position in the ``FrameSet``), the sample index, °C, and the channel and run as
    positions in ``names`` and ``runs``. A failed read (None) is no reading and is left out;
    ``decoded`` marks every frame decoded here (with or without a reading), the others being
    for the general decode."""

    frame: NDArray[np.int64]
    index: NDArray[np.int64]
    value: NDArray[np.float64]
    name: NDArray[np.int64]
    run: NDArray[np.int64]
    names: list[str]
    runs: list[str]
    decoded: NDArray[np.bool_]


def _u32le(buf: NDArray[np.uint8], p: NDArray[np.int64]) -> NDArray[np.int64]:
    b = buf[p[:, None] + np.arange(4)].astype(np.int64)
    return b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16) | (b[:, 3] << 24)


def frames_in(buf: NDArray[np.uint8], start: NDArray[np.int64], end: NDArray[np.int64]
              ) -> FrameSet:
    """The frames that fill each range ``[start, end)`` of ``buf`` one after another (the
    scan found and checked them there). Raises ``ValueError(offset)`` at a frame that does
    not end inside its range: the file is not what the scan read."""
    bodies, lens, crcs = [], [], []
    pos = np.asarray(start, dtype=np.int64).copy()
    end = np.asarray(end, dtype=np.int64)
    live = np.flatnonzero(pos < end)
    while len(live):
        p = pos[live]
        if np.any(p + _HEADER > end[live]):
            raise ValueError(int(p[np.argmax(p + _HEADER > end[live])]))
        n = _u32le(buf, p)
        crc = _u32le(buf, p + 4)
        over = p + _HEADER + n > end[live]
        if over.any():
            raise ValueError(int(p[np.argmax(over)]))
        bodies.append(p + _HEADER)
        lens.append(n)
        crcs.append(crc)
        pos[live] = p + _HEADER + n
        live = live[pos[live] < end[live]]
    if not bodies:
        z = np.zeros(0, dtype=np.int64)
        return FrameSet(z, z, z)
    body = np.concatenate(bodies)
    order = np.argsort(body, kind="stable")
    return FrameSet(body[order], np.concatenate(lens)[order], np.concatenate(crcs)[order])


#: Longest frame read in the service's layout (its records are ~150 bytes); a longer one
#: goes to the general decode
_MAX_ROW = 512
#: Most distinct strings told apart by comparing rows with each one; beyond, by sorting
_FEW = 16


class _Cursor:
    """Reading the service's layout in many frames at once, each frame's payload a row of
    ``rows`` (padded past its end with whatever follows): a cursor per frame, ``ok`` False
    for a frame once anything is not where the layout puts it (its later reads are then
    meaningless but harmless: every index is kept inside the row)."""

    def __init__(self, rows: NDArray[np.uint8], n: NDArray[np.int64]) -> None:
        self.rows = rows
        self.w = rows.shape[1]
        self.ar = np.arange(len(rows))
        self.n = n
        self.c = np.zeros(len(rows), dtype=np.int64)
        self.ok = np.ones(len(rows), dtype=bool)

    def byte(self, k: int = 0) -> NDArray[np.int64]:
        return self.rows[self.ar, np.minimum(self.c + k, self.w - 1)].astype(np.int64)

    def take(self, k: int, w: int) -> NDArray[np.uint8]:
        """``w`` bytes from each cursor + ``k``: a slice where the cursors agree (the usual
        case: one run, one layout), else gathered."""
        if len(self.c) and w:
            c0 = int(self.c[0]) + k
            if c0 + w <= self.w and bool(np.all(self.c == self.c[0])):
                return self.rows[:, c0:c0 + w]
        return self.rows[self.ar[:, None], np.minimum(self.c[:, None] + k + np.arange(w),
                                                      self.w - 1)]

    def expect(self, key: bytes) -> None:
        self.ok &= np.all(self.take(0, len(key)) == np.frombuffer(key, dtype=np.uint8), axis=1)
        self.c = self.c + len(key)

    def uint(self) -> NDArray[np.int64]:
        """A msgpack unsigned integer (positive fixint, uint 8/16/32/64 below 2^63)."""
        s = self.byte()
        width = np.select([s < 0x80, s == 0xCC, s == 0xCD, s == 0xCE, s == 0xCF],
                          [1, 2, 3, 5, 9], 0)
        self.ok &= width > 0
        val = np.where(s < 0x80, s, 0).astype(np.uint64)
        for w in (2, 3, 5, 9):
            sel = np.flatnonzero(width == w)
            if len(sel):
                cols = np.minimum(self.c[sel, None] + 1 + np.arange(w - 1), self.w - 1)
                big = self.rows[sel[:, None], cols].astype(np.uint64)
                v = np.zeros(len(sel), dtype=np.uint64)
                for j in range(w - 1):
                    v = (v << np.uint64(8)) | big[:, j]
                val[sel] = v
        self.ok &= val < np.uint64(1 << 63)
        self.c = self.c + width
        return val.astype(np.int64)

    def string(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """A msgpack fixstr or str 8: (offset of its bytes in the row, length)."""
        s = self.byte()
        fix = (s >= 0xA0) & (s <= 0xBF)
        self.ok &= fix | (s == 0xD9)
        size = np.where(fix, s & 0x1F, self.byte(1))
        at = self.c + np.where(fix, 1, 2)
        self.c = at + size
        return at, size

    def skip_float64(self) -> None:
        self.ok &= self.byte() == 0xCB
        self.c = self.c + 9


def _strings(rows: NDArray[np.uint8], at: NDArray[np.int64], size: NDArray[np.int64]
             ) -> tuple[NDArray[np.int64], list[str], NDArray[np.bool_]]:
    """Each string's position in the list of the distinct ones, and whether it is UTF-8
    (a frame whose string is not goes to the general decode, which refuses it). The strings
    (a run's name, a channel's) are few: each row is compared with each distinct one."""
    n = len(at)
    if not n:
        return np.zeros(0, dtype=np.int64), [], np.zeros(0, dtype=bool)
    w = int(size.max())
    keys = np.zeros((n, w + 1), dtype=np.uint8)
    keys[:, 0] = size                       # a str 8's length: below 256
    if w:
        cur = _Cursor(rows, size)
        cur.c = at
        keys[:, 1:] = np.where(np.arange(w) < size[:, None], cur.take(0, w), 0)
    inverse = np.full(n, -1, dtype=np.int64)
    reps: list[NDArray[np.uint8]] = []
    left = np.arange(n)
    while len(left) and len(reps) < _FEW:
        rep = keys[left[0]]
        same = np.all(keys[left] == rep, axis=1)
        inverse[left[same]] = len(reps)
        reps.append(rep)
        left = left[~same]
    if len(left):
        uniq, inv = np.unique(np.ascontiguousarray(keys[left]).view(
            np.dtype((np.void, w + 1))).ravel(), return_inverse=True)
        inverse[left] = len(reps) + inv.ravel()
        reps += [np.frombuffer(bytes(u), dtype=np.uint8) for u in uniq]
    out: list[str] = []
    utf8 = np.ones(len(reps), dtype=bool)
    for k, rep in enumerate(reps):
        raw = rep.tobytes()
        try:
            out.append(raw[1:1 + raw[0]].decode("utf-8"))
        except UnicodeDecodeError:
            out.append("")
            utf8[k] = False
    return inverse, out, utf8[inverse]


def _rows(buf: NDArray[np.uint8], body: NDArray[np.int64], w: int) -> NDArray[np.uint8]:
    """``w`` bytes of ``buf`` from each ``body`` (zeros past the buffer's end)."""
    rows = np.zeros((len(body), w), dtype=np.uint8)
    if not len(body) or not w:
        return rows
    inside = body + w <= len(buf)
    if len(buf) >= w:
        rows[inside] = np.lib.stride_tricks.sliding_window_view(buf, w)[body[inside]]
    for k in np.flatnonzero(~inside).tolist():     # a frame near the end of the file
        b = int(body[k])
        rows[k, :len(buf) - b] = buf[b:]
    return rows


def service_readings(buf: NDArray[np.uint8], fs: FrameSet, temp: NDArray[np.bool_]
                     ) -> TempReadings:
    """The readings of the frames ``temp`` marks (kind ``temp``) that are laid out as the
    service writes them (``frames.temp_record``: ten keys in its order, one reading, ints
    and strings in their usual encodings, the reading a float64 or nil)."""
    cand = np.flatnonzero(temp & (buf[np.minimum(fs.body, len(buf) - 1)] == _LEAD)
                          & (fs.n > 1 + len(TEMP_KIND)) & (fs.n <= _MAX_ROW))
    n = fs.n[cand]
    cur = _Cursor(_rows(buf, fs.body[cand], int(n.max()) if len(n) else 0), n)
    cur.c = cur.c + 1 + len(TEMP_KIND)        # the map's lead and kind, checked by the caller
    cur.expect(_K_V)
    cur.ok &= cur.byte() < 0x80               # the format version, a positive fixint
    cur.c = cur.c + 1
    cur.expect(_K_RUN)
    run_at, run_n = cur.string()
    cur.expect(_K_SEQ)
    cur.uint()
    cur.expect(_K_I0)
    index = cur.uint()
    cur.expect(_K_TMONO)
    cur.skip_float64()
    cur.expect(_K_TREAL)
    cur.skip_float64()
    cur.expect(_K_NAMES)
    name_at, name_n = cur.string()
    cur.expect(_K_VALUES)
    lead = cur.byte()
    is_nil = lead == 0xC0
    cur.ok &= is_nil | (lead == 0xCB)
    value = np.ascontiguousarray(cur.take(1, 8)).view(">f8").ravel().astype(np.float64)
    cur.c = cur.c + np.where(is_nil, 1, 9)
    cur.expect(_K_SOURCE)
    cur.string()
    cur.ok &= cur.c == n
    ok = np.flatnonzero(cur.ok)
    rows = cur.rows[ok]
    run, runs, run_utf8 = _strings(rows, run_at[ok], run_n[ok])
    name, names, name_utf8 = _strings(rows, name_at[ok], name_n[ok])
    good = run_utf8 & name_utf8
    frame = cand[ok][good]
    decoded = np.zeros(len(fs.body), dtype=bool)
    decoded[frame] = True
    keep = ~is_nil[ok][good]
    return TempReadings(frame[keep], index[ok][good][keep], value[ok][good][keep],
                        name[good][keep], run[good][keep], names, runs, decoded)
