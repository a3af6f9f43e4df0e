"""``avard analyze`` as a library: stream a record, fit every channel, and write it out.

A pass over a record source (``core.io.source``: an .npz, a CSV or a recording, streamed)
feeds two bounded-memory accumulators per
channel: the fully overlapping Allan variance (``overlapping.OverlappingAllan``, OADEV as
Stable32 and allantools compute it, NIST SP 1065 eq. 12, at octave τ; memory a ring of 2·m_max
running-sum points) and a Welch spectrum used to find sinusoids. A file long enough that the
rings of all its channels would exceed ``PASS_BUDGET_BYTES`` is read once per group of
channels that fit (``oadev_pass_groups``), so only one group's rings are live; the OADEV
then leaves R(n) out and reads a channel again for it only where B1 needs it.
``estimator="cascade"`` gives the service's streaming cascade instead
(``streaming.StreamingAllan``, stride m/8 above m = 8: partially overlapping, a different
estimator with ≥ 98 % of the OADEV's EDF).
Lines found in the spectrum enter the noise fit as fixed components (their
amplitude is measured far more precisely by the spectrum than by the AVAR bump), so they do
not bias N, B or K; then ``fit.fit_noise`` fits the IEEE terms.

Outputs: a text table, the ``--json`` dictionary (shape fixed by issue 4), a kalibr IMU yaml
(written by hand: no yaml dependency) and a csv of the ADEV table. All values SI.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, replace
from functools import partial
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from avard.core.allan.noise_id import check_noise_id
from avard.core.allan.scratch import histories_passed_on
from avard.core.analysis.drift import BlockMeans, BlockSumsPart, drift_block
from avard.core.analysis.options import DEFAULT_OPTIONS, AnalyzeOptions
from avard.core.analysis.results import ESTIMATORS, Analysis, ChannelAnalysis
from avard.core.analysis.signal_edf import with_signal_edf
from avard.core.analysis.spectrum import (
    WelchAccumulator,
    find_lines,
    line_components,
    welch_nperseg,
)
from avard.core.blas import one_blas_thread
from avard.core.errors import DataError, FitError
from avard.core.io.screen.stream import ScreenedSource
from avard.core.io.source import RecordFormat, RecordInfo, RecordSource
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.allan.overlapping import OverlappingAllan
    from avard.core.allan.streaming import StreamingAllan


# analyze of a file does not import scipy: the line threshold's F quantile and the p-value's
# χ² tail come from core/allan/beta.py and chi2.py (scipy.special cost 0.1–0.2 CPU-s of every
# analyze, ~1 s on a Pi), and the chip filter's model (an ADXL355 record's) from the
# simulator's numpy Butterworth (model.terms._butterworth; scipy.signal was 0.5 CPU-s and
# ~70 MB). What still needs scipy (--psd's intervals) imports it where it is used, after the
# pass over the data: loaded before the pass it would sit under the OADEV's history at the
# peak (measured 190 → 129 MB peak for a 60 h, 3-axis analyze).


__all__ = ["AnalyzeOptions", "FirstPassTap", "analyze"]

#: A progress callback: (samples read, total or None).
ProgressFn = Callable[[int, int | None], None]

log = logging.getLogger(__name__)

# OADEV τ grid: octaves while the record holds ≥ 4 non-overlapping intervals (Stable32's
# default range), and while the running-sum rings live at once (2·m_max points per channel)
# fit a quarter of the memory available when analyze starts, at least this much. A fixed
# 96 MiB cut a 60 h, 3-axis record two octaves short of N/4, where rate random walk shows.
# ``analyze`` of a file also uses this much as the rings of one pass: channels whose rings
# do not fit it together are read in further passes (one 60 h axis per pass), which keeps the
# whole analysis of such a record at ~1/10 of the memory of allantools' oadev.
RING_BUDGET_BYTES = 96 << 20
# ``analyze`` of a file reads it once per group of channels whose rings fit this together:
# two 60 h axes (68 MB each) per pass, so a 3-axis record is read twice, not three times
# (the R(n) sums that took another 56 MB per axis are computed only where B1 needs them,
# ``OverlappingAllan(defer_rn=True)``). The whole analysis of such a record then peaks at
# ~180 MB, 1/6 of allantools' oadev of the same axes (``python -m benchmarks analyze``).
PASS_BUDGET_BYTES = 144 << 20


def ring_budget_bytes() -> int:
    """Bytes the OADEV's running-sum history may take (see ``RING_BUDGET_BYTES``)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return max(RING_BUDGET_BYTES, int(line.split()[1]) * 1024 // 4)
    except (OSError, ValueError, IndexError):
        pass
    return RING_BUDGET_BYTES


def _select(names: list[str], channels: Sequence[str] | None) -> list[int]:
    if not channels:
        return list(range(len(names)))
    out = []
    for ch in channels:
        if ch in names:
            out.append(names.index(ch))
        elif ch.isdigit() and int(ch) < len(names):
            out.append(int(ch))
        else:
            raise DataError(f"channel {ch!r} is not in this record; its channels are "
                            f"{', '.join(names)} (or their numbers 0..{len(names) - 1})")
    return sorted(set(out))


#: A record's blocks: (samples (n, C) in m/s², True where a segment ends).
_Blocks = Iterable[tuple[NDArray[np.float64], bool]]
#: One pass over a record: its channels (numbers in the record), their blocks, and the block
#: columns to take (None: all).
_Pass = tuple[list[int], _Blocks, list[int] | None]
#: One channel's blocks read again (R(n) deferred by the OADEV; see ``_deferred_rn``).
_Reread = Callable[[int], _Blocks]


def _accel(source: RecordSource, block: int, columns: Sequence[int] | None,
           verify: bool = True) -> Iterator[tuple[NDArray[np.float64], bool]]:
    """The source's accel blocks of ``columns`` (no temperatures), opened when the pass
    starts (not before, so one file handle is open at a time)."""
    for a, _t, end in source.blocks(block, columns=columns, temperature=False, verify=verify):
        yield a, end


class FirstPassTap(Protocol):
    """What a caller sees of the record on analyze's first pass, so that it need not read
    the record again (``avard explain``'s slow view): every block as the pass reads it,
    every accel column and the temperatures (each reading on its row, NaN between), after
    the input screen when the source is screened; ``end`` once the pass has read the whole
    record. A parallel analysis (worker processes read the chunks) feeds no tap: ``end`` is
    then never called, and the caller reads the record itself."""

    def update(self, accel: NDArray[np.float64], temp: NDArray[np.float64] | None) -> None: ...

    def end(self) -> None: ...


def _tapped(source: RecordSource, block: int, tap: FirstPassTap
            ) -> Iterator[tuple[NDArray[np.float64], bool]]:
    """The first pass's blocks with every column and the temperatures, each shown to ``tap``
    before the pass takes its columns (``_Pass``'s ``take``); ``tap.end()`` after the last."""
    for a, t, end in source.blocks(block, columns=None, temperature=True, verify=True):
        tap.update(a, t)
        yield a, end
    tap.end()


def _take(chans: list[int], info: RecordInfo) -> list[int] | None:
    """The columns a pass takes of blocks holding every column: None (the block itself, no
    copy) when it takes them all."""
    return None if chans == list(range(len(info.names))) else chans


@one_blas_thread  # the fit and the spectrum too, not only the Allan pass (core/blas.py)
def analyze(source: RecordSource, options: AnalyzeOptions = DEFAULT_OPTIONS, *,
            progress: ProgressFn | None = None, tap: FirstPassTap | None = None) -> Analysis:
    """Per-channel AVAR and spectrum of ``source`` (``core.io.source.open_record``, or a
    ``StreamSource`` of blocks from anywhere), and the noise fit, as ``options`` say.

    A source that can be read again is read once per group of channels whose OADEV
    histories fit ``PASS_BUDGET_BYTES`` together, so only that group's histories are live
    (the first pass checks an .npz member's CRC, the others skip it), and the OADEV defers
    R(n), reading a channel again only where B1 needs it. A one-shot stream, or the
    ``cascade`` estimator, is read once with every channel at a time. The fit models the
    record's own low-pass corner (``RecordInfo.filter_corner_hz``) with ``"auto"``, whatever
    path the blocks took.

    ``tap``: shown every block of the first serial pass (``FirstPassTap``), which then reads
    every column and the temperatures and takes its own channels from them: the same pass,
    the same results.
    """
    check_noise_id(options.noise_id)
    if options.screen and not isinstance(source, ScreenedSource):
        # the input screen (core/io/screen/): glitches and shocks cut out as gaps, said in
        # the results; explain screens once itself and hands analyze the screened blocks
        screened = ScreenedSource(source, options.temperature_units)
        an = analyze(screened, options, progress=progress, tap=tap)
        an.meta["screen"] = screened.log
        return an
    info = source.info
    sel = _select(list(info.names), options.channels)
    total = info.n_samples
    if total is None and options.estimator == "oadev" and info.format is RecordFormat.CSV:
        total = _count_rows(info.source)
    block = options.block
    if options.estimator != "oadev" or not source.rereadable or total is None:
        one: _Pass = ((sel, _accel(source, block, sel), None) if tap is None
                      else (sel, _tapped(source, block, tap), _take(sel, info)))
        return _analyze_passes(info, total, [one], options=options, progress=progress)
    workers = _workers(options.workers, int(total))
    if info.format is not RecordFormat.NPZ:
        workers = 1  # a CSV's length is only bounded; a recording's gaps are found as it is read
    # one worker's passes (also the fallback of a parallel analysis the screen cuts); the
    # workers' own groups are made from them (_parallel_groups)
    groups = oadev_pass_groups(sel, int(total))
    passes: list[_Pass] = [(g, _accel(source, block, g, verify=k == 0), None)
                           for k, g in enumerate(groups)]
    if tap is not None:
        # the first pass reads every column anyway when the screen judges them all
        passes[0] = (groups[0], _tapped(source, block, tap), _take(groups[0], info))

    def reread(column: int) -> _Blocks:
        return _accel(source, block, [column], verify=False)

    parallel = None
    if workers > 1:
        # the chunks read the file itself; with the screen on, each pass's chunks judge
        # their own channels' columns (and the first pass the columns no pass analyses) over
        # the samples they own, as this read would (a record the screen cuts has gaps no
        # chunk plan knows of, and is then read on one worker)
        screened = source if isinstance(source, ScreenedSource) else None
        raw = source.source if screened is not None else source
        from avard.core.analysis.parallel import CHUNK_BLOCKS

        # the chunks read longer blocks (the screen still judges each of ``block``)
        parallel = _Parallel(workers, partial(_accel_columns, raw, CHUNK_BLOCKS * block),
                             (0, int(total)),
                             screened=screened, block=block,
                             groups=_parallel_groups(groups, sel, workers),
                             n_columns=len(info.names))
    return _analyze_passes(info, total, passes, reread=reread, options=options,
                           progress=progress, parallel=parallel)


def _workers(workers: int | str, n_samples: int) -> int:
    """``AnalyzeOptions.workers`` as a number: ``"auto"`` is ``parallel.default_workers()``
    for records of ``PARALLEL_MIN_SAMPLES`` or more, else 1; a number, at most the cores
    (said when it is cut: more processes than cores run no sooner, and each holds an OADEV
    history of its own, which could shorten the τ grid the memory allows)."""
    from avard.core.analysis.parallel import PARALLEL_MIN_SAMPLES, cores, default_workers

    if workers == "auto":
        return default_workers() if n_samples >= PARALLEL_MIN_SAMPLES else 1
    assert isinstance(workers, int)  # AnalyzeOptions checked it when it was made
    if workers > cores():
        log.warning("workers=%d: this machine lets analyze use %d cores; running %d worker "
                    "processes (more would be no faster and would hold more memory)",
                    workers, cores(), cores())
        return cores()
    return workers


def _parallel_groups(groups: list[list[int]], sel: list[int], workers: int
                     ) -> list[list[int]]:
    """The channel groups of a parallel analysis: as many channels per pass as leave the
    workers together with no more live histories than one worker's passes hold, one at
    least (``parallel.plan_passes`` then cuts some of the passes by time)."""
    size = max(1, max(len(g) for g in groups) // workers)
    return [sel[i:i + size] for i in range(0, len(sel), size)]


def _split_for_workers(groups: list[list[int]], workers: int) -> list[list[int]]:
    """Each worker holds an OADEV history of its own: a pass's channels split so that all
    workers together hold as many histories as one pass would."""
    if workers <= 1:
        return groups
    return [g[i:i + -(-len(g) // workers)] for g in groups
            for i in range(0, len(g), -(-len(g) // workers))]


def _accel_columns(source: RecordSource, block: int, columns: list[int] | None, *,
                   verify: bool = False) -> Iterator[tuple[NDArray[np.float64], bool]]:
    """A source's accel blocks of ``columns`` (None: all) from its start: a picklable reader
    for the chunks of a parallel pass (the chunk that reads a first pass to the end
    verifies)."""
    return _accel(source, block, columns, verify=verify)


def analyze_records(sources: Sequence[RecordSource], options: AnalyzeOptions = DEFAULT_OPTIONS,
                    *, chunks: int = 1, executor: Executor | None = None,
                    progress: ProgressFn | None = None) -> Analysis:
    """Several .npz records of one sensor analysed as one record whose segments they are
    (no difference or spectrum segment spans two of them): the same channels, rates that
    agree by ``core/io/rates.py``'s rule (τ labelled with the first record's rate), the
    OADEV at the τ the longest record reaches. Each pass is cut into ``chunks`` and run on
    ``executor`` (``avard fleet``: a Dask client's) or forked processes; one record and one
    chunk is ``analyze(source)``."""
    from dataclasses import replace

    from avard.core.analysis.parallel import ChainedRead
    from avard.core.io.rates import require_compatible

    check_noise_id(options.noise_id)
    if not sources:
        raise DataError("no records to analyse")
    if options.estimator != "oadev":
        raise DataError("records are pooled with the OADEV only; analyse them one by one "
                        "for the cascade")
    infos = [s.info for s in sources]
    first = infos[0]
    for i in infos:
        if i.format is not RecordFormat.NPZ or i.n_samples is None:
            raise DataError(f"{i.source}: only .npz records are pooled (its format is "
                            f"{i.format.value}); analyse it on its own")
        if i.names != first.names:
            raise DataError(f"{i.source} has channels {', '.join(i.names)} and {first.source}"
                            f" {', '.join(first.names)}: pool records of one sensor only")
        require_compatible(first.source, first.rate_hz, i.source, i.rate_hz, first.rate_u_hz,
                           i.rate_u_hz)
    sizes = [int(i.n_samples or 0) for i in infos]
    bounds = tuple(int(v) for v in np.cumsum([0, *sizes]))
    read = ChainedRead(tuple(partial(_accel_columns, s, options.block) for s in sources))
    info = replace(first, source=", ".join(i.source for i in infos), n_samples=bounds[-1])
    sel = _select(list(info.names), options.channels)
    groups = _split_for_workers(oadev_pass_groups(sel, max(sizes)), chunks)
    passes: list[_Pass] = [(g, read(g), None) for g in groups]
    parallel = (_Parallel(chunks, read, bounds, executor)
                if chunks > 1 or executor is not None else None)

    def reread(column: int) -> _Blocks:
        return read([column])

    return _analyze_passes(info, bounds[-1], passes, reread=reread, options=options,
                           progress=progress, parallel=parallel, longest=max(sizes))


def oadev_pass_groups(sel: list[int], n_samples: int) -> list[list[int]]:
    """``sel`` split into groups whose OADEV histories (8 bytes × (2·m_max + PIECE) points per
    channel) fit ``PASS_BUDGET_BYTES`` together, one channel at least: the channels of one
    pass over a file. Short records take every channel in one pass."""
    from avard.core.allan.overlapping import PIECE

    grid = oadev_grid(n_samples, 1)
    per_channel = 8 * (2 * int(grid[-1]) + PIECE)
    size = max(1, PASS_BUDGET_BYTES // per_channel)
    return [sel[i:i + size] for i in range(0, len(sel), size)]


def _count_rows(path: str) -> int:
    """Upper bound on the data rows of a text record (lines after the header), read in 1 MiB
    pieces: the OADEV grid is fixed before the data arrive. An overestimate only adds τ that
    end up without differences, which are dropped."""
    lines = 0
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            lines += chunk.count(b"\n")
    return max(0, lines)


def oadev_grid(n_samples: int, n_channels: int,
               budget_bytes: int | None = None) -> NDArray[np.int64]:
    """Octave m for the OADEV of a record: ≥ 4 non-overlapping intervals (m ≤ N/4, where
    Stable32's tables stop), and a ring of 2·m_max points per channel within
    ``budget_bytes`` (default :func:`ring_budget_bytes`); m = 1 at least."""
    from avard.core.allan.overlapping import PIECE

    budget = ring_budget_bytes() if budget_bytes is None else budget_bytes
    m_max = max(1, n_samples // 4)
    ring_max = budget // (8 * max(1, n_channels)) - PIECE
    m_max = max(1, min(m_max, ring_max // 2))
    return 2 ** np.arange(int(math.log2(m_max)) + 1, dtype=np.int64)


def _with_differences(res: Any) -> Any:
    """The result without the τ that got no difference (NaN variance, n = 0)."""
    from dataclasses import replace

    keep = np.asarray(res.n) > 0
    if keep.all():
        return res
    cut = {k: getattr(res, k)[keep] for k in ("tau", "m", "stride", "var", "n", "edf", "lo",
                                               "hi", "alpha")}
    if res.cov is not None:
        cut["cov"] = res.cov[keep]
    return replace(res, **cut)


@dataclass
class _PassResult:
    """What one pass over the blocks gives for its channels."""

    allan: Any  # AllanResult of the pass's channels, τ without differences dropped
    welch: WelchAccumulator | None
    n: int  # samples read
    #: the channels' block means for the drift test (None: none kept; the channel is then
    #: read again)
    means: BlockMeans | BlockSumsPart | None = None


def _one_pass(blocks: _Blocks, take: list[int] | None,
              names: list[str], rate: float, estimator: str, grid: NDArray[np.int64] | None,
              nper: int | None, progress: ProgressFn | None, done: int,
              total: int | None, quantiles: str = "exact",
              n_record: int | None = None, reread: _Reread | None = None,
              noise_id: str = "avard") -> _PassResult:
    """Stream ``blocks`` (their columns ``take``, or all) into the chosen Allan accumulator and
    the Welch spectrum of the channels ``names``; ``done``/``total`` place it in the progress
    of the whole analysis. ``reread(j)``: channel j's blocks again, for the R(n) sums the
    OADEV then leaves out until B1 asks for them (``_deferred_rn``)."""
    from avard.core.allan.overlapping import OverlappingAllan
    from avard.core.allan.streaming import StreamingAllan

    sa: OverlappingAllan | StreamingAllan
    if estimator == "oadev":
        assert grid is not None
        defer = reread is not None and n_record is not None
        sa = OverlappingAllan(len(names), rate, grid, names=names, n_total=n_record,
                              defer_rn=defer)
    else:
        sa = StreamingAllan(len(names), rate, names=names)
    welch = WelchAccumulator(len(names), rate, nper) if nper is not None else None
    # the drift test's block means, carried here so that a one-shot stream has them
    means = (BlockMeans(len(names), drift_block(n_record))
             if estimator == "oadev" and n_record is not None else None)
    n = 0
    for accel, segment_end in blocks:
        a = accel if take is None else accel[:, take]
        sa.update(a)
        if welch is not None:
            welch.update(a)
        if means is not None:
            means.update(a)
        n += len(a)
        if segment_end:
            # a gap in the recording: no Allan difference and no spectrum segment spans it
            sa.gap()
            if welch is not None:
                welch.gap()
            if means is not None:
                means.gap()
        if progress is not None:
            progress(done + n, total)
    return replace(_finish_pass(sa, welch, n, reread, quantiles, noise_id), means=means)


def _finish_pass(sa: OverlappingAllan | StreamingAllan, welch: WelchAccumulator | None, n: int,
                 reread: _Reread | None, quantiles: str, noise_id: str) -> _PassResult:
    """A pass's result from its accumulators, fed by one pass or added up from a parallel
    pass's chunks (``parallel.run_passes``): R(n) read again where B1 needs it, then the
    Allan result."""
    from avard.core.allan.overlapping import OverlappingAllan

    if isinstance(sa, OverlappingAllan) and reread is not None and n >= 16:
        _deferred_rn(sa, reread, n, noise_id)
    # "stable32": the intervals' χ² quantiles, and the B1 rule, as Stable32's
    res = (_with_differences(sa.result(quantiles=quantiles, noise_id=noise_id)) if n >= 16
           else None)
    return _PassResult(res, welch, n)


def _deferred_rn(sa: OverlappingAllan, reread: _Reread, n: int, noise_id: str = "avard"
                 ) -> None:
    """The R(n) sums ``sa`` (an ``OverlappingAllan(defer_rn=True)`` fed the whole record)
    needs where B1 says PM in its range: each such channel read again into an accumulator of
    those τ alone, which keeps them (the same differences in the same pieces, so the same
    sums as keeping them in the first pass). One channel at a time: a history of 3·m per τ.
    Nothing is read on records without PM noise at the long τ."""
    from avard.core.allan.overlapping import OverlappingAllan

    need = sa.rn_needed(noise_id)
    for ch in sorted({c for chans in need.values() for c in chans}):
        ks = [k for k, chans in need.items() if ch in chans]
        # said, since the progress shown is the passes' and this read comes after them
        log.info("channel %s read again for R(n) at τ = %s s, where B1 says PM",
                 sa.names[ch], ", ".join(f"{m / sa.rate_hz:g}" for m in sa.ms[ks]))
        extra = OverlappingAllan(1, sa.rate_hz, sa.ms[ks])
        got = 0
        for accel, segment_end in reread(ch):
            extra.update(accel)
            got += len(accel)
            if segment_end:
                extra.gap()
        if got != n:
            raise DataError(f"read {got} samples of channel {sa.names[ch]} again for R(n) "
                            f"after {n}; the file changed while it was analysed")
        sums = extra.rn_sums()
        sa.set_rn(ch, {k: r for k, r in zip(ks, sums, strict=True) if r is not None})


@dataclass(frozen=True)
class _Parallel:
    """How to run an OADEV pass on several processes: the workers (chunks), the record's
    blocks of some channels from its start (re-readable and picklable: every worker reads
    its own chunk), the segments' bounds, and where to run (forks, or e.g. a Dask client's
    executor for ``avard fleet``)."""

    workers: int
    read: Callable[..., _Blocks]
    bounds: tuple[int, ...]
    executor: Executor | None = None
    #: the record's input screen, judged by the chunks (``screen_accel`` on blocks of
    #: ``block`` samples, as a one-worker read): told when nothing was cut
    screened: ScreenedSource | None = None
    block: int = 1 << 16
    #: the passes' channels (None: the one-worker passes'), and the record's accel columns
    groups: list[list[int]] | None = None
    n_columns: int = 0


def _parallel_passes(par: _Parallel, groups: list[list[int]], names: list[str], rate: float,
                     grid: NDArray[np.int64], nper: int | None, total: int,
                     reread: _Reread | None, quantiles: str, noise_id: str,
                     progress: ProgressFn | None, scale: float, all_total: int | None,
                     on_result: Callable[[int, list[int], _PassResult], None] | None = None
                     ) -> list[tuple[list[int], _PassResult]]:
    """``_one_pass`` of the OADEV for every group of channels, the record cut into chunks
    and all of them run together on the workers (``parallel.run_passes``). The first pass
    checks the file's CRC, as one pass does (its last chunk reads to the end).
    ``on_result(k, channels, result)``: each group's result as soon as it is made, most of
    them while the workers still analyse the others (the caller fits them meanwhile)."""
    from avard.core.analysis.parallel import PassSpec, run_passes

    def step(samples: int) -> None:
        if progress is not None:
            progress(round(samples * scale), all_total)

    screen = par.screened is not None
    specs = []
    covered = {c for g in groups for c in g}
    for k, chans in enumerate(groups):
        # the screen judges each axis on its own (a row is cut when any axis says so): a
        # pass judges the columns it reads, the first also those no pass analyses
        extra = [c for c in range(par.n_columns) if c not in covered] if screen and k == 0 \
            else []
        cols = chans + extra
        specs.append(PassSpec(partial(par.read, cols), list(range(len(chans))) if extra
                              else None, [names[i] for i in chans], verify=k == 0,
                              screen=list(range(len(cols))) if screen else None))
    finished: dict[int, _PassResult] = {}

    def again_for(chans: list[int]) -> _Reread | None:
        if reread is None:
            return None
        return lambda j: reread(chans[j])

    def early(p: int, sa: OverlappingAllan, welch: WelchAccumulator | None, n: int) -> None:
        # a pass whose chunks are all in is finished while the workers go on, unless it
        # reads the record again for R(n): that read goes through the screen, whose verdict
        # on the chunks still out is not known yet
        if on_result is None or (reread is not None and n >= 16
                                 and sa.rn_needed(noise_id)):
            return
        finished[p] = finish(p, sa, welch, n)
        on_result(p, groups[p], finished[p])

    # the drift test's block means kept by the chunks (analysis/drift.py: none read again)
    means: dict[int, BlockSumsPart] = {}

    def finish(p: int, sa: OverlappingAllan, welch: WelchAccumulator | None, n: int
               ) -> _PassResult:
        one = _finish_pass(sa, welch, n, again_for(groups[p]), quantiles, noise_id)
        return replace(one, means=means.get(p))

    parts = run_passes(specs, rate, grid, nper, total, par.bounds, par.workers,
                       progress=step, executor=par.executor,
                       screen_block=par.block if screen else None, on_pass=early,
                       means_block=drift_block(total), means_out=means)
    if par.screened is not None:
        par.screened.judged_clean(par.block)  # later reads cut nothing, as the chunks found
    out = []
    for p, (chans, (sa, welch, n)) in enumerate(zip(groups, parts, strict=True)):
        if p not in finished:
            finished[p] = finish(p, sa, welch, n)
            if on_result is not None:
                on_result(p, chans, finished[p])
        out.append((chans, finished[p]))
    return out


@dataclass(frozen=True)
class _FitJob:
    """One channel's noise fit (``fit.fit_noise``): picklable, for a worker process."""

    allan: Any  # the channel's AllanResult
    corner: float | None
    extra: list[dict[str, Any]]
    check_filter: bool
    kw: dict[str, float]


def _fit_one(job: _FitJob) -> Any:
    """The fit, or the ``FitError``'s message (an exception need not cross a process)."""
    from avard.core.analysis.live_fit import decimation_guard
    from avard.core.model.fit import fit_noise

    kw = {"filter_corner_hz": job.corner, "extra": job.extra, "check_filter": job.check_filter,
          **job.kw}
    try:
        # the cascade's claims with the live fit's margin (live_fit.py); the OADEV's as fitted
        return decimation_guard(fit_noise(job.allan, **kw), job.allan, fit_kw=kw)
    except FitError as exc:
        return str(exc)


def _fit_all(jobs: list[_FitJob], workers: int) -> list[Any]:
    """Every channel's fit, on ``workers`` forked processes when there are more channels than
    one (after a parallel analysis the fits would otherwise be its one serial step)."""
    if workers <= 1 or len(jobs) <= 1:
        return [_fit_one(j) for j in jobs]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(min(workers, len(jobs)),
                             mp_context=multiprocessing.get_context("fork")) as pool:
        return list(pool.map(_fit_one, jobs))


def _analyze_passes(
    info: RecordInfo,
    total: int | None,
    passes: Sequence[_Pass],
    *,
    options: AnalyzeOptions,
    progress: ProgressFn | None,
    reread: _Reread | None = None,
    parallel: _Parallel | None = None,
    longest: int | None = None,
) -> Analysis:
    """The analysis of the channels of ``passes``: each (channel numbers in ``info.names``,
    its blocks, the block columns to take or None for all), read one after another.
    ``total``: the record's sample count (or an upper bound; None when unknown).
    ``progress`` counts the samples read over all passes (the record's length × passes).
    ``reread(column)``, when the record can be read again, gives one column's blocks: the
    OADEV then defers R(n) and reads a column again only where B1 needs it.
    ``parallel`` (the OADEV only): each pass's chunks on that many worker processes
    (``parallel.run_passes``), exactly the one-pass sums. ``longest``: records pooled as
    segments (``analyze_records``) have no τ beyond the longest one's."""
    estimator, source = options.estimator, info.source
    if estimator not in ESTIMATORS:
        raise DataError(f"estimator {estimator!r} is unknown; use one of {sorted(ESTIMATORS)}")
    rate = float(info.rate_hz)
    names = list(info.names)
    meta: dict[str, Any] = info.as_meta()
    grid = None
    if estimator == "oadev":
        if total is None:
            raise DataError(f"{source}: the record length is unknown, so the OADEV τ grid "
                            "cannot be fixed; give n_samples or use estimator='cascade'")
        width = max(len(chans) for chans, _b, _t in passes)  # channels live at once
        if parallel is not None and parallel.executor is None:
            # each local worker holds its chunk's history here (a Dask worker holds its own
            # elsewhere: the grid is then one analyze's)
            width = max(width, max(len(g) for g in parallel.groups or [[0] * width])
                        * parallel.workers)
        reach = int(total) if longest is None else longest
        grid = oadev_grid(reach, width)
        full = oadev_grid(reach, width, budget_bytes=1 << 62)
        if len(grid) < len(full):
            # said in the table and the JSON: the longest τ the memory here allowed
            meta["oadev_cut"] = {
                "tau_max_s": float(grid[-1] / rate), "tau_full_s": float(full[-1] / rate),
                "bytes_needed": int(16 * full[-1] * width)}
    nper = None
    find_sinusoids, psd = options.find_sinusoids, options.psd
    if (find_sinusoids or psd) and (total is None or total >= 1024):
        nper = welch_nperseg(total)
    all_total = None if total is None else int(total) * len(passes)
    results: list[tuple[list[int], _PassResult]] = []
    # "auto": the record's own corner, carried by its RecordInfo whatever path it came by
    corner = (info.filter_corner_hz if options.filter_corner_hz == "auto"
              else options.filter_corner_hz)
    # an ADXL355 record rounds to its LSB after the chip filter: unfiltered white noise the
    # fit holds as a fixed term (simulated records and recordings carry the LSB)
    lsb = info.lsb_mps2
    kw: dict[str, float] = {"ci": options.ci}
    if corner is not None and lsb is not None:
        kw["rounding_lsb"] = lsb
    prep = _FitPrep(corner, options.filter_corner_hz == "auto", kw, find_sinusoids)
    # the passes' lines and fits, by position in ``results``: a parallel analysis makes
    # those of a pass whose chunks are all in while its workers analyse the others (so
    # they are off the serial end; a pass cut short by the screen wastes them)
    fitted: dict[int, _PassFits] = {}

    def fit_early(k: int, chans: list[int], one: _PassResult) -> None:
        if one.allan is not None:  # else too short: said below
            pf = _pass_fit_jobs(one, len(chans), prep)
            fitted[k] = replace(pf, fits=[_fit_one(job) for job in pf.jobs])

    if parallel is not None and grid is not None and total is not None and \
            reread is not None:  # R(n) is read again after a parallel pass
        from avard.core.analysis.parallel import ScreenCut, ShortRead

        groups = parallel.groups or [chans for chans, _b, _t in passes]
        try:
            results = _parallel_passes(parallel, groups, names, rate, grid, nper, int(total),
                                       reread, options.quantiles, options.noise_id,
                                       progress, len(passes) / len(groups), all_total,
                                       on_result=fit_early)
        except ShortRead as exc:
            # the screen's cuts are gaps no plan knew of: one worker needs no plan, and
            # takes the chunks' verdicts instead of judging the record again
            log.info("%s: the parallel pass read short (%s); analysed on one worker",
                     source, exc)
            if (isinstance(exc, ScreenCut) and exc.verdicts is not None
                    and exc.block is not None and parallel.screened is not None):
                parallel.screened.judged(exc.block, exc.verdicts)
            results = []
            fitted.clear()  # of passes the screen then cut
        if any(one.n != results[0][1].n for _c, one in results):
            raise DataError(f"{source}: the passes read different sample counts "
                            f"({sorted({one.n for _c, one in results})}); the file changed "
                            "while it was analysed")
    done = 0
    with histories_passed_on():  # each pass takes over the last one's mapped history
        for chans, blocks, take in passes if not results else ():
            again = None
            if reread is not None:
                def again(j: int, chans: list[int] = chans) -> _Blocks:
                    return reread(chans[j])
            one = _one_pass(blocks, take, [names[i] for i in chans], rate, estimator, grid,
                            nper, progress, done, all_total, options.quantiles,
                            None if total is None else int(total), again, options.noise_id)
            if results and one.n != results[0][1].n:
                raise DataError(f"{source}: read {one.n} samples on one pass and "
                                f"{results[0][1].n} on another; the file changed while it "
                                "was analysed")
            done += one.n
            results.append((chans, one))
    n = results[0][1].n
    if n < 16:
        raise DataError(f"{source}: only {n} samples; the Allan variance needs a record of at "
                        "least a few hundred samples")
    todo = [k for k in range(len(results)) if k not in fitted]
    more = [_pass_fit_jobs(results[k][1], len(results[k][0]), prep) for k in todo]
    fits = iter(_fit_all([job for pf in more for job in pf.jobs],
                         parallel.workers if parallel is not None
                         and parallel.executor is None else 1))
    for k, pf in zip(todo, more, strict=True):
        fitted[k] = replace(pf, fits=[next(fits) for _ in pf.jobs])
    out: dict[str, ChannelAnalysis] = {}
    for k, (chans, one) in enumerate(results):
        pf = fitted[k]
        welch, f, spectrum, fits_k = one.welch, pf.f, pf.spectrum, pf.fits
        assert fits_k is not None
        for j, i in enumerate(chans):
            lines, job, fit = pf.lines[j], pf.jobs[j], fits_k[j]
            if isinstance(fit, str):
                raise FitError(f"{source}, channel {names[i]}: {fit}")
            if estimator == "oadev" and reread is not None:
                # a ramp claimed from an OADEV that stops at N/4 is tested against the
                # channel's TOTVAR out to T/2, read again only then (long_tau_check)
                from avard.core.analysis.long_tau_check import check_ramp

                fit = check_ramp(fit, partial(reread, i), n, rate)
            slow = slow_fit = None
            if estimator == "oadev":
                base = fit
                # a drift the time domain tells from a random walk (analysis/drift.py)
                fit = _drift(fit, job, one.means, j, partial(reread, i)
                             if reread is not None else None, n)
                if prep.find_sinusoids and one.means is not None:
                    # a slow sinusoid below the line finder's band (analysis/slow_sine.py)
                    slow, slow_fit = _slow_sine(base, fit, job, one.means, j, n)
            out[names[i]] = _channel(names[i], job, fit, lines, estimator, psd, welch, f,
                                     None if spectrum is None else spectrum[:, j], rate,
                                     corner, source, n, slow, slow_fit)
    # channels in the record's order, whatever the passes
    out = {names[i]: out[names[i]] for i in sorted(i for chans, _r in results for i in chans)}
    return Analysis(source=source, rate_hz=rate, n_samples=n, channels=out,
                    meta={**meta, "filter_corner_hz": corner}, estimator=estimator, info=info)


def _drift(fit: Any, job: _FitJob, means: BlockMeans | BlockSumsPart | None, j: int,
           again: Callable[[], _Blocks] | None, n: int) -> Any:
    """``fit``, or it with the drift the time domain finds as a resolved ramp, of one
    channel: the block means the pass carried (``means``, column ``j``; a parallel pass's
    chunks keep them too), or else the channel read again (``again``)."""
    from avard.core.analysis.drift import resolve_drift

    b = means.block if means is not None else drift_block(n)
    if means is not None:
        yb = means.longest()[:, j]
    elif again is not None:
        one = BlockMeans(1, b)
        for accel, segment_end in again():
            one.update(accel)
            if segment_end:
                one.gap()
        yb = one.longest()[:, 0]
    else:
        return fit
    rate = float(job.allan.rate_hz)
    return resolve_drift(fit, job.allan, yb, b / rate, _refit(job))[0]


def _refit(job: _FitJob) -> Callable[..., Any]:
    """The channel's own fit on an AVAR less a resolved part (``fit_noise`` with the job's
    arguments, and those the caller adds: terms, added_cov)."""
    from avard.core.model.fit import fit_noise

    def refit(less: Any, **kw: Any) -> Any:
        return fit_noise(less, filter_corner_hz=job.corner, extra=job.extra,
                         check_filter=job.check_filter, **{**job.kw, **kw})
    return refit


def _slow_sine(base: Any, fit: Any, job: _FitJob, means: BlockMeans | BlockSumsPart, j: int,
               n: int) -> tuple[Any, Any]:
    """The slow-sinusoid search on one channel's block means (``means``, column ``j``)
    against its AVAR fit ``base``, and the fit with what it resolves, which sets the printed
    EDF (``fit``: the channel's, a drift resolved or not; ``slow_sine.resolve_slow_sine``)."""
    from avard.core.analysis.slow_sine import resolve_slow_sine, welch_top_hz

    rate = float(job.allan.rate_hz)
    lines = [float(e["params"]["frequency_hz"]) for e in job.extra
             if e.get("cause") == "sinusoid"]
    return resolve_slow_sine(base, fit, job.allan, means.longest()[:, j], means.block / rate,
                             welch_top_hz(n, rate), _refit(job), lines)


def _channel(name: str, job: _FitJob, fit: Any, lines: list[dict[str, float]],
             estimator: str, psd: bool, welch: WelchAccumulator | None,
             f: NDArray[np.float64] | None, spectrum: NDArray[np.float64] | None,
             rate: float, corner: float | None, source: str, n: int,
             slow: Any = None, slow_fit: Any = None) -> ChannelAnalysis:
    """One channel's analysis from its fit, with its PSD when asked for; ``slow``: the
    slow-sinusoid search, ``slow_fit`` the fit with what it resolved, which sets the printed
    EDF (``fit`` stays the base model explain reads)."""
    chan_psd = None
    if psd:
        if welch is None or spectrum is None or f is None or welch.n_seg < 1:
            raise DataError(f"{source}: {n} samples are too few for a spectrum (--psd "
                            "needs at least 1024)")
        from avard.core.analysis.psd import channel_psd, white_density

        chan_psd = channel_psd(f, spectrum, welch.n_seg, lines=lines)
        chan_psd.white = white_density(chan_psd, fit, rate, filter_corner_hz=corner)
    # the printed interval: the part of the AVAR the fit's resolved deterministic terms
    # hold does not scatter (signal_edf.py; unchanged on noise alone)
    return ChannelAnalysis(name, with_signal_edf(job.allan, fit if slow_fit is None
                                                 else slow_fit),
                           fit, lines, estimator, chan_psd, slow, slow_fit)


@dataclass(frozen=True)
class _FitPrep:
    """What every channel's lines and fit take from the options and the record."""

    corner: float | None
    auto_corner: bool
    kw: dict[str, float]
    find_sinusoids: bool


@dataclass(frozen=True)
class _PassFits:
    """A pass's spectrum and, per channel, the lines found in it, its fit job and its fit
    (or the ``FitError``'s message; None until fitted)."""

    f: NDArray[np.float64] | None
    spectrum: NDArray[np.float64] | None
    lines: list[list[dict[str, float]]]
    jobs: list[_FitJob]
    fits: list[Any] | None = None


def _pass_fit_jobs(one: _PassResult, n_channels: int, prep: _FitPrep) -> _PassFits:
    """A pass's spectrum, the lines in each channel's and the channels' fit jobs."""
    welch = one.welch
    f, spectrum = welch.result() if welch is not None else (None, None)
    lines: list[list[dict[str, float]]] = []
    for j in range(n_channels):
        lines.append(find_lines(f, spectrum[:, j], welch.n_seg)
                     if welch is not None and spectrum is not None and prep.find_sinusoids
                     else [])
    jobs = [_FitJob(one.allan.channel(j), prep.corner,
                    [{"cause": "sinusoid", "params": ln} for ln in line_components(lines[j])],
                    prep.auto_corner, prep.kw) for j in range(n_channels)]
    return _PassFits(f, spectrum, lines, jobs)
