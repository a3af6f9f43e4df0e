"""Exact parallel analysis of one record: cut by time, each chunk analysed on its own core,
the chunks' sums added (``avard analyze --workers N``).

Cutting a record into chunks and merging their Allan variances (``StreamingAllan.merge``)
loses the second differences that straddle each cut: a fraction of about 2mK/N of them for K
cuts, nothing at short τ and a lot near N/4. Here nothing is lost. A chunk [start, stop)
owns the differences D_i and the averages that *start* in it. It reads the record from its
start, the samples before the chunk only advancing the running sum (so its differences are
one pass's to the bit), and reads on past ``stop`` by
the reach of its longest difference and of the noise identification's sums of products
(``LADDER_REACH`` averages), which it keeps apart and takes away again
(``OverlappingAllan(own_until=…)``, ``OadevPart``). Its Welch segments are those that start
in it. The parts then add up to what one pass over the whole record holds, to the rounding
of the sums, so the ADEV, its noise identification (α), EDF and intervals, the spectrum and
the fit are the single-worker ones (``tests/core/test_parallel.py``).

Cuts fall on multiples of ``alignment`` (the Welch hop, and the input screen's block)
counted from the start of the segment (the stretch between gaps) they are in: the Welch
segments and the screen's blocks are aligned to that start, and a cut elsewhere would shift
them. The OADEV's averages need no such cut: an average that straddles a cut is the
earlier chunk's, which reads on past its end anyway, and the later chunk's first own
average is the next one on that τ's grid, so the chunks can be evened out to a hop's
samples. Records without any stretch longer than two alignments run on one worker.

What stays single-worker: the cascade estimator (``--estimator cascade``: the service's
streaming accumulator, whose stride the chunks would shift), the R(n) sums (read again for
the few channels and τ that need them after the pass, as on one worker) and the fit.

Every pass (a group of channels) is planned at once (``plan_passes``): each is cut into as
many chunks as make the workers, taking the chunks longest first, end soonest, since a cut
costs a read of the record's start and of the reach past it again. Three channels on two
workers are two passes analysed whole and one cut in two. The passes hold fewer channels
than one worker's (``engine._parallel_groups``), so the workers together hold no more OADEV
histories than one worker does. With the input screen on, each chunk judges the blocks it
owns, each axis on its own (a row is cut when any axis says so: the first pass also judges
the axes no pass analyses); a cut is a gap the plan does not know, and the record is then
analysed on one worker (``ScreenCut``), which takes the chunks' verdicts instead of judging
the record again: once any chunk cuts (a flag the forked workers share), every chunk only
judges the rest of the blocks it owns.

The parent takes the chunks as they end and hands each pass on as soon as its last chunk is
in (``run_passes(on_pass=…)``), so the engine finishes and fits it while the workers
analyse the others.

The workers are forked processes (a ``ProcessPoolExecutor`` on ``multiprocessing``'s "fork"
context): each inherits the jobs (how to read the record, the τ grid, the chunks) and sends
back only its part, a few numbers per τ and the spectrum's power sums. A worker that dies
(killed, out of memory) ends the analysis with an error that says so, instead of a wait for
its chunk. The workers are told to exit when the last chunk is in, so their exit overlaps
the parent's finishing of the last pass.

A pass here holds fewer channels than a one-worker pass, so a local chunk reads
``CHUNK_BLOCKS`` one-worker blocks at a time and takes OADEV pieces of as many
channel-samples (``chunk_piece``): what each read, piece and spectrum batch costs in Python
is paid for as many samples as on one worker. The input screen still judges each one-worker
block on its own (``_Job.screen_block``), and the reader and the spectrum bound what a long
block holds (``readers.READ_ROWS``, ``spectrum.SEGMENT_BATCH``).
"""

from __future__ import annotations

import gc
import itertools
import math
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from avard.core.allan.overlapping import LADDER_REACH, PIECE, OadevPart, OverlappingAllan
from avard.core.allan.scratch import reuse_histories
from avard.core.analysis.drift import BlockSums, BlockSumsPart
from avard.core.analysis.spectrum import WelchAccumulator, WelchPart
from avard.core.errors import AvardError, DataError
from numpy.typing import NDArray

__all__ = ["MAX_WORKERS", "PARALLEL_MIN_SAMPLES", "Chunk", "ChunkResult", "PassSpec", "ScreenCut",
           "ShortRead", "cores", "default_workers", "plan_chunks", "plan_passes", "run_passes"]

#: The most workers ``default_workers`` proposes: a Raspberry Pi's four cores.
MAX_WORKERS = 4
#: Below this much memory (a Pi 3 has 1 GB) the default is one worker: each worker holds an
#: OADEV history of its own.
SMALL_MACHINE_BYTES = 2 << 30

#: ``workers="auto"`` runs shorter records on one worker: below ~9 h at 125 Hz the forks and
#: the re-read prefix cost about what the second core saves.
PARALLEL_MIN_SAMPLES = 1 << 22

#: A record's blocks: (samples (n, C) in m/s², True where a segment ends).
Blocks = Iterable[tuple[NDArray[np.float64], bool]]


def cores() -> int:
    """The cores this process may run on."""
    return max(1, len(os.sched_getaffinity(0)))


def default_workers() -> int:
    """1 on a machine with less than 2 GB of memory, else the cores, at most 4."""
    try:
        with open("/proc/meminfo") as f:
            total = next(int(line.split()[1]) * 1024 for line in f
                         if line.startswith("MemTotal:"))
    except (OSError, StopIteration, ValueError, IndexError):
        total = 0
    if total < SMALL_MACHINE_BYTES:
        return 1
    return min(MAX_WORKERS, cores())


class ShortRead(DataError):
    """A chunk found fewer samples than planned: the input screen cut rows out of the
    record (its cuts are gaps the plan could not know), or the file changed. The engine then
    reads the pass on one worker, which needs no plan."""


class ScreenCut(ShortRead):
    """A chunk's input screen (``_Job.screen``) found acceleration to cut: a gap the chunk
    plan does not know of, so the record is analysed on one worker, as ``ShortRead``.
    ``verdicts``: the rows the screen cuts, {block offset: rows in the block} for the blocks
    with any, judged by the chunks on every axis over the whole record (block by block as a
    one-worker read in blocks of ``block`` samples would), so that read need not judge the
    record again (``ScreenedSource.judged``); None when the chunks did not judge it all."""

    def __init__(self, message: str, verdicts: dict[int, NDArray[np.intp]] | None = None,
                 block: int | None = None) -> None:
        super().__init__(message)
        self.verdicts = verdicts
        self.block = block


@dataclass(frozen=True)
class ChunkResult:
    """What a chunk sends back: its OADEV part and Welch power sums, or None for both when
    the input screen cut something (the record is then read on one worker), and the screen's
    verdicts on the blocks it owns ({block offset: rows cut}, the blocks with any)."""

    part: OadevPart | None
    power: WelchPart | None
    cuts: dict[int, NDArray[np.intp]]
    #: the drift test's block sums over the rows the chunk owns (None: not asked)
    means: BlockSumsPart | None = None


@dataclass(frozen=True)
class Chunk:
    """One worker's stretch of a record: it owns samples [start, stop) and reads [start,
    read_to)."""

    start: int
    stop: int
    read_to: int


def alignment(nperseg: int | None) -> int:
    """The step cuts fall on: the Welch hop (a chunk's segments start at its first sample,
    so a cut elsewhere would shift them), 1 without a spectrum. The OADEV needs none: a
    chunk owns the differences and the averages of every τ that start in it (an average
    that straddles a cut is the earlier chunk's: ``OverlappingAllan(own_from=…)``), so the
    plan can even out the chunks' work to a hop's samples, not to the longest τ's (a
    quarter of a 60 h record)."""
    return nperseg // 2 if nperseg else 1


def reach(grid: NDArray[np.int64], nperseg: int | None) -> int:
    """Samples a chunk reads past its end: its last differences' (2·m_max), the noise
    identification's averages' (``LADDER_REACH``·m_max) and its last Welch segment's."""
    return max(LADDER_REACH * int(grid[-1]), (nperseg or 0) // 2)


#: What a chunk's own samples cost against the samples it only reads (the differences at
#: every τ, the spectrum and the screen against a read and a running sum): the chunk plan
#: evens out reads + OWN_COST × owned samples. Every chunk reads from the record's start,
#: and all but the last on past their end, so the last owns the most. Fitted to the chunks
#: of one 60 h axis cut at several points (their CPU against what they read and own).
OWN_COST = 4.0


def _ideal_cuts(n: int, workers: int, reach_: int, own_cost: float) -> list[float]:
    """Cut points (not yet aligned) at which every chunk costs the same: a chunk [s, e)
    reads [0, min(n, e + reach)) and owns e − s samples, so costs min(n, e + reach) +
    own_cost·(e − s); the last, n + own_cost·(n − s). Found by bisection on that cost."""
    rho = float(own_cost)

    def cuts_for(cost: float) -> tuple[list[float], float]:
        s, out = 0.0, []
        for _ in range(workers - 1):
            e = (cost - reach_ + rho * s) / (1 + rho)  # its reach inside the record
            if e + reach_ > n:
                e = s + (cost - n) / rho if rho > 0 else float(n)
            e = min(max(e, s), float(n))
            out.append(e)
            s = e
        return out, n + rho * (n - s)

    lo, hi = 0.0, (n + reach_) * (1 + rho)
    for _ in range(80):
        mid = (lo + hi) / 2
        if cuts_for(mid)[1] > mid:
            lo = mid
        else:
            hi = mid
    return cuts_for(hi)[0]


def plan_chunks(bounds: Sequence[int], workers: int, align: int, reach_: int,
                own_cost: float = OWN_COST) -> list[Chunk]:
    """Chunks of about equal work for ``workers`` (``_ideal_cuts``: the later a chunk, the
    more it owns), cut at multiples of ``align`` from the start of the segment
    each cut is in (``bounds``: the segments' first samples and the record's length, as
    ``meta["segment_bounds"]``). Fewer chunks where the record has too few such points."""
    n = int(bounds[-1])
    cuts = set()
    for ideal in _ideal_cuts(n, workers, reach_, own_cost):
        best = None
        for s0, s1 in itertools.pairwise(bounds):
            j = round((ideal - s0) / align)
            for jj in (j - 1, j, j + 1):
                c = s0 + jj * align
                if s0 < c < s1 and (best is None or abs(c - ideal) < abs(best - ideal)):
                    best = c
        if best is not None:
            cuts.add(int(best))
    edges = [0, *sorted(cuts), n]
    return [Chunk(a, b, min(n, b + reach_) if b < n else n)
            for a, b in itertools.pairwise(edges)]


@dataclass(frozen=True)
class _Job:
    """One pass's chunks and what every worker needs for them: handed to the forked local
    processes when they start (never pickled), pickled (so ``read`` must be picklable, e.g.
    ``ChainedRead``) for another executor's. ``read(verify=...)`` gives the record's blocks
    from its start, of which the columns ``take`` (None: all) are the pass's channels; the
    chunk that reads to the record's end checks the file's CRC when ``verify``. ``screen``:
    the columns whose blocks each chunk judges by the input screen over the samples it owns
    (``ScreenCut`` when it would cut), None for none, in blocks of ``screen_block`` samples
    from the record's start (a one-worker read's: ``read``'s blocks are whole multiples of
    it, ``CHUNK_BLOCKS`` of them on a local analysis)."""

    read: Callable[..., Blocks]
    take: list[int] | None
    names: list[str]
    rate_hz: float
    grid: NDArray[np.int64]
    nperseg: int | None
    n_total: int
    verify: bool
    chunks: list[Chunk]
    screen: list[int] | None = None
    screen_block: int | None = None
    #: samples per block of the drift test's block means (None: none kept)
    means_block: int | None = None


class _Flag(Protocol):
    """A flag the chunks of one analysis share (a ``multiprocessing`` event)."""

    def is_set(self) -> bool: ...

    def set(self) -> None: ...


#: The jobs of this forked worker process (``_take_jobs``): one list per process, never
#: shared between concurrent analyses (each starts processes of its own), and the flag its
#: chunks set when the screen cuts (then every chunk only judges what it owns).
_JOBS: list[_Job] = []
_CUT: _Flag | None = None


def _take_jobs(jobs: list[_Job], cut: _Flag | None = None) -> None:
    global _JOBS, _CUT
    _JOBS, _CUT = jobs, cut
    # a worker's chunks after its first take the first's OADEV ring, its pages mapped
    reuse_histories()


def _chunk_part(p: int, i: int) -> ChunkResult:
    """Chunk i of pass p, in a forked local worker (the jobs handed to it at its start)."""
    return chunk_part(_JOBS[p], i, _CUT)


#: A local chunk reads the record in blocks of this many one-worker blocks (the screen's):
#: a parallel pass holds fewer channels than a one-worker pass (one each on two workers),
#: and what every block and OADEV piece costs in Python (a few dozen numpy calls per τ,
#: per read and per spectrum batch, whatever their length) would otherwise be paid for
#: fewer samples. The screen still judges each one-worker block on its own.
CHUNK_BLOCKS = 4


def chunk_piece(n_channels: int) -> int:
    """The OADEV piece of a chunk's accumulator of ``n_channels``: ``CHUNK_BLOCKS`` ×
    ``PIECE`` samples of one channel, as many channel-samples as a four-channel piece
    (``PIECE`` at least). A longer piece only splits the sums differently (rounding)."""
    return PIECE * max(1, CHUNK_BLOCKS // max(1, n_channels))


def chunk_part(job: _Job, i: int, cut: _Flag | None = None) -> ChunkResult:
    """Chunk i's OADEV part and Welch power sums (a worker's task), with the input screen's
    verdicts on the blocks it owns. Once the screen cuts anything (here, or in another chunk
    of the analysis: ``cut``, which it then sets), the sums are of no use (the record is
    read on one worker) and the chunk only judges the rest of its blocks, so that read can
    take the verdicts instead of judging the record again."""
    ch = job.chunks[i]
    last = ch.stop >= job.n_total
    c = len(job.names)
    # R(n) is never part of a chunk: the caller reads it again after the pass (defer_rn)
    acc = OverlappingAllan(c, job.rate_hz, job.grid, names=job.names, n_total=job.n_total,
                           defer_rn=True, own_from=ch.start,
                           own_until=None if last else ch.stop, piece=chunk_piece(c))
    welch = (WelchAccumulator(c, job.rate_hz, job.nperseg) if job.nperseg is not None
             else None)
    means = (BlockSums(c, job.means_block, ch.start, None if last else ch.stop)
             if job.means_block is not None else None)
    # the Welch segments that start before ``stop`` end by half a segment past it
    welch_to = ch.read_to if last or job.nperseg is None else ch.stop + job.nperseg // 2
    pos = 0
    cuts: dict[int, NDArray[np.intp]] = {}
    judging = False  # only the screen's verdicts are still wanted
    sb = job.screen_block
    for accel, segment_end in job.read(verify=job.verify and last):
        lo, hi = pos, min(pos + len(accel), ch.read_to)
        pos = hi
        a = accel[:hi - lo]
        if job.screen and lo < ch.stop and hi > ch.start:
            # each one-worker block (of ``screen_block`` samples from the record's start)
            # the chunk owns, judged on its own, as that read would judge it
            step = sb or len(a)
            # the screen's columns taken (a copy) only when they are not the whole block
            cols = None if job.screen == list(range(accel.shape[1])) else job.screen
            for b0 in range(lo, hi, step):
                if not ch.start <= b0 < ch.stop:
                    continue
                blk = accel[b0 - lo:b0 - lo + step]  # whole, even past read_to
                bad = _screen(blk if cols is None else blk[:, cols])
                if bad is not None:
                    cuts[b0] = bad
            if cuts and cut is not None and not cut.is_set():
                cut.set()  # the other chunks' sums are of no use either
        if job.screen and (cuts or (cut is not None and cut.is_set())):
            judging = True
            if hi >= ch.stop:
                break
            continue
        if job.take is not None:
            a = a[:, job.take]
        # from the record's start: what comes before the chunk advances the running sum
        # only, so the chunk's differences are one pass's to the bit (a running sum begun
        # at the chunk's start moves the long records' ADEV by a few 1e-12)
        acc.update(a)
        if welch is not None and hi > ch.start and lo < welch_to:
            welch.update(a[max(0, ch.start - lo):welch_to - lo])
        if means is not None:
            means.update(a)
        if hi >= ch.read_to:
            break
        if segment_end:
            acc.gap()
            if welch is not None:
                welch.gap()
            if means is not None:
                means.gap()
    if pos < (ch.stop if judging else ch.read_to):
        raise ShortRead(f"read {pos} samples where the record had {ch.read_to}: the input "
                        "screen cut rows out, or the file changed while it was analysed")
    if judging:
        return ChunkResult(None, None, cuts)
    return ChunkResult(acc.part(), None if welch is None else welch.part(), cuts,
                       None if means is None else means.part())


def _screen(a: NDArray[np.float64]) -> NDArray[np.intp] | None:
    """The input screen's verdict on one block a chunk owns (its columns; a one-worker read's
    block, since chunks start on a block boundary): the rows it cuts, None for none. Any cut
    is a gap the plan does not know: the analysis is then read on one worker
    (``ScreenCut``)."""
    from avard.core.io.screen import screen_accel
    from avard.core.io.screen.held_accel import held_suspect

    if held_suspect(a):
        # a held acceleration is judged over the whole record (its axis's runs), which a
        # chunk does not see: the record is read on one worker and judged there
        return np.array([HELD_SUSPECT], dtype=np.intp)
    bad = screen_accel(a)
    return np.flatnonzero(bad) if bad.any() else None


#: A chunk's verdict row that says "a held acceleration may lie here": no verdicts are
#: handed on, the one-worker read judges the whole record (``_screen_cut``)
HELD_SUSPECT = -1


@dataclass(frozen=True)
class PassSpec:
    """One OADEV pass of a parallel analysis: its channels ``names``, read by ``read``
    (blocks from the record's start, of which ``take`` are its channels, None: all),
    whether its chunk that reads to the end checks the file's CRC, and the block columns its
    chunks judge by the input screen (None: none)."""

    read: Callable[..., Blocks]
    take: list[int] | None
    names: list[str]
    verify: bool = False
    screen: list[int] | None = None


def _chunk_costs(chunks: list[Chunk], n: int) -> list[float]:
    """The work of each chunk as the plan counts it (``_ideal_cuts``)."""
    return [min(n, ch.read_to) + OWN_COST * (ch.stop - ch.start) for ch in chunks]


def _makespan(costs: list[float], workers: int) -> float:
    """The longest worker's work when the tasks go, longest first, to the least loaded."""
    loads = [0.0] * workers
    for c in sorted(costs, reverse=True):
        k = loads.index(min(loads))
        loads[k] += c
    return max(loads)


#: The most plans ``plan_passes`` compares (ways to cut the passes); beyond, every pass is
#: cut alike (many passes, or a machine of many cores).
PLAN_CHOICES = 2000


def plan_passes(n_passes: int, bounds: Sequence[int], workers: int, align: int,
                reach_: int) -> list[list[Chunk]]:
    """How many chunks each of ``n_passes`` passes is cut into, so that the passes' chunks,
    run longest first on ``workers`` processes, end soonest: a pass analysed whole reads
    the record once, and each cut makes its chunks read the record's start and the reach
    past their ends again, so e.g. three channels on two workers are two whole passes and
    one cut in two. Ties go to fewer chunks, and to cutting the later passes (the first
    checks the file's CRC)."""
    n = int(bounds[-1])
    options = [plan_chunks(bounds, k, align, reach_) for k in range(1, workers + 1)]
    costs = [_chunk_costs(o, n) for o in options]
    if math.comb(len(options) + n_passes - 1, n_passes) > PLAN_CHOICES:
        # every pass cut alike: the choices per pass would be too many
        k = min(range(len(options)), key=lambda j: (_makespan(costs[j] * n_passes, workers),
                                                    j))
        return [options[k]] * n_passes
    # the passes are of one record, so only how many are cut how often matters: each
    # choice once, in ascending order (the later passes cut most)
    combo = min(itertools.combinations_with_replacement(range(len(options)), n_passes),
                key=lambda ks: (_makespan([c for k in ks for c in costs[k]], workers),
                                sum(len(costs[k]) for k in ks)))
    return [options[k] for k in combo]


def run_passes(passes: Sequence[PassSpec], rate_hz: float, grid: NDArray[np.int64],
               nperseg: int | None, n_total: int, bounds: Sequence[int], workers: int, *,
               progress: Callable[[int], None] | None = None,
               executor: Executor | None = None, screen_block: int | None = None,
               on_pass: Callable[[int, OverlappingAllan, WelchAccumulator | None, int], None]
               | None = None, means_block: int | None = None,
               means_out: dict[int, BlockSumsPart] | None = None,
               ) -> list[tuple[OverlappingAllan, WelchAccumulator | None, int]]:
    """The OADEV passes ``passes`` over one record, their chunks (``plan_passes``) run
    together on ``workers`` processes, longest first: per pass the OADEV accumulator
    holding the whole record's sums (``OverlappingAllan.from_part``), the Welch accumulator
    and the samples read, as one pass would give them. ``progress(samples)`` after each
    chunk (its own samples, summed over the passes). ``executor``: run the chunks there
    (e.g. a Dask client's, ``avard fleet``) instead of on forked local processes; ``read``
    must then be picklable. ``screen_block``: the chunks judge their blocks by the input
    screen, as a one-worker read in blocks of that size would (so chunks start on its
    multiples); ``ScreenCut`` when it would cut anything. R(n) is left to the caller: the
    accumulators are ``defer_rn`` (``rn_needed``/``set_rn``), as analyze of a file does
    after one pass. ``on_pass(p, acc, welch, n)``: called with pass p's sums as soon as its
    last chunk is in, while the workers go on with the others (the caller finishes that
    pass meanwhile: its results and fits are then off the serial end), unless the screen
    has cut anything. ``means_block``: the chunks also keep the drift test's block sums
    (``drift.BlockSums``) in blocks of that many samples, each pass's added up into
    ``means_out[p]`` before ``on_pass`` hears of it (the one pass's ``BlockMeans``, so a
    parallel analysis reads no channel again for its drift test)."""
    align = alignment(nperseg)
    if screen_block is not None:
        align = align * screen_block // math.gcd(align, screen_block)
    n = int(n_total)
    plans = plan_passes(len(passes), bounds, workers, align, reach(grid, nperseg))
    jobs = [_Job(ps.read, ps.take, ps.names, float(rate_hz), grid, nperseg, n, ps.verify,
                 chunks, screen=ps.screen if screen_block is not None else None,
                 screen_block=screen_block, means_block=means_block)
            for ps, chunks in zip(passes, plans, strict=True)]
    tasks = sorted(((p, i) for p, job in enumerate(jobs) for i in range(len(job.chunks))),
                   key=lambda t: -_chunk_costs([jobs[t[0]].chunks[t[1]]], n)[0])
    parts: dict[tuple[int, int], ChunkResult] = {}
    wholes: dict[int, tuple[OverlappingAllan, WelchAccumulator | None, int]] = {}
    left = [len(job.chunks) for job in jobs]
    done = 0

    def whole(p: int) -> tuple[OverlappingAllan, WelchAccumulator | None, int]:
        """Pass p's chunks added up: what one pass over the record holds."""
        if p in wholes:
            return wholes[p]
        job = jobs[p]
        total: OadevPart | None = None
        welch = (WelchAccumulator(len(job.names), rate_hz, nperseg) if nperseg is not None
                 else None)
        for i in range(len(job.chunks)):
            part, power = parts[(p, i)].part, parts[(p, i)].power
            assert part is not None
            total = part if total is None else total + part
            if welch is not None and power is not None:
                welch.add(power)
        assert total is not None
        if means_out is not None and means_block is not None:
            sums = [m for i in range(len(job.chunks)) if (m := parts[(p, i)].means) is not None]
            if len(sums) == len(job.chunks):
                added = sums[0]
                for m in sums[1:]:
                    added = added + m
                means_out[p] = added
        acc = OverlappingAllan.from_part(total, rate_hz, names=job.names, n_total=n,
                                         defer_rn=True)
        wholes[p] = (acc, welch, total.n_samples)
        return wholes[p]

    def take(t: tuple[int, int], one: ChunkResult) -> None:
        nonlocal done
        parts[t] = one
        ch = jobs[t[0]].chunks[t[1]]
        done += ch.stop - ch.start
        if progress is not None:
            progress(done)
        left[t[0]] -= 1
        if on_pass is not None and left[t[0]] == 0 and all(
                r.part is not None for r in parts.values()):
            # while the workers go on with the other passes' chunks
            on_pass(t[0], *whole(t[0]))

    if len(tasks) == 1 and executor is None:
        take(tasks[0], chunk_part(jobs[0], 0))
    else:
        # forked local processes get the jobs when they start (only task numbers cross to
        # them, so ``read`` may be any callable); another executor (Dask's) gets them pickled
        own = executor is None
        ctx = multiprocessing.get_context("fork")
        cut = ctx.Event() if own and screen_block is not None else None
        pool = executor or ProcessPoolExecutor(
            min(workers, len(tasks)), mp_context=ctx, initializer=_take_jobs,
            initargs=(jobs, cut))
        try:
            # submitted longest first; taken as they end, so a pass is finished as soon as
            # its last chunk is in
            with _frozen_heap(own):
                futures = {(pool.submit(_chunk_part, p, i) if own else
                            pool.submit(chunk_part, jobs[p], i)): (p, i) for p, i in tasks}
            for fut in as_completed(futures):
                one = fut.result()
                if own and len(parts) == len(tasks) - 1:
                    # the last chunk is in: the workers exit (their histories unmapped) while
                    # this process finishes the last pass, not after it
                    pool.shutdown(wait=False)
                take(futures[fut], one)
        except BrokenProcessPool as exc:
            # a worker killed (out of memory, a signal): said, never waited for forever
            raise AvardError(f"a worker process of the parallel analysis died ({exc}); "
                             "run again with fewer --workers (each holds an OADEV "
                             "history of its own) or --workers 1") from exc
        finally:
            if own:
                pool.shutdown(wait=True, cancel_futures=True)
    if any(r.part is None for r in parts.values()):
        raise _screen_cut(parts, screen_block)
    return [whole(p) for p in range(len(jobs))]


@contextmanager
def _frozen_heap(forking: bool) -> Iterator[None]:
    """While the workers are forked (at the pool's first task): this process's objects out
    of the garbage collector's reach (``gc.freeze``), so a worker's collections do not
    write to every inherited object and copy the pages they sit on (about 4 MB a worker)."""
    if not forking:
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _screen_cut(parts: dict[tuple[int, int], ChunkResult], block: int | None) -> ScreenCut:
    """The ``ScreenCut`` of chunks of which some found rows to cut: the rows every chunk's
    screen cut, per block (a row is cut when any axis says so: the union of the passes'
    verdicts on their own axes, each margin included, is the verdict on all of them)."""
    verdicts: dict[int, NDArray[np.intp]] = {}
    for r in parts.values():
        for off, rows in r.cuts.items():
            verdicts[off] = np.union1d(verdicts[off], rows) if off in verdicts else rows
    if not verdicts:  # no chunk says what it cut: the one-worker read judges it all again
        return ScreenCut("the input screen cut samples", None, block)
    if any(len(rows) and rows[0] == HELD_SUSPECT for rows in verdicts.values()):
        return ScreenCut("the input screen found a run of identical samples that may be a "
                         "held acceleration", None, block)
    first = min(off + int(rows[0]) for off, rows in verdicts.items())
    return ScreenCut(f"the input screen cuts {sum(len(r) for r in verdicts.values())} samples"
                     f" from sample {first} on", verdicts, block)


@dataclass(frozen=True)
class ChainedRead:
    """Several records read one after another as the segments of one record (a gap at each
    record's end): what ``analyze_records`` pools. Picklable, so a Dask worker can read."""

    read: tuple[Callable[..., Blocks], ...]

    def __call__(self, columns: list[int], *, verify: bool = False
                 ) -> Iterator[tuple[NDArray[np.float64], bool]]:
        for r in self.read:
            last: tuple[NDArray[np.float64], bool] | None = None
            for b in r(columns, verify=verify):
                if last is not None:
                    yield last
                last = b
            if last is not None:
                yield last[0], True  # no difference or spectrum segment spans two records
