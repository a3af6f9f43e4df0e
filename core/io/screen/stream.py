"""The screen as one pass over a record's blocks (``screen_blocks``), the whole-record rules after
it, and the one screened segment source analyze and explain read (``ScreenedSource``)."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
from avard.core.io.screen.accel import STARTUP_S, _runs, screen_accel
from avard.core.io.screen.held_accel import HeldAccel
from avard.core.io.screen.held_log import HELD_WAIT_SAMPLES, _Dehold
from avard.core.io.screen.log_step import DS18B20_BITS, log_step
from avard.core.io.screen.notes import Block, LogNote, Screened, ScreenLog
from avard.core.io.screen.temperature import (
    DROPOUT_READINGS,
    DROPOUT_S,
    NOT_DS18B20,
    _TempTrack,
    screen_temperature,
    stuck_runs,
)
from avard.core.io.screen.units import (
    _celsius_evidence,
    _never_converted,
    fahrenheit_columns,
    temperature_units,
    to_celsius,
    units_note,
)
from avard.core.io.source import RecordFormat
from numpy.typing import NDArray


def screen_blocks(blocks: Iterator[Block], rate_hz: float, names: Sequence[str],
                  temperature_names: Sequence[str], log: ScreenLog,
                  columns: Sequence[int] | None = None,
                  bad_rows: Callable[[int, NDArray[np.float64], NDArray[np.bool_]],
                                     NDArray[np.bool_]] | None = None,
                  check_units: bool = True,
                  held_rows: Callable[[int, int], NDArray[np.bool_]] | None = None,
                  on_verdict: Callable[[int, NDArray[np.bool_], NDArray[np.bool_]], None]
                  | None = None) -> Iterator[Block]:
    """``blocks`` (all accel columns) with the outlying acceleration rows cut out (a segment
    ends before each cut) and the bad temperature readings set to NaN; what was masked goes
    to ``log``. ``columns``: the accel columns to hand on (after screening on all).
    ``bad_rows(offset, block, held rows)``: the block's outlying rows (default ``screen_accel``; a
    ``ScreenedSource`` hands the first read's verdicts to its later reads). Held acceleration
    (``HeldAccel``, over the whole read: each block is fed to it when read, and judged when
    handed on, a block later) is cut likewise; ``held_rows(offset, n)`` gives its verdict
    instead ((n, axes) held flags: a later read's, which may read fewer axes).
    ``on_verdict(offset, cut rows, held flags)``: each block's verdicts, for a later read.

    Temperature readings are judged with one block of look-ahead (a spike's right-hand
    neighbour may be in the next block), so each block is handed on when the next has been
    read; the stuck and dropout rules need the whole channel and are applied at the end
    (they mask nothing analyze reads; explain masks its slow view by ``log.holes``).
    ``check_units``: judge each log's units by the DS18B20's grid (``units_note``; off for a
    recording, whose daemon writes °C itself). ``log.units`` (``--temperature-units``): "C"
    takes every log as °C (a °F verdict is said, not acted on), "F" converts each log the
    units rule judges to °C as it is read (before every rule: 85 °C is 185 °F)."""
    tnames = list(temperature_names)
    to_c = fahrenheit_columns(tnames, log.units, check_units)
    tracks = [_TempTrack() for _ in tnames]
    held = [_Dehold() for _ in tnames]
    pending: list[tuple[int, Block]] = []
    offset = 0
    start_n = round(STARTUP_S * rate_hz)
    cols = None if columns is None else list(columns)
    detector = HeldAccel() if held_rows is None else None
    # the log's held stretch that may go on into the next block (its index)
    held_at = [-1]

    def emit(off: int, blk: Block, last: bool) -> Iterator[Block]:
        a, t, end = blk
        if t is not None and tnames:
            t = _mask_readings(off, t, tracks, tnames, log, rate_hz, final=last)
        flags = (detector.verdict(off, len(a)) if detector is not None
                 else held_rows(off, len(a)) if held_rows is not None
                 else np.zeros((len(a), 0), dtype=bool))
        held: NDArray[np.bool_] = (np.asarray(flags.any(axis=1), dtype=bool) if flags.shape[1]
                                   else np.zeros(len(a), dtype=bool))
        shock = (bad_rows(off, a, held) if bad_rows is not None
                 else screen_accel(a, held) if held.any() else screen_accel(a))
        if on_verdict is not None:
            on_verdict(off, shock, flags)
        for f, l_ in _runs(shock & ~held):
            kind = "startup_glitch" if off + f < start_n else "shock"
            log.stretches.append(Screened("accel", kind, off + f, off + l_, (off + f) / rate_hz,
                                          (off + l_ + 1) / rate_hz, l_ - f + 1))
        for f, l_ in _runs(held):
            axes = tuple(str(names[j]) if j < len(names) else str(j)
                         for j in range(flags.shape[1]) if flags[f:l_ + 1, j].any())
            k = held_at[0]
            prev = log.stretches[k] if 0 <= k < len(log.stretches) else None
            if prev is not None and prev.kind == "held_accel" and prev.last + 1 == off + f:
                # a held stretch across the blocks' boundary: one stretch
                log.stretches[k] = Screened(
                    "accel", "held_accel", prev.first, off + l_, prev.start_s,
                    (off + l_ + 1) / rate_hz, prev.count + l_ - f + 1,
                    tuple(x for x in names if x in prev.axes or x in axes) or prev.axes)
                continue
            held_at[0] = len(log.stretches)
            log.stretches.append(Screened("accel", "held_accel", off + f, off + l_,
                                          (off + f) / rate_hz, (off + l_ + 1) / rate_hz,
                                          l_ - f + 1, axes))
        runs = _runs(shock | held)
        pos = 0
        pieces: list[Block] = []
        for f, l_ in runs:
            if f > pos:
                pieces.append((a[pos:f], None if t is None else t[pos:f], True))
            pos = l_ + 1
        if pos < len(a):
            pieces.append((a[pos:], None if t is None else t[pos:], end))
        elif pieces:
            pieces[-1] = (pieces[-1][0], pieces[-1][1], True)
        for pa, pt, pe in pieces:
            yield (pa if cols is None else pa[:, cols]), pt, pe

    def take(off: int, blk: Block) -> Block:
        """The block's temperatures read as readings (a held log's) and tracked."""
        a, t, end = blk
        if t is not None and tnames:
            tt = np.asarray(t, dtype=float).reshape(len(a), -1)
            given = [tt[:, j] for j in range(tt.shape[1])]
            cols_t = [d.apply(off, c) for c, d in zip(given, held, strict=True)]
            if any(c is not g for c, g in zip(cols_t, given, strict=True)):
                # a held log read as readings: the block hands the readings on, NaN between
                tt = np.stack(cols_t, axis=1)
                blk = (a, tt if np.ndim(t) == 2 else tt[:, 0], end)
            for j, tr in enumerate(tracks):
                tr.add(off, tt[:, j])
        return blk

    # a log with a value on every row whose first block holds too few runs to tell a held
    # log is judged on more of it: the blocks wait (at most HELD_WAIT_SAMPLES rows, a few
    # MB) until every channel is judged; a log of readings is judged on its first block
    waiting: list[tuple[int, Block]] = []
    waited = 0

    def judge(final: bool) -> bool:
        ok = True
        for j, d in enumerate(held):
            if d.k is not None:
                continue
            col = np.concatenate([
                np.full(len(b[0]), np.nan) if b[1] is None
                else np.asarray(b[1], dtype=float).reshape(len(b[0]), -1)[:, j]
                for _, b in waiting])
            ok = d.decide(col, final) and ok
        return ok

    def observe(blks: list[tuple[int, Block]]) -> None:
        """Each channel's log watched over these blocks (``_Dehold.observe``)."""
        for off_w, (a, t, _end) in blks:
            tt = (np.full((len(a), len(tnames)), np.nan) if t is None
                  else np.asarray(t, dtype=float).reshape(len(a), -1))
            for j, d in enumerate(held):
                d.observe(off_w, tt[:, j])

    observed = 0  # the waiting blocks already watched
    for blk in blocks:
        blk = _infinite_readings(offset, to_celsius(blk, to_c), tnames, log, rate_hz)
        if detector is not None:
            detector.feed(offset, np.asarray(blk[0], dtype=float))
        waiting.append((offset, blk))
        offset += len(blk[0])
        waited += len(blk[0])
        if tnames and not judge(waited >= HELD_WAIT_SAMPLES):
            continue
        observe(waiting[observed:])
        observed = len(waiting)
        # every block but the newest is handed on (a held stretch found in it may begin in
        # the block before: a log with a value on consecutive rows only), or none while a
        # channel's test for a held stretch is close (at most HELD_WAIT_SAMPLES rows)
        if ((any(d.close for d in held) or (detector is not None and detector.undecided()))
                and sum(len(b[0]) for _, b in waiting) < HELD_WAIT_SAMPLES):
            continue
        hold = 1 if any(d.dense for d in held) else 0
        while len(waiting) > hold:
            off_w, b_w = waiting.pop(0)
            observed -= 1
            pending.append((off_w, take(off_w, b_w)))
        while len(pending) > 1:
            off, b = pending.pop(0)
            yield from emit(off, b, False)
    if waiting:
        judge(True)
        observe(waiting[observed:])
        for off_w, b_w in waiting:
            pending.append((off_w, take(off_w, b_w)))
    while pending:
        off, b = pending.pop(0)
        yield from emit(off, b, not pending)
    _whole_record_rules(tracks, tnames, log, rate_hz, offset)
    log.readings = {name: len(tr) for name, tr in zip(tnames, tracks, strict=True)}
    for name, tr, d in zip(tnames, tracks, held, strict=True):
        note = d.note(rate_hz)
        if note is not None:
            log.notes[name] = note
        if not check_units or name in NOT_DS18B20:
            unit, refused = None, None
            if log.units == "F":
                unit = LogNote("units_given", (
                    "not converted from °F: " + ("avard's own die temperature" if check_units
                                                 else "a recording's log") + " is °C"))
        elif log.units == "F":
            unit, refused = LogNote("units_given", "converted from °F to °C as asked "
                                    "(--temperature-units F)"
                                    + _celsius_evidence(tr.arrays()[1])), None
        else:
            unit, refused = units_note(tr.arrays()[1])
            if log.units == "C":
                # said by the user: taken as °C, and what the readings looked like said
                evidence = ("" if refused is None else
                            refused.split("; a coupling")[0].removeprefix("taken for °F: "))
                seen = ("" if unit is None else f" (its readings look like °F: {evidence})"
                        if refused is not None else f" (its readings: {unit.text})")
                unit, refused = LogNote("units_given", "taken as °C as asked "
                                        f"(--temperature-units C){seen}"), None
        grid = log_step(tr.arrays()[1], tr.arrays()[0] / rate_hz) if len(tr) else None
        if grid is not None and ((check_units and name not in NOT_DS18B20)
                                 or (grid[1] == 0.0 and grid[0] in DS18B20_BITS)):
            # avard's own logs (the die's ~0.11 K LSB, a recording's) only on a DS18B20
            # resolution the data show: the candidates' print tolerance would take the die's
            # 0.1105 K for a °F DS18B20's 0.1125
            log.steps[name] = grid
        coarse = log.coarse(name)
        if refused is None and coarse is not None:
            # said beside the log's other note, under its kind: its rounding is not the one
            # the thermal model's rounding terms assume (a refused log is used by no model)
            unit = (LogNote("coarse_step", coarse) if unit is None else
                    LogNote(unit.kind, f"{unit.text}; {coarse}", unit.stretches))
        if unit is not None:
            # one line per channel: a held log's note and its units' note joined
            log.notes[name] = unit if note is None else note.joined(unit)
        if refused is not None:
            log.refused[name] = refused
        _refuse(log, name, _spiky(log, name, len(tr)) or _level_jump(log, name, tr, rate_hz))
        if name not in NOT_DS18B20:
            _refuse(log, name, _never_converted(tr.arrays()[1]))
    log.stretches.sort(key=lambda s: (s.start_s, s.channel))
    log.done = True


def _refuse(log: ScreenLog, name: str, note: LogNote | None) -> None:
    """A whole-log rule's verdict: its note beside the log's others, and the log refused for
    the thermal model with it (the first reason kept); nothing where the rule found nothing."""
    if note is None:
        return
    log.notes[name] = note if name not in log.notes else log.notes[name].joined(note)
    log.refused.setdefault(name, note.text)


#: A log more than this share of whose readings are spikes is not one sensor's readings of
#: one place: a real DS18B20 log has a spike in thousands of readings at most
SPIKY_SHARE = 0.05


def _spiky(log: ScreenLog, name: str, readings: int) -> LogNote | None:
    """A note refusing a log whose readings are spikes more than ``SPIKY_SHARE`` of the time
    (two sensors answering on one column, a noisy line): masking each spike had left a log
    of one sensor's readings in the other's gaps, and the axis unexplained without a word of
    why."""
    spikes = sum(1 for st in log.stretches if st.channel == name and st.kind == "spike")
    if readings < 20 or spikes <= SPIKY_SHARE * readings:
        return None
    return LogNote("spiky", f"{spikes} of its {readings} readings are spikes (a reading, or "
                   "up to three in a row, more than 0.5 K from both neighbours): more than "
                   f"{SPIKY_SHARE:.0%} is not one sensor reading one place (two sensors "
                   "answering on one column, or a noisy line); not used for the thermal model")


#: A change of a log's level larger than ``LEVEL_JUMP_K`` plus ``LEVEL_JUMP_K_PER_S`` times the
#: time between the two readings (K), that stays (the median of the readings within
#: ``LEVEL_JUMP_WINDOW_S`` after against before): no room or plate makes it (a DS18B20 in air
#: needs minutes for a few K); a log that switched units (°C to °F: +40 K at a room's values)
#: or sensors midway, also across a logger's restart
LEVEL_JUMP_K, LEVEL_JUMP_K_PER_S, LEVEL_JUMP_WINDOW_S = 5.0, 20.0 / 3600.0, 60.0


def _level_jump(log: ScreenLog, name: str, tr: _TempTrack, rate_hz: float) -> LogNote | None:
    """A note refusing a log whose level jumps and stays (``LEVEL_JUMP_K``…): its two sides
    are not one sensor reading one place in one unit, and a coupling fitted across the jump
    is the jump's. Readings inside any stretch the screen masked or cut on this channel
    (single bad readings, stuck runs) are left out, so the span across them is a gap; a
    glitch of a few readings that returns is no jump (the medians around it agree)."""
    idx, val = tr.arrays()
    if len(idx) < 3:
        return None
    keep = np.ones(len(idx), dtype=bool)
    for st in log.stretches:
        if st.channel == name:
            keep[int(np.searchsorted(idx, st.first)):
                 int(np.searchsorted(idx, st.last, side="right"))] = False
    t, v = idx[keep] / rate_hz, val[keep]
    if len(t) < 3:
        return None
    dv, dt = np.diff(v), np.diff(t)
    allow = LEVEL_JUMP_K + LEVEL_JUMP_K_PER_S * dt
    jumps: list[tuple[int, float]] = []
    for k in np.flatnonzero(np.abs(dv) > allow):
        b0 = int(np.searchsorted(t, t[k] - LEVEL_JUMP_WINDOW_S))
        a1 = int(np.searchsorted(t, t[k + 1] + LEVEL_JUMP_WINDOW_S, side="right"))
        step = float(np.median(v[k + 1:a1]) - np.median(v[b0:k + 1]))
        if abs(step) > allow[k]:
            jumps.append((int(k), step))
    if not jumps:
        return None
    j, step = jumps[0]
    return LogNote("level_jump", f"its level jumps by {step:+.3g} K in {dt[j]:.3g} s at "
                   f"t = {t[j + 1]:.6g} s and stays ({len(jumps)} such jump(s)): no room or "
                   "plate moves so fast; a log that changed units (°C to °F) or sensors midway "
                   "is not one sensor reading one place; not used for the thermal model (split "
                   "the record there, or fix the log's units)")


def _infinite_readings(off: int, blk: Block, tnames: list[str], log: ScreenLog,
                       rate_hz: float) -> Block:
    """The block with each infinite temperature value a read error: masked (NaN) and counted
    like −127 °C. Every reader takes a finite value for a reading and NaN for none, so an
    inf (a driver's overflow, a log's "inf" text) had been neither: dropped uncounted."""
    a, t, end = blk
    if t is None or not tnames:
        return blk
    tt = np.asarray(t, dtype=float)
    inf = np.isinf(tt)
    if not inf.any():
        return blk
    for i, j in zip(*np.nonzero(inf.reshape(len(a), -1)), strict=True):
        k = off + int(i)
        log.stretches.append(Screened(tnames[int(j)], "read_error", k, k, k / rate_hz,
                                      k / rate_hz, 1))
    return a, np.where(inf, np.nan, tt), end


def _mask_readings(off: int, t: NDArray[np.float64], tracks: list[_TempTrack],
                   tnames: list[str], log: ScreenLog, rate_hz: float, final: bool
                   ) -> NDArray[np.float64]:
    """The block's temperatures with the readings the per-reading rules reject set to NaN,
    judged on every reading seen so far (this block's neighbours included)."""
    t = np.array(t, dtype=float).reshape(len(t), -1)
    for j, tr in enumerate(tracks):
        idx, val = tr.arrays()
        # the neighbours that matter: the few readings either side of this block
        lo = max(0, int(np.searchsorted(idx, off)) - 4)
        hi = min(len(idx), int(np.searchsorted(idx, off + len(t))) + 4)
        for p, kind in screen_temperature(val[lo:hi]):
            i = int(idx[lo + p])
            if not off <= i < off + len(t):
                continue
            t[i - off, j] = np.nan
            log.stretches.append(Screened(tnames[j], kind, i, i, i / rate_hz, i / rate_hz, 1))
    return t


def _whole_record_rules(tracks: list[_TempTrack], tnames: list[str], log: ScreenLog,
                        rate_hz: float, n_samples: int) -> None:
    """Dropouts, a log's late start and early end, and stuck runs: rules that need the
    channel's whole record (``n_samples``: the record's rows)."""
    for j, tr in enumerate(tracks):
        idx, val = tr.arrays()
        if len(idx) < 3:
            continue
        sec = idx / rate_hz
        gaps = np.diff(sec)
        typical = float(np.median(gaps))
        hole = max(DROPOUT_S, DROPOUT_READINGS * typical)
        for k in np.flatnonzero(gaps > hole):
            log.stretches.append(Screened(tnames[j], "dropout", int(idx[k]) + 1,
                                          int(idx[k + 1]) - 1, float(sec[k]),
                                          float(sec[k + 1]), 0))
        # the record's start and end bound the log as a reading would: a span there without
        # a reading, longer than a dropout by the same rule, says nothing of the temperature
        # either (a log with NaN between readings starts and ends within a reading interval)
        end_s = n_samples / rate_hz
        if sec[0] > hole:
            log.stretches.append(Screened(tnames[j], "log_starts_late", 0, int(idx[0]) - 1,
                                          0.0, float(sec[0]), 0))
        if end_s - sec[-1] > hole:
            log.stretches.append(Screened(tnames[j], "log_ends_early", int(idx[-1]) + 1,
                                          n_samples - 1, float(sec[-1]), end_s, 0))
        for a, b in stuck_runs(sec, val):
            log.stretches.append(Screened(tnames[j], "stuck", int(idx[a]), int(idx[b]),
                                          float(sec[a]), float(sec[b]), b - a + 1))


def screen_record(meta: dict[str, Any], blocks: Iterator[Block],
                  columns: Sequence[int] | None = None) -> Iterator[Block]:
    """``screen_blocks`` of a record's blocks (every accel column), its ``ScreenLog`` put in
    ``meta["screen"]`` for the results (analyze's and explain's text, JSON and report)."""
    log = ScreenLog(float(meta["rate_hz"]))
    meta["screen"] = log
    return screen_blocks(blocks, log.rate_hz, list(meta["names"]),
                         list(meta.get("temperature_names") or []), log, columns)


class ScreenedSource:
    """A record source read through the input screen (``screen_blocks``): what analyze and
    explain read. Every read screens alike (the same blocks, the same rule); ``log`` is the
    first complete read's ``ScreenLog``, for the results. The screen judges every accel
    axis, so it reads all of them and hands on the ``columns`` asked for."""

    def __init__(self, source: Any, units: str = "auto") -> None:
        self.source = source
        #: the logs' units as asked (``--temperature-units``: auto, C or F)
        self.units = temperature_units(units)
        self.log: ScreenLog | None = None
        # the first complete read's verdicts, per block size: {offset: outlying rows} (only
        # blocks with any), so later passes (one per channel group) cut the very same rows
        # without judging every axis again (the neighbours' medians cost as much as the
        # OADEV of a long record)
        self._verdicts: dict[int, dict[int, NDArray[np.intp]]] = {}
        #: ... and its held acceleration: {offset: (rows, their (rows, axes) held flags)}
        self._held: dict[int, dict[int, tuple[NDArray[np.intp], NDArray[np.bool_]]]] = {}

    @property
    def info(self) -> Any:
        return self.source.info

    def judged_clean(self, block: int) -> None:
        """The record's acceleration was judged elsewhere, block by block in blocks of
        ``block`` samples (the chunks of a parallel analysis, ``parallel.ScreenCut``
        otherwise), and nothing is to be cut: later reads take that verdict, and the log
        says the screen ran."""
        self.judged(block, {})

    def judged(self, block: int, cuts: Mapping[int, NDArray[np.intp]]) -> None:
        """The record's acceleration was judged elsewhere on every axis, block by block in
        blocks of ``block`` samples (the chunks of a parallel analysis, which found rows to
        cut: ``parallel.ScreenCut``): ``cuts`` {block offset: rows cut} for the blocks with
        any. Later reads cut those rows without judging again, and the next complete read's
        log says what was cut (nothing cut: the log says the screen ran)."""
        self._verdicts[block] = dict(cuts)
        # the chunks' verdicts hold no held acceleration: a chunk that sees a run that may be
        # one sends the record to be judged whole (``held_suspect``)
        self._held[block] = {}
        if not cuts and self.log is None:
            self.log = ScreenLog(float(self.source.info.rate_hz), done=True, units=self.units)

    @property
    def rereadable(self) -> bool:
        return bool(self.source.rereadable)

    def blocks(self, block: int = 1 << 16, *, columns: Sequence[int] | None = None,
               temperature: bool = True, verify: bool = True) -> Iterator[Block]:
        info = self.source.info
        log = ScreenLog(float(info.rate_hz), units=self.units)
        if self.log is None:
            self.log = log
        known = self._verdicts.get(block)
        held_known = self._held.get(block, {})
        n_axes = len(info.names)
        # judged once on every axis; later reads take only the columns asked for
        raw = self.source.blocks(block, columns=None if known is None else columns,
                                 temperature=temperature, verify=verify)
        found: dict[int, NDArray[np.intp]] = {}

        def judged(off: int, a: NDArray[np.float64], held: NDArray[np.bool_]
                   ) -> NDArray[np.bool_]:
            if known is not None:
                bad = np.zeros(len(a), dtype=bool)
                bad[known.get(off, np.empty(0, dtype=np.intp))] = True
                return bad
            bad = screen_accel(a, held) if held.any() else screen_accel(a)
            if bad.any():
                found[off] = np.flatnonzero(bad)
            return bad

        found_held: dict[int, tuple[NDArray[np.intp], NDArray[np.bool_]]] = {}

        def held_rows(off: int, n: int) -> NDArray[np.bool_]:
            out = np.zeros((n, n_axes), dtype=bool)
            if off in held_known:
                rows, flags = held_known[off]
                out[rows] = flags
            return out

        def keep(off: int, _cut: NDArray[np.bool_], flags: NDArray[np.bool_]) -> None:
            if flags.shape[1] and flags.any():
                rows = np.flatnonzero(flags.any(axis=1))
                found_held[off] = (rows, flags[rows])

        yield from screen_blocks(raw, log.rate_hz, list(info.names),
                                 list(info.temperature_names), log,
                                 columns if known is None else None, judged,
                                 check_units=info.format is not RecordFormat.RECORDING,
                                 held_rows=None if known is None else held_rows,
                                 on_verdict=keep if known is None else None)
        if known is None and log.done:
            self._verdicts[block] = found
            self._held[block] = found_held
