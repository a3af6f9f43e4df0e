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
  The streaming accumulator (``avard.core.streaming``) uses the same grid, so the two agree to
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
from numpy.typing import ArrayLike, NDArray

from .edf import chi2_interval, edf_greenhall
from .errors import DataError, FormatError
from .noise_id import MIN_POINTS, alpha_from_lag1, alpha_from_slope, identify_alpha
from .scratch import ones, scratch

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
    for the noise exponent ``alpha`` (see ``avard.core.edf``).
    ``cov`` (K, C, C), when present, is the Allan covariance: AVAR of Σ w_c y_c = w·cov·w.
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
                     "names": list(self.names)}
        for key in ("tau", "m", "stride", "var", "n", "edf", "lo", "hi", "alpha"):
            out[key] = np.asarray(getattr(self, key)).tolist()
        out["cov"] = None if self.cov is None else self.cov.tolist()
        return out

    @classmethod
    def from_dict(cls, d: dict) -> AllanResult:
        """Inverse of ``to_dict``; also reads ``AllanSnapshot.to_dict()`` (its "avar" is
        ``var``; kind "pavar" when absent). Raises ``FormatError`` naming a missing key."""
        try:
            var = np.asarray(d["var"] if "var" in d else d["avar"], dtype=np.float64)
            cov = d.get("cov")
            return cls(
                kind=str(d.get("kind", "pavar")),
                rate_hz=float(d["rate_hz"]),
                tau=np.asarray(d["tau"], dtype=np.float64),
                m=np.asarray(d["m"], dtype=np.int64),
                stride=np.asarray(d["stride"], dtype=np.int64),
                var=var,
                n=np.asarray(d["n"], dtype=np.int64),
                edf=np.asarray(d["edf"], dtype=np.float64),
                lo=np.asarray(d["lo"], dtype=np.float64),
                hi=np.asarray(d["hi"], dtype=np.float64),
                alpha=np.asarray(d["alpha"], dtype=np.float64),
                ci=float(d.get("ci", 0.683)),
                cov=None if cov is None else np.asarray(cov, dtype=np.float64),
                names=tuple(d.get("names", ())),
            )
        except KeyError as exc:
            raise FormatError(f"Allan result/snapshot dict lacks {exc}; it is not one") from exc


@dataclass
class DifferenceSums:
    """Running sums of the order-o phase differences Q at one (m, stride), for C channels.

    Full grid (every difference, used for the variance of the highest order only):
    n, the number of differences, and s2 (C, C) = Σ Q Qᵀ.
    Subgrid for the lag-1 ACF noise identification (differences Q_j whose start j is a
    multiple of ``id_period`` grid points from the segment start): na, s1 (C,) = Σ Q_j,
    sa (C, C) = Σ Q_j Q_jᵀ, and nl pairs with lag (C, C) = Σ Q_{j−m} Q_jᵀ, Q_{j−m} being the
    difference one τ earlier. Q_{j−m} and Q_j are built from adjacent, non-overlapping
    m-averages as NIST SP 1065 §5.6 asks; the subgrid takes one such pair in every
    max(m, 8) samples, which keeps the cost of the identification at short τ below that of
    the variance itself (there are millions of pairs there; the ACF needs about 30).
    """

    n: int
    s2: NDArray[np.float64]
    na: int
    s1: NDArray[np.float64]
    sa: NDArray[np.float64]
    nl: int
    lag: NDArray[np.float64]

    @classmethod
    def zeros(cls, c: int) -> DifferenceSums:
        return cls(0, np.zeros((c, c)), 0, np.zeros(c), np.zeros((c, c)), 0, np.zeros((c, c)))

    FIELDS = ("n", "s2", "na", "s1", "sa", "nl", "lag")

    def add(self, other: DifferenceSums) -> None:
        for f in self.FIELDS:
            setattr(self, f, getattr(self, f) + getattr(other, f))

    def add_subgrid(self, sel: NDArray, prev: NDArray | None) -> None:
        """Add subgrid differences ``sel`` and, if given, their lag partners ``prev``."""
        # Row-strided views would send matmul down numpy's slow non-BLAS loop: copy them
        # (into reused buffers, see avard.core.scratch).
        sel = _contiguous(sel, "sel")
        if sel.shape[0]:
            self.na += sel.shape[0]
            self.s1 += ones(sel.shape[0]) @ sel
            self.sa += gram(sel)
        if prev is not None and prev.shape[0]:
            prev = _contiguous(prev, "prev")
            self.nl += prev.shape[0]
            self.lag += prev.T @ sel[sel.shape[0] - prev.shape[0] :]


def gram(a: NDArray) -> NDArray[np.float64]:
    """aᵀa made exactly symmetric (BLAS may round the two triangles differently), so that a
    state can store one triangle and still restore bit for bit."""
    g = a.T @ a
    return 0.5 * (g + g.T)


def _contiguous(a: NDArray, key: str) -> NDArray:
    """A C-contiguous copy of a row-strided (k, C) view, in a reused buffer."""
    if a.flags.c_contiguous:
        return a
    out = scratch(key, a.shape[0], a.shape[1], a.dtype)
    if a.strides[1] == a.itemsize:
        # Copy whole rows as opaque items: numpy's 2-D copy loop pays per row of C values,
        # which made this copy cost twice the Gram matrix computed from it.
        row = np.dtype((np.void, a.itemsize * a.shape[1]))
        np.copyto(out.view(row)[:, 0], a.view(row)[:, 0])
    else:
        np.copyto(out, a)
    return out


ID_MIN_PERIOD = 8  # grid points between noise-identification pairs, at least


def id_period(sp: int) -> int:
    """Subgrid period (grid points) for the noise-identification sums: a multiple of sp ≥ 8."""
    return sp * -(-ID_MIN_PERIOD // sp)


def grid_sums(
    q: NDArray, sp: int, h: int, sums: Sequence[DifferenceSums], d: int, base: int = 0
) -> None:
    """Add the sums of phase differences of orders 1 … d taken on one stride grid.

    ``q`` (L, C) holds phase points X on a grid of constant stride (consecutive rows are
    ``stride`` samples apart), int64 (exact) or float64; rows from index ``h`` on are new, and
    q[0] is grid point number ``base`` of its segment. With sp = m / stride the order-o
    difference is computed recursively, E_j = q[j+sp] − q[j] (o = 1; m times an m-average of
    the rate) and Q^o_j = Q^{o−1}_{j+sp} − Q^{o−1}_j, for j ∈ [0, L − o·sp). A difference is
    counted when it is new (its last point j + o·sp ≥ h). The recursion gives the same numbers
    for any split of the grid into blocks, which is what makes streaming equal batch. Works
    in chunks of j so that memory stays bounded on long records.
    """
    length = q.shape[0]
    n_e = length - sp  # number of first differences E
    if n_e <= 0:
        return
    chunk = max(_CHUNK, sp)
    period = id_period(sp)
    a = max(0, h - d * sp)
    while a < n_e:
        b = min(n_e, a + chunk)
        lo = max(0, a - sp)  # room for the lag partners of the chunk's first differences
        hi = min(n_e, b + (d - 1) * sp)  # E needed to build order d up to b
        c = q.shape[1]
        arr = np.subtract(q[lo + sp : hi + sp], q[lo:hi], out=scratch("e", hi - lo, c, q.dtype))
        if arr.dtype != np.float64:
            as_float = scratch("ef", hi - lo, c, np.float64)
            np.copyto(as_float, arr)  # exact: integer differences are far below 2**53
            arr = as_float
        for o in range(1, d + 1):
            if o > 1:  # covers j ∈ [lo, hi − (o−1)·sp)
                out = scratch(f"q{o}", max(0, arr.shape[0] - sp), c, np.float64)
                arr = np.subtract(arr[sp:], arr[:-sp], out=out)
            s = sums[o - 1]
            new0 = max(a, h - o * sp, 0)
            new1 = min(b, length - o * sp)
            if new1 <= new0:
                continue
            if o == d:
                rows = arr[new0 - lo : new1 - lo]
                s.n += new1 - new0
                s.s2 += gram(rows)
            # noise-identification subgrid: every `period`-th grid point of the segment
            first = new0 + (-(new0 + base)) % period
            if first >= new1:
                continue
            sel = arr[first - lo : new1 - lo : period]
            f_lag = first if first - sp >= 0 else first + period
            prev = arr[f_lag - sp - lo : new1 - sp - lo : period] if f_lag < new1 else None
            s.add_subgrid(sel, prev)
        a = b


def strided_sums(p: NDArray, m: int, stride: int, d: int, sums: Sequence[DifferenceSums]) -> None:
    """``grid_sums`` for a stride that does not divide m (batch only, whole segment).

    Differences D_i = Σ_k c_k p[i + k·m] at i = 0, stride, 2·stride, …; the noise-
    identification pairs are (D_i, D_{i+q·stride}) with q = round(m/stride), at every
    id_period(q)-th grid point.
    """
    length = p.shape[0]
    every = id_period(max(1, round(m / stride)))
    for o in range(1, d + 1):
        last = length - 1 - o * m
        if last < 0:
            continue
        coefs = COEFS[o]
        s = sums[o - 1]
        if o == d:
            count = last // stride + 1
            for t in range(0, count, _CHUNK):
                j0 = t * stride
                stop = (min(count, t + _CHUNK) - 1) * stride + 1
                dd = sum(c * p[j0 + k * m : stop + k * m : stride] for k, c in enumerate(coefs))
                dd = np.asarray(dd, dtype=np.float64)
                s.n += dd.shape[0]
                s.s2 += gram(dd)
        step = every * stride
        lag_step = max(1, round(m / stride)) * stride  # one τ later, on the stride grid
        sub = np.asarray(sum(c * p[k * m : last + 1 + k * m : step]
                             for k, c in enumerate(coefs)), dtype=np.float64)
        lagged = np.asarray(sum(c * p[k * m + lag_step : last + 1 + k * m : step]
                                for k, c in enumerate(coefs)), dtype=np.float64)
        s.add_subgrid(lagged, sub[: lagged.shape[0]])


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
        Noise exponent for the EDF; by default identified per τ and channel from the lag-1
        autocorrelation of the differences (≥ 30 independent averages), else the local slope.
    gaps : sample indices at which a new segment starts; no difference straddles a gap.
    names : channel names, kept in the result.

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
    sums = [[DifferenceSums.zeros(c) for _ in range(d)] for _ in ms]
    for s0, s1 in bounds:
        seg = a[s0:s1]
        if seg.shape[0] < 1:
            continue
        p = segment_phase(seg, is_int)
        for k, m in enumerate(ms):
            st = int(strides[k])
            if int(m) % st == 0:
                grid_sums(p[::st], int(m) // st, 0, sums[k], d)
            else:
                strided_sums(p, int(m), st, d, sums[k])
    return finish_result(kind, rate_hz, ms, strides, sums, ci=ci, alpha=alpha,
                         one_d=one_d, names=names)


def finish_result(
    kind: str,
    rate_hz: float,
    ms: NDArray[np.int64],
    strides: NDArray[np.int64],
    sums: Sequence[Sequence[DifferenceSums]],
    *,
    ci: float = 0.683,
    alpha: int | ArrayLike | None = None,
    one_d: bool = False,
    names: Sequence[str] | None = None,
    weights: ArrayLike | None = None,
) -> AllanResult:
    """Turn difference sums into an ``AllanResult`` (shared by batch and streaming).

    ``sums[k][q]`` holds the sums of the (q+1)-th phase differences at ``ms[k]``; the last
    order (d) gives the variance, all orders feed the lag-1 ACF noise identification.
    With ``weights`` (C,), the result is the single channel Σ w_c y_c, computed from the
    covariance sums.
    """
    d = KINDS[kind]
    norm = NORM[d]
    k_count = len(ms)
    # stacked[q][field] = array over τ of DifferenceSums field, for difference order q+1
    stacked = []
    for q in range(d):
        col = [s[q] for s in sums]
        stacked.append({
            f: np.array([getattr(s, f) for s in col],
                        dtype=np.int64 if f in ("n", "na", "nl") else np.float64)
            for f in DifferenceSums.FIELDS
        })
    c = stacked[0]["s2"].shape[1] if k_count else 0
    if weights is not None:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (c,) or not np.all(np.isfinite(w)):
            raise DataError(f"weights must be {c} finite numbers, one per channel; got {w!r}")
        for st in stacked:
            st["s1"] = (st["s1"] @ w)[:, None]
            for f in ("s2", "sa", "lag"):
                st[f] = np.einsum("i,kij,j->k", w, st[f], w)[:, None, None]
        c = 1
        one_d = True
        names = ["+".join(f"{wi:g}*{nm}" for wi, nm in zip(w, names, strict=True))] \
            if names else None
    n, s2 = stacked[d - 1]["n"], stacked[d - 1]["s2"]
    scale = norm * ms.astype(np.float64) ** 2 * np.maximum(n, 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = np.where((n > 0)[:, None, None], s2 / scale[:, None, None], np.nan)
    var = np.diagonal(cov, axis1=1, axis2=2).copy() if k_count else np.zeros((0, c))
    alphas = _alphas(alpha, var, ms, strides, stacked, d)
    edf = np.full_like(var, np.nan)
    for k in range(k_count):
        if n[k] == 0:
            continue
        n_phase = (int(n[k]) - 1) * int(strides[k]) + d * int(ms[k]) + 1
        for ch in range(c):
            edf[k, ch] = edf_greenhall(int(alphas[k, ch]), d, int(ms[k]), int(strides[k]),
                                       n_phase)
    lo, hi = chi2_interval(var, edf, ci)
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
    )


def _alphas(
    alpha: int | ArrayLike | None,
    var: NDArray[np.float64],
    ms: NDArray[np.int64],
    strides: NDArray[np.int64],
    stacked: list,
    d: int,
) -> NDArray[np.int64]:
    """Noise exponent per (τ, channel): given, else lag-1 ACF of the differences, else slope.

    The lag-1 ACF ladder of Riley & Greenhall (2004) on m-averages of the rate: k = 0 uses
    the averages themselves (first phase differences), k = 1 their first differences (second
    phase differences), …; stop at the first k whose δ = r1/(1+r1) is below 0.25, or at
    k = d − 1, and take alpha = −2(δ + k). The means are removed; a linear rate drift is
    not, so it pushes the ladder one step further, where it becomes a constant.
    """
    lowest = 2 - 2 * d  # alpha + 2d > 1
    if alpha is not None:
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
    k_count, c = var.shape
    out = np.zeros((k_count, c), dtype=np.int64)
    have = np.zeros((k_count, c), dtype=bool)
    for k in range(k_count):
        for ch in range(c):
            a = _ladder(stacked, k, ch, int(ms[k]), int(strides[k]), d)
            if math.isfinite(a):
                out[k, ch] = int(min(2, max(lowest, round(a))))
                have[k, ch] = True
    if not have.all():
        logv = np.log(np.where(var > 0, var, np.nan))
        logt = np.log(ms.astype(np.float64))
        for k in range(k_count):
            for ch in range(c):
                if have[k, ch]:
                    continue
                out[k, ch] = alpha_from_slope(_local_slope(logt, logv[:, ch], k), d)
    return out


def _ladder(stacked: list, k: int, ch: int, m: int, stride: int, d: int) -> float:
    """alpha from the lag-1 ACF ladder at τ index k, channel ch; NaN if the data are too few."""
    for q in range(d):
        na, s1, sa, nl, lag = (stacked[q][f][k] for f in ("na", "s1", "sa", "nl", "lag"))
        # Non-overlapping m-averages behind the sums; the ACF needs about 30 (Riley & Greenhall).
        if na < MIN_POINTS or nl == 0:
            return math.nan
        mean = s1[ch] / na
        v = sa[ch, ch] / na - mean**2
        if not v > 0:
            return math.nan
        r1 = (lag[ch, ch] / nl - mean**2) / v
        if not math.isfinite(r1) or r1 <= -1.0:
            return math.nan
        delta = r1 / (1.0 + r1)
        if delta < 0.25 or q == d - 1:
            return alpha_from_lag1(r1, q)
    return math.nan


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
