"""Fully overlapping Allan variance (OADEV as Stable32 and allantools define it), streamed.

NIST SP 1065 eq. 12 in the phase form of ``avard.core.allan.deviations``: with X the running
sum of the
rate samples y (X_0 = 0, X_i = Σ_{k<i} y_k, kept in sample units so τ0 never multiplies),

    σ²(τ = m τ0) = Σ_{i=0}^{N−2m} (X_{i+2m} − 2X_{i+m} + X_i)² / (2 m² (N − 2m + 1)),

every i, at every m of the grid. A difference only ever reaches 2m samples back, so the
accumulator keeps a ring of the last 2·m_max + P running-sum points per channel (P the piece
processed at once), never the record: memory O(τ_max), whatever the duration. Integer counts
are summed in int64 and every difference is exact; float samples are summed in float64 after
subtracting the segment's first sample (a constant moves X by a straight line, which no second
difference sees, and it keeps the sums small).

Per τ it keeps n and Σ D² per channel (with ``covariance=True`` Σ D Dᵀ, C×C, the Allan
covariance, as the batch estimator), and the non-overlapping m-averages of the segment go to
a ``noise_id.Lag1Ladder``: the noise exponent alpha is identified as Stable32 does it, on the
same data for every Allan estimator at that τ.
``result()`` is an ``AllanResult`` of kind "oavar", equal to ``allan.allan_variance(y, rate,
ms / rate, kind="oavar")`` to rounding of the final sums, for any split into blocks.

The arithmetic: with the compiled loop (``kernels``, built at install where a compiler is
present) each channel's Σ D² at a τ is one pass over the three spans of the ring, D never
stored (and R(n)'s moving sums fused into it while they are kept). Without it, or for counts
(int64, exact) and the covariance, numpy element-wise work on cache-sized pieces (the ring is
channel-major, so each channel's differences are contiguous rows) and one dot product per
channel (pair) per piece and τ; no BLAS thread pool is involved in anything larger than a
vector. For m shorter than the piece, D comes from the window sums W_j = X_{j+m} − X_j of the
piece's span as D_i = W_{i+m} − W_i (two passes over the data per τ instead of three); longer
m read the three points straight from the ring. All paths give exact differences for counts
and agree to the rounding of the float64 sums (``tests/core/test_overlapping.py`` runs one
record through both numpy paths, ``tests/core/test_kernels.py`` the compiled against numpy).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from avard.core.allan import kernels
from avard.core.allan.deviations import (
    AllanResult,
    alphas_from_ladders,
    checked_block,
    result_from_sums,
)
from avard.core.allan.noise_id import (
    MIN_POINTS,
    Lag1Ladder,
    RnSums,
    check_noise_id,
    row_products,
)
from avard.core.allan.scratch import mapped_zeros, scratch
from avard.core.blas import one_blas_thread
from avard.core.errors import DataError
from numpy.typing import ArrayLike, NDArray

__all__ = ["OadevPart", "OverlappingAllan"]

# New samples processed at once. Larger pieces mean fewer numpy calls per τ (the Python cost
# of a call is fixed); at 2**16 the temporaries (a few × PIECE × C doubles) still sit in the
# 1 MiB L2 for one channel, and the kernel measured 1.5 ns per sample and τ against 3.1 ns at
# 2**13 and 1.6 ns at 2**17 (one float64 channel, 2**22 samples, 21 octaves).
PIECE = 1 << 16
# A chunk of a parallel analysis keeps this many averages of each τ past its end: the ladder's
# sums of products reach that far (order-2 differences of adjacent pairs: four averages).
LADDER_REACH = 4
# Averages pushed to a noise-identification ladder at once. A push makes a few arrays of the
# batch's size and reads each several times; at 2**15 doubles (256 KiB) they stay in the
# L2 cache (the ladder's referenced copy is a reused buffer: fresh ones were page-faulted in
# on every push, which made 2**15 and 2**16 slower than 2**14 before); measured with the
# compiled OADEV loop: the feed and push 0.13 s at 2**15 against 0.15 s at 2**14 and 2**16
# per 5.4 M samples × 3 channels.
LADDER_BATCH = 1 << 15
# With the compiled loop, a piece's averages at a τ go to the ladder straight from the ring
# when there are at least this many (short τ: no interval sums made, no copies); fewer wait
# in a batch as above (one push costs tens of Python operations, whatever its size).
LADDER_SPAN_MIN = 1 << 10
# Such averages wait in the ring until their span reaches this many samples (or the next
# piece would overwrite or wrap it), then go in one push: a push per piece and τ cost a 60 h
# analyze 0.2 CPU-s of Python; spans of 2**18 samples (2 MiB a channel) are still in the L3
# cache when the loop reads them.
LADDER_SPAN = 1 << 18


@dataclass(frozen=True)
class OadevPart:
    """What one chunk of a record contributes to its OADEV: the sums of the differences
    that start in the chunk (``n``, Σ D Dᵀ per τ) and the noise-identification ladders of
    the averages that start in it (their products with the next chunk's first averages
    included), as ``OverlappingAllan(own_until=…).part()`` gives them.

    Parts of adjacent chunks add (``+``, associative): the parts of a record's chunks add up
    to the part of the whole record, to the rounding of the sums, and
    ``OverlappingAllan.from_part`` turns a sum of parts into an accumulator whose
    ``result()`` is the one-pass result. Small: no history, a few numbers per τ."""

    ms: NDArray[np.int64]
    n: NDArray[np.int64]
    s2: NDArray[np.float64]
    ladders: tuple[Lag1Ladder, ...]
    n_samples: int

    def __add__(self, other: OadevPart) -> OadevPart:
        if not np.array_equal(self.ms, other.ms) or self.s2.shape != other.s2.shape:
            raise DataError("parts of different τ grids or channels do not add")
        ladders = []
        for a, b in zip(self.ladders, other.ladders, strict=True):
            lad = copy.deepcopy(a)
            lad.add(b)
            ladders.append(lad)
        return OadevPart(self.ms, self.n + other.n, self.s2 + other.s2, tuple(ladders),
                         self.n_samples + other.n_samples)


class OverlappingAllan:
    """Streaming fully overlapping Allan variance of C channels at a fixed grid of m.

    Parameters
    ----------
    n_channels : int
        Number of channels C.
    rate_hz : float
        Sample rate; τ = m / rate_hz.
    ms : sequence of int
        Averaging factors (≥ 1). The largest fixes the memory: a ring of 2·max(ms) + piece
        points per channel (8 bytes each).
    names : channel names, kept in the result.
    covariance : bool
        Also accumulate the cross-channel sums: the result's ``cov`` (the Allan covariance,
        AVAR of any weighted sum of channels). Off by default: for C channels it costs
        (C + 1)/2 times the arithmetic of the variances alone.
    piece : int
        New samples processed at once (default ``PIECE``). τ with m below the piece take the
        window-sum path, longer ones the three-cursor path; both give the same sums (a test
        runs one record through small and large pieces).
    n_total : int, optional
        The record's length, when known: R(n)'s sums are kept only at the τ where it leaves
        fewer than ``MIN_POINTS`` averages (B1's range).
    defer_rn : bool
        With ``n_total``: keep no R(n) sums at all; ``rn_needed()`` says after the last
        block where the identification needs them, and ``set_rn`` supplies them. A
        ``result()`` before that takes flicker PM where B1 says PM (as without R(n)).
    """

    def __init__(self, n_channels: int, rate_hz: float, ms: Sequence[int] | NDArray,
                 *, names: Sequence[str] | None = None, covariance: bool = False,
                 piece: int = PIECE, n_total: int | None = None,
                 defer_rn: bool = False, own_from: int = 0,
                 own_until: int | None = None) -> None:
        if not isinstance(n_channels, int | np.integer) or n_channels < 1:
            raise DataError(f"n_channels={n_channels!r} must be a positive integer")
        if not (isinstance(rate_hz, int | float | np.integer | np.floating)
                and math.isfinite(float(rate_hz)) and float(rate_hz) > 0):
            raise DataError(f"rate_hz={rate_hz!r} must be a finite sample rate > 0 Hz")
        grid = np.unique(np.asarray(ms, dtype=np.int64))
        if grid.size == 0 or grid[0] < 1:
            raise DataError("ms must be one or more averaging factors >= 1")
        if names is not None and len(names) != n_channels:
            raise DataError(f"{len(names)} names given for {n_channels} channels")
        self.n_channels = int(n_channels)
        self.rate_hz = float(rate_hz)
        self.ms = grid
        self.names = list(names) if names is not None else [f"ch{i}" for i in range(n_channels)]
        if not isinstance(piece, int | np.integer) or piece < 1:
            raise DataError(f"piece={piece!r} must be a positive number of samples")
        c = self.n_channels
        self._piece = int(piece)
        self._cap = 2 * int(grid[-1]) + self._piece
        self._integer: bool | None = None
        self._ring: NDArray | None = None  # allocated with the first block's dtype
        self._n = np.zeros(grid.size, dtype=np.int64)
        self._s2 = np.zeros((grid.size, c, c))
        self.covariance = bool(covariance)
        self._ladders = [Lag1Ladder(c, dmax=2, cross=self.covariance) for _ in grid]
        # R(n) = MVAR/AVAR sums, kept only while a τ has < MIN_POINTS averages (B1's range).
        # ``n_total`` (the record's length, when the caller knows it, as analyze of a file
        # does) leaves them out from the start where a gapless record of that length holds
        # ≥ MIN_POINTS averages: R(n) of the long τ alone is kept. Fed all the way to the τ
        # that end in B1's range, they cost a 60 h analyze a third more CPU and 56 MB for
        # sums it would discard (measured with `python -m benchmarks analyze --hours 60`).
        # A gap then can leave such a τ short of MIN_POINTS averages without R(n): it is
        # identified by B1 alone (flicker PM where B1 says PM), as the cascade does.
        #
        # ``defer_rn=True`` (with ``n_total``) keeps none at all: R(n) is read only where B1
        # says PM at a τ that keeps its own α, which on an accelerometer's records is rare
        # (B1 of 8–29 averages of FM noise saying PM by chance), so the caller that can
        # read the record again (analyze of a file) asks ``rn_needed()``
        # after the last block and supplies those few sums from a pass of their own
        # (``set_rn``). That spares every such analyze their cost, 56 MB per 60 h axis and
        # 0.2 CPU-s for three, and lets two axes share a pass.
        if n_total is not None and (not isinstance(n_total, int | np.integer) or n_total < 0):
            raise DataError(f"n_total={n_total!r} must be a sample count >= 0")
        if defer_rn and n_total is None:
            raise DataError("defer_rn needs n_total: which τ end in B1's range depends on it")
        self._rn_deferred = [bool(defer_rn) and int(n_total or 0) // int(m) < MIN_POINTS
                             for m in grid]
        self._rn: list[RnSums | None] = [
            RnSums(c, int(m)) if (n_total is None or int(n_total) // int(m) < MIN_POINTS)
            and not deferred else None for m, deferred in zip(grid, self._rn_deferred,
                                                              strict=True)]
        # averages waiting for their ladder: pushed in batches, since at long τ each piece
        # brings only a few and a push costs tens of numpy calls whatever its size
        self._pending: list[list[NDArray]] = [[] for _ in grid]
        self._pending_n = [0] * grid.size
        # or, with the compiled loop, the first and last end point (q) of the averages that
        # wait in the ring (``_ring_take``); never both at once for a τ
        self._due: list[tuple[int, int] | None] = [None] * grid.size
        self.n_samples = 0
        self.n_segments = 0
        if own_until is not None and (not isinstance(own_until, int | np.integer)
                                      or own_until < 0):
            raise DataError(f"own_until={own_until!r} must be a sample index >= 0")
        self._own_until = None if own_until is None else int(own_until)
        if not isinstance(own_from, int | np.integer) or own_from < 0:
            raise DataError(f"own_from={own_from!r} must be a sample index >= 0")
        self._own_from = int(own_from)
        # the averages at and past ``own_until`` (the next chunk's), kept to be taken away
        self._past = ([Lag1Ladder(c, dmax=2, cross=self.covariance) for _ in grid]
                      if own_until is not None else None)
        self._seg_first = 0  # sample index (in this stream) of the open segment's first sample
        self._closed = False  # made by ``from_part``: sums only, no history
        self._reset_segment()

    # ------------------------------------------------------------------------ input
    def _flush_ladders(self) -> None:
        for k in range(len(self._ladders)):
            self._flush_ladder(k)

    def _flush_ladder(self, k: int) -> None:
        """Push τ k's waiting averages to its ladder."""
        if self._due[k] is not None:
            self._push_due(k)
        if self._pending[k]:
            # m × the segment's first sample (removed from the phase) added back: every
            # segment's averages on one scale for the identification's pooled mean
            assert self._offset is not None
            self._ladders[k].push_rows(np.concatenate(self._pending[k], axis=1),
                                       int(self.ms[k]) * self._offset)
            self._pending[k] = []
            self._pending_n[k] = 0

    def _reset_segment(self) -> None:
        self._flush_ladders()
        self._pos = 0  # phase points of this segment written so far (X_0 included)
        self._offset: NDArray | None = None
        self._carry: NDArray | None = None
        for lad in self._ladders:
            lad.gap()
        for lad in self._past or ():
            lad.gap()
        for r in self._rn:
            if r is not None:
                r.gap()

    def _check_block(self, block: ArrayLike) -> NDArray:
        first = self._integer is None
        a, self._integer = checked_block(block, self.n_channels, self._integer)
        if first and self._integer is not None:
            # channel-major: each channel's running sum is a contiguous row
            self._ring = mapped_zeros((self.n_channels, self._cap),
                                      np.int64 if self._integer else np.float64)
        return a.astype(np.int64 if self._integer else np.float64, copy=False)

    @one_blas_thread  # long dot products would wake OpenBLAS's pool (core/blas.py)
    def update(self, block: ArrayLike) -> None:
        """Add a block of samples, (n, C) or (n,) for one channel; any n ≥ 0."""
        if self._closed:
            raise DataError("this accumulator was made from parts (from_part) and takes no "
                            "samples")
        a = self._check_block(block)
        i = 0
        while i < a.shape[0]:
            # a piece ends where the chunk's own samples begin: the ones before only advance
            # the running sum
            end = i + self._piece
            if self.n_samples < self._own_from:
                end = min(end, i + self._own_from - self.n_samples)
            self._process(a[i:end])
            self.n_samples += min(end, a.shape[0]) - i
            i = end

    def gap(self) -> None:
        """End the current segment: later differences never reach back across this point."""
        self._reset_segment()

    # ------------------------------------------------------------------------ kernel
    def _span(self, start: int, length: int) -> NDArray:
        """Phase points (C, length) of segment positions [start, start + length)."""
        assert self._ring is not None
        i = start % self._cap
        if i + length <= self._cap:
            return self._ring[:, i:i + length]
        return np.concatenate([self._ring[:, i:], self._ring[:, :i + length - self._cap]],
                              axis=1)

    def _process(self, a: NDArray) -> None:
        ring = self._ring
        assert ring is not None
        c = self.n_channels
        n = a.shape[0]
        if self._offset is None:
            self._offset = a[0].copy()
            self._carry = np.zeros(c, dtype=ring.dtype)
            ring[:, 0] = 0  # X_0
            self._pos = 1
            self.n_segments += 1
            self._seg_first = self.n_samples
        p0 = self._pos  # segment position of the first new phase point
        i = p0 % self._cap
        kern = kernels.compiled() if ring.dtype == np.float64 else None
        assert self._carry is not None
        if kern is not None:
            # the compiled loop reads each column once and writes its running sum straight
            # into the ring (two stretches where the piece wraps), the same bits as cumsum
            first = min(n, self._cap - i)
            for ch in range(c):
                off = float(self._offset[ch])
                carry = kern.running_sum(a[:first, ch], off, float(self._carry[ch]),
                                         ring[ch, i:i + first])
                if first < n:
                    carry = kern.running_sum(a[first:, ch], off, carry, ring[ch, :n - first])
                self._carry[ch] = carry
        elif 0 < i and i + n <= self._cap:
            # the running sum straight into the ring, after the point before it (X_{p0−1},
            # the carry): each channel's row in one transposing copy and one cumsum
            span = ring[:, i - 1:i + n]
            np.subtract(a.T, self._offset[:, None], out=span[:, 1:], casting="unsafe")
            np.cumsum(span, axis=1, out=span)
            self._carry = span[:, -1].copy()
        else:  # the piece wraps round the ring: through reused work rows
            work = scratch("oadev.work", c, n + 1, ring.dtype)
            work[:, 0] = self._carry
            np.subtract(a.T, self._offset[:, None], out=work[:, 1:], casting="unsafe")
            np.cumsum(work, axis=1, out=work)
            self._carry = work[:, -1].copy()
            first = min(n, self._cap - i)
            ring[:, i:i + first] = work[:, 1:1 + first]
            ring[:, :n - first] = work[:, 1 + first:]
        self._pos = p1 = p0 + n
        if self.n_samples < self._own_from:
            return  # before a parallel chunk's own samples: the running sum only
        # D in the ring's dtype (int64: exact); window sums need up to 2·piece points
        buf = scratch("oadev.d", c, n, ring.dtype)
        window = scratch("oadev.window", c, 2 * n, ring.dtype)
        as_float = scratch("oadev.float", c, n, np.float64) if buf.dtype != np.float64 else buf
        if self.covariance:
            kern = None  # the compiled loop sums per channel: the covariance takes numpy's
        # a chunk of a parallel analysis: where the next chunk's differences begin, as a
        # segment position (D_i spans samples i … i + 2m − 1 of the segment)
        own = None if self._own_until is None else self._own_until - self._seg_first
        first = self._own_from - self._seg_first  # a chunk's first own difference
        # the compiled loop's spans (lo, m, count) of every τ, summed in one call after the
        # loop (nothing in it changes the ring or the sums)
        spans: list[tuple[int, int, int]] = []
        span_k: list[int] = []
        for k, m in enumerate(self.ms.tolist()):
            lo = max(0, p0 - 2 * m, first)  # first new difference D_lo (its last point ≥ p0)
            hi = p1 - 2 * m  # differences D_i, i < hi
            if own is not None:
                hi = min(hi, own)
            if hi > lo:
                count = hi - lo
                rk = self._rn[k]
                if rk is not None and self._ladders[k].count() + self._waiting(k) >= MIN_POINTS:
                    # R(n) matters only while B1 decides (< MIN_POINTS averages)
                    rk = self._rn[k] = None
                self._n[k] += count
                if kern is not None and rk is None:
                    spans.append((lo, m, count))
                    span_k.append(k)
                elif kern is not None:
                    self._compiled_sums(k, m, lo, count, kern, rk)
                else:
                    self._numpy_sums(k, m, lo, count, buf, window, as_float, rk)
            # non-overlapping m-averages (as sums X_{(j+1)m} − X_{jm}) ending at new points
            q0 = max(m, -(-p0 // m) * m)
            if first > 0:
                # a chunk's averages are those that start in it: the one that straddles
                # its start (a cut off this τ's grid) is the chunk's before
                q0 = max(q0, -(-(first + m) // m) * m)
            last = q0 + ((p1 - 1 - q0) // m) * m
            if own is not None and q0 <= last:
                last = self._past_averages(k, m, own, q0, last)
            if q0 <= last:
                if kern is None or not self._ring_take(k, m, q0, last):
                    self._feed(k, self._interval_sums(m, q0, last))
            elif self._due[k] is not None:
                self._guard_due(k)  # no new average, but the next piece still moves the ring
        if spans:
            self._ring_sums(span_k, spans, kern)

    def _past_averages(self, k: int, m: int, own: int, q0: int, last: int) -> int:
        """For a chunk of a parallel analysis: the averages of τ k ending at q0 … last (step
        m) that start at the next chunk's first sample (segment position ``own``) or later
        go to ``_past`` as well, up to ``LADDER_REACH`` of them; returns the last end point
        the ladder itself takes (averages starting before ``own + LADDER_REACH·m``).
        ``part()`` takes ``_past`` away again: what remains is every sum of the averages
        whose first value starts before ``own``, those reaching past it included."""
        assert self._past is not None and self._offset is not None
        reach = own + LADDER_REACH * m  # averages starting before this are taken
        keep = min(last, (reach // m) * m)  # end points q ≤ reach: start q − m < reach
        p0 = max(q0, -(-(own + m) // m) * m)  # first end point whose start is ≥ own
        if p0 <= keep:
            self._past[k].push_rows(self._interval_sums(m, p0, keep), m * self._offset)
        return keep

    def _waiting(self, k: int) -> int:
        """Averages of τ k not yet pushed to its ladder."""
        due = self._due[k]
        return self._pending_n[k] + (0 if due is None else (due[1] - due[0]) // int(self.ms[k])
                                     + 1)

    def _due_span(self, k: int, first_q: int) -> tuple[int, int, int]:
        """(first point, its ring index, averages already pushed it begins with) of the span
        for τ k's averages from the one ending at ``first_q``: it reaches back to the last
        few pushed, whose products with the new ones the compiled loop then sums too."""
        m = int(self.ms[k])
        old = self._ladders[k].span_overlap()
        first = first_q - m - old * m
        return first, first % self._cap, old

    def _ring_take(self, k: int, m: int, q0: int, last: int) -> bool:
        """The averages ending at q0 … last (step m) wait in the ring for τ k's compiled
        ladder push (``LADDER_SPAN``), when the piece brings at least ``LADDER_SPAN_MIN``
        of them or some already wait, and their span is one unwrapped, intact stretch;
        False (they go through the batches) otherwise."""
        due = self._due[k]
        if due is None:
            if (last - q0) // m + 1 < LADDER_SPAN_MIN:
                return False
            self._flush_ladder(k)  # batched averages first, in order
            first_q = q0
        else:
            first_q = due[0]
        first, start, _old = self._due_span(k, first_q)
        if first < 0 or self._pos - first > self._cap or start + last - first >= self._cap:
            # before the segment, overwritten or wrapped round the ring: what waits goes now
            # (its span was whole at the last piece), these through the batches
            if due is not None:
                self._push_due(k)
            return False
        self._due[k] = (first_q, last)
        self._guard_due(k)
        return True

    def _guard_due(self, k: int) -> None:
        """Push τ k's waiting averages when their span is long enough, or when the next
        piece could overwrite or wrap it. Checked after every piece, with a new average at k
        or not: a short piece without one (a block's end) still moves the ring on."""
        due = self._due[k]
        assert due is not None
        first, start, _old = self._due_span(k, due[0])
        if due[1] - due[0] >= LADDER_SPAN or start + self._pos + self._piece - first >= self._cap:
            self._push_due(k)

    def _push_due(self, k: int) -> None:
        """Push the averages waiting in the ring for τ k, straight from their span."""
        due = self._due[k]
        ring = self._ring
        assert due is not None and ring is not None and self._offset is not None
        self._due[k] = None
        m = int(self.ms[k])
        first, start, old = self._due_span(k, due[0])
        self._ladders[k].push_spans(ring[:, start:start + due[1] - first + 1], m,
                                    m * self._offset, old)

    def _compiled_sums(self, k: int, m: int, lo: int, count: int, kern: Any,
                       rk: RnSums | None) -> None:
        """Σ D² of differences D_lo … D_{lo+count−1} at τ k by the compiled loop (float64,
        variances only): the three spans X_i, X_{i+m}, X_{i+2m} are read once, D stays in
        registers (and, while R(n) is kept, its moving sums too)."""
        if m < count:  # one span holds all three points: sliced, not copied three times
            x = self._span(lo, count + 2 * m)
            x0, x1, x2 = x[:, :count], x[:, m:m + count], x[:, 2 * m:2 * m + count]
        else:
            x0, x1, x2 = (self._span(lo, count), self._span(lo + m, count),
                          self._span(lo + 2 * m, count))
        s2 = self._s2[k]
        if rk is not None:
            sums = rk.push_phase(x0, x1, x2)
            for ch in range(self.n_channels):
                s2[ch, ch] += sums[ch]
            return
        for ch in range(self.n_channels):
            s2[ch, ch] += kern.sumsq(x0[ch], x1[ch], x2[ch])

    def _ring_sums(self, ks: list[int], spans: list[tuple[int, int, int]], kern: Any) -> None:
        """Σ D² of every channel at the τ ``ks``, each over its span (lo, m, count) as
        ``_compiled_sums`` takes it, by one call of the compiled loop: the same sums (the
        loop's very bits), added to the same diagonal entries."""
        assert self._ring is not None
        c = self.n_channels
        got = np.empty((len(spans), c))
        kern.sumsq_ring(self._ring, np.array(spans, dtype=np.int64), got)
        ch = np.arange(c)
        self._s2[np.array(ks)[:, None], ch, ch] += got  # s2[k, ch, ch], each entry once

    def _numpy_sums(self, k: int, m: int, lo: int, count: int, buf: NDArray, window: NDArray,
                    as_float: NDArray, rk: RnSums | None) -> None:
        """Σ D² (or Σ D Dᵀ) of differences D_lo … D_{lo+count−1} at τ k in numpy: the
        general path (counts in int64, the covariance, no compiled kernel)."""
        d = buf[:, :count]
        if m < count:
            # short τ: the window sums W_j = X_{j+m} − X_j over the span once, then
            # D_i = W_{i+m} − W_i (two passes instead of three)
            x = self._span(lo, count + 2 * m)
            w = window[:, :count + m]
            np.subtract(x[:, m:], x[:, :count + m], out=w)
            np.subtract(w[:, m:], w[:, :count], out=d)
        else:
            # long τ: the three points X_{i+2m}, X_{i+m}, X_i lie far apart in the ring
            kernels.second_differences(self._span(lo, count), self._span(lo + m, count),
                                       self._span(lo + 2 * m, count), out=d)
        if d.dtype != np.float64:
            np.copyto(as_float[:, :count], d)  # exact: differences are far below 2**53
            d = as_float[:, :count]
        if self.covariance:
            self._s2[k] += row_products(d, d, True)
        else:
            s2 = self._s2[k]
            for ch in range(self.n_channels):
                s2[ch, ch] += float(np.dot(d[ch], d[ch]))
        if rk is not None:
            rk.push(d)

    def _interval_sums(self, m: int, q0: int, last: int) -> NDArray:
        """X_q − X_{q−m} for q = q0, q0 + m, … last (C, k): the non-overlapping sums of m
        samples ending there, in a reused buffer (valid until the next call)."""
        ring = self._ring
        assert ring is not None
        k = (last - q0) // m + 1
        start = (q0 - m) % self._cap
        if start + last - q0 + m < self._cap:  # the interval ends as a strided view
            ends = ring[:, start:start + last - q0 + m + 1:m]
        else:
            # wrapped: only the ends are gathered (a span of m points would copy up to m
            # values, 32 MB at m = 2**22)
            ends = ring[:, np.arange(q0 - m, last + 1, m) % self._cap]
        sums = scratch("oadev.sums", self.n_channels, k, ring.dtype)
        np.subtract(ends[:, 1:], ends[:, :-1], out=sums)  # exact in int64 for counts
        return sums

    def _feed(self, k: int, sums: NDArray) -> None:
        """Pass averages to τ k's ladder in batches of about ``LADDER_BATCH``: at long τ each
        piece brings only a few (a push costs tens of numpy calls whatever its size), at short
        τ a piece brings more than one batch."""
        if self._pending_n[k] + sums.shape[1] < LADDER_BATCH:
            self._pending[k].append(sums.astype(np.float64, copy=True))
            self._pending_n[k] += sums.shape[1]
            return
        if self._pending[k]:
            sums = np.concatenate([*self._pending[k], sums.astype(np.float64)], axis=1)
            self._pending[k] = []
            self._pending_n[k] = 0
        # m × the segment's first sample (removed from the phase) added back: every segment's
        # averages on one scale for the identification's pooled mean (pending averages are
        # of this segment: a gap flushes them)
        assert self._offset is not None
        shift = int(self.ms[k]) * self._offset
        for i in range(0, sums.shape[1], LADDER_BATCH):
            self._ladders[k].push_rows(sums[:, i:i + LADDER_BATCH], shift)

    # ------------------------------------------------------------------------ parallel
    def part(self) -> OadevPart:
        """This accumulator's sums as an ``OadevPart``: with ``own_until``, only what the
        chunk owns (the averages past its end taken away again); the open segment counts
        as ended. R(n) sums are not part of it (analyze defers them and reads them later)."""
        self._flush_ladders()
        ladders = []
        for k, lad in enumerate(self._ladders):
            own = copy.deepcopy(lad)
            if self._past is not None:
                own.add(self._past[k], -1)
            ladders.append(own)
        end = self.n_samples if self._own_until is None else min(self.n_samples,
                                                                   self._own_until)
        return OadevPart(self.ms.copy(), self._n.copy(), self._s2.copy(), tuple(ladders),
                         max(0, int(end) - self._own_from))

    @classmethod
    def from_part(cls, part: OadevPart, rate_hz: float, *, names: Sequence[str] | None = None,
                  covariance: bool = False, n_total: int | None = None,
                  defer_rn: bool = False) -> OverlappingAllan:
        """An accumulator holding ``part``'s sums (e.g. the sum of a record's chunks): its
        ``result()``, ``rn_needed()`` and ``set_rn()`` are those of one pass over the record
        made with ``defer_rn`` (R(n) is never part of a part: with ``defer_rn`` the caller
        supplies it, as analyze does; without, B1 alone identifies the long τ). It takes no
        further samples."""
        c = part.s2.shape[1]
        out = cls(c, rate_hz, part.ms, names=names, covariance=covariance, n_total=n_total,
                  defer_rn=defer_rn)
        if not defer_rn:
            # a part carries no R(n) sums: without them B1 alone identifies the long τ
            # (flicker PM where it says PM), never from empty sums
            out._rn = [None] * len(out.ms)
        out._n = part.n.copy()
        out._s2 = part.s2.copy()
        out._ladders = [copy.deepcopy(lad) for lad in part.ladders]
        out.n_samples = part.n_samples
        out._closed = True
        return out

    # ------------------------------------------------------------------------ R(n) later
    def rn_needed(self, noise_id: str = "avard") -> dict[int, list[int]]:
        """{index into ``ms``: channels} where R(n) was deferred and the noise
        identification (by the rule ``noise_id``) will read it: B1 says PM with fewer than
        ``MIN_POINTS`` averages, at a τ whose α is not the shorter τ's (``result()``'s own
        identification says where). For a ``set_rn`` before ``result()``. Empty unless
        ``defer_rn``, and on records with no PM noise at the long τ."""
        self._flush_ladders()
        if check_noise_id(noise_id) == "avard":
            # rate data with no LSB given (``result`` passes none): PM is never kept, so
            # which PM R(n) would name is never read; no channel is read again for it
            return {}
        read = np.zeros((len(self.ms), self.n_channels), dtype=bool)
        alphas_from_ladders(self._ladders, 2, None, self.ms, self._n, np.ones_like(self.ms),
                            noise_id, rn_read=read)
        return {k: [int(ch) for ch in np.flatnonzero(read[k])]
                for k, deferred in enumerate(self._rn_deferred)
                if deferred and self._n[k] > 0 and read[k].any()}

    def rn_sums(self) -> list[RnSums | None]:
        """The R(n) sums kept per τ (None where there are none)."""
        return list(self._rn)

    def set_rn(self, ch: int, sums: dict[int, RnSums], of: int = 0) -> None:
        """Channel ``ch``'s deferred R(n) sums at the τ ``sums`` names (index into ``ms``:
        the sums of an accumulator fed this channel's blocks again at that m; its channel
        ``of``)."""
        for k, r in sums.items():
            if not self._rn_deferred[k]:
                raise DataError(f"R(n) at m = {int(self.ms[k])} was not deferred")
            if self._rn[k] is None:
                self._rn[k] = RnSums(self.n_channels, int(self.ms[k]))
            rk = self._rn[k]
            assert rk is not None
            rk.take_channel(ch, r, of)

    # ------------------------------------------------------------------------ results
    @one_blas_thread
    def result(self, ci: float = 0.683, alpha: int | ArrayLike | None = None,
               quantiles: str = "exact", noise_id: str = "avard") -> AllanResult:
        """The accumulated OADEV as an ``AllanResult`` of kind "oavar" (1-D arrays for one
        channel, else (K, C)); τ with no complete difference have NaN variance and n = 0.
        ``quantiles="stable32"``: bounds with Stable32's χ² quantiles (``edf.chi2_interval``);
        ``noise_id="stable32"``: α by Stable32's B1 rule (``noise_id.NOISE_IDS``)."""
        self._flush_ladders()
        res = result_from_sums(
            "oavar", self.rate_hz, self.ms, np.ones_like(self.ms), self._n, self._s2,
            n_phase=self._n + 2 * self.ms, alpha=alpha,
            alpha_id=alphas_from_ladders(self._ladders, 2, self._rn, self.ms, self._n,
                                          np.ones_like(self.ms), noise_id), ci=ci,
            one_d=self.n_channels == 1, names=self.names, quantiles=quantiles,
            noise_id=noise_id)
        return res if self.covariance else replace(res, cov=None)
