"""Theo1, TheoBR and TheoH of one channel's phase (NIST SP 1065 §5.2.14–5.2.15).

Sample units (``extension.centred_phase``), N phase points x_0 … x_{N−1}, m even, 10 ≤ m ≤
N − 1 as Stable32 runs it (any even m ≥ 2 is computed):

* Theo1 (eq. 30), at τ = 0.75·m·τ0:
      Theo1(m) = Σ_{i=0}^{N−m−1} Σ_{δ=0}^{m/2−1} [(x_i − x_{i−δ+m/2}) + (x_{i+m} − x_{i+δ+m/2})]²
                 / (m/2 − δ) / (0.75 (N − m) m²).
  It reaches τ = 0.75·T with far more averages than the AVAR, but is biased against AVAR
  for any noise but white FM.
* TheoBR (eq. 31), the bias removed by the data themselves:
      TheoBR(m) = [1/(n+1) Σ_{i=0}^{n} AVAR(m = 9 + 3i) / Theo1(m = 12 + 4i)] · Theo1(m),
  n = ⌊0.1·N/3 − 3⌋ (the ratio is taken where both are estimated well, τ = (9 + 3i)·τ0 ≤
  10 % of the record; AVAR is the overlapping one).
* TheoH (eq. 32): the overlapping AVAR up to τ_k, the longest of its τ that lie within 10 %
  of the record, and TheoBR beyond.

Theo1's double sum costs N·m/2 per τ: on a long record it is computed on averaged data
(``extension.decimate``), as NIST recommends for TheoH.
"""

from __future__ import annotations

import numpy as np
from avard.core.errors import DataError
from numpy.typing import NDArray

__all__ = ["bias_ratio_terms", "oavar_sums", "theo1_sums"]

# Elements of the (subsequence, δ) block processed at once (8 bytes each): 16 MiB.
BLOCK_ELEMENTS = 1 << 21


def theo1_sums(x: NDArray[np.float64], m: int) -> tuple[float, int]:
    """(the double sum of eq. 30, N − m) at one even m; (0, 0) when m > N − 1.
    Theo1 = sum / (0.75 (N − m) m²)."""
    if m < 2 or m % 2:
        raise DataError(f"Theo1 takes an even averaging factor m >= 2; got {m}")
    n = x.shape[0]
    count = n - m
    if count < 1:
        return 0.0, 0
    h = m // 2
    ends = x[:count] + x[m:m + count]
    # rows i, columns δ: x_{i+h−δ} and x_{i+h+δ} as views of one sliding window
    win = np.lib.stride_tricks.sliding_window_view(x, m + 1)[:count]
    inner = win[:, h:0:-1]  # x_{i+h−δ}, δ = 0 … h − 1
    outer = win[:, h:m]  # x_{i+h+δ}
    weight = 1.0 / (h - np.arange(h, dtype=np.float64))
    rows = max(1, BLOCK_ELEMENTS // h)
    total = 0.0
    for a in range(0, count, rows):
        b = min(count, a + rows)
        d = ends[a:b, None] - inner[a:b] - outer[a:b]
        total += float(np.einsum("ij,ij,j->", d, d, weight))
    return total, count


def oavar_sums(x: NDArray[np.float64], m: int) -> tuple[float, int]:
    """(Σ (x_{i+2m} − 2x_{i+m} + x_i)², N − 2m): the overlapping AVAR of SP 1065 eq. 12,
    = sum / (2 m² count)."""
    count = x.shape[0] - 2 * m
    if count < 1:
        return 0.0, 0
    d = x[2 * m:] - 2 * x[m:m + count] + x[:count]
    return float(d @ d), count


def bias_ratio_terms(n_phase: int) -> int:
    """TheoBR's n = ⌊0.1·N/3 − 3⌋ (eq. 31); negative when the record is too short (N < 90)."""
    return int(np.floor(0.1 * n_phase / 3 - 3))
