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


def _str_head(rows: NDArray[np.uint8], ar: NDArray[np.int64], at: NDArray[np.int64]
              ) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.int64]]:
    """A msgpack fixstr or str 8 at ``at`` of each row: (whether it is one, where its bytes
    start, their length)."""
    w = rows.shape[1] - 1
    s = rows[ar, np.minimum(at, w)].astype(np.int64)
    fix = (s >= 0xA0) & (s <= 0xBF)
    size = np.where(fix, s & 0x1F, rows[ar, np.minimum(at + 1, w)])
    return fix | (s == 0xD9), at + np.where(fix, 1, 2), size


def _uint_width(rows: NDArray[np.uint8], ar: NDArray[np.int64], at: NDArray[np.int64]
                ) -> NDArray[np.int64]:
    """Bytes of a msgpack unsigned integer at ``at`` (positive fixint, uint 8/16/32/64), 0
    for anything else."""
    s = rows[ar, np.minimum(at, rows.shape[1] - 1)]
    return np.select([s < 0x80, s == 0xCC, s == 0xCD, s == 0xCE, s == 0xCF],
                     [1, 2, 3, 5, 9], 0)


def _distinct(sub: NDArray[np.uint8]) -> tuple[NDArray[np.int64], list[bytes]]:
    """Each row's position in the list of the distinct rows (a run's name, a channel's: few,
    so each row is compared with each distinct one; beyond ``_FEW``, by sorting)."""
    n = len(sub)
    inverse = np.full(n, -1, dtype=np.int64)
    reps: list[bytes] = []
    left = np.arange(n)
    while len(left) and len(reps) < _FEW:
        rep = sub[left[0]]
        same = np.all(sub[left] == rep, axis=1)
        inverse[left[same]] = len(reps)
        reps.append(rep.tobytes())
        left = left[~same]
    if len(left):
        keys = np.ascontiguousarray(sub[left]).view(np.dtype((np.void, sub.shape[1]))).ravel()
        uniq, inv = np.unique(keys, return_inverse=True)
        inverse[left] = len(reps) + inv.ravel()
        reps += [bytes(u) for u in uniq]
    return inverse, reps


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
    and strings in their usual encodings, the reading a float64 or nil). Each frame's
    fields are placed from its few type bytes; frames placed alike (one run, one channel,
    the same integer widths: a handful a file) are then checked and read together, column
    by column."""
    cand = np.flatnonzero(temp & (buf[np.minimum(fs.body, len(buf) - 1)] == _LEAD)
                          & (fs.n > 1 + len(TEMP_KIND)) & (fs.n <= _MAX_ROW))
    n = fs.n[cand]
    if not len(cand):
        z = np.zeros(0, dtype=np.int64)
        return TempReadings(z, z, np.zeros(0), z, z, [], [], np.zeros(len(fs.body), bool))
    rows = _rows(buf, fs.body[cand], int(n.max()))
    ar = np.arange(len(cand))
    # where each field lies: the run after the fixed head (map, kind, v), then seq, i0, two
    # float64 times, the name (a one-string array), the reading, the source
    head = 1 + len(TEMP_KIND) + len(_K_V) + 1
    ok, run_at, run_n = _str_head(rows, ar, np.full(len(ar), head + len(_K_RUN)))
    at_seq = run_at + run_n
    ws = _uint_width(rows, ar, at_seq + len(_K_SEQ))
    at_i0 = at_seq + len(_K_SEQ) + ws
    wi = _uint_width(rows, ar, at_i0 + len(_K_I0))
    at_t = at_i0 + len(_K_I0) + wi
    at_names = at_t + 2 * (len(_K_TMONO) + 9)
    name_ok, name_at, name_n = _str_head(rows, ar, at_names + len(_K_NAMES))
    at_val = name_at + name_n
    lead = rows[ar, np.minimum(at_val + len(_K_VALUES), rows.shape[1] - 1)]
    is_nil = lead == 0xC0
    at_src = at_val + len(_K_VALUES) + np.where(is_nil, 1, 9)
    src_ok, src_at, src_n = _str_head(rows, ar, at_src + len(_K_SOURCE))
    ok &= name_ok & src_ok & (ws > 0) & (wi > 0) & (is_nil | (lead == 0xCB)) \
        & (src_at + src_n == n)
    # frames placed alike: one key of their field positions (each below 512: 9 bits)
    places = np.stack([run_at, run_n, at_seq, at_i0, wi, name_at, name_n, at_val, is_nil,
                       at_src, src_at, src_n])
    sel = np.flatnonzero(ok)
    key = np.zeros(len(sel), dtype=np.int64)
    for row in places[:, sel]:
        key = key * 512 + np.minimum(row, 511)
    _, group = np.unique(key, return_inverse=True)
    group = group.ravel()
    got_frame, got_index, got_value, got_name, got_run = [], [], [], [], []
    names: list[str] = []
    runs: list[str] = []
    decoded = np.zeros(len(fs.body), dtype=bool)
    tmono = _K_TMONO + b"\xcb"
    treal = _K_TREAL + b"\xcb"
    for g in range(int(group.max()) + 1 if len(group) else 0):
        idx = sel[group == g]
        f = idx[0]
        p = {k: int(v[f]) for k, v in (("run_at", run_at), ("run_n", run_n), ("seq", at_seq),
                                        ("i0", at_i0), ("wi", wi), ("name_at", name_at),
                                        ("name_n", name_n), ("val", at_val),
                                        ("src", at_src))}
        sub = rows[idx]
        # every byte the layout fixes, checked at once
        fixed = [(head - len(_K_V) - 1, _K_V), (head, _K_RUN), (p["seq"], _K_SEQ),
                 (p["i0"], _K_I0), (int(at_t[f]), tmono),
                 (int(at_t[f]) + len(tmono) + 8, treal), (int(at_names[f]), _K_NAMES),
                 (p["val"], _K_VALUES), (p["src"], _K_SOURCE)]
        cols = np.concatenate([np.arange(c0, c0 + len(k)) for c0, k in fixed])
        want = np.frombuffer(b"".join(k for _c, k in fixed), dtype=np.uint8)
        good = np.all(sub[:, cols] == want, axis=1) & (sub[:, head - 1] < 0x80)
        # the index, big-endian after its type byte (a fixint is its own value)
        w = p["wi"]
        if w == 1:
            index = sub[:, p["i0"] + len(_K_I0)].astype(np.uint64)
        else:
            index = np.zeros(len(idx), dtype=np.uint64)
            for j in range(w - 1):
                index = (index << np.uint64(8)) | sub[:, p["i0"] + len(_K_I0) + 1 + j]
        good &= index < np.uint64(1 << 63)
        run_k, run_reps = _distinct(sub[:, p["run_at"]:p["run_at"] + p["run_n"]])
        name_k, name_reps = _distinct(sub[:, p["name_at"]:p["name_at"] + p["name_n"]])
        # a string that is no UTF-8 leaves its frame to the general decode (which refuses it)
        for reps, ks, out in ((run_reps, run_k, runs), (name_reps, name_k, names)):
            to = np.full(len(reps), -1, dtype=np.int64)
            for r, raw in enumerate(reps):
                try:
                    text = raw.decode("utf-8")
                except UnicodeDecodeError:
                    continue
                if text not in out:
                    out.append(text)
                to[r] = out.index(text)
            ks[:] = to[ks]
            good &= ks >= 0
        decoded[cand[idx[good]]] = True
        if is_nil[f]:
            continue                      # failed reads: decoded, no reading
        v0 = p["val"] + len(_K_VALUES) + 1
        value = np.ascontiguousarray(sub[:, v0:v0 + 8]).view(">f8").ravel()
        got_frame.append(cand[idx[good]])
        got_index.append(index[good].astype(np.int64))
        got_value.append(value[good].astype(np.float64))
        got_name.append(name_k[good])
        got_run.append(run_k[good])
    if not got_frame:
        z = np.zeros(0, dtype=np.int64)
        return TempReadings(z, z, np.zeros(0), z, z, names, runs, decoded)
    frame = np.concatenate(got_frame)
    order = np.argsort(frame, kind="stable")
    return TempReadings(frame[order], np.concatenate(got_index)[order],
                        np.concatenate(got_value)[order], np.concatenate(got_name)[order],
                        np.concatenate(got_run)[order], names, runs, decoded)
