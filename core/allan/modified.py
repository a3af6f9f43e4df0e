"""Modified Allan and time variance of one channel's phase (NIST SP 1065 eqs. 14–15).

In the sample units of ``extension.centred_phase`` (X, τ0 never multiplies), N phase points:

    Mod σ²(τ = mτ0) = Σ_{j=0}^{N−3m} (Σ_{i=j}^{j+m−1} X_{i+2m} − 2X_{i+m} + X_i)²
                      / (2 m⁴ (N − 3m + 1))                                      (eq. 14)

and TVAR = (τ²/3)·Mod σ² (eq. 15, τ in seconds: TDEV is in input unit × s, m/s for
acceleration). The inner sum is W_{j+2m} − 2W_{j+m} + W_j of the window sums W_j of m phase
points, taken from a running sum restarted every chunk, so the sums never grow with the record
(no digits lost to a long cumulative sum) and the memory is one chunk.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["mvar_sums", "window_second_differences"]

# Differences per chunk: bounds the working memory and the length of the running sums.
CHUNK = 1 << 16


def window_second_differences(z: NDArray[np.float64], m: int, start: int, count: int
                              ) -> NDArray[np.float64]:
    """W_{j+2m} − 2W_{j+m} + W_j for j = start … start + count − 1, W_j = Σ_{i<m} z_{j+i},
    along the last axis of ``z`` (a block of rows at once); z must hold start + count + 3m − 1
    points."""
    seg = z[..., start:start + count + 3 * m - 1]
    c = np.zeros((*seg.shape[:-1], seg.shape[-1] + 1))
    np.cumsum(seg, axis=-1, out=c[..., 1:])
    w = c[..., m:] - c[..., :-m]  # count + 2m window sums
    return w[..., 2 * m:] - 2 * w[..., m:count + m] + w[..., :count]


def mvar_sums(x: NDArray[np.float64], m: int) -> tuple[float, int]:
    """(Σ of the squared inner sums, their count N − 3m + 1) of eq. 14 at one m; (0, 0) when
    the record is shorter than 3m + 1 phase points. MVAR = sum / (2 m⁴ count)."""
    count = x.shape[0] - 3 * m + 1
    if count <= 0:
        return 0.0, 0
    total = 0.0
    for a in range(0, count, CHUNK):
        d = window_second_differences(x, m, a, min(CHUNK, count - a))
        total += float(d @ d)
    return total, count
