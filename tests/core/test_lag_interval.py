"""The one-lag thermal fit's 68 % lag interval (``thermal_fit.lag_interval``): never narrower
than the readings' own time allows, and its coverage on the adversary's generator."""

from __future__ import annotations

import math

import numpy as np
import pytest


def _stamped_late_record(seed: int, late_s: float, lag_s: float = 60.0, hours: float = 2.0):
    """A slow view (1 s blocks) of a strongly driven axis: a ±0.6 K 25-minute cycle reaching
    the die through ``lag_s``, ``c`` 1e-3 m/s²/K, little white noise on the axis (the lag is
    then known to a small fraction of a second by the data's own scatter); the logged
    DS18B20 readings (0.0625 K steps) are the temperature ``late_s`` before their time
    stamp, as a reading taken during its conversion and logged at its end is."""
    rng = np.random.default_rng(seed)
    n = int(hours * 3600)
    t = np.arange(n, dtype=float)
    ph = rng.uniform(0, 2 * math.pi)

    def room(s: np.ndarray) -> np.ndarray:
        return 21.0 + 0.6 * np.sin(2 * math.pi * s / 1500.0 + ph)

    from avard.core.explain.thermal_fit import lag_filter

    # the die's temperature on a 0.1 s grid, where the stamps' offset is resolved
    f = 10
    fine = np.arange(n * f, dtype=float) / f
    die = lag_filter(room(fine), lag_s, float(f))[::f]
    y = 1e-3 * (die - die.mean()) + 2e-5 * rng.standard_normal(n)
    logged = np.round(room(t - late_s) / 0.0625) * 0.0625
    return y, logged[:, None]


def test_the_lag_interval_carries_the_readings_time():
    """Readings stamped 0.3 s after the moment they measured (within half the DS18B20's
    0.75 s conversion, which a log does not say): the lag the data fix is the physical lag
    less 0.3 s, to about a tenth of a second by the parts' spread. The interval carries the
    readings' time uncertainty beside that spread (it was the spread alone, ±0.1–0.2 s, and
    missed the physical lag), so each end is at least that uncertainty from the lag and the
    intervals hold the physical lag as a 68 % interval should."""
    from avard.core.explain.thermal_fit import fit_thermal
    from avard.core.explain.thermal_fit.settings import READ_TIME_S

    assert READ_TIME_S == pytest.approx(0.375)
    lags, held = [], 0
    for seed in (7, 8, 9):
        y, T = _stamped_late_record(seed, late_s=0.3)
        th = fit_thermal(y, T, ["plate"], 1.0)
        assert th.passed and not th.lag_open
        assert th.lag_hi - th.lag_s >= READ_TIME_S * (1 - 1e-9)
        assert th.lag_s - th.lag_lo >= READ_TIME_S * (1 - 1e-9)
        # no wider than the two uncertainties together make it
        assert th.lag_hi - th.lag_lo < 4 * READ_TIME_S
        lags.append(th.lag_s)
        held += th.lag_lo <= 60.0 <= th.lag_hi
    # the data fix the lag of the log's time stamps: the physical lag less the stamps' delay
    assert np.mean(lags) == pytest.approx(60.0 - 0.3, abs=0.15)
    assert held >= 2
