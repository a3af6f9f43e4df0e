"""Power-law noise identification: lag-1 ACF (Riley & Greenhall 2004) and the slope fallback."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan import oavar
from avard.core.errors import DataError
from avard.core.noise_id import alpha_from_lag1, alpha_from_slope, identify_alpha, lag1_acf


def power_law(alpha: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """Rate noise with S_y ∝ f^alpha by Kasdin & Walter's fractional differencing filter."""
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 1 - alpha / 2) / k)])
    w = rng.normal(size=n)
    size = 2 * n
    return np.fft.irfft(np.fft.rfft(h, size) * np.fft.rfft(w, size), size)[:n]


@pytest.mark.parametrize("alpha", [2, 1, 0, -1, -2])
def test_identify_alpha_on_generated_noise(alpha: int) -> None:
    rng = np.random.default_rng(100 + alpha)
    y = power_law(alpha, 2**15, rng)
    assert [identify_alpha(y, m) for m in (1, 4)] == [alpha, alpha]
    # the accumulators' own identification (same ACF ladder on their difference sums)
    assert list(oavar(y, 1.0, [1, 4]).alpha) == [alpha, alpha]


def test_lag1_formulas() -> None:
    assert alpha_from_lag1(0.0, 0) == 0.0  # white rate noise
    assert alpha_from_lag1(-0.5, 1) == pytest.approx(0.0)  # differenced white
    assert alpha_from_lag1(0.0, 1) == pytest.approx(-2.0)  # differenced random walk
    assert np.isnan(alpha_from_lag1(-1.0, 0))
    x = np.array([1.0, 2.0, 1.0, 2.0, 1.0, 2.0])
    assert lag1_acf(x) < -0.8


def test_slope_fallback() -> None:
    assert alpha_from_slope(-1.0) == 0
    assert alpha_from_slope(0.0) == -1
    assert alpha_from_slope(1.0) == -2
    assert alpha_from_slope(-2.0) == 2
    assert alpha_from_slope(3.0, d=2) == -2  # clipped where AVAR converges
    assert alpha_from_slope(3.0, d=3) == -4


def test_short_data_fall_back_to_slope_in_results() -> None:
    """Fewer than 30 averages at a τ: the result still has an alpha (from the slope)."""
    y = np.random.default_rng(5).normal(size=400)
    res = oavar(y, 1.0)
    assert np.all(np.isfinite(res.alpha)) and np.all(np.isfinite(res.edf))
    with pytest.raises(DataError, match="30"):
        identify_alpha(y, 64)


def test_identify_alpha_rejects_bad_input() -> None:
    with pytest.raises(DataError, match="NaN"):
        identify_alpha(np.array([1.0, np.nan] * 50), 1)
    with pytest.raises(DataError, match="1-D"):
        identify_alpha(np.ones((100, 2)), 1)
    with pytest.raises(DataError, match="data_type"):
        identify_alpha(np.ones(100), 1, data_type="volts")
