"""ADEV by temperature (``allan.dynamic.temperature_binned_adev``; issue 24 item 4): a
record whose white level doubles above a temperature shows it in the bins, with Bartlett's
test saying so at every τ; a stationary one does not, at its test's level."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.dynamic import CHANGE_LEVEL, temperature_binned_adev
from avard.core.errors import DataError

RATE = 10.0
N = int(6 * 3600 * RATE)
# ±1 °C over a 3 h cycle, one temperature per sample
TEMP = 20.0 + np.sin(2 * np.pi * np.arange(N) / (RATE * 3 * 3600))


def test_a_white_level_that_doubles_above_a_temperature_shows_in_its_bin() -> None:
    rng = np.random.default_rng(1)
    y = rng.normal(size=N) * 1e-4 * np.where(TEMP > 20.5, 2.0, 1.0)
    r = temperature_binned_adev(y, TEMP, RATE)
    # up to τ ≈ 100 s (a difference spans 2τ, short against the 3 h cycle, and each bin
    # holds hundreds): flagged at every τ; longer differences average over the cycle
    assert np.all(r.changes[r.tau <= 102.4]), r.p_value
    # the warmest quarter is all above 20.5 °C: twice the ADEV of the coolest, within bounds
    ratio = r.dev[-1] / r.dev[0]
    assert np.all(np.abs(ratio[:6] - 2.0) < 0.1), ratio
    white = 1e-4 / np.sqrt(r.tau * RATE)
    inside = (r.lo[0] <= white) & (white <= r.hi[0])
    assert inside[:8].mean() >= 0.5, (r.lo[0], white, r.hi[0])


def test_a_stationary_record_shows_no_temperature_dependence() -> None:
    """Over 8 records × every τ, Bartlett's test flags at about its level (1 %), not more
    (counts: at most 3 of the 112 tests; measured 3)."""
    flagged, tests = 0, 0
    for seed in range(8):
        y = np.random.default_rng(100 + seed).normal(size=N) * 1e-4
        r = temperature_binned_adev(y, TEMP, RATE)
        ok = np.isfinite(r.p_value)
        flagged += int(np.sum(r.p_value[ok] < CHANGE_LEVEL))
        tests += int(ok.sum())
    assert tests >= 80
    assert flagged <= 3, (flagged, tests)


def test_bad_temperatures_are_refused_in_one_line() -> None:
    y = np.zeros(1000)
    with pytest.raises(DataError, match="one temperature per sample"):
        temperature_binned_adev(y, np.zeros(999), 1.0)
    with pytest.raises(DataError, match="no reading"):
        temperature_binned_adev(y, np.full(1000, np.nan), 1.0)
    with pytest.raises(DataError, match="does not vary enough"):
        temperature_binned_adev(y, np.full(1000, 21.0), 1.0)


def test_differences_without_a_reading_are_in_no_bin() -> None:
    """The first hour has no temperature (NaN, as before a DS18B20's first conversion): its
    differences are left out, the rest binned as before."""
    y = np.random.default_rng(5).normal(size=N) * 1e-4
    t = TEMP.copy()
    t[: int(3600 * RATE)] = np.nan
    r = temperature_binned_adev(y, t, RATE)
    full = temperature_binned_adev(y, TEMP, RATE)
    assert r.count[:, 0].sum() == N - int(3600 * RATE) - 1  # τ0: those from 1 h on
    assert np.all(r.count.sum(axis=0) < full.count.sum(axis=0))
    assert np.all(np.isfinite(r.dev[:, :8]))
