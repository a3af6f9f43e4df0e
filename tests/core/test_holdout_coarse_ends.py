"""A `--holdout FILE` record whose log reads on a coarse step: the lag interval's ends are
read off the same de-rounded log as the held-out prediction (coarse29)."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.explain.holdout import Claims, Part, _signals
from avard.core.explain.thermal_fit import ThermalFit

RATE = 1 / 1.6


def _log(seed: int, q: float) -> np.ndarray:
    """2 h of a room's 30-min cycle of ±0.9 K with a wander, read on step ``q`` (slow view)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(2 * 3600 * RATE)) / RATE
    walk = np.cumsum(rng.standard_normal(len(t))) / np.sqrt(len(t))
    T = 22.1 + 0.9 * np.sin(2 * np.pi * t / 1800 + rng.uniform(0, 2 * np.pi)) + 0.05 * walk
    return np.asarray(np.round(T / q) * q, dtype=float)


@pytest.mark.parametrize("q", [0.25, 0.5])
def test_a_lag_interval_of_no_width_spreads_no_prediction(q: float) -> None:
    """The ends of a lag interval a hundredth of a second wide move the held-out
    prediction by a hundredth of a second's worth of lag, whatever the log's step. Read
    off the raw readings while the prediction reads their reconstruction, each end also
    carried the coarse rounding through the lag: a spread of the prediction of the order
    of ĉ·q/√12 that no lag moves."""
    c, lag = 3e-3, 300.0
    th = ThermalFit(channel="t", channel_index=0, coefficient=c, coef_se=0.0, lag_s=lag,
                    lag_lo=lag - 0.01, lag_hi=lag + 0.01, z=50.0, rate_hz=RATE, grid=(q, 0.0))
    T_fit, T_held = _log(1, q), _log(2, q)
    n = len(T_held)
    rng = np.random.default_rng(3)
    fit = Part(rng.standard_normal(len(T_fit)) * 1e-4, 0.0, "data", True)
    held = Part(rng.standard_normal(n) * 1e-4, 0.0, "holdout", True, grid=(q, 0.0))
    claims = Claims(thermal_channel=0, whole_thermal=th)
    _d_fit, d_held, _skip, _longest, spread, _w_held, _gaps = _signals(
        fit, held, claims, RATE, False, (T_fit, slice(None)), (T_held, slice(None)))
    assert len(spread) == 1
    lo, hi = spread[0]
    # the prediction's own swing, and what 0.02 s of lag can move it by
    swing = float(np.std(d_held))
    assert swing > 0.5 * c * 0.9 / np.sqrt(2)
    for end in (lo, hi):
        assert float(np.sqrt(np.mean(end**2))) < 1e-4 * swing
