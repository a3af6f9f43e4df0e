"""A held acceleration (a stuck FIFO, a driver repeating its last frame): a run of one value
longer than the axis's own chance of a repeat makes likely, judged over the whole read in
bounded memory."""

from __future__ import annotations

import math

import numpy as np
from avard.core.io.screen.held_log import HELD_WAIT_SAMPLES
from numpy.typing import NDArray

# a held (stuck) accelerometer: a run of identical samples its own noise makes implausible

#: A false alarm of the held rule at most this often per record (per axis) ...
HELD_ALARM = 1e-6
#: ... of up to this many samples (2^25: 74 h at 125 Hz, beyond the daemon's 60 h records); a
#: longer record is counted by the rows seen
HELD_RECORD_SAMPLES = 1 << 25
#: A held stretch is at least this many identical samples whatever its chance (a repeated
#: frame or two is no stretch the estimators need cut), and the parallel chunks (which judge
#: each block on its own) send the record to one read where a block holds half of it
#: (``held_suspect``: a run across a block boundary has half its length on one side)
HELD_MIN_RUN = 16
#: Runs of an axis reaching a length, at least, for the chance of going on from there to be
#: measured (an axis with fewer runs than this is not judged: its chance of a repeat is
#: unknown)
HELD_MIN_RUNS = 200
#: Runs of an axis reaching a length, for the tail's decay to be measured to there (the
#: longest few: a held stretch or two among them do not move it)
HELD_TAIL_RUNS = 20
#: The decay length measured on the tail's runs is taken this much longer (1 + 3/√20: three
#: standard errors of a rate of 20 counts)
HELD_TAIL_MARGIN = 1.0 + 3.0 / math.sqrt(20.0)
#: Runs of this length and longer are counted together (the histogram's bound)
HELD_HIST = 4096


def held_threshold(hist: NDArray[np.int64], rows: int, seen: int | None = None) -> float:
    """The shortest run of identical samples an axis's noise makes implausible, from the
    lengths of its runs (``hist[L]``: runs of L samples, the last bin HELD_HIST and more)
    over ``rows`` samples (of ``seen`` read so far, ``rows`` by default); inf where the axis
    has too few runs to tell.

    A quiet axis on a coarse grid repeats values legitimately, and a chip filter's correlated
    samples repeat in clusters, so the chance is measured on the axis itself, by counts of
    *runs* (a held stretch is one run whatever its length, so it cannot raise the chance that
    clears it): the length L_a that ``HELD_MIN_RUNS`` runs reach and the length L_b that
    ``HELD_TAIL_RUNS`` reach give the tail's decay length λ (runs reaching a length fall e-fold
    every λ samples: a geometric tail, the chance of a repeat independent of the run so far,
    measured on the longest runs, so a mixture of quiet and busy hours has its tail from the
    quiet ones), taken ``HELD_TAIL_MARGIN`` longer for the few runs it is measured on. From
    L_b on, P(run ≥ L_b + x) = F(L_b)·e^(−x/λ); the threshold is the length the runs of a
    record (``HELD_RECORD_SAMPLES`` rows, or the rows seen, at the axis's runs per row) reach
    by chance ``HELD_ALARM`` times, at least ``HELD_MIN_RUN``."""
    ge = np.cumsum(hist[::-1])[::-1].astype(float)  # ge[L]: runs of L samples or more
    n1 = float(ge[1]) if len(ge) > 1 else 0.0
    if n1 < HELD_MIN_RUNS or rows <= 0:
        return math.inf
    la = int(np.flatnonzero(ge >= HELD_MIN_RUNS)[-1])
    lb = int(np.flatnonzero(ge >= HELD_TAIL_RUNS)[-1])
    if lb >= HELD_HIST:
        return math.inf  # runs beyond the histogram are common: nothing to measure
    beyond = max(float(ge[lb + 1]), 0.5)  # the first length fewer runs reach
    lam = (lb + 1 - la) / math.log(float(ge[la]) / beyond) * HELD_TAIL_MARGIN
    runs = n1 / rows * max(HELD_RECORD_SAMPLES, rows if seen is None else seen)
    extra = lam * math.log(max(1.0, runs * float(ge[lb]) / n1 / HELD_ALARM))
    return float(max(HELD_MIN_RUN, lb + math.ceil(extra)))


def _max_run(col: NDArray[np.float64]) -> int:
    """The longest run of identical consecutive samples in ``col``."""
    if not len(col):
        return 0
    ch = np.flatnonzero(col[1:] != col[:-1])
    edges = np.concatenate([[-1], ch, [len(col) - 1]])
    return int(np.max(np.diff(edges)))


def held_suspect(a: NDArray[np.float64]) -> bool:
    """Whether the block (judged on its own, as a parallel chunk does) holds a run of at least
    half ``HELD_MIN_RUN`` identical samples on an axis: then a held stretch may lie here (a run
    across the block's boundary has half its length on one side), and the record is read
    through the whole-record screen (``HeldAccel``) instead. A conservative test: it never
    misses a held stretch, and sends a quiet, coarsely quantised record to one read."""
    half = HELD_MIN_RUN // 2
    return any(_max_run(np.asarray(a[:, j])) >= half for j in range(a.shape[1]))


class HeldAccel:
    """The held-acceleration rule over a whole read, block by block in bounded memory: per
    axis a histogram of run lengths, each block's own (trimmed) while its rows may still be
    judged, and the runs long enough to be candidates that reach rows not yet judged.

    Per axis: a repeated frame repeats every axis, so each axis's own rule sees it; a stuck
    channel of one axis is seen too; and a row cut when any axis says so is the verdict the
    parallel chunks (each judging its own axes) can form. The blocks are ``feed``-ed in order,
    ahead of the rows judged (the screen hands a block on once the next is read, and waits
    while ``undecided``); ``verdict`` judges a block's rows. A run is held when its length
    clears the longer of two thresholds (``held_threshold``): the whole read's, and that of
    the runs from the run's own block on (so an axis that turns quiet, its runs long, is
    judged by its new noise, and not before that noise is measured; a held stretch in a busy
    record has the busy runs after it). A run judged held stays held on the rows that come
    later; a run still open is judged again on the next block, and one longer than
    ``HELD_WAIT_SAMPLES`` by the whole read's threshold alone."""

    def __init__(self) -> None:
        self.rows = 0
        self.last: NDArray[np.float64] | None = None
        self.start: NDArray[np.int64] | None = None  # record row where each open run began
        self.hist: NDArray[np.int64] | None = None
        #: per axis, runs of ≥ HELD_MIN_RUN samples reaching rows not yet judged: [first, last]
        #: (last the run's end so far for the open one)
        self.cand: list[NDArray[np.int64]] = []  # per axis, (k, 2)
        #: per axis, whether each candidate is judged held
        self.held: list[NDArray[np.bool_]] = []
        #: the blocks' own run histograms (per axis, trimmed) while they may be needed:
        #: (offset, rows, [hist per axis])
        self.blocks: list[tuple[int, int, list[NDArray[np.int64]]]] = []
        self._cache: dict[int, tuple[int, float]] = {}

    def feed(self, off: int, a: NDArray[np.float64]) -> None:
        n, c = a.shape
        if not n:
            return
        first = self.last is None
        if self.last is None:
            self.last = np.asarray(a[0], dtype=float).copy()
            self.start = np.full(c, off, dtype=np.int64)
            self.hist = np.zeros((c, HELD_HIST + 1), dtype=np.int64)
            self.cand = [np.zeros((0, 2), dtype=np.int64) for _ in range(c)]
            self.held = [np.zeros(0, dtype=bool) for _ in range(c)]
        assert self.start is not None and self.hist is not None
        own: list[NDArray[np.int64]] = []
        for j in range(c):
            col = np.asarray(a[:, j], dtype=float)
            new = np.flatnonzero(col[1:] != col[:-1]) + 1
            if not first and not col[0] == self.last[j]:
                new = np.concatenate([[0], new])
            begins = np.concatenate([[self.start[j]], off + new])
            lengths = np.minimum(np.diff(begins), HELD_HIST)  # the runs completed here
            h = np.bincount(lengths).astype(np.int64) if len(lengths) else np.zeros(
                1, dtype=np.int64)
            self.hist[j, :len(h)] += h
            own.append(h)
            cand, held = self.cand[j], self.held[j]
            was = False
            if len(cand) and cand[-1, 0] == self.start[j]:
                # the open run, seen again below (completed or still open), its verdict kept
                was = bool(held[-1])
                cand, held = cand[:-1], held[:-1]
            k = np.flatnonzero(lengths >= HELD_MIN_RUN)
            new_c = np.column_stack([begins[k], begins[k + 1] - 1]).astype(np.int64)
            self.start[j] = begins[-1]
            if off + n - self.start[j] >= HELD_MIN_RUN:
                new_c = np.vstack([new_c, [[self.start[j], off + n - 1]]]).astype(np.int64)
            new_h = np.zeros(len(new_c), dtype=bool)
            if was and len(new_c) and new_c[0, 0] == begins[0]:
                new_h[0] = True
            self.cand[j] = np.vstack([cand, new_c]) if len(new_c) else cand
            self.held[j] = np.concatenate([held, new_h])
            self.last[j] = col[-1]
        self.blocks.append((off, n, own))
        self.rows = off + n

    def _since(self, j: int, first: int) -> tuple[NDArray[np.int64], int]:
        """Axis j's runs completed in the blocks from the one holding row ``first`` on."""
        h = np.zeros(HELD_HIST + 1, dtype=np.int64)
        rows = 0
        for off, n, own in self.blocks:
            if off + n > first:
                h[:len(own[j])] += own[j]
                rows += n
        return h, rows

    def _whole(self, j: int) -> float:
        """Axis j's threshold by the whole read so far (kept until the next block is fed)."""
        assert self.hist is not None
        if self._cache.get(j, (-1, 0.0))[0] != self.rows:
            self._cache[j] = (self.rows, held_threshold(self.hist[j], self.rows))
        return self._cache[j][1]

    def _threshold(self, j: int, first: int, last: int) -> float:
        k = self._whole(j)
        if last - first + 1 >= k and last - first + 1 < HELD_WAIT_SAMPLES:
            h, rows = self._since(j, first)
            k = max(k, held_threshold(h, rows, self.rows))
        return k

    def undecided(self) -> bool:
        """An open run the whole read's threshold would hold, not yet judged held because the
        runs after its start are too few to tell: the screen waits for more blocks (at most
        ``HELD_WAIT_SAMPLES`` rows)."""
        if self.hist is None:
            return False
        for j, cand in enumerate(self.cand):
            if len(cand) and cand[-1, 1] == self.rows - 1 and not self.held[j][-1]:
                first, last = int(cand[-1, 0]), int(cand[-1, 1])
                if (last - first + 1 >= self._whole(j)
                        and not last - first + 1 >= self._threshold(j, first, last)):
                    return True
        return False

    def verdict(self, off: int, n: int) -> NDArray[np.bool_]:
        """(n, axes): the rows [off, off + n) held on each axis."""
        c = 0 if self.hist is None else self.hist.shape[0]
        out = np.zeros((n, c), dtype=bool)
        if self.hist is None or not n:
            return out
        for j in range(c):
            cand, held = self.cand[j], self.held[j]
            if not len(cand):
                continue
            f, la = cand[:, 0], cand[:, 1]
            here = (la >= off) & (f < off + n)
            # only a run longer than the whole read's threshold is judged further
            for i in np.flatnonzero(here & ~held & (la - f + 1 >= self._whole(j))):
                held[i] = la[i] - f[i] + 1 >= self._threshold(j, int(f[i]), int(la[i]))
            for i in np.flatnonzero(here & held):
                out[max(int(f[i]), off) - off:min(int(la[i]), off + n - 1) - off + 1, j] = True
            keep = la >= off + n
            self.cand[j], self.held[j] = cand[keep], held[keep]
        # a block's own runs are needed while a candidate or a row still to judge is in it
        low = min([off + n, *(int(cand[:, 0].min()) for cand in self.cand if len(cand))])
        self.blocks = [b for b in self.blocks if b[0] + b[1] > low]
        return out
