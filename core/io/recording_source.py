"""An avard recording as a record source: scanned once when opened, walked frame by frame
(``RecordingSource``)."""

from __future__ import annotations

import itertools
import logging
import math
import os
import re
import zlib
from array import array
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core.errors import DataError, FormatError
from avard.core.io.rates import rates_compatible
from avard.core.io.record_info import (
    BLOCK,
    Duplicate,
    Gap,
    Loss,
    RecordBlock,
    RecordFormat,
    RecordInfo,
    RecordingSummary,
    RunSummary,
    _check_block,
    _check_columns,
)
from numpy.typing import NDArray

if TYPE_CHECKING:
    from types import ModuleType

    from avard.core.io.recording import Frame, Problem
    from avard.core.io.tempscan import FrameSet

log = logging.getLogger(__name__)


_SEGMENT_NAME = re.compile(r"^(?P<run>.+)_(?P<seq>\d{4,})_[^_]*$")


@dataclass(frozen=True)
class _SegmentFile:
    path: Path
    run: str | None
    seq: int | None
    state: str            # "ok", "empty" or "not a file"


def _segment_entries(p: Path) -> list[_SegmentFile]:
    """Every ``*.avr`` entry of a recording directory, readable or not: an emptied segment or
    a directory in a segment's place is named when a loss lies where it was."""
    from avard.core.io.recording import SEGMENT_SUFFIX

    if not p.is_dir():
        return []
    out = []
    for f in sorted(p.iterdir()):
        if f.suffix != SEGMENT_SUFFIX:
            continue
        m = _SEGMENT_NAME.match(f.stem)
        state = ("not a file" if not f.is_file()
                 else "empty" if f.stat().st_size == 0 else "ok")
        out.append(_SegmentFile(f, m["run"] if m else None, int(m["seq"]) if m else None,
                                state))
    return out


def _between(entries: list[_SegmentFile], run: str, a: str | None, b: str | None) -> str:
    """Where samples of ``run`` went missing between file ``a`` and file ``b`` (None: the
    run's start or end), with what the directory shows there."""
    by_name = {str(e.path): e for e in entries}
    ea, eb = by_name.get(a or ""), by_name.get(b or "")
    lo = ea.seq if ea is not None and ea.run == run else None
    hi = eb.seq if eb is not None and eb.run == run else None
    mine = {e.seq: e for e in entries if e.run == run and e.seq is not None}
    said = []
    if lo is not None:
        top = hi if hi is not None else max(mine, default=lo) + 1
        for s in range(lo + 1, top):
            e = mine.get(s)
            said.append(f"segment {s:04d} " + ("missing" if e is None else
                                               f"{e.state} ({e.path.name})"))
    place = (f"between {Path(a).name} and {Path(b).name}" if a and b
             else f"after {Path(a).name}" if a else f"before {Path(b).name}" if b
             else "in the recording")
    return place + (": " + ", ".join(said) if said else "")


#: One raw block as the blocks assemble it: (first index, counts (n, 3) int32, scale m/s² per
#: count, a segment ends before it).
_Piece = tuple[int, NDArray[np.int32], float, bool]


#: Bytes of a segment the fast path reads at once (the counts of consecutive blocks and the
#: records between them). Under glibc's mmap threshold on purpose: freeing larger buffers
#: raises that threshold, and the analysis's arrays then fragment the heap (+17 MB of peak
#: RSS at 60 h with 1 MB reads).
_READ_BYTES = 120 << 10
#: Bytes between two blocks' counts above which the fast path reads them apart: the records
#: between (an Allan snapshot, a checkpoint: tens of kB) are not read again.
_SKIP_BYTES = 1 << 14
#: Blocks of the read plan looked at together by the fast path.
_PLAN_WINDOW = 1 << 14
#: Bytes of a segment whose temperature records are decoded together (a mapped window: its
#: pages are dropped from the process after it, or when the file is done; an hourly
#: segment is one window).
_TEMP_WINDOW = 32 << 20

#: Record kinds that hold no samples and no sample index the scan needs.
_NO_SAMPLES = frozenset({"temp", "avar", "checkpoint", "status"})
#: A temperature record's first bytes after its map's header (``_peek_kind``'s layout).
_TEMP_KIND = b"\xa4kind\xa4temp"
#: Record kinds the temperature pass does not decode (it needs the temperatures, and the
#: headers the walk orders every record by).
_NOT_TEMPERATURE = frozenset({"raw", "avar", "checkpoint", "status", "event", "gap"})


def _peek_kind(payload: bytes) -> str | None:
    """The ``kind`` of an encoded record from its first bytes (frames.encode writes it first:
    a map, the key "kind", a short string), or None when it is not laid out so."""
    if not payload:
        return None
    b0 = payload[0]
    i = 1 if 0x80 <= b0 <= 0x8F else 3 if b0 == 0xDE else 5 if b0 == 0xDF else -1
    if i < 0 or payload[i:i + 5] != b"\xa4kind" or len(payload) <= i + 5:
        return None
    size = payload[i + 5] - 0xA0
    if not 0 <= size < 32:
        return None
    return payload[i + 6:i + 6 + size].decode("ascii", "replace")


def _counts_offset(fr: Frame, counts: Any, header_bytes: int) -> int:
    """Byte offset in the file of a raw record's counts (little-endian int32, 3 columns, C
    order), found in its frame's payload; -1 when they are stored otherwise (the general path
    then reads such a recording). Any occurrence of the very bytes is the same data."""
    if not (isinstance(counts, np.ndarray) and counts.dtype == np.dtype("<i4")
            and counts.ndim == 2 and counts.shape[1] == 3 and counts.size):
        return -1
    at = fr.payload.find(counts.tobytes())
    return -1 if at < 0 else fr.offset + header_bytes + at


class _Plan:
    """Where each kept raw block's counts lie, in walk order: compact columns (about 25
    bytes a block: 10 MB for 60 h of 0.5 s blocks)."""

    def __init__(self) -> None:
        self.fidx = array("H")
        self.off = array("q")
        self.i0 = array("q")
        self.n = array("I")
        self.sidx = array("H")
        self.cut = array("B")
        self.scales: list[float] = []
        self.ok = True

    def extend(self, fidx: int, off: NDArray[np.int64], i0: NDArray[np.int64],
               n: NDArray[np.int64], scale: float, cut: bool) -> None:
        """Blocks of one file whose counts lie at ``off``, as :meth:`add` of each in turn
        (``cut`` before the first)."""
        if (not self.ok or fidx >= 1 << 16 or len(self.scales) >= (1 << 16) - 1
                or not len(off) or int(off.min()) < 0):
            self.ok = False
            return
        if not self.scales or self.scales[-1] != scale:
            self.scales.append(scale)
        k = len(off)
        self.fidx.extend(array("H", [fidx]) * k)
        self.off.frombytes(np.ascontiguousarray(off, dtype=np.int64).tobytes())
        self.i0.frombytes(np.ascontiguousarray(i0, dtype=np.int64).tobytes())
        self.n.extend(n.tolist())
        self.sidx.extend(array("H", [len(self.scales) - 1]) * k)
        self.cut.append(1 if cut else 0)
        self.cut.extend(array("B", [0]) * (k - 1))

    def add(self, at: tuple[int, int, int] | None, i0: int, n: int, scale: float,
            cut: bool) -> None:
        if (not self.ok or at is None or at[1] < 0 or at[0] >= 1 << 16
                or len(self.scales) >= (1 << 16) - 1):
            self.ok = False
            return
        if not self.scales or self.scales[-1] != scale:
            self.scales.append(scale)
        self.fidx.append(at[0])
        self.off.append(at[1] + 12 * (i0 - at[2]))    # a part of a duplicated block
        self.i0.append(i0)
        self.n.append(n)
        self.sidx.append(len(self.scales) - 1)
        self.cut.append(cut)


class _TempPlaces:
    """Where the scan skipped the temperature records, in walk order: byte ranges
    ``[start, end)`` of file ``fidx`` that hold whole frames of the kinds the scan skips only
    (temp, avar, checkpoint, status), their CRC checked by it. About 18 bytes a range, one
    range between two raw blocks: ~3 MB for 24 h. ``ok`` False: not usable (more files than
    the column holds); the temperatures are then read by a walk."""

    def __init__(self) -> None:
        self.fidx = array("H")
        self.start = array("q")
        self.end = array("q")
        self.ok = True

    def add(self, k: int, a: int, b: int) -> None:
        if b <= a:
            return
        if k >= 1 << 16:
            self.ok = False
            return
        self.fidx.append(k)
        self.start.append(a)
        self.end.append(b)

    def around_stretch(self, k: int, last: int, st: Any) -> int:
        """The ranges before and between the frames of a ``rawscan.Stretch`` (its raw blocks
        and the headers among them), ``last`` the end of the frame before it; returns the
        end of its last frame."""
        from avard.core.io.recording import FRAME_HEADER

        offs = np.asarray(st.offsets, dtype=np.int64)
        lens = np.asarray(st.lengths, dtype=np.int64)
        if st.headers:
            offs = np.concatenate([offs, [fr.offset for _, fr in st.headers]])
            lens = np.concatenate([lens, [len(fr.payload) for _, fr in st.headers]])
            order = np.argsort(offs, kind="stable")
            offs, lens = offs[order], lens[order]
        ends = offs + FRAME_HEADER.size + lens
        prev = np.concatenate([[last], ends[:-1]])
        gap = offs > prev
        m = int(np.count_nonzero(gap))
        if m:
            if k >= 1 << 16:
                self.ok = False
            else:
                self.fidx.extend(array("H", [k]) * m)
                self.start.frombytes(np.ascontiguousarray(prev[gap]).tobytes())
                self.end.frombytes(np.ascontiguousarray(offs[gap]).tobytes())
        return int(ends[-1]) if len(ends) else last


def _temp_record(payload: bytes, msgpack: Any, frames: Any) -> dict[str, Any] | None:
    """A temperature record's fields as the walk would give them, or None for a frame that
    is no valid temperature record. The common layout (``frames.temp_record``'s) is checked
    field by field after one bounded msgpack decode; anything else goes through
    ``frames.decode`` (its full validation) and is dropped if that refuses it. ``msgpack``
    and ``frames``: the modules (imported once by the caller)."""
    try:
        # msgpack ≥ 1.0's defaults: str keys only, every length capped by the payload's
        # size; an extension type comes back as an object the type checks below refuse
        rec = msgpack.unpackb(payload)
    except (ValueError, TypeError, OverflowError, msgpack.UnpackException):
        rec = None
    if type(rec) is dict and rec.get("kind") == "temp":
        names, vals, i0 = rec.get("names"), rec.get("values_c"), rec.get("i0")
        if (type(i0) is int and i0 >= 0 and type(rec.get("run")) is str
                and type(names) is list and type(vals) is list and len(names) == len(vals)):
            if len(names) == 1:      # the service's: one reading a record
                v = vals[0]
                if type(names[0]) is str and (v is None or type(v) is float):
                    return rec
            elif (all(type(x) is str for x in names)
                  and all(v is None or type(v) is float for v in vals)):
                return rec
    try:
        got = frames.decode(payload)
    except FormatError:   # refused: not a reading (the walk's decode drops it too)
        return None
    if got.get("kind") != "temp" or len(got["names"]) != len(got["values_c"]):
        return None
    if not all(v is None or (isinstance(v, int | float) and not isinstance(v, bool))
               for v in got["values_c"]):
        return None
    return got


class _RunTally:
    """What the scan counts for one run."""

    def __init__(self) -> None:
        self.first = -1          # the run's first sample index read
        self.n = 0
        self.lost = 0
        self.dup = 0


class RecordingSource:
    """An avard recording, walked frame by frame (``recording.walk``): never held whole.

    Opening scans it once (no samples kept): the runs and their rates, the sample count, the
    losses (damage, and every jump of a run's sample index that no gap record explains: a
    missing, emptied or replaced segment), the duplicates, and a read plan (where each kept
    raw block's counts lie), so later reads take only those bytes, and where it skipped the
    temperature records; those are read from there the first time a consumer asks for
    temperatures, and reach the blocks as an .npz's do (each reading on its sample's row,
    NaN between). ``runs`` keeps only those runs."""

    rereadable = True

    def __init__(self, path: Path, rate_hz: float | None = None,
                 runs: Sequence[str] | None = None) -> None:
        self.path = path
        self.runs = None if runs is None else frozenset(runs)
        self._rate_hz = rate_hz
        self._info: RecordInfo | None = None
        self._temps: list[tuple[NDArray[np.int64], NDArray[np.float64]]] | None = None
        self._ends: dict[str, int] = {}          # bytes of each file the scan read
        self._plan: _Plan | None = None          # where the scan found each kept block
        self._places: _TempPlaces | None = None  # where the scan skipped temperature records
        self.files: list[Path] = []
        self.entries: list[_SegmentFile] = []

    def records(self) -> Iterator[dict[str, Any]]:
        """The recording's records as ``recording.walk`` gives them (each run's header once,
        duplicates dropped), the files as they are now: what ``avard web --history``
        replays. Needs no scan."""
        from avard.core.io.recording import segment_files

        self.files = segment_files(self.path)
        self._ends = {}
        return self._walk()

    # -- the walk both the scan and the blocks use -------------------------------------------
    def _walk(self, problems: list[Problem] | None = None, report: Any = None,
              where: list[str] | None = None, tag: bool = False,
              skip: frozenset[str] = frozenset(), places: _TempPlaces | None = None
              ) -> Iterator[dict[str, Any]]:
        """The records of ``walk`` over this recording's files. The reader's problems go to
        ``problems`` (reported once, by the scan), not to the log at every pass; ``where``
        is kept at the file being read. ``tag``: each raw record gets ``_at`` = (file number,
        byte offset of its counts in that file or -1, its first index), what the scan's read
        plan needs (the walk passes it through, also to the parts of a duplicated block).
        ``skip``: record kinds not decoded at all (the scan needs no temperatures, Allan
        snapshots or checkpoints: two thirds of a recording's decoding). ``places``: where
        the skipped temperature records lie is noted there (the byte ranges between the
        frames the C loop hands back, which hold only skipped kinds, and each skipped
        ``temp`` frame the general reader meets), so the temperatures are read later from
        those bytes alone (``_temperature_tables``), not by a second walk of every record."""
        from avard.core.io import rawscan
        from avard.core.io.recording import FRAME_HEADER, RecordingReader, walk

        sink = problems if problems is not None else []
        # the scan reads each file's frames in C where that is built (the walk takes its
        # stretches of raw blocks as their blocks one by one); every other read, and the rest
        # of a file after a frame that does not check, is the general reader's (the C loop
        # skips exactly the kinds the scan skips)
        fast = tag and skip == _NO_SAMPLES and rawscan.available()

        class _Reader(RecordingReader):
            number = 0

            def _report(self, local: list[Problem]) -> None:
                while local:
                    prob = local.pop(0)
                    self.problems.append(prob)
                    sink.append(prob)

            def __iter__(self) -> Iterator[dict[str, Any]]:
                for k, f in enumerate(self.files):
                    self.number = k
                    self.current = f
                    if where is not None:
                        where[0] = str(f)
                    if fast:
                        yield from self._fast_file(k, f)
                        continue
                    for fr in _one_file(self, f, ends):
                        yield from self._record(fr)

            def _fast_file(self, k: int, f: Path) -> Iterator[dict[str, Any]]:
                name = str(f)
                last = 0                    # the end of the last frame the C loop handed back
                with os.fdopen(_open_segment(f), "rb") as fh:
                    frames = rawscan.scan_file(fh, name, k, self.max_bytes, ends.get(name))
                    while True:
                        try:
                            got = next(frames)
                        except StopIteration as stop:
                            pos, clean = stop.value
                            break
                        if isinstance(got, tuple):
                            if places is not None:
                                last = places.around_stretch(k, last, got[1])
                            yield rawscan.stretch_record(*got)
                        else:
                            if places is not None:
                                places.add(k, last, got.offset)
                                last = got.offset + FRAME_HEADER.size + len(got.payload)
                            yield from self._record(got)
                if places is not None:
                    places.add(k, last, pos)
                if clean:
                    ends[name] = pos
                    return
                for fr in _one_file(self, f, ends, pos):   # damage, or a torn tail
                    yield from self._record(fr)

            def _record(self, fr: Frame) -> Iterator[dict[str, Any]]:
                """One frame as RecordingReader reads it: skipped by its kind, decoded (an
                undecodable one reported), a raw one tagged with where its counts lie."""
                if skip:
                    kind = _peek_kind(fr.payload)
                    if kind in skip:
                        if places is not None and kind == "temp":
                            places.add(self.number, fr.offset,
                                       fr.offset + FRAME_HEADER.size + len(fr.payload))
                        return              # CRC-checked, not decoded: no samples in it
                rec = self.decoded(fr)
                if rec is None:
                    return
                if tag and rec["kind"] == "raw":
                    rec["_at"] = (self.number, _counts_offset(fr, rec["counts"],
                                                              FRAME_HEADER.size),
                                  int(rec["i0"]))
                yield rec

        # the scan notes how far it read each file; later reads stop there, so a recording
        # the service is still appending to reads as the scan found it
        ends = self._ends
        reader = _Reader(self.path)
        reader.files = list(self.files)
        return walk(reader, report)

    def _scan(self, rate_hz: float | None) -> RecordInfo:
        """The scan, with the walk's own WARNING per damaged block held back: ``_say`` sums
        them up per file and per run (the walk still logs them for its other readers)."""
        quiet = logging.getLogger("avard.core.io.recording")
        quiet.addFilter(_below_warning)
        try:
            return self._scan_walk(rate_hz)
        finally:
            quiet.removeFilter(_below_warning)

    def _scan_walk(self, rate_hz: float | None) -> RecordInfo:
        from avard.core.allan.feed import Segmenter, scale_of
        from avard.core.io.recording import WalkReport, segment_files

        self.files = segment_files(self.path)
        self.entries = _segment_entries(self.path)
        self._ends = {}

        problems: list[Problem] = []
        report = WalkReport()
        where = [""]
        cuts = Segmenter()
        tally: dict[str, _RunTally] = {}
        losses: list[Loss] = []
        dups: list[Duplicate] = []
        gaps: list[Gap] = []
        expect: dict[str, int] = {}          # next sample index of each run
        last_file: dict[str, str] = {}       # the file of each run's last raw block
        prev_run: str | None = None
        scales: set[float] = set()
        tnames: list[str] = []
        n_losses = n_dups = 0
        n = 0
        last_run = ""

        def reported() -> None:
            """What the walk reported since the last record: damage losses (of the run they
            name) and duplicates (of the file being read)."""
            nonlocal n_losses, n_dups
            for x in report.losses[n_losses:]:
                losses.append(Loss(x.run, x.i0, x.n, x.cause, f"in {Path(where[0]).name}"))
                if x.run in tally:
                    tally[x.run].lost += x.n
            n_losses = len(report.losses)
            for (i0, k), seen in zip(report.duplicates[n_dups:],
                                     report.duplicate_files[n_dups:], strict=True):
                _add_duplicate(dups, Duplicate(last_run, i0, k, seen or where[0]))
                if last_run in tally:
                    tally[last_run].dup += k
            n_dups = len(report.duplicates)

        plan = _Plan()
        cut = False
        scale = 0.0
        places = _TempPlaces()
        for rec in self._walk(problems, report, where, tag=True, skip=_NO_SAMPLES,
                              places=places):
            kind, run = rec["kind"], rec["run"]
            reported()
            last_run = run
            if self.runs is not None and run not in self.runs:
                continue
            if kind == "header":
                scale = scale_of(rec)
                scales.add(scale)
                for name in rec.get("temperature_channels", []):
                    if name not in tnames:
                        tnames.append(name)
                tally.setdefault(run, _RunTally())
            cut = cuts.starts_segment(rec) or cut
            if kind == "gap":
                i0, k = int(rec["i0"]), int(rec["n"])
                gaps.append(Gap(run, i0, k, str(rec.get("reason", ""))))
                # a restart continues the sample index: what the last run's end lacks up to
                # the restart's gap is a loss too (its last segment deleted, say)
                if (rec.get("reason") == "restart" and prev_run is not None
                        and prev_run != run and prev_run in expect and i0 > expect[prev_run]):
                    self._lost(losses, tally, prev_run, expect[prev_run], i0,
                               last_file.get(prev_run), where[0])
                    expect[prev_run] = i0
                if run in expect:
                    expect[run] = max(expect[run], i0 + k)
                else:
                    expect[run] = i0 + k
            elif kind == "raw":
                i0, k = int(rec["i0"]), int(rec["n"])
                t = tally[run]
                if t.first < 0:
                    t.first = i0
                # the run's start is where its first block is (or its restart gap ends)
                expect.setdefault(run, i0)
                if i0 > expect[run] and not _damage_covers(report.losses, run, expect[run], i0):
                    self._lost(losses, tally, run, expect[run], i0, last_file.get(run),
                               where[0])
                expect[run] = max(expect[run], i0 + k)
                last_file[run] = where[0]
                t.n += k
                n += k
                prev_run = run
                stretch = rec.get("_stretch")
                if stretch is None:
                    plan.add(rec.get("_at"), i0, k, scale, cut)
                else:
                    plan.extend(stretch.number, stretch.counts, stretch.i0, stretch.n, scale,
                                cut)
                cut = False
        reported()     # the walk reports headerless losses, and a last copied file, at its end
        if not tally:
            if self.runs is not None:
                raise DataError(f"{self.path}: no run {', '.join(sorted(self.runs))} in this "
                                "recording")
            lost = f" ({report.samples_lost} samples without a header)" if report.losses else ""
            raise FormatError(f"{self.path}: no header record found{lost}; not an avard "
                              "recording, or every header copy of it is damaged")
        if n == 0:
            raise DataError(f"{self.path}: the recording holds no samples")
        self._plan = plan if plan.ok else None
        self._places = places
        run_list = self._runs(tally, report.newest_header)
        rate, rate_u = self._rate(run_list, rate_hz)
        summary = RecordingSummary(
            runs=tuple(run_list), losses=tuple(losses), duplicates=tuple(dups),
            gaps=tuple(gaps), n_segments=len(cuts.segment_bounds()) - 1,
            files=tuple(str(f) for f in self.files),
            problems=tuple(str(p) for p in problems),
            dropped_bytes=sum(p.dropped_bytes for p in problems))
        self._say(summary, problems)
        head = report.newest_header[run_list[0].run]
        device = (head.get("sensor") or {}).get("device")
        # the configured name (``sensor.name``, a rig's lane) names it; older headers: the part
        named = (head.get("sensor") or {}).get("name") or device
        model = "ADXL355" if device is None or "ADXL355" in str(device) else str(device)
        return RecordInfo(
            source=str(self.path), format=RecordFormat.RECORDING, rate_hz=rate,
            rate_u_hz=rate_u, names=("x", "y", "z"), temperature_names=tuple(tnames),
            n_samples=n, lsb_mps2=scales.pop() if len(scales) == 1 else None,
            sensor_name=str(named) if named is not None else None, sensor_model=model,
            # the ADXL355's digital low-pass sits at ODR/4 whatever the ODR
            filter_corner_hz=rate / 4.0 if model == "ADXL355" else None,
            recording=summary)

    def _lost(self, losses: list[Loss], tally: dict[str, _RunTally], run: str, a: int, b: int,
              before: str | None, after: str) -> None:
        """Samples ``[a, b)`` of ``run`` absent with no gap record: a loss, placed between the
        file of the run's last block and the file read now."""
        losses.append(Loss(run, a, b - a, "no gap record explains them",
                           _between(self.entries, run, before, after if after != before
                                    else None)))
        tally[run].lost += b - a

    def _runs(self, tally: dict[str, _RunTally], newest: dict[str, dict[str, Any]]
              ) -> list[RunSummary]:
        from avard.core.allan.feed import nominal_of

        out = []
        for run, t in tally.items():
            h = newest.get(run, {})
            tb = h.get("timebase") or {}
            u = tb.get("odr_u_hz")
            fitted = isinstance(u, int | float) and u > 0
            out.append(RunSummary(run, float(h.get("rate_hz", math.nan)),
                                  float(u) if isinstance(u, int | float) and fitted else 0.0,
                                  t.first, t.n, t.lost, t.dup,
                                  rate_fitted=fitted or not isinstance(tb.get("odr_hz"),
                                                                       int | float),
                                  # the one reader of it (the loader's and the feed's): a
                                  # value no avard writes (NaN, ≤ 0) says nothing, as none
                                  nominal_hz=nominal_of(h)))
        return out

    def _rate(self, runs: list[RunSummary], rate_hz: float | None) -> tuple[float, float]:
        """The record's rate: the runs' fitted rates, which must agree by the rule of
        core/io/rates.py (never averaged across ODR settings), weighted by their samples. A
        run too short for the service's rate fit agrees when its nominal ODR is the others'
        (its nominal rate says nothing finer) and does not enter the mean."""
        from avard.core.io.readers import check_rate

        with_data = [r for r in runs if r.n_samples > 0]
        fitted = [r for r in with_data if r.rate_fitted] or with_data[:1]
        ref = fitted[0]
        nominal = ref.nominal_hz if ref.nominal_hz is not None else ref.rate_hz
        bad = [r for r in with_data
               if (r.rate_fitted and ref.rate_fitted
                   and not rates_compatible(ref.rate_hz, r.rate_hz, ref.rate_u_hz,
                                            r.rate_u_hz))
               or ((not r.rate_fitted or not ref.rate_fitted)
                   and (r.nominal_hz if r.nominal_hz is not None else r.rate_hz) != nominal)]
        if bad:
            listed = "; ".join(f"run {r.run} at {r.rate_text()} ({r.n_samples} samples)"
                               for r in with_data)
            raise DataError(f"{self.path}: runs at incompatible rates ({listed}); they are not "
                            "averaged: analyse each separately with --run RUN")
        if rate_hz is not None:
            return check_rate(rate_hz, str(self.path)), 0.0
        if len(fitted) == 1:
            return check_rate(ref.rate_hz, str(self.path)), ref.rate_u_hz
        w = np.array([r.n_samples for r in fitted], dtype=float)
        rates = np.array([r.rate_hz for r in fitted])
        rate = float(np.sum(w * rates) / np.sum(w))
        us = [r.rate_u_hz for r in fitted]
        u = float(math.sqrt(sum((wi * ui) ** 2 for wi, ui in zip(w, us, strict=True)))
                  / np.sum(w)) if all(x > 0 for x in us) else 0.0
        return check_rate(rate, str(self.path)), u

    def _say(self, summary: RecordingSummary, problems: list[Problem]) -> None:
        """One WARNING per damaged file and one per run that lost or repeated samples."""
        per_file: dict[str, list[Problem]] = {}
        for p in problems:
            per_file.setdefault(p.file, []).append(p)
        for f, probs in per_file.items():
            log.warning("%s: %d damaged or truncated frame(s) skipped (%d bytes), first at "
                        "byte %d", f, len(probs), sum(p.dropped_bytes for p in probs),
                        probs[0].offset)
        for r in summary.runs:
            if r.samples_lost or r.samples_duplicated:
                mine = [x for x in summary.losses if x.run == r.run]
                x = mine[0] if mine else None
                first = (f"; first: {x.n} samples from index {x.i0}, {x.where} ({x.cause})"
                         if x is not None else "")
                log.warning("%s: run %s: %d samples lost in %d place(s), %d read twice "
                            "(counted once)%s; detail in --json", self.path, r.run,
                            r.samples_lost, len(mine), r.samples_duplicated, first)

    def _temperature_tables(self) -> list[tuple[NDArray[np.int64], NDArray[np.float64]]]:
        """Each temperature channel's readings (sample index, °C) in index order, one per
        index (a later record wins at an equal index, as ``load_recording``'s hold), a failed
        read (None) no reading: read the first time a consumer asks for temperatures
        (analyze never does), from the byte ranges where the scan skipped them
        (``_placed_readings``: the raw blocks are not read again, the records decoded in
        bulk); without those, by one more walk that decodes the temperature records only.
        About one reading a second a channel: 60 h of three channels is ~10 MB here."""
        if self._temps is None:
            # the runs whose header was read: the walk drops a headerless run's records (its
            # samples are reported lost), and its readings, keyed by index alone, would land
            # on another run's rows
            summary = self.info.recording
            known = None if summary is None else {r.run for r in summary.runs}

            def keep(run: str) -> bool:
                return ((self.runs is None or run in self.runs)
                        and (known is None or run in known))

            chunks: dict[str, tuple[list[NDArray[np.int64]], list[NDArray[np.float64]]]] = {}
            places = self._places
            got = (self._placed_readings(places, keep) if places is not None and places.ok
                   else self._walked_readings(keep))
            for name, idx, vals in got:
                have = chunks.setdefault(name, ([], []))
                have[0].append(idx)
                have[1].append(vals)
            self._temps = []
            for name in self.info.temperature_names:
                ii, vv = chunks.pop(name, ([], []))
                st = np.concatenate(ii) if ii else np.zeros(0, np.int64)
                v = np.concatenate(vv) if vv else np.zeros(0)
                order = np.argsort(st, kind="stable")
                st, v = st[order], v[order]
                last = np.ones(len(st), dtype=bool)   # the last record at each index wins
                last[:-1] = st[1:] != st[:-1]
                self._temps.append((st[last], v[last]))
        return self._temps

    def _walked_readings(self, keep: Callable[[str], bool]
                         ) -> Iterator[tuple[str, NDArray[np.int64], NDArray[np.float64]]]:
        """(channel, indices, °C) of every reading, in walk order, by a walk that decodes the
        temperature records only (no read plan, or places the scan could not note)."""
        readings: dict[str, tuple[array[int], array[float]]] = {}
        for rec in self._walk(skip=_NOT_TEMPERATURE):
            if rec["kind"] != "temp" or not keep(rec["run"]):
                continue
            i0 = int(rec["i0"])
            for name, value in zip(rec["names"], rec["values_c"], strict=True):
                if value is not None:
                    got = readings.get(name)
                    if got is None:
                        got = readings[name] = (array("q"), array("d"))
                    got[0].append(i0)
                    got[1].append(float(value))
        for name, (idx, vals) in readings.items():
            yield (name, np.frombuffer(idx, dtype=np.int64) if len(idx) else np.zeros(0, np.int64),
                   np.frombuffer(vals, dtype=np.float64) if len(vals) else np.zeros(0))

    def _placed_readings(self, places: _TempPlaces, keep: Callable[[str], bool]
                         ) -> Iterator[tuple[str, NDArray[np.int64], NDArray[np.float64]]]:
        """(channel, indices, °C) of the readings in the ranges the scan noted
        (``_TempPlaces``), each channel's in walk order: a file mapped, its ranges taken a
        window at a time, the frames in them found, each temperature frame's CRC checked
        again and the records decoded together (``tempscan``: the service's layout in bulk,
        any other through ``_temp_record``), every other frame stepped over."""
        import mmap

        import msgpack
        from avard.core.io import frames, tempscan

        fidx = np.frombuffer(places.fidx, dtype=np.uint16)
        start = np.frombuffer(places.start, dtype=np.int64)
        end = np.frombuffer(places.end, dtype=np.int64)
        kind = np.frombuffer(tempscan.TEMP_KIND, dtype=np.uint8)
        page = mmap.PAGESIZE
        for a0, b0 in _file_spans(fidx):
            f = self.files[int(fidx[a0])]
            fd = _open_segment(f)
            try:
                if os.fstat(fd).st_size < int(end[a0:b0].max()):
                    raise DataError(f"{f}: shorter than when it was opened; the recording "
                                    "changed while it was read (analyse a copy)")
                mm = mmap.mmap(fd, 0, access=mmap.ACCESS_READ)
            finally:
                os.close(fd)
            buf = np.frombuffer(mm, dtype=np.uint8)
            view = memoryview(mm)
            try:
                a = a0
                while a < b0:
                    c = max(a + 1, a + int(np.searchsorted(end[a:b0], int(start[a])
                                                          + _TEMP_WINDOW, side="right")))
                    try:
                        fs = tempscan.frames_in(buf, start[a:c], end[a:c])
                    except ValueError as exc:
                        raise DataError(f"{f}: a frame at byte {exc.args[0]} is not where the "
                                        "scan found one; the recording changed while it was "
                                        "read (analyse a copy)") from None
                    yield from self._window_readings(buf, view, fs, kind, keep, f,
                                                     msgpack, frames)
                    if c < b0 and hasattr(mm, "madvise"):
                        # the pages read leave this process's RSS (the last window's go when
                        # the file is closed)
                        lo = int(start[a]) // page * page
                        mm.madvise(mmap.MADV_DONTNEED, lo, int(end[c - 1]) - lo)
                    a = c
            finally:
                del buf
                view.release()
                try:
                    mm.close()
                except BufferError:   # a view still held (an error on the way): the
                    pass              # mapping goes with it

    @staticmethod
    def _window_readings(buf: NDArray[np.uint8], view: memoryview, fs: FrameSet,
                         kind: NDArray[np.uint8], keep: Callable[[str], bool], f: Path,
                         msgpack: ModuleType, frames: ModuleType
                         ) -> Iterator[tuple[str, NDArray[np.int64], NDArray[np.float64]]]:
        """The readings of one window's frames (``tempscan.FrameSet``), per channel in frame
        order."""
        from avard.core.io import tempscan

        last = len(buf) - 1
        lead = buf[np.minimum(fs.body, last)]
        fixmap = (lead >= 0x80) & (lead <= 0x8F) & (fs.n > 0)
        temp = fixmap & (fs.n > len(kind)) & np.all(
            buf[np.minimum(fs.body[:, None] + 1 + np.arange(len(kind)), last)] == kind, axis=1)
        for k in np.flatnonzero(~fixmap & (fs.n > 0)).tolist():   # not the usual map header
            b = int(fs.body[k])
            temp[k] = _peek_kind(bytes(view[b:b + min(int(fs.n[k]), 48)])) == "temp"
        at = np.flatnonzero(temp)
        for b, n, crc in zip(fs.body[at].tolist(), fs.n[at].tolist(), fs.crc[at].tolist(),
                             strict=True):
            if zlib.crc32(view[b:b + n]) & 0xFFFFFFFF != crc:
                raise DataError(f"{f}: the frame at byte {b - 8} no longer checks; the "
                                "recording changed while it was read (analyse a copy)")
        tr = tempscan.service_readings(buf, fs, temp)
        names = list(tr.names)
        frame, index, value = [tr.frame], [tr.index], [tr.value]
        name = [tr.name]
        run_ok = [np.array([keep(r) for r in tr.runs], dtype=bool)[tr.run]]
        # the frames of another layout, decoded one by one as the walk would
        o_frame: list[int] = []
        o_index: list[int] = []
        o_value: list[float] = []
        o_name: list[int] = []
        o_ok: list[bool] = []
        for k in np.flatnonzero(temp & ~tr.decoded).tolist():
            b = int(fs.body[k])
            rec = _temp_record(bytes(view[b:b + int(fs.n[k])]), msgpack, frames)
            if rec is None:
                continue
            ok = keep(rec["run"])
            for nm, v in zip(rec["names"], rec["values_c"], strict=True):
                if v is not None:
                    if nm not in names:
                        names.append(nm)
                    o_frame.append(k)
                    o_index.append(int(rec["i0"]))
                    o_value.append(float(v))
                    o_name.append(names.index(nm))
                    o_ok.append(ok)
        if o_frame:
            frame.append(np.array(o_frame, dtype=np.int64))
            index.append(np.array(o_index, dtype=np.int64))
            value.append(np.array(o_value, dtype=np.float64))
            name.append(np.array(o_name, dtype=np.int64))
            run_ok.append(np.array(o_ok, dtype=bool))
        fr = np.concatenate(frame)
        order = np.argsort(fr, kind="stable")      # frame order, a frame's readings in order
        idx, val = np.concatenate(index)[order], np.concatenate(value)[order]
        nm_of, ok_of = np.concatenate(name)[order], np.concatenate(run_ok)[order]
        for j, nm in enumerate(names):
            sel = (nm_of == j) & ok_of
            if sel.any():
                yield nm, idx[sel], val[sel]

    def _walked(self) -> Iterator[_Piece]:
        """The raw pieces in walk order, by the general path: every record decoded and
        checked (``recording.walk``), cut where the service's ``Segmenter`` cut."""
        from avard.core.allan.feed import Segmenter, scale_of

        cuts = Segmenter()
        scale, cut = 0.0, False
        for rec in self._walk():
            if self.runs is not None and rec["run"] not in self.runs:
                continue
            cut = cuts.starts_segment(rec) or cut
            if rec["kind"] == "header":
                scale = scale_of(rec)
            elif rec["kind"] == "raw":
                yield int(rec["i0"]), np.asarray(rec["counts"]), scale, cut
                cut = False

    @staticmethod
    def _window(plan: _Plan, lo: int, hi: int
                ) -> Iterator[tuple[int, int, list[tuple[int, int]], int, float, bool]]:
        """Reads for the plan's blocks ``[lo, hi)``: (file number, byte offset, each block's
        counts as (offset from there, bytes), first index, scale, a segment ends before),
        each read a run of blocks that continue each other (same file and scale, no cut,
        the next index, at most ``_SKIP_BYTES`` of other records between) ending within
        ``_READ_BYTES`` of its start (at least one block)."""
        from avard.core.io import rawscan

        hi = min(hi, len(plan.i0))
        fidx = np.frombuffer(plan.fidx, dtype=np.uint16)[lo:hi]
        off = np.frombuffer(plan.off, dtype=np.int64)[lo:hi]
        i0 = np.frombuffer(plan.i0, dtype=np.int64)[lo:hi]
        size = np.frombuffer(plan.n, dtype=np.uint32)[lo:hi].astype(np.int64) * 12
        sidx = np.frombuffer(plan.sidx, dtype=np.uint16)[lo:hi]
        cut = np.frombuffer(plan.cut, dtype=np.uint8)[lo:hi]
        end = off + size
        cont = np.zeros(len(i0), dtype=bool)
        cont[1:] = ((fidx[1:] == fidx[:-1]) & (sidx[1:] == sidx[:-1]) & (cut[1:] == 0)
                    & (i0[1:] == i0[:-1] + size[:-1] // 12) & (off[1:] >= end[:-1])
                    & (off[1:] - end[:-1] <= _SKIP_BYTES))
        for a, b in rawscan.spans(cont):
            first = True
            while a < b:
                c = max(a + 1, int(np.searchsorted(end[a:b], int(off[a]) + _READ_BYTES,
                                                   side="right")) + a)
                at = int(off[a])
                rel = (off[a:c] - at).tolist()
                yield (int(fidx[a]), at, list(zip(rel, size[a:c].tolist(), strict=True)),
                       int(i0[a]), plan.scales[int(sidx[a])], first and bool(cut[a]))
                first = False
                a = c

    def _planned(self) -> Iterator[_Piece]:
        """The same pieces by the fast path: the scan walked and checked every frame and
        noted where each kept block's counts lie; a later read takes just those bytes (no
        decoding of the raw, temperature, Allan and checkpoint records again), a run of
        blocks that continue each other in one read of at most ``_READ_BYTES``. Held equal
        to :meth:`_walked` by tests/daemon/test_record_source.py and
        tests/core/test_recording_fastscan.py."""
        plan = self._plan
        assert plan is not None
        fd, open_k = -1, -1
        try:
            # a window of the plan at a time: temporaries of the whole plan's length would be
            # ~40 bytes a block, more than the plan itself
            for w in range(0, len(plan.i0), _PLAN_WINDOW):
                for k, at, counts, i0, scale, cut in self._window(plan, w, w + _PLAN_WINDOW):
                    if k != open_k:
                        if fd >= 0:
                            os.close(fd)
                        fd, open_k = _open_segment(self.files[k]), k
                    data = os.pread(fd, counts[-1][0] + counts[-1][1], at)
                    if len(data) != counts[-1][0] + counts[-1][1]:
                        raise DataError(f"{self.files[k]}: shorter than when it was opened; "
                                        "the recording changed while it was read (analyse a "
                                        "copy)")
                    view = memoryview(data)
                    yield i0, np.frombuffer(b"".join([view[r:r + m] for r, m in counts]),
                                            dtype="<i4").reshape(-1, 3), scale, cut
        finally:
            if fd >= 0:
                os.close(fd)

    @property
    def info(self) -> RecordInfo:
        """The description, from one scan of the recording on first use."""
        if self._info is None:
            self._info = self._scan(self._rate_hz)
        return self._info

    def blocks(self, block: int = BLOCK, *, columns: Sequence[int] | None = None,
               temperature: bool = True, verify: bool = True) -> Iterator[RecordBlock]:
        """The recording's samples in SI units, in blocks of at most ``block`` samples that
        end where the service's accumulators ended a segment (every gap record, run change
        and index jump). Temperatures as an .npz or a CSV holds them: each reading on the
        row of its sample index, NaN between readings (``_readings_on_rows``), so the screen
        and explain see one reading per conversion of every source, not one per sample."""
        info = self.info
        _check_block(block)
        _check_columns(columns, info)
        cols = [0, 1, 2] if columns is None else [int(c) for c in columns]
        temps = (self._temperature_tables() if temperature and info.temperature_names
                 else None)
        buf = np.empty((block, len(cols)))
        fill = 0
        start = 0                      # sample index of buf[0]
        n = 0
        after = [-(1 << 62)]           # the index after the last block's last row

        def flush(end: bool) -> RecordBlock:
            a = buf[:fill].copy()
            t = None
            if temps is not None:
                t = _readings_on_rows(temps, start, fill, after[0])
            after[0] = start + fill
            return a, t, end

        pieces = self._planned() if self._plan is not None else self._walked()
        for i0, counts, scale, cut in pieces:
            if cut and fill:
                yield flush(True)
                fill = 0
            k = int(counts.shape[0])
            at = 0
            while at < k:
                if fill == 0:
                    start = i0 + at
                take = min(block - fill, k - at)
                part = counts[at:at + take]
                for j, c in enumerate(cols):     # counts × scale in one pass per column
                    np.multiply(part[:, c], scale, out=buf[fill:fill + take, j])
                fill += take
                at += take
                if fill == block:
                    yield flush(False)
                    fill = 0
            n += k
        if fill:
            yield flush(True)
        if n != info.n_samples:
            raise DataError(f"{self.path}: read {n} samples, {info.n_samples} when it "
                            "was opened; the recording changed while it was read (analyse a "
                            "copy, or a recording the service has finished)")


def _file_spans(col: NDArray[Any]) -> list[tuple[int, int]]:
    """``[a, b)`` of each run of equal values in ``col``."""
    if not len(col):
        return []
    cut = np.flatnonzero(col[1:] != col[:-1]) + 1
    bounds = [0, *cut.tolist(), len(col)]
    return list(itertools.pairwise(bounds))


def _readings_on_rows(temps: Sequence[tuple[NDArray[np.int64], NDArray[np.float64]]],
                      start: int, n: int, after: int) -> NDArray[np.float64]:
    """A block's temperatures (n, k): the readings whose sample index lies in the block's
    rows ``[start, start + n)`` on their row, NaN on every other row. A reading whose index
    is no recorded sample (stamped during a gap, or before the first sample) goes to the first
    row after it (``after``: the index after the block before, when the blocks run forward),
    the last one there winning: what the old hold gave that row, and a hold of these blocks
    is ``load_recording``'s hold."""
    t = np.full((n, len(temps)), np.nan)
    lo_index = after if after <= start else start
    for c, (st, v) in enumerate(temps):
        lo = int(np.searchsorted(st, lo_index))
        hi = int(np.searchsorted(st, start + n))
        if hi <= lo:
            continue
        rows = np.maximum(st[lo:hi] - start, 0)
        last = np.ones(hi - lo, dtype=bool)       # one reading per row: the last
        last[:-1] = rows[1:] != rows[:-1]
        t[rows[last], c] = v[lo:hi][last]
    return t


def _one_file(reader: Any, f: Path, ends: dict[str, int], start: int | None = None
              ) -> Iterator[Frame]:
    """The frames of one segment file as ``recording.scan_frames`` finds them, read frame by
    frame: a clean hour-long segment is never held whole (it would be most of the memory
    analyze may add over an .npz). At the first frame that is not valid (damage, or the
    truncated tail a power cut leaves) the file is handed to ``scan_frames``, which reports
    and resynchronises exactly as for any reader; the frames before are the same either way.
    ``ends[file]``, when set, is where to stop (what the first read of the file found); else
    it is set to that. ``start``: the frames before that offset were read and checked
    already (by the scan's C loop, core/io/rawscan.py), which stopped there."""
    from avard.core.io.recording import FRAME_HEADER, Frame, scan_frames

    name = str(f)
    limit = ends.get(name)
    hdr = FRAME_HEADER.size
    pos = 0 if start is None else start
    with os.fdopen(_open_segment(f), "rb") as fh:
        while start is None:
            if limit is not None and pos >= limit:
                return
            head = fh.read(hdr)
            if not head:
                ends[name] = pos             # a clean end
                return
            if len(head) < hdr:
                break
            n, crc = FRAME_HEADER.unpack(head)
            if not 0 < n <= reader.max_bytes:
                break
            payload = fh.read(n)
            if len(payload) != n or zlib.crc32(payload) & 0xFFFFFFFF != crc:
                break
            yield Frame(name, pos, payload)
            pos += hdr + n
    data = f.read_bytes()
    if limit is not None:
        data = data[:limit]
    ends.setdefault(name, len(data))
    local: list[Problem] = []
    for fr in scan_frames(data, name, max_bytes=reader.max_bytes, problems=local):
        if fr.offset >= pos:
            reader._report(local)
            yield fr
    reader._report(local)


def _below_warning(record: logging.LogRecord) -> bool:
    return record.levelno < logging.WARNING


def _open_segment(f: Path) -> int:
    """A segment's file descriptor, or one line saying it went while the recording was
    read (retention, or a hand, deleted it) or cannot be read."""
    try:
        return os.open(f, os.O_RDONLY)
    except FileNotFoundError:
        raise DataError(f"{f}: removed while the recording was read (the service's retention "
                        "deletes the oldest segments); analyse a copy of the recording") from None
    except OSError as exc:
        raise DataError(f"{f}: cannot be read ({exc.strerror}); check its permissions") from exc


def _damage_covers(losses: Sequence[Any], run: str, a: int, b: int) -> bool:
    """Whether the walk already reported ``[a, b)`` of ``run`` lost to damage."""
    return any(x.run == run and x.i0 <= a and x.i0 + x.n >= b for x in losses[-4:])


def _add_duplicate(dups: list[Duplicate], d: Duplicate) -> None:
    """Duplicates of one file merged into one range when they follow each other."""
    if dups:
        last = dups[-1]
        if last.run == d.run and last.where == d.where and last.i0 + last.n == d.i0:
            dups[-1] = Duplicate(d.run, last.i0, last.n + d.n, d.where)
            return
    dups.append(d)
