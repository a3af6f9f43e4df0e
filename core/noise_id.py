"""Power-law noise identification: lag-1 autocorrelation with a local-slope fallback.

The EDF of a variance estimate depends on the noise type at each τ (see ``avard.core.edf``).
Two ways to find it, both from W. J. Riley and C. A. Greenhall, "Power law noise
identification using the lag 1 autocorrelation", Proc. 18th EFTF (2004), and NIST SP 1065
§5.6:

* Lag-1 ACF: average the rate data in blocks of m, difference the averages k times until the
  lag-1 autocorrelation r1 is small, then δ = r1 / (1 + r1) and alpha = −2(δ + k) (rate data).
  White rate noise gives r1 = 0 at k = 0; each difference of a white sequence gives r1 = −1/2.
* Local slope: AVAR ∝ τ^μ with μ = −alpha − 1 for −3 < alpha ≤ 1; it cannot tell white PM
  (alpha = 2) from flicker PM (both μ = −2) and is noisy, so it is the fallback only.

``alpha_from_lag1`` is the bare formula; the Allan accumulators (batch and streaming) apply it
to their own differences: the second difference of the phase at lag m is m times the first
difference of adjacent m-averages, so the products of differences m apart that the
accumulators keep give r1 at k = d − 1 for the d-th difference variance, with every overlapping
difference used, whatever the record length and without keeping the data.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from .errors import DataError

__all__ = ["alpha_from_lag1", "alpha_from_slope", "identify_alpha", "lag1_acf"]

# Riley & Greenhall: below this many (averaged) points the lag-1 ACF is too noisy to use.
MIN_POINTS = 30


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
        −1 flicker FM, −2 random-walk FM, … Raises ``DataError`` when fewer than 30 averages
        are available (use ``alpha_from_slope`` on the variance curve instead).
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
        x = a[::m]  # decimated phase, then remove frequency offset and drift
        x = _detrend(x, 2)
        extra = 2.0  # phase data are one integration above rate data
    elif data_type == "rate":
        n = a.size // m
        x = a[: n * m].reshape(n, m).mean(axis=1)
        x = _detrend(x, 1)
        extra = 0.0
    else:
        raise DataError(f"data_type={data_type!r} must be 'rate' or 'phase'")
    if x.size < MIN_POINTS:
        raise DataError(
            f"only {x.size} averages of {m} samples: the lag-1 ACF needs >= {MIN_POINTS}; "
            "use a smaller m or alpha_from_slope"
        )
    k = 0
    while True:
        r1 = lag1_acf(x)
        if not math.isfinite(r1):
            return 0
        delta = r1 / (1.0 + r1)
        if delta < 0.25 or k >= dmax:
            alpha = -2.0 * (delta + k) + extra
            return int(min(2, max(-2 * dmax + 2, round(alpha))))
        x = np.diff(x)
        k += 1


def _detrend(x: np.ndarray, deg: int) -> np.ndarray:
    t = np.arange(x.size, dtype=np.float64)
    if x.size <= deg:
        return x - x.mean()
    coef = np.polyfit(t, x, deg)
    return x - np.polyval(coef, t)
