"""One reader of measured (or simulated) data for every avard command.

Formats:

* ``.npz``: ``accel`` (N, C) or (N,) in m/s² (required), ``rate_hz`` (scalar Hz; or pass
  ``rate_hz=``), optional ``axes`` (C names), ``gyro`` (N, G) rad/s, ``temperature_c`` (N,)
  or (N, k) °C aligned with the samples (NaN where not read), ``temperature_names``. Never
  unpickled. Big members are read from the zip stream in blocks, not loaded whole.
* ``.csv``: one header row; a ``t`` (or ``time``, ``t_s``, ``time_s``) column in seconds or
  ``rate_hz=``; ``temp_*`` columns in °C; ``gyro_*`` columns in rad/s; every other column is an
  acceleration in m/s². Comma, semicolon or tab separated.
* an avard recording (a directory of segment files, or one ``.avr`` segment): streamed by
  :mod:`avard.core.io.source` (``open_record``); ``load_record`` loads one whole through
  ``avard.core.io.recording.load_recording``, imported lazily.

Every command reads records through ``avard.core.io.source.open_record``, which uses this
module's file readers. ``load_record`` returns a whole :class:`Record`; ``iter_blocks``
streams a file's (accel, temperature) blocks with the metadata first.
"""

from __future__ import annotations

import csv
import io
import itertools
import logging
import math
import re
import struct
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from avard.core.errors import DataError, FormatError
from avard.core.finite import first_nonfinite_row
from avard.core.io.crc import crc32
from numpy.typing import NDArray

__all__ = ["Record", "check_rate", "iter_blocks", "load_record", "record_info", "record_kind"]

log = logging.getLogger(__name__)

_TIME_COLUMNS = ("t", "time", "t_s", "time_s")


@dataclass
class Record:
    """A whole record in SI units: ``accel`` (N, C) m/s² sampled at ``rate_hz`` Hz, channel
    ``names``; ``temperature_c`` (N, k) °C or None with ``temperature_names``; ``gyro``
    (N, G) rad/s or None; ``source`` the file it came from; ``meta`` anything else."""

    accel: NDArray[np.float64]
    rate_hz: float
    names: list[str]
    temperature_c: NDArray[np.float64] | None = None
    temperature_names: list[str] = field(default_factory=list)
    source: str = ""
    gyro: NDArray[np.float64] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n_samples(self) -> int:
        return int(self.accel.shape[0])

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.rate_hz


def check_rate(rate_hz: Any, where: str) -> float:
    """A usable sample rate in Hz, or a DataError saying what is wrong with it."""
    try:
        r = float(np.asarray(rate_hz).reshape(()))
    except (TypeError, ValueError) as exc:
        raise DataError(f"{where}: sample rate {rate_hz!r} is not a number; give it in Hz "
                        "(e.g. --rate 125)") from exc
    if not math.isfinite(r) or r <= 0:
        raise DataError(f"{where}: sample rate {r} Hz is impossible; it must be a positive, "
                        "finite number of Hz (e.g. --rate 125)")
    if r > 1e7:
        raise DataError(f"{where}: sample rate {r:g} Hz is beyond any accelerometer; is it in "
                        "Hz (not a period)?")
    return r


def _is_recording(p: Path) -> bool:
    return p.is_dir() or p.suffix == ".avr"


def record_kind(path: str | Path) -> tuple[Path, str]:
    """The path and what it holds: "npz", "csv" or "recording" (a DataError or FormatError
    naming the path when it is none of them)."""
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file or directory")
    if not p.is_dir() and not p.is_file():
        # a FIFO, device or socket: open() of a FIFO waits for a writer, so the command hung
        # instead of saying what is wrong
        raise DataError(f"{p}: not a regular file (a FIFO, device or socket); give an .npz, a "
                        ".csv, or a recording directory / .avr segment")
    if _is_recording(p):
        return p, "recording"
    suffix = p.suffix.lower()
    if suffix == ".npz":
        return p, "npz"
    if suffix == ".csv":
        return p, "csv"
    if suffix == ".txt":
        # a .txt is often a CSV export under another name; say how it is read
        log.warning("%s: reading it as CSV (a header row, then comma, semicolon or tab "
                    "separated numbers); rename it .csv to silence this", p)
        return p, "csv"
    raise FormatError(f"{p}: unknown data format {suffix or '(no suffix)'!r}; avard reads .npz, "
                      ".csv, or a recording directory / .avr segment")


# ---------------------------------------------------------------------------------------------
# .npz, streamed from the zip


class _NpzMember:
    """One .npy member of an .npz opened as a stream: shape, dtype and sequential row reads."""

    def __init__(self, zf: zipfile.ZipFile, name: str, where: str) -> None:
        self.fh: IO[bytes] = zf.open(name)
        try:
            version = np.lib.format.read_magic(self.fh)
            read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                    else np.lib.format.read_array_header_2_0)
            shape, fortran, dtype = read(self.fh, max_header_size=1 << 16)
        except ValueError as exc:
            raise FormatError(f"{where}: member {name} is not a valid .npy array ({exc})") \
                from exc
        if dtype.hasobject:
            raise FormatError(f"{where}: member {name} holds Python objects; avard never "
                              "unpickles data. Save plain numeric arrays")
        if fortran and len(shape) > 2:
            raise FormatError(f"{where}: member {name} is a Fortran-ordered array of "
                              f"{len(shape)} dimensions; save it with np.ascontiguousarray")
        self.shape: tuple[int, ...] = tuple(shape)
        self.dtype = dtype
        # Fortran order (column after column, as R and MATLAB write) is read through one
        # sequential handle per column, each positioned once at its column's start: a deflated
        # member cannot seek back cheaply, but each handle only ever moves forward.
        self.fortran = bool(fortran) and len(shape) == 2
        self.data_offset = self.fh.tell()
        self.pos = 0
        self._zf, self._name = zf, name
        self._cols: list[IO[bytes]] = []

    def rows(self, n: int) -> NDArray:
        if self.fortran:
            return self._fortran_rows(n)
        row = int(np.prod(self.shape[1:], dtype=np.int64)) if len(self.shape) > 1 else 1
        nbytes = n * row * self.dtype.itemsize
        buf = self.fh.read(nbytes)
        got = len(buf) // (row * self.dtype.itemsize)
        a = np.frombuffer(buf[: got * row * self.dtype.itemsize], dtype=self.dtype)
        self.pos += got
        return a.reshape((got, *self.shape[1:])) if len(self.shape) > 1 else a

    def _fortran_rows(self, n: int) -> NDArray:
        nrow, ncol = self.shape
        n = max(0, min(n, nrow - self.pos))
        isz = self.dtype.itemsize
        if not self._cols:
            for c in range(ncol):
                fh = self._zf.open(self._name)
                fh.seek(self.data_offset + c * nrow * isz)
                self._cols.append(fh)
        out = np.empty((n, ncol), dtype=self.dtype)
        for c, fh in enumerate(self._cols):
            out[:, c] = np.frombuffer(fh.read(n * isz), dtype=self.dtype)
        self.pos += n
        return out

    def close(self) -> None:
        self.fh.close()
        for fh in self._cols:
            fh.close()


class _StoredRows:
    """Row reads of an uncompressed (ZIP_STORED), C-ordered member straight from the file into
    one reused buffer: no zip stream, no new bytes object per block (measured 0.27 s → 0.07 s
    per pass over one column of a 518 MB member). With ``verify`` the member's CRC-32 is
    checked as through ``zipfile`` when its last row is read; a second pass over a file whose
    first pass checked it can skip that (0.13 s of the 0.18 s per pass)."""

    def __init__(self, p: Path, zf: zipfile.ZipFile, member: _NpzMember, verify: bool) -> None:
        info = zf.getinfo(member._name)
        self.shape, self.dtype = member.shape, member.dtype
        self.row_bytes = int(np.prod(self.shape[1:], dtype=np.int64)) * self.dtype.itemsize
        # Rows are read up to the member's own end, never past it: a member whose npy header
        # promises more rows than the zip entry holds (a file cut and re-zipped, a bad writer)
        # would otherwise read the next entry's bytes as samples. The caller says "ends after
        # N" for a short member; its CRC is not checked (the truncation is the finding).
        stored_rows = max(0, info.compress_size - member.data_offset) // self.row_bytes
        self.left = min(self.shape[0], stored_rows)
        self.short = stored_rows < self.shape[0]
        self.expected_crc = info.CRC
        self.where = str(p)
        self.fh = open(p, "rb")  # closed by close(), as the zip members' handles
        try:
            # local file header: 30 bytes, file name and extra field lengths at 26 and 28
            self.fh.seek(info.header_offset)
            head = self.fh.read(30)
            name_len, extra_len = struct.unpack("<HH", head[26:30])
            start = info.header_offset + 30 + name_len + extra_len
            self.fh.seek(start)
            npy_head = self.fh.read(member.data_offset)
        except (OSError, struct.error) as exc:
            self.fh.close()
            raise FormatError(f"{p}: the zip entry of {member._name} cannot be read ({exc}); "
                              "the file is damaged: copy or write it again") from exc
        self.crc: int | None = crc32(npy_head) if verify else None
        self._buf = np.empty(0, dtype=self.dtype)

    def rows(self, n: int) -> NDArray:
        """The next ≤ n rows, valid until the next call (the buffer is reused)."""
        n = max(0, min(n, self.left))
        size = n * self.row_bytes // self.dtype.itemsize
        if self._buf.size < size:
            self._buf = np.empty(size, dtype=self.dtype)
        view = self._buf[:size].data.cast("B")
        got = self.fh.readinto(view) or 0
        k = got // self.row_bytes
        if self.crc is not None:
            self.crc = crc32(view[:got], self.crc)
        self.left -= k
        if (self.left == 0 and not self.short and self.crc is not None
                and self.crc != self.expected_crc):
            raise FormatError(f"{self.where}: accel fails its CRC-32 check; the file is damaged "
                              "(copy or write it again)")
        a = self._buf[:k * self.row_bytes // self.dtype.itemsize]
        return a.reshape((k, *self.shape[1:])) if len(self.shape) > 1 else a

    def close(self) -> None:
        self.fh.close()


def _small(zf: zipfile.ZipFile, key: str, where: str) -> Any:
    with zf.open(f"{key}.npy") as fh:
        try:
            return np.lib.format.read_array(fh, allow_pickle=False)
        except ValueError as exc:
            raise FormatError(f"{where}: key {key!r} cannot be read without unpickling "
                              f"({exc}); store plain numbers or strings") from exc


def _open_npz(p: Path) -> zipfile.ZipFile:
    try:
        return zipfile.ZipFile(p)
    except zipfile.BadZipFile as exc:
        # an .npz is a zip archive; one that is not (or whose end is missing) was cut short
        # while being copied or written, or is another format under an .npz name
        raise FormatError(f"{p}: not a complete .npz (zip) archive ({exc}); it is truncated "
                          "or not an .npz: copy or write it again") from exc


def _npz_meta(zf: zipfile.ZipFile, p: Path, rate_hz: float | None) -> dict[str, Any]:
    keys = {n[:-4] for n in zf.namelist() if n.endswith(".npy")}
    if "accel" not in keys:
        raise DataError(f"{p}: no 'accel' array (found {sorted(keys) or 'nothing'}); the .npz "
                        "needs accel (N, C) in m/s² and rate_hz")
    acc = _NpzMember(zf, "accel.npy", str(p))
    acc.close()
    if len(acc.shape) not in (1, 2) or acc.shape[0] == 0 or 0 in acc.shape:
        raise DataError(f"{p}: accel has shape {acc.shape}; it must be (N,) or (N, C) with "
                        "N > 0 and C > 0")
    if acc.dtype.kind not in "iuf":
        raise DataError(f"{p}: accel has dtype {acc.dtype}; it must be numbers (m/s²)")
    n = int(acc.shape[0])
    c = 1 if len(acc.shape) == 1 else int(acc.shape[1])
    if rate_hz is not None:
        rate = check_rate(rate_hz, str(p))
    elif "rate_hz" in keys:
        rate = check_rate(_small(zf, "rate_hz", str(p)), f"{p} (key rate_hz)")
    else:
        raise DataError(f"{p}: no 'rate_hz' in the file; give the sample rate with --rate HZ")
    names = [f"ch{i}" for i in range(c)] if c != 3 else ["x", "y", "z"]
    if "axes" in keys:
        axes = [str(a) for a in np.atleast_1d(_small(zf, "axes", str(p)))]
        if len(axes) != c:
            raise DataError(f"{p}: {len(axes)} axis names for {c} accel columns; fix 'axes'")
        _unique_names(axes, "axis name", "fix 'axes'", p)
        names = axes
    tshape = None
    tnames: list[str] = []
    if "temperature_c" in keys:
        t = _NpzMember(zf, "temperature_c.npy", str(p))
        t.close()
        tshape = t.shape
        if t.dtype.kind not in "iuf":
            # strings went through analyze unread and ended explain in a ValueError
            raise DataError(f"{p}: temperature_c has dtype {t.dtype}; it must be numbers "
                            "(°C, NaN where a reading is missing)")
        if len(tshape) not in (1, 2) or tshape[0] != n or 0 in tshape:
            raise DataError(f"{p}: temperature_c has shape {tshape}; it must be (N,) or (N, k) "
                            f"aligned with the {n} accel samples")
        k = 1 if len(tshape) == 1 else tshape[1]
        tnames = [f"temp{i}" for i in range(k)]
        if "temperature_names" in keys:
            tn = [str(a) for a in np.atleast_1d(_small(zf, "temperature_names", str(p)))]
            if len(tn) != k:
                # dropping them had named the logs temp0, temp1…: a plate read as the ambient
                raise DataError(f"{p}: {len(tn)} temperature names ({', '.join(tn)}) for {k} "
                                "temperature_c columns; fix 'temperature_names' (one name a "
                                "column, in order)")
            _unique_names(tn, "temperature name", "fix 'temperature_names'", p)
            tnames = tn
    meta: dict[str, Any] = {"format": "npz", "n_samples": n, "rate_hz": rate, "names": names,
                            "temperature_names": tnames, "source": str(p),
                            "units": {"accel": "m/s^2", "temperature": "degC", "rate": "Hz"}}
    for key in ("source", "preset", "odr_nominal_hz", "lsb_mps2", "seed", "sensor"):
        if key in keys:
            v = _small(zf, key, str(p))
            meta["file_" + key if key == "source" else key] = v.item() if v.ndim == 0 else v
    meta["has_gyro"] = "gyro" in keys
    return meta


def _unique_names(names: Sequence[str], what: str, fix: str, p: Path) -> None:
    """Refuse a name given to two columns: channels are picked and reported by name, and the
    second of two columns named alike went unreported (``--channels x`` took the first)."""
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise DataError(f"{p}: the {what} {name!r} is given to two columns "
                            f"({', '.join(names)}); {fix}")
        seen.add(name)


def _check_finite(a: NDArray, offset: int, where: str) -> None:
    i = first_nonfinite_row(a)
    if i is not None:
        raise DataError(f"{where}: accel sample {offset + i} is not finite (NaN or inf); cut "
                        "the record there or fill the hole before analysing")


#: The most rows of an .npz member read at once when only some columns are wanted (a read
#: takes every column of its rows).
READ_ROWS = 1 << 16


def _rows(acc: _NpzMember | _StoredRows, n: int, done: int, total: int, p: Path) -> NDArray:
    """The member's next ≤ n rows, 2-d; a member that ends before ``total`` rows is
    truncated."""
    raw = acc.rows(n)
    if len(raw) == 0:
        raise FormatError(f"{p}: accel ends after {done} of {total} samples; the file is "
                          "truncated")
    return raw[:, None] if raw.ndim == 1 else raw


def _npz_blocks(p: Path, meta: dict[str, Any], block: int, columns: Sequence[int] | None,
                temperature: bool, verify: bool
                ) -> Iterator[tuple[NDArray[np.float64], NDArray[np.float64] | None]]:
    with _open_npz(p) as zf:
        member = _NpzMember(zf, "accel.npy", str(p))
        acc: _NpzMember | _StoredRows = member
        if zf.getinfo("accel.npy").compress_type == zipfile.ZIP_STORED and not member.fortran:
            member.close()
            acc = _StoredRows(p, zf, member, verify)
        tm = (_NpzMember(zf, "temperature_c.npy", str(p))
              if temperature and meta["temperature_names"] else None)
        done = 0
        try:
            while done < meta["n_samples"]:
                if columns is None:
                    a = _rows(acc, block, done, meta["n_samples"], p).astype(np.float64)
                else:
                    # only the columns asked for are converted (one copy, column by column),
                    # read READ_ROWS rows at a time: a long block of a few columns never
                    # holds every column's rows at once
                    a = np.empty((min(block, meta["n_samples"] - done), len(columns)))
                    got = 0
                    while got < len(a):
                        raw = _rows(acc, min(READ_ROWS, len(a) - got), done + got,
                                    meta["n_samples"], p)
                        for j, col in enumerate(columns):
                            a[got:got + len(raw), j] = raw[:, col]
                        got += len(raw)
                _check_finite(a, done, str(p))
                t = None
                if tm is not None:
                    t = tm.rows(len(a)).astype(np.float64)
                    if t.ndim == 1:
                        t = t[:, None]
                done += len(a)
                yield a, t
        finally:
            acc.close()
            if tm is not None:
                tm.close()


# ---------------------------------------------------------------------------------------------
# .csv


def _not_utf8(p: Path) -> DataError:
    """A CSV that is not UTF-8 (spreadsheets also write cp1252 and UTF-16), in one line."""
    with open(p, "rb") as fh:
        bom = fh.read(2)
    kind = " (it is UTF-16)" if bom in (b"\xff\xfe", b"\xfe\xff") else ""
    return DataError(f"{p}: not UTF-8 text{kind}; save the CSV as UTF-8 (\"CSV UTF-8\" in a "
                     "spreadsheet) and give it again")


def _csv_open(p: Path) -> tuple[IO[str], list[str], str]:
    # utf-8-sig: a byte-order mark (spreadsheets' "CSV UTF-8" writes one) is not part of the
    # first column's name: read as one, it hid the t column ("no time column")
    fh = open(p, newline="", encoding="utf-8-sig")  # closed by the caller
    try:
        head = fh.readline()
    except UnicodeDecodeError:
        fh.close()
        raise _not_utf8(p) from None
    if not head.strip():
        fh.close()
        raise DataError(f"{p}: empty file or empty first line; a .csv needs a header row")
    delim = max((",", ";", "\t"), key=head.count)
    cols = [c.strip().strip('"').strip() for c in next(csv.reader([head], delimiter=delim))]
    try:
        float(cols[0])
    except ValueError:
        pass
    else:
        fh.close()
        raise DataError(f"{p}: the first line is numbers, not a header; add a header row "
                        "naming the columns (e.g. t,x,y,z)")
    return fh, cols, delim


def _csv_layout(p: Path, cols: list[str]) -> dict[str, Any]:
    blank = [i for i, c in enumerate(cols) if not c]
    if blank:
        # a trailing delimiter made a nameless column, read as acceleration of NaN
        raise DataError(f"{p}: column {blank[0] + 1} of the header has no name (a trailing or "
                        "doubled delimiter?); name every column (t, x, y, z, temp_NAME …)")
    low = [c.lower() for c in cols]
    tcol = next((i for i, c in enumerate(low) if c in _TIME_COLUMNS), None)
    temp = [i for i, c in enumerate(low) if c.startswith("temp")]
    gyro = [i for i, c in enumerate(low) if c.startswith("gyro")]
    accel = [i for i in range(len(cols)) if i != tcol and i not in temp and i not in gyro]
    if not accel:
        raise DataError(f"{p}: no acceleration column among {cols}; columns other than t, "
                        "temp_* and gyro_* are read as acceleration in m/s²")
    _unique_names(cols, "column name", "name every column once in the header row", p)
    return {"t": tcol, "temp": temp, "gyro": gyro, "accel": accel}


def _csv_chunks(fh: IO[str], delim: str, ncols: int, block: int, p: Path
                ) -> Iterator[tuple[int, NDArray[np.float64]]]:
    line0 = 2
    while True:
        try:
            lines = [ln for ln in itertools.islice(fh, block) if ln.strip()]
        except UnicodeDecodeError:
            raise _not_utf8(p) from None
        if not lines:
            return
        text = "".join(lines)
        try:
            a = np.loadtxt(io.StringIO(text), delimiter=delim, ndmin=2, dtype=np.float64)
        except ValueError as exc:
            filled, why = _with_empty_fields(text, delim)
            if filled is None:
                hint = ("; the numbers use decimal commas: write them with decimal points "
                        "(e.g. 9.81; export with a point as the decimal separator)"
                        if delim != "," and re.search(r"(^|\D)\d+,\d+", text) else "")
                raise DataError(f"{p}: unreadable number in lines {line0}–"
                                f"{line0 + len(lines) - 1} ({why or exc}); every field must be "
                                "a number (NaN, or an empty field, where a temperature has no "
                                f"reading){hint}") from exc
            a = filled
        if a.shape[1] != ncols:
            raise DataError(f"{p}: lines from {line0} have {a.shape[1]} fields, the header "
                            f"{ncols}; fix the missing or extra column")
        yield line0, a
        line0 += len(lines)


def _with_empty_fields(text: str, delim: str
                       ) -> tuple[NDArray[np.float64] | None, ValueError | None]:
    """The chunk read with its empty fields as NaN (what pandas' ``to_csv`` writes for a
    missing value: a temperature column between readings), or None and the error of what
    else is unreadable (None where no field was empty). Only a chunk the fast read refused
    pays for this."""
    d = re.escape(delim)
    # after a delimiter with nothing before the next one or the line's end, or a line that
    # starts with the delimiter
    filled = re.sub(rf"(?m)(?<={d})(?=[ \t]*(?:{d}|\r?\n|\Z))|^(?=[ \t]*{d})", "nan", text)
    if filled == text:
        return None, None
    try:
        return np.loadtxt(io.StringIO(filled), delimiter=delim, ndmin=2, dtype=np.float64), None
    except ValueError as exc:
        return None, exc


def _finite_times(t: NDArray, done: int, p: Path) -> None:
    """One line where a time (rows from ``done``) is empty or not a number."""
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise DataError(f"{p}: the t column is empty or not a number at sample "
                        f"{done + int(bad[0]) + 1}; every row needs its time in seconds (or "
                        "drop t and give --rate HZ)")


def _check_times(t: NDArray, last_t: float, rate: float, done: int, p: Path) -> None:
    """A chunk's t column (``last_t``: the chunk before's last time, −inf for the first)
    strictly increasing, and without a jump past 1.5 sample spacings: that is missing
    samples, and read end to end the hole would become a step or a shift in time that
    nothing records. A CSV carries no gap records, so it is refused in one line (a
    recording carries its gaps)."""
    _finite_times(t, done, p)
    first = math.isfinite(last_t)
    tt = np.concatenate([[last_t], t]) if first else t
    dt = np.diff(tt)
    if np.any(dt <= 0):
        raise DataError(f"{p}: the t column does not increase near sample {done}; times must "
                        "be strictly increasing")
    holes = np.flatnonzero(dt > 1.5 / rate)
    if len(holes):
        k = int(holes[0])
        i = done + k - (1 if first else 0)    # the sample before the hole, from 0
        gap = float(dt[k])
        raise DataError(f"{p}: the t column jumps by {gap:.6g} s after t = {tt[k]:.6g} s "
                        f"(sample {i + 1}) where its spacing is {1 / rate:.3g} s: about "
                        f"{round(gap * rate) - 1} samples are missing; a CSV cannot carry "
                        "the gap, so split the file at the hole (or give --rate HZ to read "
                        "the samples end to end, the hole included)")


#: The rows whose times give a CSV's rate and time base (the first ones: the rest is checked
#: against them, a rate that changes later is refused, not averaged in)
RATE_ROWS = 4096


@dataclass(frozen=True)
class _TimeBase:
    """A CSV's rate and the line its first rows' times follow, t ≈ ``t_ref`` + i/``rate``
    (least squares over the first ``RATE_ROWS`` rows, or their median spacing where a hole
    lies among them: the hole is refused when it is read), with the largest residual of
    those rows (``offset_s``: a start-up burst or a clock step early on is no rate change)
    and their spacing's scatter (``jitter_s``)."""

    rate: float
    t_ref: float
    offset_s: float
    jitter_s: float

    @classmethod
    def of(cls, t: NDArray, p: Path) -> _TimeBase:
        t = t[:RATE_ROWS]
        _finite_times(t, 0, p)
        dt = np.diff(t)
        if len(dt) == 0:
            raise DataError(f"{p}: one sample cannot give a sample rate; give --rate HZ")
        if np.any(dt <= 0):
            i = int(np.flatnonzero(dt <= 0)[0])
            raise DataError(f"{p}: the t column does not increase at sample {i + 1}; times "
                            "must be strictly increasing seconds (or drop t and give --rate)")
        med = float(np.median(dt))
        if float(dt.max()) > 1.5 * med or len(dt) < 2:
            return cls(check_rate(1.0 / med, f"{p} (from the t column)"), float(t[0]), 0.0,
                       0.0)
        # no hole: the least-squares spacing, which the times' rounding and jitter do not
        # bias (3 Hz printed to 0.1 s has a median spacing of 0.3 s, 11 % off)
        rows = np.arange(len(t), dtype=float)
        slope, ref = np.polyfit(rows, t - t[0], 1)
        resid = t - t[0] - (ref + slope * rows)
        return cls(check_rate(1.0 / float(slope), f"{p} (from the t column)"),
                   float(t[0] + ref), float(np.max(np.abs(resid))), float(np.std(dt)))


#: A CSV's times may leave its first rows' line (``_TimeBase``) by that line's own largest
#: residual, two sample spacings, this share of the time elapsed and ``RATE_DRIFT_Z`` times
#: the spacing's scatter grown as a random walk (a PC-stamped log whose every spacing
#: wanders): a clock's ppm and a logger's jitter stay inside, a rate that changes midway
#: leaves it within minutes.
RATE_DRIFT_SHARE, RATE_DRIFT_Z = 0.01, 6.0


class _RateWatch:
    """The times of every chunk against the first rows' rate: a spacing that changes by less
    than the hole rule's 1.5 (a logger switched from 10 to 8 Hz, or sped up) had been read at
    one rate end to end, every τ and the record's length wrong, without a word. Refused in
    one line naming where the times last followed the rate (the change's place, to split the
    file there) and the spacing after it."""

    def __init__(self, base: _TimeBase, p: Path) -> None:
        self.base, self.p = base, p
        self.on_rate = (0, base.t_ref)   # the last (row, time) still on the first rows' line

    def check(self, t: NDArray, done: int) -> None:
        b = self.base
        idx = done + np.arange(len(t))
        off = t - (b.t_ref + idx / b.rate)
        base = b.offset_s + 2.0 / b.rate
        on = np.flatnonzero(np.abs(off) <= base)
        far = np.abs(off) > (base + RATE_DRIFT_SHARE * (t - b.t_ref)
                             + RATE_DRIFT_Z * b.jitter_s * np.sqrt(idx + 1.0))
        if not far.any():
            if len(on):
                self.on_rate = (int(idx[on[-1]]), float(t[on[-1]]))
            return
        k = int(np.flatnonzero(far)[0])
        before = on[on < k]
        if len(before):
            self.on_rate = (int(idx[before[-1]]), float(t[before[-1]]))
        near = np.diff(t[max(0, k - 256):k + 1])
        here = float(np.median(near)) if len(near) else float("nan")
        row, at = self.on_rate
        raise DataError(f"{self.p}: the t column leaves the rate of its first rows "
                        f"({b.rate:.6g} Hz, spacing {1 / b.rate:.4g} s) after about t = "
                        f"{at:.6g} s (sample {row + 1}): by t = {t[k]:.6g} s its times are "
                        f"{off[k]:+.4g} s from that rate's and its spacing is {here:.4g} s; a "
                        "CSV holds one rate, so split the file there (or give --rate HZ to "
                        "read the samples end to end at one rate)")


def _csv_meta_and_blocks(p: Path, rate_hz: float | None, block: int
                         ) -> tuple[dict[str, Any], Iterator[tuple[NDArray, NDArray | None]]]:
    fh, cols, delim = _csv_open(p)
    lay = _csv_layout(p, cols)
    chunks = _csv_chunks(fh, delim, len(cols), block, p)
    try:
        first = next(chunks)
    except StopIteration:
        fh.close()
        raise DataError(f"{p}: a header but no data rows") from None
    except Exception:
        fh.close()
        raise
    times: _TimeBase | None = None
    if rate_hz is not None:
        rate = check_rate(rate_hz, str(p))
    elif lay["t"] is not None:
        times = _TimeBase.of(first[1][:, lay["t"]], p)
        rate = times.rate
    else:
        fh.close()
        raise DataError(f"{p}: no time column ({', '.join(_TIME_COLUMNS)}) and no rate; give "
                        "--rate HZ")
    meta: dict[str, Any] = {
        "format": "csv", "n_samples": None, "rate_hz": rate,
        "names": [cols[i] for i in lay["accel"]],
        "temperature_names": [cols[i] for i in lay["temp"]], "source": str(p),
        "units": {"accel": "m/s^2", "temperature": "degC", "rate": "Hz"},
        "has_gyro": bool(lay["gyro"]),
    }

    def gen() -> Iterator[tuple[NDArray, NDArray | None]]:
        last_t = -math.inf
        done = 0
        watch = _RateWatch(times, p) if times is not None else None
        try:
            for _, a in itertools.chain([first], chunks):
                if watch is not None:  # times read from the t column (no --rate given)
                    t = a[:, lay["t"]]
                    _check_times(t, last_t, rate, done, p)
                    watch.check(t, done)
                    last_t = float(t[-1])
                acc = a[:, lay["accel"]]
                _check_finite(acc, done, str(p))
                temp = a[:, lay["temp"]] if lay["temp"] else None
                done += len(a)
                yield acc, temp
        finally:
            fh.close()

    return meta, gen()


# ---------------------------------------------------------------------------------------------
# public API


def iter_blocks(path: str | Path, block: int = 1 << 16, *, rate_hz: float | None = None,
                columns: Sequence[int] | None = None, temperature: bool = True,
                verify: bool = True
                ) -> tuple[dict[str, Any], Iterator[tuple[NDArray[np.float64],
                                                          NDArray[np.float64] | None]]]:
    """Metadata and a stream of (accel (n, C) m/s², temperature (n, k) °C or None) blocks.

    The metadata holds ``rate_hz``, ``names``, ``temperature_names``, ``n_samples`` (None for
    CSV, unknown until read), ``source`` and ``format``. Memory stays at one block.
    ``columns``: only these accel columns (by number, in this order), e.g. one channel per
    pass when a consumer's memory grows with the channels; ``temperature=False`` skips the
    temperatures (None in every block). The metadata always describes the whole record.
    ``verify=False`` skips the CRC-32 check of an uncompressed .npz member: for another pass
    over a file whose first pass checked it.
    """
    if block < 1:
        raise DataError(f"block size {block} must be >= 1 sample")
    p, kind = record_kind(path)
    if kind == "npz":
        with _open_npz(p) as zf:
            meta = _npz_meta(zf, p, rate_hz)
        _check_columns(columns, len(meta["names"]), p)
        return meta, _npz_blocks(p, meta, block, columns, temperature, verify)
    if kind != "csv":
        raise DataError(f"{p}: a recording is streamed by avard.core.io.source.open_record "
                        "(its runs, losses and segments come with it), not by iter_blocks")
    meta, blocks = _csv_meta_and_blocks(p, rate_hz, block)
    _check_columns(columns, len(meta["names"]), p)
    if columns is None and temperature:
        return meta, blocks
    cols = None if columns is None else list(columns)
    return meta, ((a if cols is None else a[:, cols], t if temperature else None)
                  for a, t in blocks)


def _check_columns(columns: Sequence[int] | None, n: int, p: Path) -> None:
    if columns is not None and any(not 0 <= int(c) < n for c in columns):
        raise DataError(f"{p}: accel columns {list(columns)} asked for, the record has {n} "
                        f"(0..{n - 1})")


def _load_recording(p: Path, rate_hz: float | None) -> Record:
    """The service's recordings, through avard.core.io.recording (imported only when needed)."""
    from avard.core.io.recording import load_recording

    rec = load_recording(p)
    if not isinstance(rec, Record):  # a fallback record class: same fields
        rec = Record(rec.accel, rec.rate_hz, list(rec.names), rec.temperature_c,
                     list(rec.temperature_names), rec.source, rec.gyro, dict(rec.meta))
    if rec.n_samples == 0:
        raise DataError(f"{p}: the recording holds no samples")
    rec.rate_hz = check_rate(rate_hz if rate_hz is not None else rec.rate_hz, str(p))
    return rec


def record_info(path: str | Path, *, rate_hz: float | None = None) -> dict[str, Any]:
    """The metadata of ``iter_blocks`` without reading the samples (CSV: first block only)."""
    meta, blocks = iter_blocks(path, rate_hz=rate_hz)
    close = getattr(blocks, "close", None)
    if close is not None:
        close()
    return meta


def load_record(path: str | Path, *, rate_hz: float | None = None) -> Record:
    """The whole record in memory (see the module docstring for the formats). For records
    larger than memory use :func:`iter_blocks`."""
    p, kind = record_kind(path)
    if kind == "recording":
        return _load_recording(p, rate_hz)
    meta, blocks = iter_blocks(p, rate_hz=rate_hz)
    acc, temps = [], []
    for a, t in blocks:
        acc.append(a)
        if t is not None:
            temps.append(t)
    accel = np.concatenate(acc)
    temperature = np.concatenate(temps) if temps else None
    gyro = None
    if kind == "npz" and meta.get("has_gyro"):
        with _open_npz(p) as zf:
            g = _NpzMember(zf, "gyro.npy", str(p))
            if g.shape[0] == accel.shape[0]:
                gyro = g.rows(g.shape[0]).astype(np.float64)
            g.close()
    return Record(accel=accel, rate_hz=float(meta["rate_hz"]), names=list(meta["names"]),
                  temperature_c=temperature, temperature_names=list(meta["temperature_names"]),
                  source=str(p), gyro=gyro, meta=meta)
