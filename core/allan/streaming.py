"""Bounded-memory streaming Allan variance with the full Allan covariance between channels.

``StreamingAllan`` accumulates, at octave averaging factors m = 2^k, the sums behind the
partially overlapping Allan variance of ``avard.core.allan.deviations`` (NIST SP 1065 eq. 12 with a
stride): for m ≤ S (S = ``overlap``, default 8) every difference is used (stride 1, the fully
overlapping estimator); above, differences every m/S samples (a decimation cascade: level k
only ever sees the phase every m/S samples). Greenhall & Riley's EDF shows that S = 8 keeps
≥ 98 % of the fully overlapping EDF for white, flicker and random-walk rate noise, so the
accumulator holds the statistical information of the whole history in kilobytes:
O(C² · S · octaves) numbers, whatever the duration.

Per level it keeps, for the second phase differences D_i = X_{i+2m} − 2X_{i+m} + X_i (X the
running sum of the rate, i on the stride grid of the current segment), n and Σ D Dᵀ (C×C: the
Allan covariance, so the AVAR of any linear combination of channels, e.g. an axis minus
k × temperature, is available afterwards via ``weights``); and the sums of Stable32's noise
identification over the non-overlapping m-averages (``avard.core.allan.noise_id.Lag1Ladder``, the
same α as the batch and the fully overlapping estimators at that τ). Per stride grid it
keeps the last 3·S phase points, to continue the differences in the next block (levels
m ≤ S share the stride-1 grid).
With ``hadamard=True`` third differences take the place of D (Hadamard variance).

Integer blocks (raw counts) are summed in int64, so every difference is exact for any record
length; float blocks are summed in float64 after subtracting the segment's first sample. The
stride grid and the offset are those of the batch estimator, so ``result()`` equals
``allan_variance(y, rate, kind="pavar", overlap=S)`` (``"phvar"`` for Hadamard) to rounding of
the final sums, for any split into blocks.

A ``gap()`` ends the segment: the phase history is dropped (no difference straddles the gap)
and the sums carry on. ``merge`` adds another accumulator's sums. ``state()`` is a plain dict
(msgpack-able) that ``from_state`` restores exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from avard.core.allan.deviations import (
    AllanResult,
    DifferenceSums,
    checked_block,
    covariance_from_sums,
    finish_result,
    grid_sums,
)
from avard.core.allan.noise_id import Lag1Ladder
from avard.core.allan.scratch import scratch
from avard.core.blas import one_blas_thread
from avard.core.errors import DataError, FormatError
from numpy.typing import ArrayLike, NDArray

__all__ = ["AllanCovariance", "AllanSnapshot", "StreamingAllan"]

STATE_VERSION = 3  # 3: noise identification by Lag1Ladder sums
# Small blocks (one FIFO drain) are collected up to this many samples before the cascade runs:
# numpy's per-call overhead would otherwise dominate. Results never depend on it.
_FLUSH_SAMPLES = 4096
# Largest piece processed at once (working memory ≈ 4 × this × C × 8 bytes).
_MAX_BLOCK = 1 << 16
_EXACT_FLOAT = 2.0**53  # integers below this are exact in float64
# m-averages a level collects before they go to its Lag1Ladder: a push costs a few dozen numpy
# calls whatever its size, and a long-τ level gets only a few averages per block. The ladder's
# sums are exact for any split, so results never depend on it.
_LADDER_BATCH = 4096


@dataclass(frozen=True)
class AllanCovariance:
    """``StreamingAllan.covariance``: τ (K,) s and the Allan covariance cov (K, C, C) in
    (input unit)², as ``AllanResult``'s ``tau`` and ``cov``."""

    tau: NDArray[np.float64]
    cov: NDArray[np.float64]


@dataclass(frozen=True)
class AllanSnapshot:
    """What the service publishes every few seconds.

    tau (K,) s; m, stride, n (K,); avar, edf, lo, hi, alpha (K, C) with avar in (input unit)²;
    cov (K, C, C) the Allan covariance; n_samples; names; ci; rate_hz; kind (the estimator,
    "pavar", or "phvar" whose ``avar`` holds the Hadamard variance).
    """

    tau: NDArray[np.float64]
    m: NDArray[np.int64]
    stride: NDArray[np.int64]
    avar: NDArray[np.float64]
    cov: NDArray[np.float64]
    n: NDArray[np.int64]
    edf: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    alpha: NDArray[np.float64]
    n_samples: int
    names: tuple[str, ...]
    ci: float
    rate_hz: float
    kind: str = "pavar"  # "phvar" for a Hadamard accumulator
    #: the quantization step of the acceleration channels (m/s²) when the publisher knows
    #: it (the service: its feed's scale), for the fit's rounding term, as analyze takes it
    #: from a recording; None when unknown
    lsb_mps2: float | None = None

    def to_dict(self) -> dict:
        """Plain lists/numbers, msgpack- and JSON-able (units: s, (input unit)²)."""
        out: dict = {"n_samples": int(self.n_samples), "names": list(self.names),
                     "ci": float(self.ci), "rate_hz": float(self.rate_hz), "kind": self.kind}
        if self.lsb_mps2 is not None:
            out["lsb_mps2"] = float(self.lsb_mps2)
        for key in ("tau", "m", "stride", "avar", "cov", "n", "edf", "lo", "hi", "alpha"):
            out[key] = np.asarray(getattr(self, key)).tolist()
        return out

    @classmethod
    def from_dict(cls, d: object) -> AllanSnapshot:
        """THE decoder of a published snapshot (the inverse of :meth:`to_dict`, lists or
        arrays): the service's fit, ``avard watch``, ``avard web`` and ``avard record`` read
        ``avar`` records through it. Every array is checked against the others' shapes (K τ,
        C named channels), so a ragged, truncated or hostile snapshot is refused here with
        one ``FormatError`` naming what is wrong, never half-drawn later."""
        if not isinstance(d, dict):
            raise FormatError(f"an Allan snapshot is a map, not {type(d).__name__}")
        try:
            names = d["names"]
            if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
                raise FormatError("snapshot names must be a list of strings")
            c = len(names)
            tau = _array(d, "tau", np.float64, 1)
            k = len(tau)
            per_tau = {key: _array(d, key, np.int64, 1, (k,)) for key in ("m", "stride", "n")}
            per_ch = {key: _array(d, key, np.float64, 2, (k, c))
                      for key in ("avar", "edf", "lo", "hi", "alpha")}
            cov = _array(d, "cov", np.float64, 3, (k, c, c))
            kind = d.get("kind", "pavar")
            if kind not in ("pavar", "phvar"):
                raise FormatError(f"snapshot kind {kind!r} is not pavar or phvar")
            lsb = d.get("lsb_mps2")
            if lsb is not None and (isinstance(lsb, bool) or not (
                    isinstance(lsb, int | float) and math.isfinite(lsb) and lsb > 0)):
                raise FormatError(f"snapshot lsb_mps2 {lsb!r} is not a positive number")
            return cls(tau, per_tau["m"], per_tau["stride"], per_ch["avar"], cov, per_tau["n"],
                       per_ch["edf"], per_ch["lo"], per_ch["hi"], per_ch["alpha"],
                       int(d["n_samples"]), tuple(names), float(d["ci"]), float(d["rate_hz"]),
                       str(kind), None if lsb is None else float(lsb))
        except KeyError as exc:
            raise FormatError(f"an Allan snapshot lacks {exc}; it is not one") from None
        except (TypeError, ValueError, OverflowError) as exc:
            raise FormatError(f"an Allan snapshot does not decode: {exc}") from None

    @property
    def n_channels(self) -> int:
        return len(self.names)

    def channel(self, c: int) -> AllanResult:
        """Channel ``c`` as a single-channel :class:`AllanResult` (what the noise fit takes)."""
        if not -self.n_channels <= c < self.n_channels:
            raise DataError(f"channel {c} does not exist: this snapshot has {self.n_channels}")
        return AllanResult(
            kind=self.kind, rate_hz=self.rate_hz, tau=self.tau, m=self.m, stride=self.stride,
            var=self.avar[:, c], n=self.n, edf=self.edf[:, c], lo=self.lo[:, c],
            hi=self.hi[:, c], alpha=self.alpha[:, c], ci=self.ci,
            cov=self.cov[:, c:c + 1, c:c + 1], names=(self.names[c],))


def _array(d: dict, key: str, dtype: type, ndim: int,
           shape: tuple[int, ...] | None = None) -> NDArray:
    """``d[key]`` as a read-only array of ``dtype`` with ``ndim`` dimensions (and ``shape``)."""
    a: NDArray = np.array(d[key], dtype=dtype)
    if a.ndim != ndim and a.size == 0 and shape is not None:
        a = a.reshape(shape)               # an empty snapshot's [] for (0, C)
    if a.ndim != ndim or (shape is not None and a.shape != shape):
        raise FormatError(f"snapshot {key} has shape {a.shape}, expected "
                          f"{shape if shape is not None else f'{ndim} dimension(s)'}")
    a.flags.writeable = False
    return a


class _Level:
    """Sums of one octave level: m = 2^k, stride, spacing sp = m / stride on its grid."""

    __slots__ = ("ladder", "m", "pending", "pending_n", "shift", "spacing", "stride", "sums")

    def __init__(self, m: int, stride: int, c: int, d: int) -> None:
        self.m = m
        self.stride = stride
        self.spacing = m // stride
        self.sums = DifferenceSums.zeros(c)
        # non-overlapping m-averages: every spacing-th first difference of the grid; per
        # channel only (the cross sums would cost C times more at m = 1, every sample)
        self.ladder = Lag1Ladder(c, dmax=d, cross=False)
        self.pending: list[NDArray] = []  # (k, C) averages not yet in the ladder
        self.pending_n = 0
        self.shift: NDArray | None = None  # added to the queued averages (the segment's)

    def take(self, averages: NDArray, shift: NDArray) -> None:
        """Queue new m-averages (k, C) of the current segment for the ladder, to which
        ``shift`` (C,) is added (the same for the whole segment)."""
        self.shift = shift
        self.pending.append(averages)
        self.pending_n += averages.shape[0]
        if self.pending_n >= _LADDER_BATCH:
            self.settle()

    def settle(self) -> None:
        """Push the queued averages into the ladder (before anything reads or ends it)."""
        if self.pending:
            self.ladder.push(self.pending[0] if len(self.pending) == 1
                             else np.concatenate(self.pending), self.shift)
            self.pending = []
            self.pending_n = 0


class _Grid:
    """Phase history on one stride grid, shared by the levels that use that stride.

    Stride 1 serves every m ≤ S (fully overlapping); each stride s = m/S > 1 serves one level.
    ``hist`` holds the last (d+1)·max(sp) points (enough for the lag partner of the next
    block's first second difference), in the accumulator's dtype (int64 counts stay exact).
    """

    __slots__ = ("base", "hist", "keep", "stride")

    def __init__(self, stride: int, keep: int, c: int, dtype: type) -> None:
        self.stride = stride
        self.keep = keep
        self.hist: NDArray = np.zeros((1, c), dtype=dtype)  # X_0 = 0 of the segment
        self.base = 0  # grid index, within the segment, of hist[0]

    def push(self, points: NDArray, levels: Sequence[_Level], d: int, offset: NDArray) -> None:
        """Append new grid points and add every completed difference to the levels' sums.

        ``offset`` is the segment's first sample, removed from the phase: the ladders get the
        m-averages with it added back (as sums of m samples), so that every segment's
        averages are on one scale and the pooled mean of the noise identification is the
        records' (a difference order ≥ 1 never sees it; order 0 does)."""
        h = self.hist.shape[0]
        arr = scratch("cat", h + points.shape[0], points.shape[1], points.dtype)
        arr[:h] = self.hist  # int64 → float64 is exact below 2**53 (checked by the caller)
        arr[h:] = points
        length = arr.shape[0]
        for lev in levels:
            sp = lev.spacing
            grid_sums(arr, sp, h, lev.sums, d)
            # averages ending at a new grid point that is a multiple of m in the segment
            e0 = max(h, sp)
            e0 += (-(self.base + e0)) % sp
            if e0 < length:
                sums = arr[e0::sp] - arr[e0 - sp:length - sp:sp]  # a new array
                lev.take(np.asarray(sums, dtype=np.float64), lev.m * offset)
        if arr.shape[0] > self.keep:
            self.base += arr.shape[0] - self.keep
            arr = arr[-self.keep :]
        # a copy in the stored dtype: the scratch buffer is reused by the next grid
        self.hist = arr.astype(self.hist.dtype)


class StreamingAllan:
    """Streaming partially overlapping Allan variance of C channels at octave τ.

    Parameters
    ----------
    n_channels : int
        Number of channels C (e.g. 3 axes + temperatures).
    rate_hz : float
        Sample rate; τ = m / rate_hz.
    overlap : int
        S: fully overlapping up to m = S, stride m/S above. A power of two.
    max_octaves : int
        Largest m is 2^(max_octaves − 1).
    names : channel names.
    hadamard : bool
        Accumulate the Hadamard variance (third differences, NIST SP 1065 eq. 18; insensitive
        to a linear rate drift) instead of the Allan variance; results have kind "phvar".
    """

    def __init__(
        self,
        n_channels: int,
        rate_hz: float,
        *,
        overlap: int = 8,
        max_octaves: int = 40,
        names: Sequence[str] | None = None,
        hadamard: bool = False,
    ) -> None:
        if not isinstance(n_channels, (int, np.integer)) or n_channels < 1:
            raise DataError(f"n_channels={n_channels!r} must be a positive integer")
        if not (isinstance(rate_hz, (int, float, np.integer, np.floating))
                and math.isfinite(float(rate_hz)) and float(rate_hz) > 0):
            raise DataError(f"rate_hz={rate_hz!r} must be a finite sample rate > 0 Hz")
        if overlap < 1 or overlap & (overlap - 1):
            raise DataError(f"overlap={overlap} must be a power of two >= 1 (default 8)")
        if not 1 <= max_octaves <= 62:
            raise DataError(f"max_octaves={max_octaves} must lie in 1..62")
        if names is not None and len(names) != n_channels:
            raise DataError(f"{len(names)} names given for {n_channels} channels")
        self.n_channels = int(n_channels)
        self.rate_hz = float(rate_hz)
        self.overlap = int(overlap)
        self.max_octaves = int(max_octaves)
        self.hadamard = bool(hadamard)
        self.kind = "phvar" if self.hadamard else "pavar"
        self._d = 3 if self.hadamard else 2  # order of the phase difference
        self.names = list(names) if names is not None else [f"ch{i}" for i in range(n_channels)]
        self.n_samples = 0  # all samples accepted, over all segments
        self.n_segments = 0  # segments started (a gap or merge adds to it)
        self._integer: bool | None = None  # decided by the first block
        self._levels: list[_Level] = []
        self._grids: list[_Grid] = []
        self._log2s = self.overlap.bit_length() - 1
        self._pending: list[NDArray] = []
        self._pending_n = 0
        self._reset_segment()

    # ----------------------------------------------------------------- segments and blocks
    def _reset_segment(self) -> None:
        self._seg_count = 0  # samples in the current segment
        self._offset: NDArray | None = None  # first sample of the segment (removed)
        self._carry: NDArray | None = None  # phase X at the segment's last sample
        self._big = False  # has |X| reached 2**53 in this segment (integer input)?
        for g in self._grids:
            g.hist = np.zeros((1, self.n_channels), dtype=self._dtype())
            g.base = 0
        for lev in self._levels:
            lev.settle()
            lev.ladder.gap()

    def _dtype(self) -> type:
        return np.int64 if self._integer else np.float64

    def _level(self, k: int) -> _Level:
        while len(self._levels) <= k:
            j = len(self._levels)
            self._levels.append(_Level(1 << j, self._stride(j), self.n_channels, self._d))
        return self._levels[k]

    def _stride(self, k: int) -> int:
        m = 1 << k
        return 1 if m <= self.overlap else m // self.overlap

    def _grid_levels(self, g: int) -> list[_Level]:
        """Levels on grid g (stride 2^g): all m ≤ S for g = 0, else the one m = 2^g·S."""
        ks = range(min(self._log2s + 1, self.max_octaves)) if g == 0 else \
            ([self._log2s + g] if self._log2s + g < self.max_octaves else [])
        return [self._level(k) for k in ks]

    def _grid(self, g: int) -> _Grid:
        while len(self._grids) <= g:
            # Grids are created when the segment first reaches their stride, so the segment's
            # only earlier point on them is X_0 = 0, which a new grid starts with.
            keep = (self._d + 1) * (self.overlap if len(self._grids) else
                               min(self.overlap, 1 << (self.max_octaves - 1)))
            self._grids.append(_Grid(1 << len(self._grids), keep, self.n_channels,
                                     self._dtype()))
        return self._grids[g]

    def _check_block(self, block: ArrayLike) -> NDArray:
        first = self._integer is None
        a, self._integer = checked_block(block, self.n_channels, self._integer)
        if first and self._integer is not None:
            for g in self._grids:
                g.hist = g.hist.astype(self._dtype())
        return a

    @one_blas_thread  # long dot products would wake OpenBLAS's pool (core/blas.py)
    def update(self, block: ArrayLike) -> None:
        """Add a block of samples, (n, C) or (n,) for one channel; any n ≥ 0."""
        a = self._check_block(block)
        n = a.shape[0]
        if n == 0:
            return
        if n >= _FLUSH_SAMPLES:
            self._flush()  # pending small blocks come first, in order
            # bounded pieces keep the working memory independent of the caller's block size
            for i in range(0, n, _MAX_BLOCK):
                self._process(a[i : i + _MAX_BLOCK])
        else:
            # copy: the caller may reuse its buffer (a FIFO drain) after we return
            self._pending.append(np.array(a, copy=True))
            self._pending_n += n
            if self._pending_n >= _FLUSH_SAMPLES:
                self._flush()
        self.n_samples += n

    def _flush(self) -> None:
        if not self._pending:
            return
        a = self._pending[0] if len(self._pending) == 1 else np.concatenate(self._pending)
        self._pending = []
        self._pending_n = 0
        self._process(a)

    def _process(self, a: NDArray) -> None:
        """Run the cascade on a validated block of the current segment."""
        dtype = self._dtype()
        if self._offset is None:
            self._offset = a[0].copy()
            self._carry = np.zeros(self.n_channels, dtype=dtype)
            self.n_segments += 1
        n = a.shape[0]
        # X continues from the carried value; cumsum over [carry, block] adds in the same order
        # as the batch cumsum over the whole segment, so float phases are bit-identical.
        work = scratch("work", n + 1, self.n_channels, dtype)
        work[0] = self._carry
        np.subtract(a, self._offset, out=work[1:], casting="unsafe")
        np.cumsum(work, axis=0, out=work)
        phase = work[1:]  # X at segment indices seg_count+1 … seg_count+n
        first_index = self._seg_count + 1
        self._carry = phase[-1].copy()
        if self._integer and not self._big:
            self._big = bool(np.abs(phase).max(initial=0) >= _EXACT_FLOAT)
        if self._integer and not self._big:
            # Every X of this segment so far is an integer below 2**53, so float64 holds it
            # exactly: one conversion here instead of one per level. Once a segment's phase
            # has gone beyond, its grids work in int64 (slower, still exact).
            phase_f = scratch("work_f", n, self.n_channels, np.float64)
            np.copyto(phase_f, phase)
            phase = phase_f
        if self._seg_count == 0:
            for g in self._grids:
                g.hist = np.zeros((1, self.n_channels), dtype=dtype)  # X_0 = 0
                g.base = 0
        self._seg_count += n
        for gi in range(self.max_octaves):
            s = 1 << gi
            if s > self._seg_count:
                break  # no point beyond X_0 on this grid yet, nor on any coarser one
            levels = self._grid_levels(gi)
            if not levels:
                break
            grid = self._grid(gi)
            off = (-first_index) % s  # first new index on this grid
            if off < n:
                grid.push(phase[off::s], levels, self._d, self._offset)

    def gap(self) -> None:
        """End the current segment: later differences never reach back across this point."""
        self._flush()
        self._reset_segment()

    def _settle(self) -> None:
        """Fold in pending blocks and queued averages: the sums are then complete."""
        self._flush()
        for lev in self._levels:
            lev.settle()

    # ------------------------------------------------------------------------ results
    def _active(self) -> list[_Level]:
        return [lev for lev in self._levels if lev.sums.n > 0]

    def _settled_levels(self) -> list[_Level]:
        """The levels holding differences, the sums complete; DataError when there are none
        (``result`` and ``covariance``)."""
        self._settle()
        levels = self._active()
        if not levels:
            raise DataError(
                f"no Allan variance yet: {self.n_samples} samples in the longest segment is "
                "too few for τ = 2 τ0; feed more samples"
            )
        return levels

    @one_blas_thread
    def result(self, weights: ArrayLike | None = None, ci: float = 0.683,
               quantiles: str = "exact", noise_id: str = "avard") -> AllanResult:
        """The accumulated variance as an ``AllanResult`` (kind "pavar", or "phvar").

        ``weights`` (C,) gives the single channel Σ w_c y_c from the covariance. A one-channel
        accumulator, or a weighted result, has 1-D arrays; otherwise (K, C).
        ``quantiles="stable32"``: bounds with Stable32's χ² quantiles (``edf.chi2_interval``);
        ``noise_id``: the B1 rule for the overlapping levels (``noise_id.NOISE_IDS``).
        """
        levels = self._settled_levels()
        ms = np.array([lev.m for lev in levels], dtype=np.int64)
        strides = np.array([lev.stride for lev in levels], dtype=np.int64)
        return finish_result(
            self.kind, self.rate_hz, ms, strides, [lev.sums for lev in levels],
            [lev.ladder for lev in levels], ci=ci, one_d=self.n_channels == 1, names=self.names,
            weights=weights, quantiles=quantiles, noise_id=noise_id,
        )

    @one_blas_thread
    def covariance(self) -> AllanCovariance:
        """τ (s) and the Allan covariance (K, C, C) alone: ``result().tau`` and
        ``result().cov`` to the bit, without the noise identification, EDF and bounds that
        ``result`` computes (most of its cost) for a caller that reads only the covariance
        (``avard explain``'s compensated AVAR: an Allan pass per removed signal)."""
        levels = self._settled_levels()
        ms = np.array([lev.m for lev in levels], dtype=np.int64)
        n = np.array([lev.sums.n for lev in levels], dtype=np.int64)
        s2 = np.array([lev.sums.s2 for lev in levels], dtype=np.float64)
        return AllanCovariance(ms / self.rate_hz, covariance_from_sums(self.kind, ms, n, s2))

    def snapshot(self, ci: float = 0.683) -> AllanSnapshot:
        """τ, AVAR per channel, covariance, counts, EDF and CI, at the current point."""
        self._settle()
        if not self._active():
            k = 0
            empty = np.zeros((0, self.n_channels))
            ints = np.zeros(0, dtype=np.int64)
            return AllanSnapshot(np.zeros(0), ints, ints, empty,
                                 np.zeros((k, self.n_channels, self.n_channels)), ints,
                                 empty, empty, empty, empty, self.n_samples,
                                 tuple(self.names), ci, self.rate_hz, self.kind)
        res = finish_result(
            self.kind, self.rate_hz,
            np.array([lev.m for lev in self._active()], dtype=np.int64),
            np.array([lev.stride for lev in self._active()], dtype=np.int64),
            [lev.sums for lev in self._active()], [lev.ladder for lev in self._active()],
            ci=ci, names=self.names,
        )
        assert res.cov is not None
        return AllanSnapshot(res.tau, res.m, res.stride, res.var, res.cov, res.n, res.edf,
                             res.lo, res.hi, res.alpha, self.n_samples, tuple(self.names),
                             ci, self.rate_hz, self.kind)

    # ------------------------------------------------------------- merge and persistence
    def merge(self, other: StreamingAllan) -> None:
        """Add the sums of another accumulator (other segments of the same channels).

        Both must have the same channels, rate, overlap and kind. ``other``'s open segment counts as
        ended; this accumulator's open segment continues.
        """
        if not isinstance(other, StreamingAllan):
            raise DataError("merge takes another StreamingAllan")
        if (other.n_channels != self.n_channels or other.overlap != self.overlap
                or other.rate_hz != self.rate_hz or other.kind != self.kind):
            raise DataError(
                "cannot merge accumulators with different channels, rate, overlap or kind: "
                f"({self.n_channels}, {self.rate_hz} Hz, S={self.overlap}, {self.kind}) vs "
                f"({other.n_channels}, {other.rate_hz} Hz, S={other.overlap}, {other.kind})"
            )
        self._settle()
        other._settle()
        for k, lev in enumerate(other._levels):
            mine = self._level(k)
            mine.sums.add(lev.sums)
            mine.ladder.add(lev.ladder)
        self.n_samples += other.n_samples
        self.n_segments += other.n_segments

    def state(self) -> dict:
        """Everything needed to continue exactly: plain numbers, lists and bytes (msgpack-able).

        Pending small blocks are folded in first. Arrays are {"dtype", "shape", "data"} maps,
        as in avard's frame format.
        """
        self._settle()
        c = self.n_channels
        # Levels past the last one with any sums are recreated empty on restore.
        count = max((k + 1 for k, lev in enumerate(self._levels)
                     if lev.sums.n or lev.ladder.count()), default=0)
        levs = self._levels[:count]
        iu = np.triu_indices(c)  # s2 is symmetric: one triangle is stored
        sums: dict = {"n": [int(lev.sums.n) for lev in levs]}
        sums["s2"] = _pack(np.array([lev.sums.s2[iu] for lev in levs],
                                    dtype=np.float64).reshape(count, len(iu[0])))
        sums["ladders"] = [lev.ladder.state() for lev in levs]
        grids = self._grids
        hist = (np.concatenate([g.hist for g in grids]) if grids
                else np.zeros((0, c), dtype=self._dtype()))
        levels = {"count": len(levs), "sums": sums, "grids": len(grids), "hist": _pack(hist),
                  "hist_len": [int(g.hist.shape[0]) for g in grids],
                  "base": [int(g.base) for g in grids]}
        return {
            "kind": "streaming_allan",
            "v": STATE_VERSION,
            "n_channels": self.n_channels,
            "rate_hz": self.rate_hz,
            "overlap": self.overlap,
            "max_octaves": self.max_octaves,
            "hadamard": self.hadamard,
            "names": list(self.names),
            "integer": self._integer,
            "n_samples": self.n_samples,
            "n_segments": self.n_segments,
            "seg_count": self._seg_count,
            "big": self._big,
            "offset": None if self._offset is None else _pack(self._offset),
            "carry": None if self._carry is None else _pack(self._carry),
            "levels": levels,
        }

    @classmethod
    def from_state(cls, state: dict) -> StreamingAllan:
        """Restore an accumulator from ``state()`` exactly (same sums, same history)."""
        try:
            if state.get("kind") != "streaming_allan" or state.get("v") != STATE_VERSION:
                raise FormatError(
                    f"not a version-{STATE_VERSION} StreamingAllan state "
                    f"(kind={state.get('kind')!r}, v={state.get('v')!r})"
                )
            self = cls(int(state["n_channels"]), float(state["rate_hz"]),
                       overlap=int(state["overlap"]), max_octaves=int(state["max_octaves"]),
                       hadamard=bool(state.get("hadamard", False)),
                       names=list(state["names"]))
            self._integer = state["integer"]
            self.n_samples = int(state["n_samples"])
            self.n_segments = int(state["n_segments"])
            self._seg_count = int(state["seg_count"])
            self._big = bool(state["big"])
            self._offset = None if state["offset"] is None else _unpack(state["offset"])
            self._carry = None if state["carry"] is None else _unpack(state["carry"])
            lv = state["levels"]
            count = int(lv["count"])
            if count > self.max_octaves:
                raise FormatError(f"state has {count} levels, more than max_octaves")
            hist = _unpack(lv["hist"])
            ends = np.cumsum([0, *lv["hist_len"]])
            for g in range(int(lv["grids"])):
                grid = self._grid(g)
                grid.hist = hist[ends[g] : ends[g + 1]].copy()
                grid.base = int(lv["base"][g])
            sums = lv["sums"]
            c = self.n_channels
            s2 = _unpack(sums["s2"])
            for k in range(count):
                lev = self._level(k)
                lev.sums.n = int(sums["n"][k])
                lev.sums.s2 = _symmetric(s2[k], c)
                lev.ladder = Lag1Ladder.from_state(sums["ladders"][k])
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise FormatError(f"StreamingAllan state is incomplete or malformed: {exc}; "
                              "start a new accumulator") from exc
        return self


def _symmetric(tri: NDArray, c: int) -> NDArray:
    """The symmetric (c, c) matrix whose upper triangle (row-major) is ``tri``."""
    out = np.zeros((c, c))
    out[np.triu_indices(c)] = tri
    return out + np.triu(out, 1).T


def _pack(a: NDArray) -> dict:
    a = np.ascontiguousarray(a)
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.tobytes()}


def _unpack(d: dict) -> NDArray:
    dtype = np.dtype(d["dtype"])
    if dtype.kind not in "if":
        raise FormatError(f"array dtype {d['dtype']!r} is not allowed in a state")
    return np.frombuffer(d["data"], dtype=dtype).reshape(d["shape"]).copy()
