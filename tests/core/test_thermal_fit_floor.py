"""The rounding floor of a logged channel whose drive swings one or two DS18B20 steps
(chan23g): a cycle's AVAR dips after its peak, and the floor must not jump past it."""

from __future__ import annotations

import math

import numpy as np


def _small_swing(seed: int, period: float, coef: float = 0.0, hours: float = 4.0):
    """A 1 s slow view: a ±0.5 K HVAC triangle of ``period`` reaching the plate through
    1100 s, the logged DS18B20 the plate through 100 s (3 mK read noise, 0.0625 K steps: a
    swing of about one step), the die the plate through 50 s (a lag of −50 s from the
    logged channel, ``lag_filter``'s lead-lag exactly); the axis ``coef``·die beside
    white noise and a rate random walk. Returns (y, logged (n, 1), the die's fundamental
    amplitude)."""
    from avard.core.explain.thermal_fit import lag_filter

    rng = np.random.default_rng(seed)
    n = int(hours * 3600)
    t = np.arange(n, dtype=float)
    room = 21.4 + 0.5 * 2 / math.pi * np.arcsin(np.sin(2 * math.pi * t / period
                                                      + rng.uniform(0, 6.3)))
    plate = lag_filter(room, 1100.0, 1.0)
    sens, die = lag_filter(plate, 100.0, 1.0), lag_filter(plate, 50.0, 1.0)
    read = np.round((sens + 0.003 * rng.standard_normal(n)) / 0.0625) * 0.0625
    y = (coef * (die - die.mean()) + 1.6e-4 * rng.standard_normal(n)
         + 1.5e-6 * np.cumsum(rng.standard_normal(n)))
    w = 2 * math.pi / period
    amp = 8 / math.pi**2 * 0.5 / math.hypot(1.0, w * 1100.0) / math.hypot(1.0, w * 50.0)
    return y, read[:, None], amp


def test_the_floor_of_a_cycle_of_a_steps_swing_stays_below_its_period():
    """HVAC periods 1300–2300 s: the cycle's AVAR stands above its readings' rounding at
    the octave of its peak and dips below the bar at the next (towards the period); the
    floor is that octave, never past the cycle (where the next octave had to pass too, it
    went past the cycle, or to ∞ on a record with no slower octave above the bar)."""
    from avard.core.explain.thermal_fit.rounding import rounding_floor_tau

    for seed, period in enumerate(np.linspace(1300.0, 2300.0, 11)):
        _y, T, _a = _small_swing(seed, float(period))
        assert rounding_floor_tau(T[:, 0], 1.0) < period / 2, period


def test_a_coupling_through_a_steps_swing_is_claimed_at_3x_its_minimum():
    """At 3× the stated minimum (``min_detectable_tempco`` on the die's swing) the coupling
    behind such a log is claimed with its coefficient within 20 % (where the floor passed
    the cycle, the slow octaves left had few degrees of freedom and no evidence); with
    nothing coupled nothing is."""
    from avard.core.explain.thermal_fit import fit_thermal, min_detectable_tempco

    for seed, period in enumerate((1300.0, 1400.0, 2000.0)):
        y0, T, amp = _small_swing(seed, period)
        c = 3 * min_detectable_tempco(1.6e-4, 0.0, 1.5e-6, 4 * 3600.0, amp, period, 0.0)
        y, _T, _a = _small_swing(seed, period, c)
        fit = fit_thermal(y, T, ["plate"], 1.0)
        assert fit.passed and abs(fit.coefficient / c - 1) < 0.2, (period, fit.z,
                                                                   fit.threshold)
        assert not fit_thermal(y0, T, ["plate"], 1.0).passed
