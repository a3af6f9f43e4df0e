"""The pieces the long-τ statistics share: one phase integration, one reflection, one
decimation (NIST SP 1065 §5.2.11–5.2.15).

* ``centred_phase``: the phase of rate samples as the other estimators keep it, in sample
  units (X_0 = 0, X_i = Σ_{k<i} y_k, so τ0 never multiplies), after removing the mean rate.
  Removing a constant rate adds a straight line to X, which none of these statistics sees:
  second and third differences cancel it, the odd reflection of TOTVAR keeps it a straight
  line, MTOT and HTOT remove a line from every subsequence, and Theo1's combination
  (x_i − x_{i−δ+m/2}) + (x_{i+m} − x_{i+δ+m/2}) is zero on a line. It keeps the running sum
  small, so fewer digits cancel.
* ``reflect``: the two extensions of SP 1065: "odd" (point reflection about the end point,
  which is not repeated: x*_{1−j} = 2x_1 − x_{1+j}, eq. 25, TOTVAR) and "even" (uninverted
  mirror image with the end point repeated, eqs. 27 and 29, MTOT and HTOT after their
  subsequence is detrended), along the last axis so a block of subsequences extends at once.
* ``decimate``: non-overlapping averages of r rate samples, for the statistics whose cost
  grows as N·m (MTOT, TTOT, HTOT, Theo1 and its derivatives): NIST recommends computing them
  on averaged data for long records (SP 1065 §5.2.14, TheoH "with an averaging factor"); the
  result then starts at τ = r·τ0.
"""

from __future__ import annotations

import numpy as np
from avard.core.errors import DataError
from numpy.typing import ArrayLike, NDArray

__all__ = ["centred_phase", "decimate", "reflect"]


def centred_phase(y: ArrayLike) -> NDArray[np.float64]:
    """Phase (N + 1 points, sample units) of one channel of rate samples, mean rate removed."""
    a = np.asarray(y, dtype=np.float64)
    if a.ndim != 1:
        raise DataError(f"one channel of rate samples is 1-D; got shape {a.shape}")
    if a.size and not np.all(np.isfinite(a)):
        raise DataError("rate samples hold NaN or infinity; remove them or split the record")
    x = np.empty(a.size + 1)
    x[0] = 0.0
    np.subtract(a, a.mean() if a.size else 0.0, out=x[1:])  # in place: no second copy
    np.cumsum(x[1:], out=x[1:])
    return x


def reflect(x: NDArray[np.float64], before: int, after: int, kind: str) -> NDArray[np.float64]:
    """``x`` (…, L) extended by ``before`` and ``after`` points along its last axis.

    kind "odd": x*_{−j} = 2x_0 − x_j and x*_{L−1+j} = 2x_{L−1} − x_{L−1−j}, j ≥ 1 (SP 1065
    eq. 25; needs before, after ≤ L − 1). kind "even": the mirror image with the end point
    repeated, x*_{−j} = x_{j−1} (eqs. 27, 29; needs before, after ≤ L)."""
    length = x.shape[-1]
    if kind == "odd":
        if max(before, after) > length - 1:
            raise DataError(f"an odd reflection of {length} points reaches {length - 1} at most")
        head = 2 * x[..., :1] - x[..., 1:before + 1][..., ::-1]
        tail = 2 * x[..., -1:] - x[..., length - 1 - after:length - 1][..., ::-1]
    elif kind == "even":
        if max(before, after) > length:
            raise DataError(f"an even reflection of {length} points reaches {length} at most")
        head = x[..., :before][..., ::-1]
        tail = x[..., length - after:][..., ::-1]
    else:
        raise DataError(f"reflection kind {kind!r} is unknown; use 'odd' or 'even'")
    return np.concatenate([head, x, tail], axis=-1)


def decimate(y: ArrayLike, factor: int) -> NDArray[np.float64]:
    """Non-overlapping means of ``factor`` rate samples (a trailing remainder is dropped):
    the rate at τ0' = factor·τ0. Axis 0 is time."""
    a = np.asarray(y, dtype=np.float64)
    if factor < 1:
        raise DataError(f"averaging factor {factor} must be >= 1")
    if factor == 1:
        return a
    n = a.shape[0] // factor
    return a[:n * factor].reshape(n, factor, *a.shape[1:]).mean(axis=1)
