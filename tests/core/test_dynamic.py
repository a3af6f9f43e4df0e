"""Dynamic ADEV: a white level that doubles mid-run is found by Bartlett's test over the
independent windows; stationary records are not flagged beyond the test's level."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.dynamic import CHANGE_LEVEL, bartlett, dynamic_adev
from avard.core.errors import DataError


def test_a_doubling_white_level_shows_and_where() -> None:
    rng = np.random.default_rng(1)
    y = rng.standard_normal(40_000)
    y[20_000:] *= 2.0
    d = dynamic_adev(y, 10.0, window_s=400.0, step_s=100.0)
    assert d.tau[-1] <= d.window_s / 4
    assert d.independent == 10
    assert bool(d.changes[0]) and d.p_value[0] < 1e-10
    first = d.t_s < 2000 - d.window_s / 2
    last = d.t_s > 2000 + d.window_s / 2
    ratio = d.dev[last, 0].mean() / d.dev[first, 0].mean()
    assert 1.9 < ratio < 2.1  # the level read off the map
    # the truth (ADEV 1 before, 2 after, at τ0) inside most windows' 68 % interval
    held = np.r_[(d.lo[first, 0] < 1.0) & (d.hi[first, 0] > 1.0),
                 (d.lo[last, 0] < 2.0) & (d.hi[last, 0] > 2.0)]
    assert held.mean() >= 0.5


def test_stationary_records_are_flagged_at_the_tests_level() -> None:
    """20 stationary records (white + random walk): at the shortest τ (EDF in the hundreds)
    Bartlett's test at 1 % flags at most 2 (expected 0.2; P(≥ 3) = 0.001)."""
    flagged = 0
    for seed in range(20):
        rng = np.random.default_rng(seed)
        y = rng.standard_normal(4_000) + np.cumsum(rng.standard_normal(4_000)) * 1e-3
        d = dynamic_adev(y, 1.0, window_s=400.0, step_s=400.0)
        flagged += int(d.changes[0])
    assert flagged <= 2
    assert CHANGE_LEVEL == 0.01


def test_bartlett_equal_and_unequal() -> None:
    assert bartlett(np.array([1.0, 1.0, 1.0]), np.array([50.0, 50.0, 50.0])) == pytest.approx(1.0)
    assert bartlett(np.array([1.0, 4.0]), np.array([200.0, 200.0])) < 1e-6
    assert np.isnan(bartlett(np.array([1.0]), np.array([10.0])))


def test_bad_windows_are_one_clear_error() -> None:
    y = np.zeros(100)
    with pytest.raises(DataError, match="longer than the record"):
        dynamic_adev(y, 1.0, window_s=200.0)
    with pytest.raises(DataError, match="at least 8"):
        dynamic_adev(y, 1.0, window_s=4.0)
    with pytest.raises(DataError, match="shorter than one sample"):
        dynamic_adev(y, 1.0, window_s=40.0, step_s=0.1)
