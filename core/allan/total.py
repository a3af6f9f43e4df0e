"""Total variances of one channel: TOTVAR, MTOT, TTOT, HTOT (NIST SP 1065 §5.2.11–5.2.13).

Sample units throughout (``extension.centred_phase``: τ0 never multiplies); N phase points
x_0 … x_{N−1}, or N − 1 rate samples y for HTOT.

* TOTVAR (eq. 25): the phase extended at both ends by odd reflection (``extension.reflect``),
      Tot σ²(τ = mτ0) = Σ_{i=1}^{N−2} (x*_{i−m} − 2x*_i + x*_{i+m})² / (2 m² (N − 2)),
  for m ≤ (N − 1)/2 (τ to half the record).
* MTOT (eq. 27): for each of the N − 3m + 1 subsequences of 3m phase points, a line through
  the means of its two halves is removed, the remainder is extended by even reflection to 9m
  points, and the 6m second differences of its m-point averages are squared and averaged:
      Mod Tot σ²(τ) = Σ_n (1/6m) Σ_j (W_{j+2m} − 2W_{j+m} + W_j)² / m² / (2 m² (N − 3m + 1)).
* TTOT (eq. 28): (τ²/3)·MTOT (TDEV's scaling; SP 1065 prints τ³, a misprint).
* HTOT (eq. 29): the same subsequence kernel on the rate samples instead of the phase (the
  second difference of rate averages is the third difference of the phase, so a linear drift
  of the rate, removed with each subsequence's line, is not seen), normalised by 6; at m = 1
  the overlapping Hadamard variance (SP 1065 and Stable32: "for best consistency").

The subsequence kernel (``subsequence_sums``) works on a block of rows at once, each row one
subsequence, with a bounded number of elements per block; its cost grows as N·m per τ, which
is why analyze gives these statistics averaged data for long records (``extension.decimate``).
"""

from __future__ import annotations

import numpy as np
from avard.core.allan.extension import reflect
from avard.core.allan.modified import window_second_differences
from numpy.typing import NDArray

__all__ = ["ramp_totvar_ratio", "subsequence_sums", "totvar_sums"]

# Elements of the extended-subsequence block processed at once (8 bytes each): 16 MiB.
BLOCK_ELEMENTS = 1 << 21


def totvar_sums(x: NDArray[np.float64], m: int) -> tuple[float, int]:
    """(Σ (x*_{i−m} − 2x*_i + x*_{i+m})², N − 2) of eq. 25; (0, 0) beyond m = (N − 1)/2."""
    n = x.shape[0]
    if m < 1 or 2 * m > n - 1:
        return 0.0, 0
    ext = reflect(x, m - 1, m - 1, "odd")  # x*_{1−m} … x*_{N−2+m} (0-based: x_0 at m − 1)
    mid = ext[m - 1 + 1:m - 1 + n - 1]  # x*_i, i = 1 … N − 2
    d = ext[:n - 2] - 2 * mid + ext[2 * m:2 * m + n - 2]
    return float(d @ d), n - 2


def subsequence_sums(z: NDArray[np.float64], m: int) -> tuple[float, int]:
    """(Σ over subsequences of the mean squared second difference of m-sums, their count) for
    the MTOT/HTOT kernel on ``z`` (phase for MTOT, rate for HTOT): each subsequence of 3m
    points detrended by the line through its halves' means, reflected evenly to 9m points,
    6m second differences of its m-point window sums. (0, 0) when z is shorter than 3m."""
    n = z.shape[0]
    count = n - 3 * m + 1
    if m < 1 or count <= 0:
        return 0.0, 0
    length = 3 * m
    half = length // 2
    upper = (length + 1) // 2  # second half starts here (the middle point left out if odd)
    dist = length / 2 if length % 2 == 0 else (length + 1) / 2
    ramp = np.arange(length, dtype=np.float64)
    rows = max(1, BLOCK_ELEMENTS // (9 * length))
    view = np.lib.stride_tricks.sliding_window_view(z, length)
    total = 0.0
    for a in range(0, count, rows):
        s = view[a:a + rows]
        slope = (s[:, upper:].mean(axis=1) - s[:, :half].mean(axis=1)) / dist
        s0 = s - slope[:, None] * ramp
        ext = reflect(s0, length, length, "even")  # 9m points per row
        d = window_second_differences(ext, m, 0, 6 * m)
        total += float(np.einsum("ij,ij->", d, d)) / (6 * m * m * m)
    return total, count


def ramp_totvar_ratio(n_phase: int, m: int) -> float:
    """TOTVAR over AVAR of a linear rate ramp (a quadratic phase) on ``n_phase`` points at
    averaging factor m: the bias of TOTVAR for a ramp, exact on the grid. Odd reflection
    turns the phase's curvature over at each end, so the differences that reach into the
    extension see none of the ramp: about 1 − 0.93·τ/T (0.53 at T/2), where the AVAR of the
    ramp is R²τ²/2 at every τ. NaN beyond m = (N − 1)/2."""
    s, c = totvar_sums(_unit_curvature(n_phase), m)
    if c == 0:
        return float("nan")
    # the ramp's AVAR: its second difference is m² everywhere, so Σ/(2m²·count) = m²/2
    return s / (2.0 * m * m * c) / (m * m / 2.0)


def _unit_curvature(n_phase: int) -> NDArray[np.float64]:
    """x_k = (k − c)²/2, centred (a line added to the phase changes no second difference,
    nor the odd reflection's, so centring only keeps the numbers small)."""
    t = np.arange(n_phase, dtype=np.float64) - (n_phase - 1) / 2.0
    return 0.5 * t * t
