"""The live separation: each co-located sensor's own noise and the common input, as the run goes.

The multi-sensor service (one reader per bus, each sensor on its own sample index with its own
fitted time base) hands this module what it reads, through two small typed seams:

* :class:`SensorBlock` — one sensor's new samples, index-contiguous, in m/s², with a
  :class:`SensorClock` (that sensor's fitted time base at that moment), pushed into an
  :class:`Aligner`;
* :class:`AlignedBlock` — what the aligner gives: N sensors' samples on common ticks (the first
  sensor's index), each with its own index at that tick (−1: it has none), which
  :meth:`SeparationStage.feed` takes.

Alignment is by index and fitted time base: tick k of the reference sensor happens at its
t(k); sensor s's sample there is the one whose own t(i) is nearest. The offset is kept while
it stays within ¾ of a sample of the fitted one (so fit jitter does not toggle it); when the
clocks' drift moves it further, the index jumps by one — a slip, which, like a lost sample,
is a gap for every pair holding that sensor (core/allan/cross.py: no difference straddles it).

:class:`SeparationStage` keeps one :class:`~avard.core.allan.cross.CrossAllan` per pair of its
2 or 3 sensors (kilobytes each) and computes the separation on demand with the one estimator
(:func:`avard.core.analysis.separate.separate_moments`); it is published as the
``separation`` field of the ``avar`` record (:meth:`SeparationStage.record_fields`), which
:func:`avard.daemon.service.snapshots.separation_of` decodes for every reader.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from avard.core.allan.cross import CrossAllan
from avard.core.analysis.separate import PAIRS, Separation, separation_of_pairs
from avard.core.errors import DataError, FormatError
from numpy.typing import NDArray

log = logging.getLogger("avard.daemon.service")

#: How far (in samples) the fitted offset between two sensors may move from the one in use
#: before the alignment slips by one sample; above ½ so that fit jitter at a half-sample
#: offset does not toggle it.
SLIP_SAMPLES = 0.75
#: Seconds of sample time between two computations of the live separation, at least: its
#: intervals (separate.covariance_interval, χ² quantiles for every τ, part and axis) cost
#: many times an Allan snapshot, more than seconds of one sensor's whole service
#: (docs/service.md has the figure); in between, the ``avar`` records carry the last one
#: computed (its ``n_samples`` says how much data it covers).
SEPARATION_INTERVAL_S = 60.0
#: ... and once the run is long, when it has grown by this fraction since the last (a
#: separation of a day moves little in a minute) ...
SEPARATION_GROWTH = 0.1
#: ... but at most this many seconds of sample time apart (the page stays live).
SEPARATION_MAX_INTERVAL_S = 600.0
#: Aligned rows collected before the pair accumulators take them (see SeparationStage.feed).
FLUSH_ROWS = 2048
#: Seconds of the reference sensor's samples the aligner waits for a late sensor before it
#: takes that sensor's samples as missing (a reader stuck on a dead bus must not grow the
#: others' buffers without bound).
MAX_WAIT_S = 30.0


class FittedTime(Protocol):
    """What a sensor's time base offers (daemon/hw/timebase.TimeBase has both)."""

    def time_of(self, index: float) -> float: ...

    @property
    def period_s(self) -> float: ...


@dataclass(frozen=True)
class SensorClock:
    """A sensor's fitted time base at one moment: sample ``i_ref`` was measured at
    ``t_ref_s`` (CLOCK_MONOTONIC, s) and samples are ``period_s`` apart."""

    i_ref: int
    t_ref_s: float
    period_s: float

    @classmethod
    def of(cls, timebase: FittedTime, index: int) -> SensorClock:
        """The clock of a running time base (hw TimeBase), read at ``index``."""
        return cls(int(index), float(timebase.time_of(index)), float(timebase.period_s))

    def time_of(self, index: NDArray[np.float64] | float) -> NDArray[np.float64] | float:
        return self.t_ref_s + (np.asarray(index, dtype=np.float64) - self.i_ref) * \
            self.period_s

    def index_at(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.i_ref + (np.asarray(t, dtype=np.float64) - self.t_ref_s) / self.period_s


@dataclass(frozen=True)
class SensorBlock:
    """One sensor's new samples as its reader delivered them: indices ``i0`` … ``i0 + n − 1``
    on the sensor's own index (consecutive; a loss is a later ``i0``), ``accel`` (n, A) m/s²."""

    name: str
    i0: int
    accel: NDArray[np.float64]


@dataclass(frozen=True)
class AlignedBlock:
    """N sensors on common ticks: ``index`` (N, n) each sensor's own sample index at each
    tick (−1 where it has none: lost, not yet started, or dropped by a slip), ``accel``
    (N, n, A) m/s² (rows where the index is −1 are meaningless)."""

    names: tuple[str, ...]
    index: NDArray[np.int64]
    accel: NDArray[np.float64]

    def __post_init__(self) -> None:
        n_s = len(self.names)
        if self.index.ndim != 2 or self.index.shape[0] != n_s or self.accel.ndim != 3 \
                or self.accel.shape[:2] != self.index.shape:
            raise DataError(f"an aligned block holds (N, n) indices and (N, n, A) samples "
                            f"for its {n_s} sensors, not {self.index.shape} and "
                            f"{self.accel.shape}")


class _Pending:
    """One sensor's samples not yet aligned: their indices, samples and how far it reported."""

    __slots__ = ("accel", "clock", "end", "index", "last")

    def __init__(self) -> None:
        self.index = np.zeros(0, dtype=np.int64)
        self.accel: NDArray[np.float64] | None = None
        self.end: int | None = None          # one past the newest index reported
        self.clock: SensorClock | None = None
        self.last: int | None = None         # the index given to the previous tick


class Aligner:
    """Per-sensor blocks in, :class:`AlignedBlock` out, on the first sensor's ticks (see the
    module docstring). ``push`` each reader's blocks with that sensor's clock; ``pop`` gives
    every tick that every sensor has reported up to (or that waited longer than
    ``max_wait_s``). Readers on different buses may push from their own threads while one
    consumer pops: both take the aligner's lock."""

    def __init__(self, names: Sequence[str], *, max_wait_s: float = MAX_WAIT_S) -> None:
        if len(names) < 2 or len(set(names)) != len(names):
            raise DataError(f"aligning needs two or more distinct sensors, not {list(names)}")
        self.names = tuple(names)
        self.max_wait_s = float(max_wait_s)
        self._p = {n: _Pending() for n in self.names}
        self._next: int | None = None          # the next reference tick to emit
        self.slips = {n: 0 for n in self.names}
        self._lock = threading.Lock()

    def push(self, block: SensorBlock, clock: SensorClock) -> None:
        with self._lock:
            self._push(block, clock)

    def pop(self, *, final: bool = False) -> AlignedBlock | None:
        """The ticks every sensor has reported up to; ``final`` (at stop, every sample
        pushed): every tick whose followed sample of each sensor is in, the rule
        core/analysis/separate.aligned_runs applies to a recorded run's end."""
        with self._lock:
            return self._pop(final)

    def _push(self, block: SensorBlock, clock: SensorClock) -> None:
        p = self._p.get(block.name)
        if p is None:
            raise DataError(f"sensor {block.name!r} is not one of {list(self.names)}")
        a = np.asarray(block.accel, dtype=np.float64)
        if a.ndim != 2:
            raise DataError(f"{block.name}: a block is (n, A) samples, not {a.shape}")
        if p.end is not None and block.i0 < p.end:
            raise DataError(f"{block.name}: block at index {block.i0} repeats indices before "
                            f"{p.end}; each sample is pushed once, in order")
        if not (math.isfinite(clock.period_s) and clock.period_s > 0):
            raise DataError(f"{block.name}: the fitted period {clock.period_s} s is not one")
        p.clock = clock
        n = a.shape[0]
        if n:
            p.index = np.concatenate([p.index, block.i0 + np.arange(n, dtype=np.int64)])
            p.accel = a.copy() if p.accel is None else np.concatenate([p.accel, a])
        p.end = block.i0 + n
        if self._next is None and block.name == self.names[0] and n:
            self._next = block.i0

    def _pop(self, final: bool = False) -> AlignedBlock | None:
        ref = self._p[self.names[0]]
        if self._next is None or ref.end is None or ref.clock is None:
            return None
        ticks = np.arange(self._next, ref.end, dtype=np.int64)
        if not len(ticks):
            return None
        t = np.asarray(ref.clock.time_of(ticks.astype(np.float64)))
        limit = len(ticks)
        mapped: dict[str, NDArray[np.float64]] = {}
        for name in self.names[1:]:
            p = self._p[name]
            if p.clock is None or p.end is None:
                limit = 0
                continue
            x = p.clock.index_at(t)
            mapped[name] = x
            if final:     # every sample is reported: a tick is whole if its partner is in
                past = np.flatnonzero(self._follow(name, x, commit=False) >= p.end)
                limit = min(limit, int(past[0]) if len(past) else len(x))
            else:         # a followed index is within SLIP_SAMPLES of x: below end − 1 it
                limit = min(limit, int(np.searchsorted(x, p.end - 1.0)))  # is reported
        wait = int(self.max_wait_s / ref.clock.period_s)
        forced = limit < len(ticks) - wait
        if forced:        # a late sensor's ticks are taken as missing for it
            limit = len(ticks) - wait
        if limit <= 0:
            return None
        ticks = ticks[:limit]
        index = np.full((len(self.names), limit), -1, dtype=np.int64)
        accel_dim = next((q.accel.shape[1] for q in self._p.values() if q.accel is not None),
                         3)
        accel = np.zeros((len(self.names), limit, accel_dim))
        for s, name in enumerate(self.names):
            p = self._p[name]
            want = ticks if s == 0 else (self._follow(name, mapped[name][:limit])
                                         if name in mapped else None)
            if want is None:
                continue
            pos = np.searchsorted(p.index, want)
            ok = pos < len(p.index)
            ok[ok] = p.index[pos[ok]] == want[ok]
            index[s, ok] = want[ok]
            if p.accel is not None:
                accel[s, ok] = p.accel[pos[ok]]
            # drop what no later tick can take
            drop = int(np.searchsorted(p.index, want[-1] + 1))
            p.index = p.index[drop:]
            p.accel = None if p.accel is None or drop >= len(p.accel) else p.accel[drop:]
        self._next = int(ticks[-1]) + 1
        return AlignedBlock(self.names, index, accel)

    def _follow(self, name: str, x: NDArray[np.float64], *,
                commit: bool = True) -> NDArray[np.int64]:
        """Sensor indices for fitted positions ``x``: each the previous one plus one while that
        stays within :data:`SLIP_SAMPLES` of the fit, else the nearest (a slip); ``commit``
        False: only look (the position and the slips count stay)."""
        p = self._p[name]
        out = np.empty(len(x), dtype=np.int64)
        k = 0
        prev = p.last
        while k < len(x):
            if prev is None or abs(x[k] - (prev + 1)) > SLIP_SAMPLES:
                if prev is not None and commit:
                    self.slips[name] += 1
                prev = int(np.rint(x[k])) - 1
            run = prev + 1 + np.arange(len(x) - k, dtype=np.int64)
            bad = np.flatnonzero(np.abs(x[k:] - run) > SLIP_SAMPLES)
            stop = len(x) - k if not len(bad) else int(bad[0])
            out[k:k + stop] = run[:stop]
            k += stop
            prev = int(out[k - 1])
        if commit:
            p.last = prev
        return out


class SeparationStage:
    """The live separation of 2 or 3 co-located sensors (see the module docstring)."""

    def __init__(self, sensors: Sequence[str], rate_hz: float, *,
                 axes: Sequence[str] = ("x", "y", "z"), ci: float = 0.683,
                 overlap: int = 8, interval_s: float = SEPARATION_INTERVAL_S) -> None:
        if len(sensors) not in PAIRS or len(set(sensors)) != len(sensors):
            raise DataError(f"the live separation takes 2 or 3 distinct co-located sensors, "
                            f"not {list(sensors)}")
        self.sensors = tuple(sensors)
        self.axes = tuple(axes)
        self.ci = float(ci)
        self.rate_hz = float(rate_hz)
        self.interval_s = float(interval_s)
        self._cached: dict[str, Any] = {}
        self._cached_at: int | None = None     # n_samples when it was computed
        self.computed = 0                      # separations computed (for tests, status)
        self._pending: list[tuple[NDArray[np.int64], NDArray[np.float64]]] = []
        self._pending_rows = 0
        self.pairs = {p: CrossAllan(rate_hz, axes=self.axes, overlap=overlap,
                                    sensors=(self.sensors[p[0]], self.sensors[p[1]]))
                      for p in PAIRS[len(self.sensors)]}

    def feed(self, block: AlignedBlock) -> None:
        """Add an aligned block (it may hold other sensors too). Rows are collected up to
        :data:`FLUSH_ROWS` before the pairs take them (a drain is a few dozen rows; numpy's
        per-call cost would dominate); every result flushes first, so none depends on it."""
        try:
            rows = [block.names.index(n) for n in self.sensors]
        except ValueError:
            raise DataError(f"an aligned block of {list(block.names)} lacks one of "
                            f"{list(self.sensors)}") from None
        if block.accel.shape[2] != len(self.axes):
            raise DataError(f"an aligned block has {block.accel.shape[2]} axes, the "
                            f"separation {len(self.axes)}")
        self._pending.append((block.index[rows], block.accel[rows]))
        self._pending_rows += block.index.shape[1]
        if self._pending_rows >= FLUSH_ROWS:
            self.flush()

    def flush(self) -> None:
        """Hand the collected rows to the pair accumulators (results do so themselves)."""
        if not self._pending:
            return
        index = np.concatenate([i for i, _ in self._pending], axis=1)
        accel = np.concatenate([a for _, a in self._pending], axis=1)
        self._pending, self._pending_rows = [], 0
        for (i, j), acc in self.pairs.items():
            acc.feed(index[i], index[j], accel[i], accel[j])

    @property
    def n_samples(self) -> int:
        """Aligned samples of the pair that has the fewest."""
        self.flush()
        return min(acc.n_samples for acc in self.pairs.values())

    def separation(self, rate_hz: float | None = None) -> Separation | None:
        """The separation of everything fed so far, τ labelled with ``rate_hz`` (the fitted
        rate; default the nominal); None while no τ has enough averages in every pair."""
        rate = float(rate_hz) if rate_hz else self.rate_hz
        self.flush()
        segments = {f"{acc.sensors[0]}-{acc.sensors[1]}": acc.n_segments
                    for acc in self.pairs.values()}
        try:
            return separation_of_pairs(
                self.pairs, self.sensors, rate, self.ci,
                notes=("live: partially overlapping Allan moments (stride m/8 above m = 8), "
                       "pairs aligned by index and fitted time base; segments per pair "
                       + ", ".join(f"{k} {v}" for k, v in segments.items()),))
        except DataError as exc:
            log.debug("no live separation yet: %s", exc)
            return None

    def record_fields(self, rate_hz: float | None = None, *,
                      force: bool = False) -> dict[str, Any]:
        """What the ``avar`` record carries: {"separation": map} once there is one, else {}.
        Computed again once ``interval_s`` of samples (at the nominal rate) came in since
        the last computation, or :data:`SEPARATION_GROWTH` of what it covered if that is
        more (at most :data:`SEPARATION_MAX_INTERVAL_S`), else the last one (counted by
        sample, not wall clock); ``force``: computed now unless nothing came in since (the
        run's last record)."""
        n = self.n_samples
        step = max(self.interval_s * self.rate_hz,
                   min(SEPARATION_GROWTH * (self._cached_at or 0),
                       SEPARATION_MAX_INTERVAL_S * self.rate_hz))
        due = self._cached_at is None or n - self._cached_at >= step \
            or (force and n != self._cached_at)
        if due and n:
            sep = self.separation(rate_hz)
            self.computed += 1
            if sep is not None:
                self._cached, self._cached_at = {"separation": sep.to_dict()}, n
        return dict(self._cached)

    def state(self) -> dict[str, Any]:
        """The pairs' states (msgpack-able), for the checkpoint."""
        self.flush()
        return {"kind": "separation_stage", "v": 1, "sensors": list(self.sensors),
                "ci": self.ci, "pairs": [acc.state() for acc in self.pairs.values()]}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> SeparationStage:
        try:
            if state.get("kind") != "separation_stage" or state.get("v") != 1:
                raise FormatError("not a version-1 separation stage state")
            pairs = [CrossAllan.from_state(s) for s in state["pairs"]]
            self = cls(list(state["sensors"]), pairs[0].rate_hz, axes=pairs[0].axes,
                       ci=float(state["ci"]))
            if len(pairs) != len(self.pairs):
                raise FormatError(f"{len(pairs)} pair states for {len(self.pairs)} pairs")
            self.pairs = dict(zip(self.pairs, pairs, strict=True))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise FormatError(f"separation stage state is malformed: {exc}") from exc
        return self
