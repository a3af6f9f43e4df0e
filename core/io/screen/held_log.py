"""A held temperature log (a logger repeating its last reading between conversions): its cadence
found from the runs of one value, read as its readings."""

from __future__ import annotations

import math

import numpy as np
from avard.core.io.screen.notes import LogNote
from numpy.typing import NDArray

#: Held-log detection, on a channel's first rows: a value on at least this share of them.
HELD_DENSE = 0.95
#: A common divisor k of n run lengths is a cadence when k^n reaches this (chance ≤ 1e-4),
#: with at least this many runs.
HELD_CHANCE, HELD_MIN_COMMON = 1e4, 3
#: A cadence that is no whole number of samples: read from the first this many changes, at
#: least this many, their phases' coherence at least this, among at most this many cadences.
HELD_EVENTS, HELD_MIN_EVENTS, HELD_COHERENCE, HELD_MAX_CANDIDATES = 64, 32, 0.9, 400_000
#: Runs that pin a common divisor as the cadence, not a multiple of it (2^-14 ≈ 6e-5),
#: waited for where the log allows.
HELD_PIN_RUNS = 14
#: A dense log whose first rows hold too few runs is judged on up to this many rows.
HELD_WAIT_SAMPLES = 1 << 19
#: A held stretch found after the first rows (the whole log is watched, block by block):
#: the chance of a log read on every sample showing it, at most 1/this a test
HELD_SWITCH_CHANCE = 1e9
#: The changes of value kept per channel for that test (bounded, whatever the record's length)
HELD_RING = 128
#: A cadence that is no whole number of samples: a run's length within a sample's rounding
#: and this share of it (a logger's clock against the sampler's) of a multiple of it
HELD_TOL_SAMPLES, HELD_TOL_DRIFT = 1.0, 1e-4
#: Stretches named in a log's note (the JSON lists all)
HELD_NOTE_STRETCHES = 8
#: A steady ramp (cannot tell): this share of the runs one multiple of the cadence and of
#: the changes one sign.
RAMP_SHARE = 0.9


class _Undecided(Exception):
    """``held_cadence`` on a dense log with too few runs yet: more of the log may tell."""


def held_cadence(col: NDArray[np.float64], final: bool = True) -> tuple[float, str]:
    """(c, why) for one channel's first rows of temperatures ``col``: c ≥ 2 the cadence in
    samples (not always whole: 0.75 s at 10 Hz is 7.5) of a *held* log (a value on every row
    that changes only on reading instants: a logger that repeats its last reading on each
    sample), 0.0 for a log of readings; ``why`` a note where a dense log's cadence cannot be
    told ('' otherwise).

    The rule: a value on at least ``HELD_DENSE`` of the rows, and the n lengths of its
    complete runs of one value (a room dwells many readings on one 0.0625 K step, so a run is
    often many readings long) all a whole number of one cadence c: exactly (a common divisor
    c ≥ 2: conversions on the sample grid), or within one sample (``_fractional_cadence``:
    readings at a cadence that is no whole number of samples, or a jittering clock), for at
    least 90 % of them. Chance must not do it: n runs of a log read on every sample are all
    multiples of c with a chance of about c^-n, and that must be below 1/``HELD_CHANCE``
    with n ≥ ``HELD_MIN_COMMON``; within a sample, ``HELD_MIN_EVENTS`` changes must agree
    on the cadence (a coherence of 0.9 among ~10^5 candidates has a chance < 1e-6 there).
    A log read on every sample (a thermistor, a DS18B20 at ≤ 1.33 Hz) has runs of no common
    cadence and is left as it is; a dense log with too few runs to tell is left as it is
    and said. A steady ramp read on every sample without noise has runs all of one length
    and changes all one way, which a held log whose every reading changes has too: where at
    least ``RAMP_SHARE`` of the runs are one multiple of the cadence and of the changes one
    sign (``_steady_ramp``) the log is left as it is and said ("cannot tell"); a held log in
    a room that dwells and turns (runs of several multiples, changes both ways) is still
    read as readings. Where the first changes lie too far apart for the cadences to be tried
    (more than ``HELD_MAX_CANDIDATES``), it is said too. Density is judged over the finite
    span (a log whose first rows are NaN is judged from its first value) or by its finite
    rows' neighbours (``_dense``: a held log with a dropout is still dense), and its runs
    between changes of two finite rows (``_clean_runs``). This is the verdict on a
    channel's first rows; the rest of the log is watched stretch by stretch (``_Dehold``:
    a log held from midway on, or read on every sample from midway on). ``final``
    False: the caller can wait for more of the log (``_Undecided`` is
    raised where more runs could decide, and where a common divisor rests on fewer than
    ``HELD_PIN_RUNS`` runs: it may be a multiple of the cadence)."""
    v = np.asarray(col, dtype=float)
    fin = np.isfinite(v)
    f = np.flatnonzero(fin)
    if not _dense(fin, f):
        return 0.0, ""
    if not final and len(f) < 2:
        raise _Undecided
    x = v[f]
    p, lengths = _clean_runs(v, fin)
    starts = np.concatenate([[f[0]], p])
    n = len(lengths)
    g = int(np.gcd.reduce(lengths.astype(np.int64))) if n else 0
    if g >= 2 and n >= HELD_MIN_COMMON and n * math.log(g) >= math.log(HELD_CHANCE):
        if n < HELD_PIN_RUNS and not final:
            # held, but its cadence may be a multiple of the true one (n runs are all even
            # multiples with a chance of 2^-n): more of the log pins it
            raise _Undecided
        if _steady_ramp(lengths, g, x):
            return 0.0, _cannot_tell(n, len(v), "all one length and its changes one way "
                                     "(a steady ramp): cannot tell")
        return float(g), ""
    c, _n, capped = _fractional_cadence(starts[1:])
    if c > 0:
        if _steady_ramp(lengths, c, x):
            return 0.0, _cannot_tell(n, len(v), "all one length and its changes one way "
                                     "(a steady ramp): cannot tell")
        return c, ""
    if capped:
        # too many cadences to try on the span of its first changes (a room that changes
        # seldom at a high rate): no verdict either way, and said
        return 0.0, _cannot_tell(n, len(v), "too far apart to read a cadence: cannot tell")
    if len(f) >= 2 * len(starts) and (g >= 2 or n < HELD_MIN_EVENTS):
        # runs of two samples or more on average, and too few of them to tell
        if not final:
            raise _Undecided
        return 0.0, _cannot_tell(n, len(v), "too few to tell")
    return 0.0, ""


def _dense(fin: NDArray[np.bool_], f: NDArray[np.intp]) -> bool:
    """A value on (nearly) every row: at least ``HELD_DENSE`` of the finite span finite (a
    log that starts late or ends early is judged where it is), or of the finite rows that
    many followed by a finite row (its NaN in a few long stretches, dropouts, not one
    between each reading: a held log with a hole is still held)."""
    if not len(f):
        return False
    if len(f) >= HELD_DENSE * (int(f[-1]) - int(f[0]) + 1):
        return True
    pairs = int(np.count_nonzero(fin[:-1] & fin[1:]))
    return len(f) >= 2 and pairs >= HELD_DENSE * (len(f) - 1)


def _clean_runs(v: NDArray[np.float64], fin: NDArray[np.bool_]
                ) -> tuple[NDArray[np.intp], NDArray[np.int64]]:
    """(p, lengths): the rows where the value changes between two finite rows (a held log's
    reading instants; a change across NaN is not one, its reading may lie in the hole), and
    the lengths of the complete runs between two of them with no NaN between (a run cut by
    a dropout is no multiple of anything)."""
    p = np.flatnonzero(fin[1:] & fin[:-1] & (v[1:] != v[:-1])) + 1
    cnan = np.concatenate([[0], np.cumsum(~fin)])
    d = np.diff(p).astype(np.int64)
    return p, d[cnan[p[1:]] == cnan[p[:-1]]]


def _cannot_tell(n: int, rows: int, why: str) -> str:
    """The note on a dense log that cannot be told held or read on every sample."""
    return (f"a value on every sample, its {n} complete runs of one value in its first "
            f"{rows} samples {why} a log held at each reading (each reading "
            "repeated until the next) from one read on every sample: taken as read on every "
            "sample (if held, its lag is late by half a reading interval; judged on its first "
            "rows, the rest of the log watched for a held stretch)")


def _steady_ramp(lengths: NDArray[np.int64], c: float, x: NDArray[np.float64]) -> bool:
    """A constant ramp read on every sample: at least ``RAMP_SHARE`` of the runs one
    multiple of ``c`` (within a sample) and of the changes one sign. Its runs are all one
    length and its steps one way, which is what a held log whose every reading changes reads
    too: the two cannot be told apart, and de-holding a log read on every sample would keep
    one row of each run and read the temperature up to a run early."""
    if not len(lengths):
        return False
    m = np.rint(lengths / c).astype(np.int64)
    same = float(np.max(np.bincount(m - m.min()))) / len(m)
    d = np.diff(x)
    d = d[d != 0]
    if not len(d):
        return False
    one_way = max(np.count_nonzero(d > 0), np.count_nonzero(d < 0)) / len(d)
    return bool(same >= RAMP_SHARE and one_way >= RAMP_SHARE)


def _fractional_cadence(starts: NDArray[np.int64]) -> tuple[float, int, bool]:
    """(c, n, capped): a cadence c (samples, ≥ 2.5, not always whole) on which the first
    ``HELD_EVENTS`` change positions ``starts`` of a dense log lie, each within a sample's
    rounding (their phases' coherence |mean e^(2πi p/c)| ≥ ``HELD_COHERENCE``: a reading
    instant rounded up to the next sample is at most one sample late, a phase of at most
    1/c), the largest such c, and the n positions it rests on; (0.0, n) where none;
    ``capped`` where there were more than ``HELD_MAX_CANDIDATES`` cadences to try (none
    tried: the caller says it cannot tell).
    Candidates: the cadences of which the shortest run is a whole number within a sample,
    on a grid fine enough that the phase across the positions' span moves < 1/8 cycle."""
    p = np.asarray(starts[:HELD_EVENTS], dtype=float)
    n = len(p)
    if n < HELD_MIN_EVENTS:
        return 0.0, n, False
    p = p - p[0]
    span = float(p[-1])
    gmin = float(np.min(np.diff(p)))
    grids = []
    for j in range(1, int((gmin + 1.0) / 2.5) + 1):
        lo, hi = max(2.5, (gmin - 1.0) / j), (gmin + 1.0) / j
        if hi > lo:
            grids.append(np.arange(lo, hi, lo * lo / (8.0 * span)))
    if not grids:
        return 0.0, n, False
    c = np.concatenate(grids)
    if len(c) > HELD_MAX_CANDIDATES:
        return 0.0, n, True
    best = 0.0
    for k in range(0, len(c), 4096):
        cc = c[k:k + 4096]
        r = np.abs(np.exp(2j * np.pi * p[None, :] / cc[:, None]).mean(axis=1))
        hit = cc[r >= HELD_COHERENCE]
        if len(hit):
            best = max(best, float(hit.max()))
    return best, n, False


class _Stretch:
    """One stretch of a temperature log read one way: from row ``start`` on, as it is
    (``k`` 0) or held at each reading on a cadence of ``k`` samples, its reading instants
    found from ``anchor`` (a change of value between two finite rows: a reading, -1 until
    one is seen). ``runs``: complete runs found on the cadence (the evidence, for a whole
    cadence shrunk to a divisor); ``why``: what is said of a stretch read as it is;
    ``whole``: a cadence of a whole number of samples (a common divisor, exact), else read
    from the changes' phases, with its uncertainty ``dk`` (samples)."""

    __slots__ = ("anchor", "dk", "fit", "k", "runs", "start", "whole", "why")

    def __init__(self, start: int, k: float, anchor: int = -1, runs: int = 0,
                 why: str = "", whole: bool = True, dk: float = 0.0) -> None:
        self.start, self.k, self.anchor, self.runs, self.why = start, k, anchor, runs, why
        self.whole, self.dk = whole or k <= 0, dk
        # a cadence that is no whole number: the straight line through its changes (row
        # against reading count from the first: n, Σm, Σx, Σm², Σmx), refined as the log
        # goes on, so a long constant stretch's readings do not drift off their instants
        self.fit = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0]

    def refine(self, p: NDArray[np.int64]) -> None:
        """Take the changes ``p`` (on this stretch's cadence, ascending) into its cadence's
        fit, as far as their reading counts are beyond doubt (the cadence's uncertainty over
        their distance from the first below half a cadence: the fit then narrows it)."""
        if self.whole or not len(p):
            return
        f = self.fit
        if f[0] < 0:
            f[0] = float(p[0])
        x_all = np.asarray(p, dtype=float) - f[0]
        while len(x_all):
            lim = math.inf if self.dk <= 0 else 0.4 * self.k * self.k / self.dk
            n_take = int(np.searchsorted(x_all, lim, side="right"))
            if not n_take:
                return
            x, x_all = x_all[:n_take], x_all[n_take:]
            m = np.rint(x / self.k)
            f[1] += len(x)
            f[2] += float(m.sum())
            f[3] += float(x.sum())
            f[4] += float((m * m).sum())
            f[5] += float((m * x).sum())
            den = f[1] * f[4] - f[2] * f[2]
            if f[1] < HELD_MIN_EVENTS or not den > 0:
                continue
            k = (f[1] * f[5] - f[2] * f[3]) / den
            if abs(k - self.k) >= 0.5:
                return
            self.k = k
            # three standard errors of the slope, for residuals of a sample's rounding
            # (σ ≈ 0.5 sample, on the safe side of √(1/12))
            self.dk = 1.5 / math.sqrt(den / f[1])


def _on_cadence(d: NDArray[np.int64], k: float, whole: bool = True, dk: float = 0.0
                ) -> NDArray[np.bool_]:
    """Run lengths ``d`` that a held log on a cadence of ``k`` samples makes: whole
    multiples of a whole cadence; within a sample's rounding (and the logger's clock drift,
    ``HELD_TOL_DRIFT`` of the run, and the cadence's own uncertainty ``dk`` times the
    readings it spans) of a multiple ≥ 1 of a cadence that is no whole number."""
    d = np.asarray(d, dtype=float)
    if whole:
        return np.asarray(d % k == 0) & (d > 0)
    m = np.rint(d / k)
    tol = HELD_TOL_SAMPLES + HELD_TOL_DRIFT * d + m * dk
    return np.asarray((m >= 1) & (np.abs(d - m * k) <= tol))


def _phase_dk(p: NDArray[np.int64], k: float) -> float:
    """The uncertainty of a cadence read from the phases of the changes ``p``
    (``_fractional_cadence``: coherence ≥ 0.9 allows the phase to slide about a quarter of
    a cycle across their span)."""
    span = float(p[-1] - p[0]) if len(p) >= 2 else 0.0
    return 0.3 * k * k / span if span > 0 else 0.5


class _Dehold:
    """One temperature channel read as readings, stretch by stretch over the whole log.

    The first rows are judged by ``held_cadence`` (the screen waits for them); from there on
    every block is watched (``observe``, before the block is handed on: its rows and the one
    block before it can still be read anew), in bounded memory (the last ``HELD_RING``
    changes of value) and a cost linear in the rows:

    - in a held stretch every change of value between two finite rows must lie on the
      cadence from the change before it (``_on_cadence``); a whole cadence may shrink to a
      divisor the stretch's runs still make significant; a change off it ends the stretch
      there (the log is read as it is from that change on). A change across NaN (a dropout)
      is not judged, and the reading instants go on from the last change before the hole
      (its first value after the hole is a repeat of a reading made inside it, or on a
      reading instant that lies on the same cadence: either way no reading's phase is lost);
    - in a stretch read as it is, the latest complete runs are tested at each block for a
      held stretch that has begun (a whole cadence: their common divisor, at a chance of
      at most 1/``HELD_SWITCH_CHANCE`` for a log read on every sample, the test being made
      at every block; a cadence that is no whole number: the last ``HELD_EVENTS`` changes'
      phases, ``_fractional_cadence``), which then starts at its first run's change (its
      rows still waiting are read anew; the screen waits, at most ``HELD_WAIT_SAMPLES``
      rows, while such a test is close). A steady ramp is not taken (``_steady_ramp``: it
      cannot be told from a held log) and said.

    A held stretch becomes each reading instant's row (each change, and one every cadence
    after it until half a cadence before the next), NaN between, which is what a
    recording's source hands over (core/io/source.py: one reading per conversion, a stuck
    value included): a stable room's long constant stretch stays readings of its value, not
    one reading and a hole."""

    def __init__(self) -> None:
        self.k: float | None = None  # the first rows' verdict: undecided; 0; ≥ 2 the cadence
        self.why = ""
        self.segs: list[_Stretch] = []  # the stretches not yet wholly handed on, in order
        self.history: list[_Stretch] = []  # every stretch, for the note
        self.rows = 0  # rows observed
        self.released = 0  # rows handed on (read as their stretch says: fixed)
        # the watch: the last row's value, the last change, a NaN since it, the last
        # HELD_RING changes (row, value after it, the run before it complete)
        self._prev, self._prev_fin = math.nan, False
        self._last, self._nan_since = -1, True
        self._rp = np.zeros(0, dtype=np.int64)
        self._rv = np.zeros(0)
        self._rc = np.zeros(0, dtype=bool)
        self._since_try = 0
        self.close = False  # a held stretch's test is close: the screen may wait for it
        self.dense = False  # a value seen on two consecutive rows (a held stretch may come)
        # the reading: the row before the next block's value, the last reading instant
        self._aprev = math.nan
        self._aanchor = -1

    def decide(self, col: NDArray[np.float64], final: bool) -> bool:
        """Judge the log on ``col`` (its first rows, as many as the screen has waited
        for); False where it cannot yet and more rows may tell (not ``final``)."""
        if self.k is not None:
            return True
        try:
            self.k, self.why = held_cadence(col, final)
        except _Undecided:
            return False
        whole, dk = float(self.k).is_integer(), 0.0
        if self.k and not whole:
            v = np.asarray(col, dtype=float)
            dk = _phase_dk(_clean_runs(v, np.isfinite(v))[0][:HELD_EVENTS], self.k)
        self._begin(_Stretch(0, self.k, why=self.why, whole=whole, dk=dk))
        return True

    def _begin(self, seg: _Stretch) -> None:
        """A new stretch from ``seg.start`` (which replaces a stretch of no rows yet; rows
        handed on are read as they were)."""
        seg.start = max(seg.start, self.released)
        while self.segs and self.segs[-1].start >= seg.start:
            self.segs.pop()
            self.history.pop()
        self.segs.append(seg)
        self.history.append(seg)

    # -- the watch ----------------------------------------------------------------------

    def observe(self, off: int, col: NDArray[np.float64]) -> None:
        """Watch the block of rows ``off`` … (after ``decide``): judge its changes of value
        against the stretch being read, and test for a held stretch beginning."""
        v = np.asarray(col, dtype=float)
        n = len(v)
        if not n:
            return
        fin = np.isfinite(v)
        vv = np.concatenate([[self._prev], v])
        ff = np.concatenate([[self._prev_fin], fin])
        pair = ff[1:] & ff[:-1]
        self.dense = self.dense or bool(pair.any())
        i = np.flatnonzero(pair & (vv[1:] != vv[:-1]))  # block rows
        cnan = np.concatenate([[0], np.cumsum(~fin)])
        p = i + off
        conn = np.empty(len(i), dtype=bool)
        if len(i):
            conn[0] = self._last >= 0 and not self._nan_since and cnan[i[0]] == 0
            conn[1:] = cnan[i[1:]] == cnan[i[:-1]]
        d = np.diff(np.concatenate([[self._last], p])).astype(np.int64)
        j = 0
        while j < len(p):
            seg = self.segs[-1]
            if seg.k <= 0:
                break
            if seg.anchor < 0:
                seg.anchor = int(p[j])
                seg.refine(p[j:j + 1])
                j += 1
                continue
            ok = _on_cadence(d[j:], seg.k, seg.whole, seg.dk) | ~conn[j:]
            bad = np.flatnonzero(~ok)
            if not len(bad):
                seg.runs += int(np.count_nonzero(conn[j:]))
                seg.refine(p[j:][conn[j:]])
                break
            b = j + int(bad[0])
            seg.runs += int(np.count_nonzero(conn[j:b]))
            seg.refine(p[j:b][conn[j:b]])
            if seg.whole and _on_cadence(d[b:b + 1], seg.k, False)[0]:
                # a reading a sample late or early on a whole cadence: a jittering clock,
                # not the log read otherwise; read from here within a sample (each change
                # its own reading, as for a cadence that is no whole number)
                seg.whole = False
                j = b
                continue
            g = math.gcd(int(seg.k), int(d[b])) if seg.whole else 0
            if g >= 2 and seg.runs < HELD_PIN_RUNS:
                # a whole cadence read from few runs may be a multiple of the log's (n runs
                # are all even multiples with a chance of 2^-n): its divisor (every change so
                # far lies on it too); a cadence pinned by many runs is not shrunk by one run
                # (a log read on every sample makes it a multiple of 2 one time in two)
                seg.k = float(g)
                seg.runs += 1
                j = b + 1
                continue
            self._begin(_Stretch(int(p[b]), 0.0, why="its changes leave the cadence"))
            j = b + 1
        # the changes watched: the ring of the last ones before this block, and the block's
        rp = np.concatenate([self._rp, p])
        rv = np.concatenate([self._rv, v[i]])
        rc = np.concatenate([self._rc, conn])
        self._rp, self._rv, self._rc = rp[-HELD_RING:], rv[-HELD_RING:], rc[-HELD_RING:]
        self._since_try += len(p)
        if len(p):
            self._last = int(p[-1])
            self._nan_since = bool(cnan[n] - cnan[i[-1]] > 0)
        else:
            self._nan_since = self._nan_since or bool(cnan[n] > 0)
        self._prev, self._prev_fin = float(v[-1]), bool(fin[-1])
        self.rows = off + n
        self.close = False
        if self.segs[-1].k <= 0:
            self._watch(rp, rv, rc)

    def _watch(self, rp: NDArray[np.int64], rv: NDArray[np.float64],
               rc: NDArray[np.bool_]) -> None:
        """In a stretch read as it is: has a held one begun among the latest runs (the
        changes ``rp``, the values after them ``rv``, the run before each complete ``rc``:
        the last block's and the ring's before it)?"""
        seg = self.segs[-1]
        keep = rp >= seg.start
        rp, rv, rc = rp[keep], rv[keep], rc[keep]
        if len(rp) < 2:
            return
        runs = np.diff(rp).astype(np.int64)
        ok = rc[1:]
        # a whole cadence: the common divisor of the newest complete runs, the count of
        # runs that makes it least likely by chance (c^-n)
        r = runs[::-1]
        stop = np.flatnonzero(~ok[::-1])
        r = r[:int(stop[0]) if len(stop) else len(r)]
        gs = np.gcd.accumulate(r) if len(r) else r
        gs = gs[:int(np.argmax(gs < 2)) if (gs < 2).any() else len(gs)]
        score, nr, g = 0.0, 0, 0
        if len(gs):
            scores = np.arange(1, len(gs) + 1) * np.log(gs.astype(float))
            m = int(np.argmax(scores))
            score, nr, g = float(scores[m]), m + 1, int(gs[m])
        if nr >= HELD_MIN_COMMON and score >= math.log(HELD_SWITCH_CHANCE):
            first = len(rp) - 1 - nr
            if _steady_ramp(runs[first:], float(g), rv[first:]):
                seg.why = ("its runs all one length and its changes one way (a steady "
                           "ramp): cannot tell a held log from one read on every sample")
                return
            self._begin(_Stretch(int(rp[first]), float(g), int(rp[first]), nr))
            return
        # close: two runs or more whose divisor is already unlikely by chance (one long run
        # alone is a stable room's, read on every sample or not)
        self.close = nr >= 2 and score >= math.log(HELD_CHANCE)
        # a cadence that is no whole number of samples: the last changes' phases
        if self._since_try < HELD_MIN_EVENTS or len(rp) < HELD_EVENTS:
            return
        self._since_try = 0
        c, _n, _capped = _fractional_cadence(rp[-HELD_EVENTS:])
        if not c > 0:
            return
        dk = _phase_dk(rp[-HELD_EVENTS:], c)
        on = _on_cadence(runs, c, False, dk) & ok
        nr = len(runs) - (int(np.flatnonzero(~on)[-1]) + 1 if (~on).any() else 0)
        if nr < HELD_MIN_EVENTS:
            return
        first = len(rp) - 1 - nr
        if _steady_ramp(runs[first:], c, rv[first:]):
            seg.why = ("its runs all one length and its changes one way (a steady ramp): "
                       "cannot tell a held log from one read on every sample")
            return
        seg = _Stretch(int(rp[first]), c, int(rp[first]), nr, whole=False, dk=dk)
        seg.refine(rp[first:])
        self._begin(seg)

    # -- the reading ----------------------------------------------------------------------

    def apply(self, off: int, col: NDArray[np.float64]) -> NDArray[np.float64]:
        """The block of rows ``off`` … read as its stretches say (handed on: fixed)."""
        col = np.asarray(col, dtype=float)
        n = len(col)
        if not n or not self.segs:
            return col
        fin = np.isfinite(col)
        vv = np.concatenate([[self._aprev], col])
        ff = np.concatenate([[math.isfinite(self._aprev)], fin])
        change = np.flatnonzero(ff[1:] & ff[:-1] & (vv[1:] != vv[:-1])) + off
        lone = fin & ~ff[:-1] & ~np.concatenate([fin[1:], [True]])
        out = col
        # the stretches over these rows (those ended before them dropped: bounded)
        while len(self.segs) > 1 and self.segs[1].start <= off:
            self.segs.pop(0)
        for s_i, seg in enumerate(self.segs):
            lo = max(seg.start, off)
            hi = min(self.segs[s_i + 1].start if s_i + 1 < len(self.segs) else off + n,
                     off + n)
            if seg.k <= 0:
                self._aanchor = -1
                continue
            if hi <= lo:
                continue
            k = seg.k
            a = change[(change >= lo) & (change < hi)]
            pos = []
            if seg.start <= self._aanchor < lo:
                # the stretch goes on from the last reading instant before these rows (across
                # a dropout too: its phase is the logger's, not the hole's)
                starts = np.concatenate([[self._aanchor], a])
            else:
                anc = seg.anchor if seg.anchor >= 0 else int(a[0]) if len(a) else lo
                if anc > lo:
                    # the stretch's first rows: its instants run back from its first reading
                    back = np.arange(1, int((anc - lo) / k) + 2)
                    pos.append(anc - np.floor(k * back + 0.5).astype(np.int64))
                starts = (np.concatenate([[anc], a[a > anc]]) if anc < hi
                          else np.zeros(0, dtype=np.int64))
            if len(starts):
                # each instant's readings: it, and one every cadence until half a cadence
                # before the next change (an open run: to the rows' end)
                nxt = np.concatenate([starts[1:], [hi + 0.5 * k]]).astype(float)
                extra = np.maximum(np.floor((nxt - starts) / k - 0.5), 0).astype(np.int64)
                # an instant before these rows: from its first reading among them (a long
                # constant stretch costs its rows, not its rows times its blocks)
                skip = np.zeros(len(starts), dtype=np.int64)
                skip[0] = max(0, math.floor((lo - int(starts[0])) / k) - 1)
                cnt = np.maximum(extra + 1 - skip, 0)
                base = np.repeat(starts, cnt)
                step = (np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
                        + np.repeat(skip, cnt))
                pos.append(base + np.floor(k * step + 0.5).astype(np.int64))
                self._aanchor = int(starts[-1])
            pp = np.concatenate(pos) if pos else np.zeros(0, dtype=np.int64)
            pp = pp[(pp >= lo) & (pp < hi)]
            keep = np.zeros(hi - lo, dtype=bool)
            keep[pp - lo] = True
            # a reading alone between NaN is a reading whatever its phase (a held log never
            # writes one: the log has gone over to NaN between readings)
            keep |= lone[lo - off:hi - off]
            if out is col:
                out = col.copy()
            piece = out[lo - off:hi - off]
            piece[~keep] = np.nan
        self._aprev = float(col[-1])
        self.released = off + n
        return out

    # -- the note -------------------------------------------------------------------------

    def note(self, rate_hz: float) -> LogNote | None:
        hist = self.history
        if not hist:
            return None
        if len(hist) == 1:
            start, k, why = hist[0].start, hist[0].k, hist[0].why
            if k:
                since = "" if start <= 0 else f" from {start / rate_hz:.6g} s"
                return LogNote("held", (
                    f"held at each reading (a value on every sample, changing only on a "
                    f"{k:.4g}-sample cadence, {k / rate_hz:.3g} s): read as "
                    f"readings{since} (each run's first sample, and one every {k:.4g} "
                    "samples while it lasts; the rest NaN)"))
            return LogNote("held_unknown", why) if why else None
        parts, stretches = [], []
        for m, seg in enumerate(hist):
            start, k, why = seg.start, seg.k, seg.why
            end = hist[m + 1].start if m + 1 < len(hist) else self.rows
            span = f"{start / rate_hz:.6g}–{end / rate_hz:.6g} s"
            stretches.append({"start_s": start / rate_hz, "end_s": end / rate_hz,
                              "read": "held" if k else "as_is",
                              "cadence_samples": k if k else None})
            if k:
                parts.append(f"{span} held at each reading ({k:.4g}-sample cadence, "
                             f"{k / rate_hz:.3g} s): read as readings")
            else:
                parts.append(f"{span} read as it is" + (f" ({why})" if why else ""))
        shown = parts[:HELD_NOTE_STRETCHES]
        more = len(parts) - len(shown)
        kind = "held" if any(x.k for x in hist) else "held_unknown"
        return LogNote(kind, (
            f"a value on every sample, read in {len(hist)} stretches (its whole log "
            "judged): " + "; ".join(shown) + (f"; … and {more} more (--json lists all)"
                                                if more else "")
            + " (a held stretch: each change and one reading every cadence after it, the "
            "rest NaN)"), tuple(stretches))
