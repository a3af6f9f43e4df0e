"""Batch Allan and Hadamard variances of rate data, with Greenhall–Riley EDF and intervals.

Conventions (NIST SP 1065, "Handbook of Frequency Stability Analysis", 2008):

* Input is *rate* data y (acceleration, or fractional frequency), sampled every τ0 = 1/rate.
  The phase is the running sum x_i = τ0 Σ_{k<i} y_k with x_0 = 0; here the sum is kept in
  sample units, X_i = Σ_{k<i} y_k, so that τ0 cancels exactly and never multiplies anything
  (a published streaming implementation gets AVAR 1/τ0 wrong for τ0 ≠ 1).
* Overlapping AVAR at τ = m·τ0 (SP 1065 eq. 12, phase form):
      σ²(τ) = Σ_i (x_{i+2m} − 2x_{i+m} + x_i)² / (2 τ² M) = Σ_i D_i² / (2 m² M),
  with D_i = X_{i+2m} − 2X_{i+m} + X_i and M the number of differences used.
  Non-overlapping AVAR (eq. 11) takes i = 0, m, 2m, …; partially overlapping takes
  i = 0, s, 2s, … for a stride 1 ≤ s ≤ m; all three are unbiased and differ in EDF only.
* Overlapping Hadamard variance (SP 1065 eq. 18): third differences
  H_i = X_{i+3m} − 3X_{i+2m} + 3X_{i+m} − X_i and Hσ²(τ) = Σ H_i² / (6 m² M).
* Integer input (raw ADC counts) is summed in int64, so the phase and every difference are
  exact for any record length; differences are squared in float64. Float input is summed in
  float64 after subtracting the segment's first sample (a constant does not change any
  difference, and removing it keeps the running sum small, so fewer digits cancel).
* Differences are placed on a grid relative to each segment's first sample: i ≡ 0 (mod s).
  The streaming accumulator (``avard.core.allan.streaming``) uses the same grid, so the two agree to
  rounding for any block split.

For every τ the result also carries the C×C matrix of mean products of differences (the Allan
covariance ``cov``), so the AVAR of any linear combination Σ w_c y_c is ``w @ cov @ w``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from avard.core.allan import kernels
from avard.core.allan.edf import chi2_interval, edf_greenhall
from avard.core.allan.noise_id import (
    HOLD_BELOW_AVERAGES,
    MIN_POINTS,
    Lag1Ladder,
    RnSums,
    alpha_from_slope,
    check_noise_id,
    identify_alpha,
    physical_alpha_edf,
)
from avard.core.allan.scratch import scratch
from avard.core.blas import one_blas_thread
from avard.core.errors import DataError
from avard.core.finite import first_nonfinite_row
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "KINDS",
    "AllanResult",
    "DifferenceSums",
    "allan_variance",
    "avar",
    "chi2_interval",
    "edf_greenhall",
    "finish_result",
    "grid_sums",
    "identify_alpha",
    "oavar",
    "ohvar",
    "pavar",
    "phvar",
    "strided_sums",
    "tau_grid",
]

# kind → order d of the phase difference (2 Allan, 3 Hadamard)
KINDS = {"avar": 2, "oavar": 2, "pavar": 2, "ohvar": 3, "phvar": 3}
# Normalisation of the mean squared d-th difference of m-averages (SP 1065 eqs. 12 and 18).
NORM = {2: 2.0, 3: 6.0}
# Coefficients of the d-th phase difference X_{i+km}, k = 0 … d.
COEFS = {1: (-1, 1), 2: (1, -2, 1), 3: (-1, 3, -3, 1)}
# Differences per chunk in the batch kernel: bounds the working memory for long records.
_CHUNK = 1 << 17
DEFAULT_OVERLAP = 8


@dataclass(frozen=True)
class AllanResult:
    """Allan-type variances at a grid of τ, with their uncertainty.

    Array shapes: K averaging times, C channels. ``var``, ``edf``, ``lo``, ``hi``, ``alpha``
    are (K,) for a 1-D input and (K, C) for an (N, C) input. Variances are in (input unit)²
    (m²/s⁴ for acceleration in m/s², counts² for raw counts); ``tau`` is in seconds.
    ``n`` is the number of squared differences summed (NaN variance where it is 0).
    ``lo``/``hi`` are the chi-squared interval at level ``ci`` with the Greenhall–Riley EDF
    for the noise exponent ``alpha`` (see ``avard.core.allan.edf``).
    ``cov`` (K, C, C), when present, is the Allan covariance: AVAR of Σ w_c y_c = w·cov·w.
    ``quantiles`` says how the χ² quantiles of the bounds were computed: "exact", or
    "stable32" (Stable32's approximation, to reproduce its printed bounds; ``edf.chi2_interval``).
    ``noise_id`` names the rule behind ``alpha`` ("avard" or "stable32":
    ``noise_id.NOISE_IDS``).
    """

    kind: str
    rate_hz: float
    tau: NDArray[np.float64]
    m: NDArray[np.int64]
    stride: NDArray[np.int64]
    var: NDArray[np.float64]
    n: NDArray[np.int64]
    edf: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    alpha: NDArray[np.float64]
    ci: float = 0.683
    cov: NDArray[np.float64] | None = None
    names: tuple[str, ...] = field(default=())
    quantiles: str = "exact"
    noise_id: str = "avard"

    @property
    def dev(self) -> NDArray[np.float64]:
        """Deviation √var (input unit; m/s² for acceleration)."""
        return np.sqrt(self.var)

    @property
    def dev_lo(self) -> NDArray[np.float64]:
        """Lower confidence bound of the deviation."""
        return np.sqrt(self.lo)

    @property
    def dev_hi(self) -> NDArray[np.float64]:
        """Upper confidence bound of the deviation."""
        return np.sqrt(self.hi)

    @property
    def n_channels(self) -> int:
        """Number of channels C (1 for a 1-D input)."""
        return 1 if self.var.ndim == 1 else int(self.var.shape[1])

    def channel(self, c: int) -> AllanResult:
        """One column of a multi-channel result, as a 1-D result."""
        if self.var.ndim == 1:
            if c not in (0, -1):
                raise DataError(f"channel {c} does not exist: this result has one channel")
            return self
        if not -self.n_channels <= c < self.n_channels:
            raise DataError(f"channel {c} does not exist: this result has {self.n_channels}")
        name = (self.names[c],) if self.names else ()
        return replace(
            self,
            var=self.var[:, c].copy(),
            edf=self.edf[:, c].copy(),
            lo=self.lo[:, c].copy(),
            hi=self.hi[:, c].copy(),
            alpha=self.alpha[:, c].copy(),
            cov=None if self.cov is None else self.cov[:, c : c + 1, c : c + 1].copy(),
            names=name,
        )

    def to_dict(self) -> dict:
        """Plain lists and numbers (msgpack/JSON-able); NaN stays NaN."""
        out: dict = {"kind": self.kind, "rate_hz": self.rate_hz, "ci": self.ci,
                     "names": list(self.names), "quantiles": self.quantiles,
                     "noise_id": self.noise_id}
        for key in ("tau", "m", "stride", "var", "n", "edf", "lo", "hi", "alpha"):
            out[key] = np.asarray(getattr(self, key)).tolist()
        out["cov"] = None if self.cov is None else self.cov.tolist()
        return out


@dataclass
class DifferenceSums:
    """Running sums of the order-d phase differences Q at one (m, stride), for C channels:
    n, the number of differences, and s2 (C, C) = Σ Q Qᵀ (the Allan covariance, unscaled).
    The noise identification has its own sums (``noise_id.Lag1Ladder``, fed the
    non-overlapping m-averages), shared by every estimator at that τ."""

    n: int
    s2: NDArray[np.float64]

    @classmethod
    def zeros(cls, c: int) -> DifferenceSums:
        return cls(0, np.zeros((c, c)))

    FIELDS = ("n", "s2")

    def add(self, other: DifferenceSums) -> None:
        for f in self.FIELDS:
            setattr(self, f, getattr(self, f) + getattr(other, f))


def gram(a: NDArray) -> NDArray[np.float64]:
    """aᵀa made exactly symmetric (BLAS may round the two triangles differently), so that a
    state can store one triangle and still restore bit for bit."""
    g = a.T @ a
    return 0.5 * (g + g.T)


def grid_sums(q: NDArray, sp: int, h: int, sums: DifferenceSums, d: int) -> None:
    """Add the sums of the order-d phase differences taken on one stride grid.

    ``q`` (L, C) holds phase points X on a grid of constant stride (consecutive rows are
    ``stride`` samples apart), int64 (exact) or float64; rows from index ``h`` on are new.
    With sp = m / stride the difference is computed recursively, E_j = q[j+sp] − q[j]
    (m times an m-average of the rate) and Q^o_j = Q^{o−1}_{j+sp} − Q^{o−1}_j up to o = d,
    for j ∈ [0, L − d·sp). A difference is counted when it is new (its last point
    j + d·sp ≥ h). The recursion gives the same numbers for any split of the grid into
    blocks, which is what makes streaming equal batch. Works in chunks of j so that memory
    stays bounded on long records.
    """
    length = q.shape[0]
    n_d = length - d * sp  # number of order-d differences
    if n_d <= 0:
        return
    chunk = max(_CHUNK, sp)
    c = q.shape[1]
    a = max(0, h - d * sp)
    while a < n_d:
        b = min(n_d, a + chunk)
        hi = b + (d - 1) * sp  # E needed to build order d on [a, b)
        arr = np.subtract(q[a + sp : hi + sp], q[a:hi], out=scratch("e", hi - a, c, q.dtype))
        if arr.dtype != np.float64:
            as_float = scratch("ef", hi - a, c, np.float64)
            np.copyto(as_float, arr)  # exact: integer differences are far below 2**53
            arr = as_float
        for o in range(2, d + 1):
            out = scratch(f"q{o}", max(0, arr.shape[0] - sp), c, np.float64)
            arr = np.subtract(arr[sp:], arr[:-sp], out=out)
        sums.n += b - a
        sums.s2 += gram(arr[: b - a])
        a = b


def grid_sums_by_part(q: NDArray, sp: int, cuts: NDArray, parts: list[DifferenceSums]
                      ) -> None:
    """``grid_sums(q[j0:j1 + 2·sp], sp, 0, part, 2)`` for each part's range [j0, j1) of
    second differences (``cuts`` (G+1,) ascending, ``parts`` (G,)), with the differences of
    the whole grid taken once instead of once per part: the same elementwise subtractions
    and the same Gram products of the same rows, so the same sums bit for bit (a test holds
    them equal). Falls back to ``grid_sums`` where that one would work in chunks."""
    n_d = q.shape[0] - 2 * sp
    if n_d <= 0:
        return
    if n_d > max(_CHUNK, sp) or q.dtype != np.float64:
        for g, part in enumerate(parts):
            j0, j1 = int(cuts[g]), int(cuts[g + 1])
            if j1 > j0:
                grid_sums(q[j0:j1 + 2 * sp], sp, 0, part, 2)
        return
    e = np.subtract(q[sp:], q[:-sp])
    diff2 = np.subtract(e[sp:], e[:-sp])
    for g, part in enumerate(parts):
        j0, j1 = int(cuts[g]), int(cuts[g + 1])
        if j1 > j0:
            part.n += j1 - j0
            part.s2 += gram(diff2[j0:j1])


def _compiled_sums(p: NDArray, m: int, d: int, sums: DifferenceSums) -> bool:
    """The fully overlapping sums of one float64 channel by the compiled loop
    (``kernels``): Σ (X_{i+2m} − 2X_{i+m} + X_i)² read in one pass (d = 2), and for d = 3 the
    same loop on the window sums W_j = X_{j+m} − X_j, since the third difference is
    W_{i+2m} − 2W_{i+m} + W_i. False (nothing added) where it does not apply: integer counts
    (exact int64 sums), several channels (the covariance), no compiled module; ``grid_sums``
    then, which a test holds equal."""
    kern = kernels.compiled()
    if kern is None or p.dtype != np.float64 or p.shape[1] != 1 or d not in (2, 3):
        return False
    col = p[:, 0]
    if d == 3:
        col = col[m:] - col[:-m]
    n_d = col.shape[0] - 2 * m
    if n_d <= 0:
        return True
    sums.n += n_d
    sums.s2[0, 0] += kern.sumsq(col[:n_d], col[m:m + n_d], col[2 * m:2 * m + n_d])
    return True


def strided_sums(p: NDArray, m: int, stride: int, d: int, sums: DifferenceSums) -> None:
    """``grid_sums`` for a stride that does not divide m (batch only, whole segment):
    differences D_i = Σ_k c_k p[i + k·m] at i = 0, stride, 2·stride, …"""
    last = p.shape[0] - 1 - d * m
    if last < 0:
        return
    coefs = COEFS[d]
    count = last // stride + 1
    for t in range(0, count, _CHUNK):
        j0 = t * stride
        stop = (min(count, t + _CHUNK) - 1) * stride + 1
        dd = sum(c * p[j0 + k * m : stop + k * m : stride] for k, c in enumerate(coefs))
        dd = np.asarray(dd, dtype=np.float64)
        sums.n += dd.shape[0]
        sums.s2 += gram(dd)


def tau_grid(n_samples: int, rate_hz: float, taus: str | ArrayLike, d: int) -> NDArray[np.int64]:
    """Averaging factors m for a τ specification and a record of ``n_samples`` rate samples.

    "octave": 1, 2, 4, …; "decade": 1, 2, 5, 10, 20, 50, …; "all": every m; these stop at the
    largest m with at least one difference (d·m ≤ n_samples). An array of τ in seconds is
    rounded to the nearest m ≥ 1, sorted and de-duplicated; τ too long for the record is kept
    (its variance is NaN with n = 0).
    """
    m_max = n_samples // d
    if isinstance(taus, str):
        if m_max < 1:
            return np.zeros(0, dtype=np.int64)
        if taus == "octave":
            ms = 2 ** np.arange(math.floor(math.log2(m_max)) + 1)
        elif taus == "decade":
            ms = np.array([b * 10**e for e in range(int(math.log10(m_max)) + 1)
                           for b in (1, 2, 5)])
            ms = ms[ms <= m_max]
        elif taus == "all":
            ms = np.arange(1, m_max + 1)
        else:
            raise DataError(
                f"taus={taus!r} is not a τ grid; use 'octave', 'decade', 'all' or an array of "
                "τ in seconds"
            )
        return ms.astype(np.int64)
    t = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)):
        raise DataError("taus must be a non-empty 1-D array of finite τ values in seconds")
    ms = np.rint(t * rate_hz)
    if np.any(ms < 1):
        bad = float(t[np.argmin(ms)])
        raise DataError(
            f"τ = {bad} s is shorter than one sample (τ0 = {1 / rate_hz} s); use τ >= τ0"
        )
    return np.unique(ms.astype(np.int64))


def default_stride(kind: str, m: int, stride: int | None, overlap: int = DEFAULT_OVERLAP) -> int:
    """Stride for an estimator: 1 overlapping, m non-overlapping, else partially overlapping.

    ``pavar``/``phvar`` without an explicit stride use the streaming cascade's choice: 1 for
    m ≤ overlap, else m // overlap (so there are ``overlap`` differences per τ).
    """
    if kind == "avar":
        return m
    if kind in ("oavar", "ohvar") and stride is None:
        return 1
    # pavar / phvar (and ohvar with an explicit stride)
    if stride is None:
        return 1 if m <= overlap else m // overlap
    return max(1, min(int(stride), m))


def _as_samples(y: ArrayLike) -> tuple[NDArray, bool]:
    a = np.asarray(y)
    if a.dtype.kind == "b":
        a = a.astype(np.int64)
    if a.dtype.kind in "iu":
        if a.dtype.kind == "u" and a.dtype.itemsize >= 8 and a.size and a.max() >= 2**62:
            raise DataError("unsigned 64-bit samples this large cannot be summed in int64")
        return a.astype(np.int64, copy=False), True
    if a.dtype.kind != "f":
        raise DataError(
            f"samples have dtype {a.dtype}; pass a real float or integer array (counts or SI)"
        )
    a = a.astype(np.float64, copy=False)
    bad = ~np.isfinite(a)
    if bad.any():
        i = int(np.argwhere(bad)[0][0])
        raise DataError(
            f"sample {i} is NaN or infinite; remove it, or split the record there with gaps=[...]"
        )
    return a, False


def validate_input(y: ArrayLike, rate_hz: float) -> tuple[NDArray, bool, bool]:
    """(samples as (N, C) int64 or float64, is_integer, was_1d); raises DataError if unusable."""
    if not (isinstance(rate_hz, (int, float, np.floating, np.integer))
            and math.isfinite(float(rate_hz)) and float(rate_hz) > 0):
        raise DataError(f"rate_hz={rate_hz!r} must be a finite sample rate > 0 Hz")
    a, is_int = _as_samples(y)
    if a.ndim == 1:
        return a[:, None], is_int, True
    if a.ndim == 2 and a.shape[1] >= 1:
        return a, is_int, False
    raise DataError(
        f"samples have shape {a.shape}; pass (N,) for one channel or (N, C) for C channels"
    )


def segment_phase(seg: NDArray, is_int: bool) -> NDArray:
    """Running sum X (len N+1, X_0 = 0) of a segment, after removing its first sample."""
    dtype = np.int64 if is_int else np.float64
    p = np.empty((seg.shape[0] + 1, seg.shape[1]), dtype=dtype)
    p[0] = 0
    np.cumsum(seg - seg[0], axis=0, out=p[1:])
    return p


@one_blas_thread  # long dot products would wake OpenBLAS's pool (core/blas.py)
def allan_variance(
    y: ArrayLike,
    rate_hz: float,
    taus: str | ArrayLike = "octave",
    *,
    kind: str = "oavar",
    stride: int | None = None,
    ci: float = 0.683,
    alpha: int | ArrayLike | None = None,
    gaps: Sequence[int] | None = None,
    overlap: int = DEFAULT_OVERLAP,
    names: Sequence[str] | None = None,
    quantiles: str = "exact",
    noise_id: str = "avard",
) -> AllanResult:
    """Allan or Hadamard variance of rate samples (NIST SP 1065 eqs. 11, 12, 18).

    Parameters
    ----------
    y : array (N,) or (N, C)
        Rate samples: acceleration in m/s², raw integer counts, fractional frequency.
    rate_hz : float
        Sample rate; τ0 = 1 / rate_hz.
    taus : "octave" | "decade" | "all" | array of τ in seconds
        See ``tau_grid``.
    kind : "oavar" (overlapping, default) | "avar" (non-overlapping) | "pavar" (stride given
        by ``stride``, default the streaming cascade's m/overlap) | "ohvar" (overlapping
        Hadamard) | "phvar" (Hadamard with the cascade's stride, as streamed).
    stride : int, optional
        Samples between successive differences for "pavar"/"ohvar"/"phvar" (clipped to
        [1, m]).
    ci : float
        Confidence level of ``lo``/``hi`` (0.683 = 1σ).
    alpha : int or (K,) or (K, C) array, optional
        Noise exponent for the EDF; by default identified per τ and channel as Stable32 does
        (``noise_id.Lag1Ladder``): lag-1 autocorrelation of the non-overlapping m-averages
        with their mean removed (≥ 30 averages), Barnes' B1 ratio with 4–29, else the local
        slope. The same α for every estimator at that τ (batch, streaming, cascade).
    gaps : sample indices at which a new segment starts; no difference straddles a gap.
    names : channel names, kept in the result.
    quantiles : "exact" (default) or "stable32": the χ² quantiles of the bounds as Stable32
        computes them, to reproduce its printed intervals (``edf.chi2_interval``).
    noise_id : "avard" (default) or "stable32": B1's N for the overlapping estimators with
        4–29 averages (``noise_id.NOISE_IDS``); "stable32" gives Stable32's printed α.

    τ longer than the record can hold give NaN variance with n = 0 (never a made-up value).
    """
    if kind not in KINDS:
        raise DataError(f"kind={kind!r} is unknown; use one of {sorted(KINDS)}")
    if stride is not None and kind in ("avar", "oavar"):
        raise DataError(f"kind={kind!r} fixes the stride; use kind='pavar' to choose one")
    if stride is not None and int(stride) < 1:
        raise DataError(f"stride={stride} must be >= 1 sample")
    d = KINDS[kind]
    a, is_int, one_d = validate_input(y, rate_hz)
    rate_hz = float(rate_hz)
    n_total, c = a.shape
    if n_total < d:
        raise DataError(
            f"{n_total} samples cannot make a single {kind} difference; need at least {d}"
        )
    bounds = _segment_bounds(n_total, gaps)
    longest = max(b - s for s, b in bounds)
    ms = tau_grid(longest, rate_hz, taus, d)
    if ms.size == 0:
        raise DataError(f"the longest segment ({longest} samples) is too short for {kind}")
    strides = np.array([default_stride(kind, int(m), stride, overlap) for m in ms], np.int64)
    sums = [DifferenceSums.zeros(c) for _ in ms]
    ladders = [Lag1Ladder(c, dmax=d, cross=False) for _ in ms]
    for s0, s1 in bounds:
        seg = a[s0:s1]
        if seg.shape[0] < 1:
            continue
        p = segment_phase(seg, is_int)
        for k, m in enumerate(ms):
            st = int(strides[k])
            if st == 1 and _compiled_sums(p, int(m), d, sums[k]):
                pass
            elif int(m) % st == 0:
                grid_sums(p[::st], int(m) // st, 0, sums[k], d)
            else:
                strided_sums(p, int(m), st, d, sums[k])
            # noise identification: the segment's non-overlapping m-averages (as sums)
            # (with m times the segment's first sample, removed from p, added back: every
            # segment's averages on one scale for the pooled mean of the identification)
            ladders[k].push((np.diff(p[::int(m)], axis=0) + int(m) * seg[0]).astype(np.float64))
            ladders[k].gap()
    # R(n) = MVAR/AVAR, only at the τ where the identification will read it (B1 says PM in
    # its range, at a τ keeping its own α): a second look at the record for those few, as
    # OverlappingAllan defers it. Summed at every τ of B1's range it cost an all-τ run of the
    # Cs 5071A record most of its noise identification.
    rn = rn_sums_for(kind, ms, [b - s for s, b in bounds], c)
    if alpha is None and any(r is not None for r in rn):
        read = np.zeros((len(ms), c), dtype=bool)
        alphas_from_ladders(ladders, d, None, ms,
                            np.array([x.n for x in sums], dtype=np.int64), strides, noise_id,
                            rn_read=read)
        rn = [r if r is not None and read[k].any() else None for k, r in enumerate(rn)]
    else:
        rn = [None] * len(ms)
    for s0, s1 in bounds:
        if not any(r is not None for r in rn):
            break
        seg = a[s0:s1]
        if seg.shape[0] < 1:
            continue
        p = segment_phase(seg, is_int)
        for k, m in enumerate(ms):
            rk = rn[k]
            if rk is not None and p.shape[0] > 2 * m:  # R(n): every second difference
                rk.push((p[2 * m:] - 2 * p[m:-m] + p[:-2 * m]).T.astype(np.float64))
                rk.gap()
    return finish_result(kind, rate_hz, ms, strides, sums, ladders, ci=ci, alpha=alpha,
                         one_d=one_d, names=names, rn=rn, quantiles=quantiles,
                         noise_id=noise_id, lsb=1.0 if is_int else None)


def rn_sums_for(kind: str, ms: NDArray[np.int64], segments: Sequence[int], c: int
                ) -> list[RnSums | None]:
    """R(n) sums for the τ where Stable32 may need them: fewer than ``MIN_POINTS``
    non-overlapping averages in all (B1 decides there, and R(n) where B1 says PM). None for
    the other τ, and for the cascade's kinds ("pavar", "phvar"), which keep the cascade's
    identification exactly (the stream sees every lag-m difference only up to m = S)."""
    if kind in ("pavar", "phvar"):
        return [None] * len(ms)
    return [RnSums(c, int(m)) if sum(s // int(m) for s in segments) < MIN_POINTS else None
            for m in ms]


def finish_result(
    kind: str,
    rate_hz: float,
    ms: NDArray[np.int64],
    strides: NDArray[np.int64],
    sums: Sequence[DifferenceSums],
    ladders: Sequence[Lag1Ladder],
    *,
    ci: float = 0.683,
    alpha: int | ArrayLike | None = None,
    one_d: bool = False,
    names: Sequence[str] | None = None,
    weights: ArrayLike | None = None,
    rn: Sequence[RnSums | None] | None = None,
    quantiles: str = "exact",
    noise_id: str = "avard",
    lsb: float | None = None,
) -> AllanResult:
    """Turn difference sums into an ``AllanResult`` (shared by batch and streaming).

    ``sums[k]`` holds the sums of the d-th phase differences at ``ms[k]`` (the variance),
    ``ladders[k]`` those of the non-overlapping averages (the noise identification), ``rn[k]``
    (optional) those of R(n) = MVAR/AVAR that separate white from flicker PM below 30
    averages.
    With ``weights`` (C,), the result is the single channel Σ w_c y_c, computed from the
    covariance sums.
    """
    d = KINDS[kind]
    n = np.array([x.n for x in sums], dtype=np.int64)
    s2 = np.array([x.s2 for x in sums], dtype=np.float64)
    c = s2.shape[1] if len(ms) else 0
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (c,) or not np.all(np.isfinite(w)):
            raise DataError(f"weights must be {c} finite numbers, one per channel; got {w!r}")
        s2 = np.einsum("i,kij,j->k", w, s2, w)[:, None, None]
        # the ladders keep per-channel sums only: a weighted channel's α comes from the
        # slope of its own curve
        ladders = [lad.weighted(w) for lad in ladders] if all(lad.cross for lad in ladders) \
            else [_no_ladder(lad.dmax) for lad in ladders]
        rn = None  # per-channel sums: a weighted channel has no R(n); flicker PM is taken
        one_d = True
        names = ["+".join(f"{wi:g}*{nm}" for wi, nm in zip(w, names, strict=True))] \
            if names else None
    n_phase = (np.maximum(n, 1) - 1) * strides + d * ms + 1
    alpha_id = alphas_from_ladders(ladders, d, rn, ms, n, strides, noise_id) \
        if alpha is None else None
    return result_from_sums(kind, rate_hz, ms, strides, n, s2, n_phase=n_phase, ci=ci,
                            alpha=alpha, alpha_id=alpha_id, one_d=one_d, names=names,
                            quantiles=quantiles, noise_id=noise_id, lsb=lsb)


def _no_ladder(dmax: int) -> Lag1Ladder:
    """An empty one-channel ladder: its α is NaN, so the slope of the curve decides."""
    return Lag1Ladder(1, dmax)


def alphas_from_ladders(ladders: Sequence[Lag1Ladder], d: int,
                        rn: Sequence[RnSums | None] | None = None,
                        ms: ArrayLike | None = None, n_terms: ArrayLike | None = None,
                        strides: ArrayLike | None = None, noise_id: str = "avard",
                        rn_read: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """(K, C) noise exponents identified as Stable32 does (``Lag1Ladder.alpha``): lag-1 ACF
    of the non-overlapping averages with ≥ 30 of them, B1 below, and R(n) = MVAR/AVAR from
    ``rn[k]`` (when given) where B1 says PM; NaN where neither applies.

    With ``ms``, ``n_terms`` (K,) (the estimator's count of differences per τ) and
    ``strides`` (K,), Stable32's B1 range (``noise_id.HOLD_BELOW_AVERAGES``): with fewer
    averages than the threshold (10, or 8 where the stride is shorter than m) the α of the
    next shorter τ, when it has one; and for the non-overlapping estimators (stride m) B1's
    expected values at N = ``n_terms[k]``. Not for the overlapping ones: Stable32 takes N =
    its count of overlapping differences there too (N − 2m + 1, thousands) while the measured
    ratio comes from the n averages, which reads flicker FM as white FM and random-walk FM as
    flicker FM (synthetic FM power-law noise at 20 averages: 9 of 30 right against 21 with
    N = n; tests/core/test_overlapping.py); avard keeps N = n there, and differs from
    Stable32's α at those rows (docs/analysis.md, "Checked against Stable32"), unless
    ``noise_id="stable32"`` asks for Stable32's N.

    ``rn_read`` (K, C), when given, is set True where the α returned rests on R(n): B1 says
    PM in its range and the τ's own α is kept (not the shorter τ's). An accumulator that
    defers R(n) learns from it which sums it must supply."""
    lowest = 2 - 2 * d
    if not ladders:
        return np.zeros((0, 0))
    rs = [None] * len(ladders) if rn is None else list(rn)
    mm = np.zeros(len(ladders), np.int64) if ms is None else np.asarray(ms, np.int64)
    st = None if strides is None else np.asarray(strides, np.int64)
    # B1's N: the count of differences for the non-overlapping estimators (and, under
    # noise_id="stable32", the overlapping ones too); see above
    nt: list[int | None] = [None] * len(ladders)
    overlapping_too = check_noise_id(noise_id) == "stable32"
    if n_terms is not None and st is not None:
        nt = [int(v) if int(s) >= int(m) or overlapping_too else None
              for v, s, m in zip(np.asarray(n_terms), st, mm, strict=True)]
    out = np.array([lad.alpha(lowest, None if r is None else r.ratio(), int(m), t)
                    for lad, r, m, t in zip(ladders, rs, mm, nt, strict=True)],
                   dtype=np.float64)
    if rn_read is not None:
        rn_read[...] = [lad.needs_rn(t) for lad, t in zip(ladders, nt, strict=True)]
    if ms is None or st is None:
        return out
    prev: int | None = None
    for k in np.argsort(mm, kind="stable"):  # Stable32 runs from short τ to long
        hold = HOLD_BELOW_AVERAGES[bool(st[k] < mm[k])]
        if prev is not None and ladders[k].count() < hold:
            have = np.isfinite(out[prev])
            out[k, have] = out[prev, have]
            if rn_read is not None:
                rn_read[k, have] = False  # the shorter τ's α: this τ's R(n) goes unread
        prev = int(k)
    return out


def result_from_sums(
    kind: str,
    rate_hz: float,
    ms: NDArray[np.int64],
    strides: NDArray[np.int64],
    n: NDArray[np.int64],
    s2: NDArray[np.float64],
    *,
    n_phase: NDArray[np.int64],
    ci: float = 0.683,
    alpha: int | ArrayLike | None = None,
    alpha_id: NDArray[np.float64] | None = None,
    one_d: bool = False,
    names: Sequence[str] | None = None,
    quantiles: str = "exact",
    noise_id: str = "avard",
    lsb: float | None = None,
) -> AllanResult:
    """The ``AllanResult`` of difference sums: n (K,) differences, s2 (K, C, C) = Σ D Dᵀ.

    ``alpha``: integers given by the user (validated); else ``alpha_id``, the identified
    exponents (K, C), whose NaN (too few averages) are filled from the local slope of the
    variance curve. EDF by Greenhall–Riley for ``n_phase`` phase points (SP 1065 §5.3).
    Under ``noise_id="avard"`` the identified α is constrained to what rate data can hold
    and the EDF is the least over the α the identification cannot rule out
    (``noise_id.physical_alpha_edf``; ``lsb``: the samples' rounding step in their unit, 1
    for integer counts, None when unknown: then no PM type anywhere).
    """
    d = KINDS[kind]
    k_count = len(ms)
    c = s2.shape[1] if s2.ndim == 3 else 1
    cov = covariance_from_sums(kind, ms, n, s2)
    var = np.diagonal(cov, axis1=1, axis2=2).copy() if k_count else np.zeros((0, c))
    if alpha is not None:
        alphas = _given_alphas(alpha, var, d)
    else:
        ident = np.full(var.shape, np.nan) if alpha_id is None else alpha_id
        alphas = _fill_alphas(np.asarray(ident, dtype=np.float64).reshape(var.shape), var, ms, d)
    edf = np.full_like(var, np.nan)
    physical = alpha is None and check_noise_id(noise_id) == "avard"
    for k in range(k_count):
        if n[k] == 0:
            continue
        for ch in range(c):
            if physical:  # what rate data can hold, and the least EDF it could have
                alphas[k, ch], edf[k, ch] = physical_alpha_edf(
                    int(alphas[k, ch]), float(var[k, ch]), d, int(ms[k]), int(strides[k]),
                    int(n_phase[k]), (int(n_phase[k]) - 1) // int(ms[k]), lsb)
                continue
            edf[k, ch] = edf_greenhall(int(alphas[k, ch]), d, int(ms[k]), int(strides[k]),
                                       int(n_phase[k]))
    lo, hi = chi2_interval(var, edf, ci, quantiles)
    squeeze = (lambda x: x[:, 0]) if one_d else (lambda x: x)
    return AllanResult(
        kind=kind,
        rate_hz=rate_hz,
        tau=ms / rate_hz,
        m=ms.copy(),
        stride=strides.copy(),
        var=squeeze(var),
        n=n,
        edf=squeeze(edf),
        lo=squeeze(lo),
        hi=squeeze(hi),
        alpha=squeeze(alphas.astype(np.float64)),
        ci=ci,
        cov=cov,
        names=tuple(names) if names else (),
        quantiles=quantiles,
        noise_id=noise_id,
    )


def covariance_from_sums(kind: str, ms: NDArray[np.int64], n: NDArray[np.int64],
                         s2: NDArray[np.float64]) -> NDArray[np.float64]:
    """The Allan covariance (K, C, C) of difference sums: n (K,) differences, s2 (K, C, C) =
    Σ D Dᵀ, each normalised as its kind's variance (NaN where n is 0). ``result_from_sums``'
    ``cov``, and all of it a caller that reads only the covariance needs
    (``StreamingAllan.covariance``)."""
    scale = NORM[KINDS[kind]] * ms.astype(np.float64) ** 2 * np.maximum(n, 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.where((n > 0)[:, None, None], s2 / scale[:, None, None], np.nan),
                          dtype=np.float64)


def _fill_alphas(ident: NDArray[np.float64], var: NDArray[np.float64], ms: NDArray[np.int64],
                 d: int) -> NDArray[np.int64]:
    """Identified exponents with their NaN filled from the local slope of the curve."""
    out = np.zeros(var.shape, dtype=np.int64)
    have = np.isfinite(ident)
    out[have] = ident[have].astype(np.int64)
    if not have.all():
        logv = np.log(np.where(var > 0, var, np.nan))
        logt = np.log(ms.astype(np.float64))
        for k, ch in zip(*np.nonzero(~have), strict=True):
            out[k, ch] = alpha_from_slope(_local_slope(logt, logv[:, ch], int(k)), d)
    return out


def _given_alphas(alpha: int | ArrayLike, var: NDArray[np.float64], d: int
                  ) -> NDArray[np.int64]:
    """A user's noise exponents, one value, one per τ or one per (τ, channel), validated."""
    lowest = 2 - 2 * d  # alpha + 2d > 1
    given = np.asarray(alpha, dtype=np.float64)
    if given.ndim == 1 and var.ndim == 2 and given.shape[0] == var.shape[0]:
        given = given[:, None]  # one alpha per τ, the same for every channel
    try:
        a = np.broadcast_to(given, var.shape).astype(np.float64)
    except ValueError as exc:
        raise DataError(f"alpha has shape {given.shape}; give one value, one per τ "
                        f"({var.shape[0]}), or one per τ and channel {var.shape}") from exc
    if not np.all(np.isfinite(a)) or np.any(np.rint(a) != a):
        raise DataError("alpha must be integers (2 white PM … -2 random-walk FM)")
    if np.any(a > 2) or np.any(a < lowest):
        raise DataError(f"alpha must lie in [{lowest}, 2] for this estimator")
    return a.astype(np.int64)


def _local_slope(logt: NDArray[np.float64], logv: NDArray[np.float64], k: int) -> float:
    """Slope of log var against log τ around point k, from its finite neighbours."""
    idx = [i for i in (k - 1, k, k + 1) if 0 <= i < logt.size and np.isfinite(logv[i])]
    if len(idx) < 2:
        return math.nan
    x, yv = logt[idx], logv[idx]
    x = x - x.mean()
    den = float(np.dot(x, x))
    return float(np.dot(x, yv - yv.mean()) / den) if den > 0 else math.nan


def _segment_bounds(n_total: int, gaps: Sequence[int] | None) -> list[tuple[int, int]]:
    if not gaps:
        return [(0, n_total)]
    g = sorted({int(i) for i in gaps})
    if g[0] < 0 or g[-1] > n_total:
        raise DataError(f"gaps must be sample indices within 0..{n_total}; got {list(gaps)}")
    edges = [0, *[i for i in g if 0 < i < n_total], n_total]
    return list(itertools.pairwise(edges))


def avar(y: ArrayLike, rate_hz: float, taus: str | ArrayLike = "octave", **kw) -> AllanResult:
    """Non-overlapping Allan variance (NIST SP 1065 eq. 11); see ``allan_variance``."""
    return allan_variance(y, rate_hz, taus, kind="avar", **kw)


def oavar(y: ArrayLike, rate_hz: float, taus: str | ArrayLike = "octave", **kw) -> AllanResult:
    """Fully overlapping Allan variance (NIST SP 1065 eq. 12); see ``allan_variance``."""
    return allan_variance(y, rate_hz, taus, kind="oavar", **kw)


def pavar(y: ArrayLike, rate_hz: float, taus: str | ArrayLike = "octave", **kw) -> AllanResult:
    """Partially overlapping Allan variance (stride between 1 and m); see ``allan_variance``."""
    return allan_variance(y, rate_hz, taus, kind="pavar", **kw)


def phvar(y: ArrayLike, rate_hz: float, taus: str | ArrayLike = "octave", **kw) -> AllanResult:
    """Hadamard variance with a stride (default the cascade's m/8); see ``allan_variance``."""
    return allan_variance(y, rate_hz, taus, kind="phvar", **kw)


def ohvar(y: ArrayLike, rate_hz: float, taus: str | ArrayLike = "octave", **kw) -> AllanResult:
    """Overlapping Hadamard variance (NIST SP 1065 eq. 18); see ``allan_variance``."""
    return allan_variance(y, rate_hz, taus, kind="ohvar", **kw)


def checked_block(block: ArrayLike, n_channels: int, integer: bool | None
                  ) -> tuple[NDArray, bool | None]:
    """A block for a streaming Allan accumulator, checked: (n, C) (or (n,) for one channel),
    finite, numeric; integer counts stay integers (exact int64 sums), floats become float64.
    ``integer`` is the accumulator's kind so far (None until its first non-empty block); the
    kind in force is returned with the block. Shared by ``StreamingAllan`` and
    ``OverlappingAllan``, so both take and refuse the same input."""
    a = np.asarray(block)
    c = n_channels
    if a.ndim == 1 and c == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[1] != c:
        raise DataError(f"block has shape {a.shape}; this accumulator takes (n, {c})"
                        + (" or (n,)" if c == 1 else ""))
    if a.dtype.kind == "b":
        a = a.astype(np.int64)
    if a.dtype.kind not in "iuf":
        raise DataError(f"block has dtype {a.dtype}; pass float or integer samples")
    if integer is None and a.shape[0]:
        integer = a.dtype.kind in "iu"
    if a.dtype.kind == "f":
        i = first_nonfinite_row(a)  # one reduction for a finite block
        if i is not None:
            raise DataError(f"block sample {i} is NaN or infinite; drop such samples and call "
                            "gap() where they were")
        if integer:
            if np.any(a != np.rint(a)):
                raise DataError("this accumulator was started with integer counts and got "
                                "fractional samples; use one kind of input per accumulator")
            return a.astype(np.int64), integer
        return a.astype(np.float64, copy=False), integer
    if not integer:
        return a.astype(np.float64), integer
    if a.dtype.kind == "u" and a.dtype.itemsize >= 8 and a.size and a.max() >= 2**62:
        raise DataError("unsigned 64-bit samples this large cannot be summed in int64")
    return a, integer  # narrower integers: the caller widens them to int64 as it sums
