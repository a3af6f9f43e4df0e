"""Power-law noise identification as Stable32 does it, one implementation for every estimator.

The EDF of a variance estimate depends on the noise type at each τ (see ``avard.core.allan.edf``).
Stable32 identifies it (W. J. Riley and C. A. Greenhall, "Power law noise identification
using the lag 1 autocorrelation", Proc. 18th EFTF (2004); NIST SP 1065 §5.6):

* ≥ 30 averages — lag-1 ACF: average the rate data in blocks of m, difference the averages
  k times until the lag-1 autocorrelation r1 (about the mean) is small, then
  δ = r1 / (1 + r1) and alpha = −2(δ + k) (rate data). White rate noise gives r1 = 0 at
  k = 0; each difference of a white sequence gives r1 = −1/2. ``Lag1Ladder`` keeps the sums.
* 4–29 averages — Barnes' B1 ratio (sample variance over two-sample variance of the
  averages, NBS TN 375), which cannot tell white PM from flicker PM; where it says PM, the
  R(n) = MVAR/AVAR ratio does (``RnSums``, ``alpha_from_rn``). Its expected values are taken
  at N = the estimator's count of differences, and below 10 averages (8 for overlapping
  estimators) the α of the next shorter τ is kept, as Stable32's output shows it does
  (``HOLD_BELOW_AVERAGES``; applied by ``deviations.alphas_from_ladders``).
* fewer than 4 with no shorter τ — the local log-log slope of the curve
  (``alpha_from_slope``; noisy, and blind to white against flicker PM).

``identify_alpha`` is the lag-1 rung on an array, through the same ``Lag1Ladder``.
"""

from __future__ import annotations

import itertools
import math
from functools import lru_cache
from math import comb
from typing import NamedTuple

import numpy as np
from avard.core.allan import kernels
from avard.core.allan.scratch import mapped_zeros, scratch
from avard.core.errors import DataError
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "HOLD_BELOW_AVERAGES",
    "Lag1Ladder",
    "RnSums",
    "alpha_from_b1",
    "alpha_from_lag1",
    "alpha_from_rn",
    "alpha_from_slope",
    "b1_theory",
    "fm_support_edf",
    "identify_alpha",
    "lag1_acf",
    "physical_alpha_edf",
    "plausible_alphas",
    "pm_possible",
    "rn_flicker_pm",
    "row_products",
]

# Riley & Greenhall: below this many (averaged) points the lag-1 ACF is too noisy to use.
MIN_POINTS = 30

# Stable32's B1 range, as its output shows it (the rule is not published; these three
# reproduce Stable32's α at every one of the 443 rows with 4 to 29 averages of its published
# runs: PHASE.DAT's ADEV, OADEV, HDEV, OHDEV at every AF, the Cs 5071A, 53230A, GPS, OCXO and
# pink-noise runs; tests/core/test_stable32_datasets.py, docs/analysis.md):
# * the expected B1(N, μ) is taken at N = the estimator's count of differences ('#' in its
#   tables: N − 2m + 1 for OADEV, n − 1 for ADEV of n averages), not at the n averages the
#   measured ratio comes from, so overlapping and non-overlapping runs can differ in α at
#   one τ from the same averages (``Lag1Ladder.alpha``'s ``n_terms``);
# * with fewer averages than these, no identification: the α of the next shorter τ of the
#   run is kept (non-overlapping estimators, overlapping ones).
HOLD_BELOW_AVERAGES = {False: 10, True: 8}
# The rules of identification (``--noise-id``):
# * "avard" (default): what an accelerometer's rate data can hold. "powerlaw"'s identification,
#   with PM types only where the rounding to the LSB can produce them (``pm_possible``; FM
#   elsewhere, so no EDF above what any FM type gives), and the EDF the least over the types
#   the identification's own sampling spread cannot rule out (``physical_alpha_edf``);
# * "powerlaw": every power-law type, Stable32's ladder with one change, B1's N for the
#   overlapping estimators (stride < m) = the count of averages the measured ratio comes
#   from (docs/analysis.md, "Checked against Stable32"); for clock (phase) data;
# * "stable32": N = the estimator's count of overlapping differences, as Stable32 takes it,
#   which reproduces its printed α (and so its bounds) at every row of its runs, and reads
#   FM noise one type too white with 4–29 averages.
# The non-overlapping estimators take N = their count of differences under all three.
NOISE_IDS = ("avard", "powerlaw", "stable32")


def check_noise_id(noise_id: str) -> str:
    """``noise_id`` if it names a rule of ``NOISE_IDS``; else a ``DataError`` that says so."""
    if noise_id not in NOISE_IDS:
        raise DataError(f"noise_id={noise_id!r} is unknown; use one of {NOISE_IDS}")
    return noise_id


def lag1_acf(x: ArrayLike) -> float:
    """Lag-1 autocorrelation r1 = Σ (x_i − x̄)(x_{i+1} − x̄) / Σ (x_i − x̄)² (NIST SP 1065 §5.6)."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1 or a.size < 3:
        raise DataError(f"lag-1 autocorrelation needs a 1-D series of >= 3 points, got {a.shape}")
    c = a - a.mean()
    den = float(np.dot(c, c))
    if den == 0.0:
        return math.nan
    return float(np.dot(c[:-1], c[1:])) / den


def alpha_from_lag1(r1: float, k: int) -> float:
    """Noise exponent alpha (rate data) from r1 of rate averages differenced k times.

    δ = r1 / (1 + r1), alpha = −2(δ + k) (Riley & Greenhall 2004, eq. 4). Returns a float; the
    caller rounds. NaN when r1 is not finite or r1 ≤ −1.
    """
    if not math.isfinite(r1) or r1 <= -1.0:
        return math.nan
    delta = r1 / (1.0 + r1)
    return -2.0 * (delta + k)


def alpha_from_slope(mu: float, d: int = 2) -> int:
    """Noise exponent from the local log-log slope μ of an AVAR (d=2) or HVAR (d=3) curve.

    μ = −alpha − 1 for alpha ≤ 1; μ ≤ −2 is reported as white PM (alpha = 2) because flicker
    and white PM cannot be told apart from the slope. Clipped to the range the estimator
    converges for (alpha ≥ −2 for d = 2, ≥ −4 for d = 3).
    """
    lowest = 1 - 2 * d + 1  # alpha + 2d > 1
    if not math.isfinite(mu):
        return 0
    if mu <= -1.75:
        return 2
    return int(min(1, max(lowest, round(-mu - 1.0))))


def identify_alpha(
    y: ArrayLike, m: int, *, dmax: int = 2, data_type: str = "rate"
) -> int:
    """Dominant power-law noise exponent at averaging factor m by the lag-1 ACF method.

    The same computation as every Allan estimator's (``Lag1Ladder``, fed the non-overlapping
    m-averages): the lag-1 autocorrelation about the mean (no detrending), differenced while
    δ = r1/(1+r1) ≥ 0.25, at most ``dmax`` times. Phase data are differenced to rate first:
    the m-averages of the rate are the differences of the phase decimated by m, so that is
    Stable32's ladder on the decimated phase one rung down.

    Parameters
    ----------
    y : array (N,)
        Rate samples (``data_type="rate"``, the accelerometer convention, = fractional
        frequency) or phase samples (``"phase"``).
    m : int
        Averaging factor.
    dmax : int
        Most differences to take: 2 for Allan variance, 3 for Hadamard variance.

    Returns
    -------
    int
        alpha rounded to an integer in [−2·dmax + 2, 2]: 2 white PM, 1 flicker PM, 0 white FM,
        −1 flicker FM, −2 random-walk FM, … (0 for a constant series, which has no noise).
        Raises ``DataError`` when fewer than 30 averages are available (Stable32 uses B1 and
        R(n) there: ``allan_variance`` does; or ``alpha_from_slope`` on the variance curve).
    """
    a = np.asarray(y, dtype=np.float64)
    if a.ndim != 1:
        raise DataError(f"identify_alpha takes one channel (1-D array), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DataError("identify_alpha got NaN or infinite samples; remove them first")
    m = int(m)
    if m < 1:
        raise DataError(f"averaging factor m={m} must be >= 1")
    if data_type == "phase":
        a = np.diff(a)
    elif data_type != "rate":
        raise DataError(f"data_type={data_type!r} must be 'rate' or 'phase'")
    n = a.size // m
    if n < MIN_POINTS:
        raise DataError(
            f"only {n} averages of {m} samples: the lag-1 ACF needs >= {MIN_POINTS}; "
            "use a smaller m or alpha_from_slope"
        )
    ladder = Lag1Ladder(1, dmax=int(dmax), cross=False)
    ladder.push(a[: n * m].reshape(n, m).sum(axis=1))  # sums of m: as the estimators feed it
    alpha = float(ladder.lag1_alpha(2 - 2 * int(dmax))[0])
    return int(alpha) if math.isfinite(alpha) else 0


# ---------------------------------------------------------------------------------------------
# Stable32's identification on running sums: one implementation for every estimator


def b1_theory(n: int, mu: int) -> float:
    """Barnes' expected B1 ratio (N-sample over two-sample variance) for N averages and a
    variance exponent μ (AVAR ∝ τ^μ): N(1 − N^μ) / (2(N − 1)(1 − 2^μ)), and its limit
    N ln N / (2(N − 1) ln 2) at μ = 0 (NBS TN 375; NIST SP 1065 §5.2)."""
    if n < 2:
        raise DataError(f"B1 needs at least 2 averages, got {n}")
    if mu == 0:
        return n * math.log(n) / (2.0 * (n - 1) * math.log(2.0))
    return n * (1.0 - float(n) ** mu) / (2.0 * (n - 1) * (1.0 - 2.0**mu))


def alpha_from_b1(b1: float, n: int) -> int | None:
    """Noise exponent from a measured B1 ratio of n averages: the μ whose expected B1 is
    nearest on a log scale (boundaries at the geometric means, as Stable32), mapped to
    alpha = −μ − 1. μ = −2 (white or flicker PM) returns None: B1 cannot tell them apart."""
    mus = (1, 0, -1, -2)  # random-walk FM, flicker FM, white FM, PM
    for hi, lo in itertools.pairwise(mus):
        if b1 > math.sqrt(b1_theory(n, hi) * b1_theory(n, lo)):
            return -hi - 1
    return None


def rn_flicker_pm(m: int) -> float:
    """Expected R(n) = MVAR/AVAR for flicker PM at averaging factor m: the ratio of the two
    asymptotic responses tabulated in NIST SP 1065 (and IEEE Std 1139-2008),
    MVAR = 3 ln(256/27) h₁ / (8π²τ²) and AVAR = [1.038 + 3 ln(2π f_h τ)] h₁ / (4π²τ²), with the
    measurement bandwidth f_h = 1/(2τ0) (the samples' Nyquist frequency), so 2π f_h τ = π m."""
    return 1.5 * math.log(256.0 / 27.0) / (1.038 + 3.0 * math.log(math.pi * m))


def alpha_from_rn(rn: float, m: int) -> int | None:
    """White (2) or flicker (1) PM from a measured R(n) = MVAR/AVAR at averaging factor m
    (Stable32's test where B1 says 'PM'; NIST SP 1065 §5.6): R(n) = 1/m for white PM, and
    ``rn_flicker_pm(m)`` for flicker PM; the boundary is their geometric mean, as for B1.
    None where R(n) cannot separate them (m so small that both expectations meet, or R(n)
    not finite)."""
    white, flicker = 1.0 / m, rn_flicker_pm(m)
    if not math.isfinite(rn) or flicker <= 1.5 * white:
        return None
    return 2 if rn < math.sqrt(white * flicker) else 1


def _row_dots(a: NDArray, b: NDArray) -> NDArray[np.float64]:
    """Σ_t a[i, t]·b[i, t] per row, by BLAS dot (4× einsum's speed on long rows)."""
    return np.array([float(np.dot(a[i], b[i])) for i in range(a.shape[0])])


class RnSums:
    """The sums behind R(n) = MVAR/AVAR at one averaging factor m, C channels at once.

    Fed the second phase differences D_i = X_{i+2m} − 2X_{i+m} + X_i of a segment at every i,
    in order (any split), it keeps Σ D² (the overlapping AVAR, NIST SP 1065 eq. 12) and
    Σ w_i² with w_i = Σ_{j=i}^{i+m−1} D_j (the modified AVAR, SP 1065 eq. 14: the same
    differences averaged over m consecutive starts). w_i = P_{i+m} − P_i with P the running
    sum of D, so a ring of the last m values of P is all the history it needs: O(m) memory and
    O(k) work for k new differences, whatever m. ``gap()`` ends the segment. Only estimators
    that see every difference at lag m can feed it (batch, the fully overlapping stream); the
    cascade above m = S cannot.
    """

    def __init__(self, n_channels: int, m: int) -> None:
        self.m = int(m)
        self.c = int(n_channels)
        self.n_d = 0
        self.s_d = np.zeros(self.c)
        self.n_mod = 0
        self.s_mod = np.zeros(self.c)
        self._ring: NDArray[np.float64] | None = None  # P_k at slot k mod m, last m of them
        self._gap_reset()

    def _gap_reset(self) -> None:
        self._k = 0  # differences seen in this segment (P_0 = 0 … P_k known)
        self._last = np.zeros(self.c)  # P_k
        if self._ring is not None:
            self._ring[:, 0] = 0.0

    def push(self, d: NDArray) -> None:
        """Add the next differences (C, k), channel-major, oldest first."""
        d = np.asarray(d, dtype=np.float64).reshape(self.c, -1)
        n = d.shape[1]
        if n == 0:
            return
        m, k = self.m, self._k
        if self._ring is None:
            self._ring = mapped_zeros((self.c, m))
        self.n_d += n
        self.s_d += _row_dots(d, d)
        p_new = np.cumsum(d, axis=1)  # P_{k+1} … P_{k+n}: the running sum is the costly pass
        p_new += self._last[:, None]
        e0, e1 = max(k + 1, m), k + n  # windows ending at a new P: w = P_e − P_{e−m}
        if e1 >= e0:
            w = p_new[:, e0 - k - 1:e1 - k].copy()
            s0, s1 = e0 - m, e1 - m  # their starts
            split = min(s1, k) + 1  # starts below it are in the ring, the rest new
            if split > s0:
                w[:, :split - s0] -= self._ring_read(s0, split - s0)
            if s1 >= split:
                w[:, split - s0:] -= p_new[:, split - k - 1:s1 - k]
            self.n_mod += w.shape[1]
            self.s_mod += _row_dots(w, w)
        last = min(n, m)
        self._ring_write(k + n - last + 1, p_new[:, n - last:])
        self._k = k + n
        self._last = p_new[:, -1].copy()

    def push_phase(self, x0: NDArray[np.float64], x1: NDArray[np.float64],
                   x2: NDArray[np.float64]) -> NDArray[np.float64]:
        """``push`` of D = (x2 − x1) − (x1 − x0) for phase spans (C, k) X_i, X_{i+m},
        X_{i+2m}, returning Σ D² per channel (the overlapping AVAR's sum, which the caller
        also needs). With the compiled kernel D never leaves the registers: one pass instead
        of the seven of numpy's D, running sum, moving sums and dots (a test holds the two
        equal)."""
        kern = kernels.compiled()
        if kern is None:
            d = kernels.second_differences(x0, x1, x2)
            self.push(d)
            return _row_dots(d, d)
        n = x0.shape[1]
        if self._ring is None:
            self._ring = mapped_zeros((self.c, self.m))
        out = np.empty(self.c)
        n_mod = 0
        for ch in range(self.c):
            s_d, s_mod, n_mod, last = kern.sumsq_mod(x0[ch], x1[ch], x2[ch], self._ring[ch],
                                                     self._k, float(self._last[ch]))
            out[ch] = s_d
            self.s_mod[ch] += s_mod
            self._last[ch] = last
        self.n_d += n
        self.s_d += out
        self.n_mod += n_mod
        self._k += n
        return out

    def _ring_read(self, start: int, length: int) -> NDArray[np.float64]:
        """P_start … P_{start+length−1} (all within the last m), as two slices at most."""
        assert self._ring is not None
        i = start % self.m
        if i + length <= self.m:
            return self._ring[:, i:i + length]
        return np.concatenate([self._ring[:, i:], self._ring[:, :i + length - self.m]], axis=1)

    def _ring_write(self, start: int, values: NDArray) -> None:
        assert self._ring is not None
        i, length = start % self.m, values.shape[1]
        first = min(length, self.m - i)
        self._ring[:, i:i + first] = values[:, :first]
        self._ring[:, :length - first] = values[:, first:]

    def gap(self) -> None:
        """End the segment: no moving sum spans what follows."""
        self._gap_reset()

    def take_channel(self, ch: int, other: RnSums, of: int = 0) -> None:
        """Channel ``ch`` of these sums from channel ``of`` of ``other`` (the same m, fed
        the same differences in a pass of its own: the counts are the same for every
        channel of a record)."""
        if other.m != self.m:
            raise DataError(f"R(n) sums at m = {other.m} given for m = {self.m}")
        self.n_d, self.n_mod = other.n_d, other.n_mod
        self.s_d[ch] = other.s_d[of]
        self.s_mod[ch] = other.s_mod[of]

    def ratio(self) -> NDArray[np.float64]:
        """Measured R(n) per channel: MVAR/AVAR = (Σ w²/n_mod) / (m² Σ D²/n_d); NaN without
        a modified difference or with zero AVAR."""
        out = np.full(self.c, np.nan)
        if self.n_mod == 0 or self.n_d == 0:
            return out
        avar = self.s_d / self.n_d
        ok = avar > 0
        out[ok] = self.s_mod[ok] / self.n_mod / (self.m**2 * avar[ok])
        return out


def row_products(a: NDArray, b: NDArray, cross: bool = True) -> NDArray[np.float64]:
    """(C, C) matrix of Σ_t a[i, t]·b[j, t] for channel-major (C, L) arrays, as dot products of
    rows: for a few channels this is several times faster than a (C×L)·(L×C) matrix product
    (measured 30 µs against 100 µs for 3 × 8192), and exactly symmetric when a is b. With
    ``cross=False`` only the diagonal is computed (zeros elsewhere)."""
    c = a.shape[0]
    if not cross:
        return np.diag([float(np.dot(a[i], b[i])) for i in range(c)])
    out = np.empty((c, c))
    for i in range(c):
        for j in range(c):
            if a is b and j < i:
                out[i, j] = out[j, i]
            else:
                out[i, j] = float(np.dot(a[i], b[j]))
    return out


class _DiagWeights(NamedTuple):
    """Fixed coefficients of ``Lag1Ladder._open_sums_diag`` for one (dmax, keep, head)."""

    lag: NDArray[np.float64]     # (orders, 2, lags) on the lag sums
    hp: NDArray[np.float64]      # (orders, 2, lags, head + 1) on the head's prefix sums
    ts: NDArray[np.float64]      # (orders, 2, lags, keep + 1) on the tail's suffix sums
    s_sum: NDArray[np.float64]   # (orders,) on the open sum
    s_head: NDArray[np.float64]  # (orders, head) less these head values
    s_tail: NDArray[np.float64]  # (orders, keep) less these tail values
    first: NDArray[np.float64]   # (orders, head): the first order-k value
    last: NDArray[np.float64]    # (orders, keep): the last order-k value


@lru_cache(maxsize=16)
def _diag_weights(dmax: int, keep: int, e: int) -> _DiagWeights:
    """The k-th difference is Σ_a c_a z_{i+a} (c_a = (−1)^(k−a) C(k, a)); its sums of products
    over the segment (ℓ = 0) and over adjacent pairs (ℓ = 1) are Σ_{a,b} c_a c_b W(start, j),
    with the window sum W = lag_j − (head prefix at start) − (tail suffix at u): the same
    bookkeeping as the general ``_open_sums``, written once as coefficients."""
    orders, lags = dmax + 1, dmax + 2
    w = _DiagWeights(np.zeros((orders, 2, lags)), np.zeros((orders, 2, lags, e + 1)),
                     np.zeros((orders, 2, lags, keep + 1)), np.zeros(orders),
                     np.zeros((orders, e)), np.zeros((orders, keep)), np.zeros((orders, e)),
                     np.zeros((orders, keep)))
    for k in range(orders):
        coef = [(-1) ** (k - a) * comb(k, a) for a in range(k + 1)]
        for a in range(k + 1):
            w.s_sum[k] += coef[a]
            w.s_head[k, :a] += coef[a]
            if k - a > 0:
                w.s_tail[k, keep - (k - a):] += coef[a]
            w.first[k, a] = coef[a]
            w.last[k, keep - 1 - k + a] = coef[a]
        for ell in (0, 1):
            for a in range(k + 1):
                for b in range(k + 1):
                    bb = ell + b
                    start, j = (a, bb - a) if bb >= a else (bb, a - bb)
                    c = coef[a] * coef[b]
                    w.lag[k, ell, j] += c
                    w.hp[k, ell, j, start] += c
                    u = start + keep - k - ell  # tail index of the first t after the window
                    if 0 <= u < keep - j:
                        w.ts[k, ell, j, u] += c
    return w


class Lag1Ladder:
    """Running sums for Stable32's noise identification of one τ, C channels at once.

    Fed the non-overlapping m-averages of the rate, in order (any unit: sums of m samples
    work as well as means), it gives, for the averages and their differences of order
    k = 0 … ``dmax``: the count n, Σz, Σ z zᵀ, and over adjacent pairs (z_i, z_{i+1}) within
    a segment their number, Σ z_i z_{i+1}ᵀ, Σ z_i and Σ z_{i+1}. From these the lag-1
    autocorrelation about the series' mean is exact (NIST SP 1065 §5.6; Riley & Greenhall
    2004, eq. 2), whatever constant offset the averages carry, and with ``cross`` the C×C
    products give it for any weighted sum of channels (``weighted``).

    The differenced series are never formed: the k-th difference is Σ_a c_a z_{i+a}, so its
    sums of products are combinations of the averages' lag products Σ z_t z_{t+j}ᵀ
    (j = 0 … dmax + 1) less the few products at the segment's two ends, which are computed
    from its first and last 2·dmax + 2 values when the segment closes (or is read). One pass
    of dot products per lag replaces three difference orders of passes. The order-0 values
    are taken relative to the first average seen, which keeps the sums well conditioned (an
    axis reading 9.81 m/s² with 1e-5 noise). ``n``, ``s``, … hold the closed segments;
    ``totals()`` adds the open one.
    """

    FIELDS = ("n", "s", "s2", "np", "p", "left", "right")

    def __init__(self, n_channels: int, dmax: int = 2, *, cross: bool = True) -> None:
        c = int(n_channels)
        self.c = c
        self.dmax = int(dmax)
        self.cross = bool(cross)  # keep channel cross products (needed by ``weighted``)
        orders = self.dmax + 1
        self.n = np.zeros(orders, dtype=np.int64)
        self.np = np.zeros(orders, dtype=np.int64)
        self.s = np.zeros((orders, c))
        self.s2 = np.zeros((orders, c, c))
        self.p = np.zeros((orders, c, c))
        self.left = np.zeros((orders, c))
        self.right = np.zeros((orders, c))
        self.ref: NDArray[np.float64] | None = None
        # (count stamp, lowest, α) of the last ``alpha`` without R(n): a snapshot asks every
        # level, and a long-τ level gets a new average only every so often
        self._alpha_memo: tuple[tuple[int, int, int, int], NDArray[np.float64]] | None = None
        self._lags = self.dmax + 1  # order dmax, pairs one apart
        self._edge = 2 * self.dmax + 2  # values kept at each end of the open segment
        self._keep = max(self._edge, self._lags)
        self._open_reset()

    def _open_reset(self) -> None:
        c = self.c
        self._n_open = 0
        self._sum = np.zeros(c)
        self._lag = np.zeros((self._lags + 1, c, c))
        self._head = np.zeros((c, 0))
        self._tail = np.zeros((c, 0))
        self._few: NDArray[np.float64] | None = np.zeros((c, 0))  # all values while few
        self._open_cache: dict[str, NDArray] | None = None  # _open_sums() until the next push

    def push(self, values: NDArray, shift: NDArray | None = None) -> None:
        """Add the next averages (k, C) of the current segment, oldest first; ``shift`` (C,),
        when given, is added to every one of them (in the same pass as the reference)."""
        z = np.asarray(values, dtype=np.float64).reshape(-1, self.c)
        if z.shape[0] == 0:
            return
        ref = self._reference(z[0], shift)
        rows = np.empty((self.c, z.shape[0]))
        np.subtract(z.T, ref[:, None], out=rows)  # channel-major and referenced in one pass
        if not self._compiled_push(rows, 0, np.zeros(self.c), z.shape[0]):
            self._push_referenced(rows)

    def push_rows(self, values: NDArray, shift: NDArray | None = None) -> None:
        """``push`` for channel-major averages (C, k): each channel a contiguous row, so the
        sums of products are dot products of rows (the cheapest form for small C)."""
        z = np.asarray(values, dtype=np.float64).reshape(self.c, -1)
        if z.shape[1] == 0:
            return
        ref = self._reference(z[:, 0], shift)
        if self._compiled_push(z, 0, ref, z.shape[1]):
            return
        if not ref.any():  # already relative (the first segment's shortest τ): no copy
            self._push_referenced(z)
            return
        # a reused buffer: a fresh array of a batch's size is page-faulted in on every push
        rows = scratch("ladder.rows", self.c, z.shape[1], np.float64)
        np.subtract(z, ref[:, None], out=rows)
        self._push_referenced(rows)

    def span_overlap(self) -> int:
        """How many averages already pushed a ``push_spans`` span may begin with: the open
        segment's last min(n, dmax + 1), whose products with the new averages the compiled
        loop then sums in the same pass."""
        return min(self._tail.shape[1], self._lags)

    def push_spans(self, x: NDArray, m: int, shift: NDArray | None = None,
                   old: int = 0) -> None:
        """``push_rows`` of the non-overlapping sums of m samples given as a span of their
        running sum: x (C, k·m + 1) channel-major, the averages x[:, (j+1)m] − x[:, jm] for
        j < k, of which the first ``old`` (0, or exactly ``span_overlap()``) are the last ones
        pushed before. With the compiled loop the averages are never stored (one pass over
        the span for all the sums); without it, or for a cross-channel ladder, they are made
        and pushed."""
        x = np.asarray(x, dtype=np.float64).reshape(self.c, -1)
        m, old = int(m), int(old)
        if m < 1:
            raise DataError(f"m={m} must be an averaging factor >= 1")
        if old not in (0, self.span_overlap()):
            # all of the reach-back products or none: with part of them the compiled loop
            # and the tail's products would both count some
            raise DataError(f"old={old}: a span begins with 0 or all "
                            f"{self.span_overlap()} of the last averages pushed")
        k = (x.shape[1] - 1) // m
        if k <= old:
            return
        ref = self._reference(x[:, (old + 1) * m] - x[:, old * m], shift)
        if self._compiled_push(x, m, ref, k, old):
            return
        pts = x[:, old * m:k * m + 1:m]
        self._push_referenced((pts[:, 1:] - pts[:, :-1]) - ref[:, None])

    def _reference(self, first: NDArray, shift: NDArray | None) -> NDArray[np.float64]:
        """What to subtract from raw averages that get ``shift`` added: ref − shift, with ref
        the first (shifted) average this ladder saw."""
        h = np.zeros(self.c) if shift is None else np.asarray(shift, dtype=np.float64)
        if self.ref is None:
            self.ref = first + h
        return self.ref - h

    #: Fewest new averages a push gives the compiled loop: below it, or while the segment is
    #: short enough to be kept whole (``_few``), numpy's path costs no more.
    COMPILED_MIN = 64

    def _compiled_push(self, x: NDArray, m: int, ref: NDArray, k: int, old: int = 0) -> bool:
        """The push of the averages ``old`` … k − 1 of x by the compiled ``lag_sums``
        (m = 0: x − ref; m ≥ 1: the span's sums of m samples less ref), when it is built and
        applies; False otherwise. Its sums come from one pass, with the products that reach
        back into the previous push when x begins with ``span_overlap()`` of its averages;
        the segment's head and tail take the first and last few averages."""
        kern = kernels.compiled()
        new = k - old
        if (kern is None or self.cross or self._lags > 3 or new < self.COMPILED_MIN
                or self._n_open + new <= 4 * self._edge or x.dtype != np.float64
                or x.strides[1] != 8):
            return False
        sums = np.zeros((self.c, self._lags + 2))
        for ch in range(self.c):
            kern.lag_sums(x[ch], m, float(ref[ch]), sums[ch], old)

        def values(j0: int, j1: int) -> NDArray[np.float64]:
            """Averages j0 … j1 − 1 of x, referenced, as the numpy path makes them."""
            if m == 0:
                return x[:, j0:j1] - ref[:, None]
            pts = x[:, j0 * m:j1 * m + 1:m]
            return (pts[:, 1:] - pts[:, :-1]) - ref[:, None]

        self._open_cache = None
        self._sum += sums[:, 0]
        idx = np.arange(self.c)
        self._lag[:, idx, idx] += sums[:, 1:].T
        reached_back = old == self.span_overlap()
        head = (values(old, old + self._edge) if self._head.shape[1] < self._edge
                or not reached_back else None)
        self._push_ends(new, head, values(max(old, k - self._keep), k),
                        tail_products=not reached_back)
        return True

    def _push_referenced(self, z: NDArray[np.float64]) -> None:
        """Add averages (C, k) already relative to ``ref``."""
        self._open_cache = None
        count = z.shape[1]
        self._sum += z.sum(axis=1)
        for j in range(self._lags + 1):
            # products z_{q−j} z_q with both ends in this push
            if count > j:
                self._lag[j] += self._prod(z[:, :count - j], z[:, j:])
        self._push_ends(count, z[:, :self._keep], z[:, max(0, count - self._keep):], every=z)

    def _push_ends(self, count: int, first: NDArray | None, last: NDArray, *,
                   tail_products: bool = True, every: NDArray | None = None) -> None:
        """The rest of a push of ``count`` averages whose own sums are in: the products whose
        earlier end is still in the previous push's tail (unless the compiled loop summed
        them: ``tail_products=False``), and the segment's head, tail and short-segment
        values. ``first``/``last``: the push's first and last min(count, keep) averages
        (``first`` may be None when neither the products nor the head need it); ``every``:
        all of them (needed while the segment is short)."""
        t = self._tail.shape[1]
        for j in range(self._lags + 1 if tail_products else 0):
            q0, q1 = max(0, j - t), min(j, count)
            if q1 > q0:
                assert first is not None
                self._lag[j] += self._prod(self._tail[:, t + q0 - j:t + q1 - j],
                                           first[:, q0:q1])
        if self._head.shape[1] < self._edge:
            assert first is not None
            self._head = np.concatenate([self._head, first[:, :self._edge - self._head.shape[1]]],
                                        axis=1)
        self._tail = (last.copy() if count >= self._keep
                      else np.concatenate([self._tail, last], axis=1)[:, -self._keep:])
        self._n_open += count
        if self._few is not None:
            if self._n_open <= 4 * self._edge:
                assert every is not None  # the compiled push is not taken while few
                self._few = np.concatenate([self._few, every], axis=1)
            else:
                self._few = None

    def gap(self) -> None:
        """End the segment: no pair and no difference spans what follows."""
        if self._n_open:
            seg = self._cached_open_sums()
            for f in self.FIELDS:
                getattr(self, f)[...] += seg[f]
        self._open_reset()

    def _cached_open_sums(self) -> dict[str, NDArray]:
        """``_open_sums`` computed once per state of the open segment: a snapshot reads every
        level's ladder, and most long-τ levels have had no new average since the last one."""
        if self._open_cache is None:
            self._open_cache = self._open_sums()
        return self._open_cache

    def _prod(self, a: NDArray, b: NDArray) -> NDArray[np.float64]:
        if not self.cross and a.shape[1] <= 256:
            # short rows: one einsum call for all channels beats a dot per channel; long
            # rows go to BLAS dot, four times faster than einsum at 65536 (measured)
            return np.diag(np.einsum("ij,ij->i", a, b))
        return row_products(a, b, self.cross)

    def _open_sums(self) -> dict[str, NDArray]:
        """The open segment's sums per difference order (the FIELDS, stacked over k)."""
        c, orders = self.c, self.dmax + 1
        out: dict[str, NDArray] = {
            "n": np.zeros(orders, dtype=np.int64), "np": np.zeros(orders, dtype=np.int64),
            "s": np.zeros((orders, c)), "s2": np.zeros((orders, c, c)),
            "p": np.zeros((orders, c, c)), "left": np.zeros((orders, c)),
            "right": np.zeros((orders, c))}
        n = self._n_open
        if self._few is not None:  # a short segment: straight from its values
            w = self._few
            for k in range(orders):
                if k:
                    w = np.diff(w, axis=1)
                if w.shape[1] == 0:
                    break
                out["n"][k] = w.shape[1]
                out["s"][k] = w.sum(axis=1)
                out["s2"][k] = self._prod(w, w)
                if w.shape[1] > 1:
                    out["np"][k] = w.shape[1] - 1
                    out["p"][k] = self._prod(w[:, :-1], w[:, 1:])
                    out["left"][k] = out["s"][k] - w[:, -1]
                    out["right"][k] = out["s"][k] - w[:, 0]
            return out
        if not self.cross:
            return self._open_sums_diag(out)
        head, tail, keep = self._head, self._tail, self._keep
        base = n - keep  # segment index of tail[:, 0]

        def window(start: int, m: int, j: int) -> NDArray:
            """Σ_{t=start}^{start+m−1} z_t z_{t+j}ᵀ from the lag sum less its two ends."""
            total = self._lag[j].copy()
            if start:
                total -= self._prod(head[:, :start], head[:, j:start + j])
            v = start + m  # first t left out at the end
            if v <= n - 1 - j:
                total -= self._prod(tail[:, v - base:keep - j], tail[:, v - base + j:keep])
            return total

        for k in range(orders):
            coef = np.array([(-1) ** (k - a) * comb(k, a) for a in range(k + 1)], float)
            nk = n - k
            sw = sum(coef[a] * (self._sum - head[:, :a].sum(axis=1)
                                - tail[:, keep - (k - a):].sum(axis=1) * (k - a > 0))
                     for a in range(k + 1))
            first = head[:, :k + 1] @ coef
            last = tail[:, keep - 1 - k:keep] @ coef
            mats = []
            for ell in (0, 1):
                m = nk - ell
                acc = np.zeros((c, c))
                for a in range(k + 1):
                    for b in range(k + 1):
                        bb = ell + b
                        blk = (window(a, m, bb - a) if bb >= a else window(bb, m, a - bb).T)
                        acc += coef[a] * coef[b] * blk
                mats.append(acc)
            out["n"][k], out["np"][k] = nk, nk - 1
            out["s"][k], out["s2"][k], out["p"][k] = sw, mats[0], mats[1]
            out["left"][k], out["right"][k] = sw - last, sw - first
        return out

    def _open_sums_diag(self, out: dict[str, NDArray]) -> dict[str, NDArray]:
        """``_open_sums`` of a per-channel ladder (cross=False), with (C,) vectors: every
        window's end corrections come from prefix sums of the head's lag products and suffix
        sums of the tail's, and every output is a fixed linear combination of those, the lag
        sums and the ends (``_diag_weights``): a few matrix products instead of one numpy call
        per window (a snapshot reads every level's ladder). Equal to the general path
        (tested)."""
        keep, head, tail = self._keep, self._head, self._tail
        lags, e = self._lags + 1, head.shape[1]
        # hp[j][:, s] = Σ_{t<s} z_t z_{t+j} over the head; ts[j][:, u] = Σ_{t≥u} over the tail
        hp = np.zeros((lags, self.c, e + 1))
        ts = np.zeros((lags, self.c, keep + 1))
        for j in range(lags):
            np.cumsum(head[:, :e - j] * head[:, j:], axis=1, out=hp[j, :, 1:e - j + 1])
            prod = tail[:, :keep - j] * tail[:, j:]
            ts[j, :, :keep - j] = np.cumsum(prod[:, ::-1], axis=1)[:, ::-1]
        w = _diag_weights(self.dmax, keep, e)
        lag = np.diagonal(self._lag, axis1=1, axis2=2)  # (lags, C)
        vec = (np.einsum("klj,jc->klc", w.lag, lag) - np.einsum("klji,jci->klc", w.hp, hp)
               - np.einsum("klji,jci->klc", w.ts, ts))  # (orders, 2, C): s2 and p
        sw = w.s_sum[:, None] * self._sum - w.s_head @ head.T - w.s_tail @ tail.T
        orders = self.dmax + 1
        ks = np.arange(orders)
        out["n"][:] = self._n_open - ks
        out["np"][:] = self._n_open - ks - 1
        out["s"][:] = sw
        out["left"][:] = sw - w.last @ tail.T
        out["right"][:] = sw - w.first @ head.T
        idx = np.arange(self.c)
        out["s2"][:, idx, idx] = vec[:, 0]
        out["p"][:, idx, idx] = vec[:, 1]
        return out

    def totals(self) -> dict[str, NDArray]:
        """Closed segments plus the open one: the FIELDS, stacked over the orders."""
        if not self._n_open:
            return {f: getattr(self, f).copy() for f in self.FIELDS}
        seg = self._cached_open_sums()
        return {f: getattr(self, f) + seg[f] for f in self.FIELDS}  # new arrays

    def count(self) -> int:
        """Averages seen (all segments)."""
        return int(self.n[0]) + self._n_open

    def add(self, other: Lag1Ladder, sign: int = 1) -> None:
        """Add another ladder's sums (other segments of the same channels; its open segment
        counts as ended, this one's continues). ``sign=-1`` takes them away instead: the
        exact parallel analysis (``core/analysis/parallel.py``) adds a chunk's sums over its
        stretch and the few averages past its end, and takes away those past its end alone,
        so that what straddles each cut is counted once."""
        if sign not in (1, -1):
            raise DataError(f"sign={sign!r}: a ladder's sums are added (1) or taken away (-1)")
        o = other.totals()
        if other.ref is not None and self.ref is not None:
            # re-reference the other's order-0 sums: z' = z + (ref_o − ref_s) = z + h
            h = other.ref - self.ref
            n, np_ = o["n"][0], o["np"][0]
            keep = np.ones((self.c, self.c)) if self.cross else np.eye(self.c)
            self.s2[0] += sign * keep * (o["s2"][0] + np.outer(o["s"][0], h)
                                         + np.outer(h, o["s"][0]) + n * np.outer(h, h))
            self.p[0] += sign * keep * (o["p"][0] + np.outer(o["left"][0], h)
                                        + np.outer(h, o["right"][0]) + np_ * np.outer(h, h))
            self.s[0] += sign * (o["s"][0] + n * h)
            self.left[0] += sign * (o["left"][0] + np_ * h)
            self.right[0] += sign * (o["right"][0] + np_ * h)
            self.n[0] += sign * n
            self.np[0] += sign * np_
            lo = 1
        else:
            if self.ref is None:
                self.ref = None if other.ref is None else other.ref.copy()
            lo = 0
        for f in self.FIELDS:
            getattr(self, f)[lo:] += sign * o[f][lo:]
        self._alpha_memo = None  # the sums changed under the count stamp it keys on

    def weighted(self, w: NDArray) -> Lag1Ladder:
        """The ladder of the single channel Σ w_c z_c (its sums, as closed segments)."""
        if not self.cross:
            raise DataError("this ladder keeps no cross-channel sums; create it with "
                            "cross=True to weight channels")
        w = np.asarray(w, dtype=np.float64)
        t = self.totals()
        out = Lag1Ladder(1, self.dmax)
        out.n, out.np = t["n"], t["np"]
        for f in ("s", "left", "right"):
            setattr(out, f, (t[f] @ w)[:, None])
        for f in ("s2", "p"):
            setattr(out, f, np.einsum("i,kij,j->k", w, t[f], w)[:, None, None])
        out.ref = None if self.ref is None else np.array([float(self.ref @ w)])
        return out

    def r1(self, k: int, t: dict[str, NDArray] | None = None) -> NDArray[np.float64]:
        """Lag-1 autocorrelation about the mean of the order-k series, per channel (NaN when
        there are fewer than 3 values or no spread)."""
        t = self.totals() if t is None else t
        n = float(t["n"][k])
        out = np.full(self.c, np.nan)
        if n < 3 or t["np"][k] < 1:
            return out
        mean = t["s"][k] / n
        den = np.diagonal(t["s2"][k]) - t["s"][k] * mean
        num = (np.diagonal(t["p"][k]) - mean * (t["left"][k] + t["right"][k])
               + t["np"][k] * mean**2)
        ok = den > 0
        out[ok] = num[ok] / den[ok]
        return out

    def lag1_alpha(self, lowest: int, t: dict[str, NDArray] | None = None
                   ) -> NDArray[np.float64]:
        """alpha per channel by the lag-1 ladder (Riley & Greenhall 2004): difference until
        δ = r1/(1+r1) < 0.25 or k = dmax, alpha = −round(2δ) − 2k, clipped to [lowest, 2];
        NaN where the sums cannot give it."""
        out = np.full(self.c, np.nan)
        todo = np.ones(self.c, dtype=bool)
        t = self.totals() if t is None else t
        for k in range(self.dmax + 1):
            r1 = self.r1(k, t)
            with np.errstate(invalid="ignore", divide="ignore"):
                delta = r1 / (1.0 + r1)
            bad = ~np.isfinite(delta) | (r1 <= -1.0)
            todo &= ~(bad & todo)  # stays NaN
            stop = todo & ((delta < 0.25) | (k == self.dmax))
            out[stop] = np.clip(-np.round(2.0 * delta[stop]) - 2 * k, lowest, 2)
            todo &= ~stop
            if not todo.any():
                break
        return out

    def b1(self, t: dict[str, NDArray] | None = None) -> NDArray[np.float64]:
        """Measured B1 per channel: sample variance of the averages over their two-sample
        (non-overlapping Allan) variance; NaN with fewer than 2 averages."""
        t = self.totals() if t is None else t
        n = float(t["n"][0])
        out = np.full(self.c, np.nan)
        if n < 2 or t["n"][1] < 1:
            return out
        var = (np.diagonal(t["s2"][0]) - t["s"][0] ** 2 / n) / (n - 1.0)
        # order-1 values are differences: the order-0 reference cancels in them
        avar = np.diagonal(t["s2"][1]) / (2.0 * float(t["n"][1]))
        ok = avar > 0
        out[ok] = var[ok] / avar[ok]
        return out

    def alpha(self, lowest: int, rn: NDArray | None = None, m: int = 0,
              n_terms: int | None = None) -> NDArray[np.float64]:
        """Stable32's choice per channel: the lag-1 ladder with at least ``MIN_POINTS``
        averages; below, Barnes' B1 ratio (with at least 4 averages), and where B1 says 'PM'
        the R(n) = MVAR/AVAR ratio ``rn`` (per channel, at averaging factor ``m``; see
        ``RnSums``) separates white PM (2) from flicker PM (1). Without a usable R(n) (the
        cascade keeps no MVAR sums) flicker PM is taken, the smaller EDF of the two, so the
        interval is never the narrower white-PM one on a guess. NaN where neither applies.

        ``n_terms``: the estimator's count of differences at this τ, the N of the expected
        B1(N, μ) the measured ratio is compared with, as Stable32 takes it (see
        ``HOLD_BELOW_AVERAGES``); the count of averages when not given."""
        # every change of the sums raises the closed count or the open one (a gap moves the
        # open into the closed one): the stamp says whether anything changed since
        stamp = (int(self.n[0]), self._n_open, int(lowest), -1 if n_terms is None else n_terms)
        if rn is None and self._alpha_memo is not None and self._alpha_memo[0] == stamp:
            return self._alpha_memo[1].copy()
        out = self._alpha(lowest, rn, m, n_terms)
        if rn is None:
            self._alpha_memo = (stamp, out.copy())
        return out

    def needs_rn(self, n_terms: int | None = None) -> NDArray[np.bool_]:
        """Per channel, whether ``alpha`` (with these ``n_terms``) takes R(n): B1's range
        (4 … MIN_POINTS − 1 averages) and a B1 that says PM. Where it does not, R(n) is never
        read, so an accumulator may leave its sums out and compute them only here."""
        n = self.count()
        if n >= MIN_POINTS or n < 4:
            return np.zeros(self.c, dtype=bool)
        return np.array([a is None for a in self._b1_alphas(n, self.totals(), n_terms)])

    def _b1_alphas(self, n: int, t: dict[str, NDArray], n_terms: int | None
                   ) -> list[float | None]:
        """Per channel, B1's noise exponent from these totals of n averages: None where B1
        says PM (R(n) decides), NaN where B1 cannot be measured. B1's range (4 … MIN_POINTS
        − 1 averages) is the caller's to check."""
        b1 = self.b1(t)
        big_n = n if n_terms is None else max(int(n_terms), 2)
        return [alpha_from_b1(float(v), big_n) if math.isfinite(v) else math.nan for v in b1]

    def _alpha(self, lowest: int, rn: NDArray | None, m: int, n_terms: int | None
               ) -> NDArray[np.float64]:
        n = self.count()
        t = self.totals()
        if n >= MIN_POINTS:
            return self.lag1_alpha(lowest, t)
        out = np.full(self.c, np.nan)
        if n < 4:
            return out
        for ch, a in enumerate(self._b1_alphas(n, t, n_terms)):
            if a is None:  # B1 says PM: R(n), when there is one, tells white from flicker
                a = None if rn is None else alpha_from_rn(float(rn[ch]), m)
            elif math.isnan(a):
                continue
            out[ch] = max(lowest, 1 if a is None else a)
        return out

    def state(self) -> dict:
        """Plain numbers and lists (msgpack/JSON-able); ``from_state`` restores it."""
        def mat(a: NDArray) -> list:  # per-channel ladders keep only the diagonal
            return (a if self.cross else np.diagonal(a, axis1=-2, axis2=-1)).tolist()

        return {"c": self.c, "dmax": self.dmax, "cross": self.cross,
                **{f: mat(getattr(self, f)) if f in ("s2", "p") else getattr(self, f).tolist()
                   for f in self.FIELDS},
                "ref": None if self.ref is None else self.ref.tolist(),
                "open": {"n": self._n_open, "sum": self._sum.tolist(),
                         "lag": mat(self._lag), "head": self._head.tolist(),
                         "tail": self._tail.tolist(),
                         "few": None if self._few is None else self._few.tolist()}}

    @classmethod
    def from_state(cls, d: dict) -> Lag1Ladder:
        self = cls(int(d["c"]), int(d["dmax"]), cross=bool(d.get("cross", True)))
        def mat(v: list, shape: tuple[int, ...]) -> NDArray:
            a = np.asarray(v, dtype=np.float64)
            if self.cross:
                return a.reshape(shape)
            out = np.zeros(shape)
            idx = np.arange(self.c)
            out[..., idx, idx] = a.reshape(shape[:-1])
            return out

        for f in cls.FIELDS:
            cur = getattr(self, f)
            setattr(self, f, mat(d[f], cur.shape) if f in ("s2", "p")
                    else np.asarray(d[f], dtype=cur.dtype).reshape(cur.shape))
        self.ref = None if d["ref"] is None else np.asarray(d["ref"], dtype=np.float64)
        o = d["open"]
        c = self.c
        self._n_open = int(o["n"])
        self._sum = np.asarray(o["sum"], dtype=np.float64)
        self._lag = mat(o["lag"], self._lag.shape)
        self._head = np.asarray(o["head"], dtype=np.float64).reshape(c, -1)
        self._tail = np.asarray(o["tail"], dtype=np.float64).reshape(c, -1)
        self._few = (None if o["few"] is None
                     else np.asarray(o["few"], dtype=np.float64).reshape(c, -1))
        return self


# ---------------------------------------------------------------------------------------------
# The EDF an accelerometer's rate data support: avard's rule ("avard")


def pm_possible(var: float, m: int, lsb: float | None) -> bool:
    """Whether white or flicker PM (α = 2, 1) can be what rate data hold at averaging factor m.

    Rate data (acceleration) hold PM-like noise only as the rounding to the LSB: the running
    sum X of rounded samples carries an error bounded by ±lsb/2 per sample, so the second
    difference D = X_{i+2m} − 2X_{i+m} + X_i of that error is at most 2·lsb and its AVAR
    D²/(2m²) at most 2·lsb²/m². Where that bound is below half the measured AVAR, the
    rounding cannot be the dominant noise and PM is not a type the data can hold. Without an
    LSB (a float record whose rounding is unknown), never.
    """
    if lsb is None or not (math.isfinite(var) and var > 0):
        return False
    return 2.0 * lsb * lsb / (m * m) >= 0.5 * var


def plausible_alphas(alpha: int, n_averages: int, d: int, pm: bool, overlapping: bool
                     ) -> list[int]:
    """The noise exponents rate data of this identification could hold at one τ.

    ``alpha``: the identified exponent; ``n_averages``: the non-overlapping averages it came
    from; ``pm``: ``pm_possible`` there. PM types outside the rounding region are read as
    white FM (the most EDF any FM type gives). The identification's own sampling spread:

    * below Stable32's hold threshold (10 averages, 8 for overlapping estimators;
      ``HOLD_BELOW_AVERAGES``) nothing is identified: every FM type (and PM where possible);
    * B1/R(n) (< ``MIN_POINTS`` averages): B1's ratio of n averages scatters by about
      √(2/n) in log, more than half the step between neighbouring types' expectations, so
      the neighbours on both sides count;
    * lag-1 ACF: r1 of n averages has a standard error of about 1/√n, so α = −2δ − 2k
      about 2/√n: below ``SPREAD_LAG1`` averages that reaches the next type's boundary from
      the middle of a bin, and the neighbours count too.
    """
    lowest = 2 - 2 * d
    top = 2 if pm else 0
    a = int(min(max(alpha, lowest), top))
    if n_averages < HOLD_BELOW_AVERAGES[overlapping]:
        return list(range(lowest, top + 1))
    if n_averages < SPREAD_LAG1:
        return [b for b in (a - 1, a, a + 1) if lowest <= b <= top]
    return [a]


# Below this many averages the lag-1 ACF's spread (≈ 2/√n in α) reaches a neighbour type.
SPREAD_LAG1 = 64


def physical_alpha_edf(alpha: int, var: float, d: int, m: int, stride: int, n_phase: int,
                       n_averages: int, lsb: float | None
                       ) -> tuple[int, float]:
    """(α, EDF) of one τ under avard's rule for rate data: α constrained to what the data
    can hold (``pm_possible``), EDF the smallest over ``plausible_alphas``, so never above
    ``fm_support_edf`` outside the rounding region."""
    from avard.core.allan.edf import edf_greenhall  # edf imports nothing from here

    pm = pm_possible(var, m, lsb)
    lowest = 2 - 2 * d
    a = int(min(max(alpha, lowest), 2 if pm else 0))
    cands = plausible_alphas(a, n_averages, d, pm, stride < m)
    # rate data: the phase is the samples' exact running sum (``edf_greenhall``'s
    # ``rate_data``; PM types, the rounding's, keep GR's one-sample averaging)
    edfs = [edf_greenhall(b, d, m, stride, n_phase, rate_data=b <= 0) for b in cands]
    finite = [e for e in edfs if math.isfinite(e)]
    return a, min(finite) if finite else math.nan


def fm_support_edf(d: int, m: int, stride: int, n_phase: int) -> float:
    """The most EDF any FM type (α ≤ 0) gives this estimator at m over n_phase points: what a
    record of rate data supports outside the rounding region. White FM for the overlapping
    estimators; for the non-overlapping ones (stride m) the redder types give a little more
    (their differences are less anti-correlated)."""
    from avard.core.allan.edf import edf_greenhall

    vals = [edf_greenhall(a, d, m, stride, n_phase, rate_data=True)
            for a in range(2 - 2 * d, 1)]
    finite = [v for v in vals if math.isfinite(v)]
    return max(finite) if finite else math.nan
