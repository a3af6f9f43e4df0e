"""The thermal path candidates read a coarse log as the one-lag fit does (coarse29): the
temperature behind the readings of the quadratic, relay and dT/dt reference columns is
``thermal_fit.coarse.behind_readings``, which on a 9–11-bit step is ``derounded`` (each
turn's top a cycle's, not the bare spline's parabola)."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.explain.thermal_fit import lag_filter
from avard.core.explain.thermal_fit.coarse import behind_readings, derounded
from avard.core.explain.thermal_paths.columns import (
    Column,
    crossing_reconstruction,
    path_columns,
)

RATE = 1.0


def _room(seed: int, amp: float) -> np.ndarray:
    """A 4 h room: a 30-min cycle of ``amp`` K with a slow wander, at 1 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(4 * 3600) / RATE
    walk = np.cumsum(rng.standard_normal(len(t))) / np.sqrt(len(t))
    return 21.1 + amp * np.sin(2 * np.pi * t / 1800 + rng.uniform(0, 2 * np.pi)) + 0.05 * walk


@pytest.mark.parametrize("amp", [0.9, 1.3])
def test_a_quadratic_column_on_a_coarse_log_follows_the_rooms_square(amp: float) -> None:
    """On a 0.5 K log of a cycle a few steps wide, the quadratic column (the square of the
    temperature behind the readings) against the true temperature's square, away from the
    record's ends (there the first and last runs say nothing of where the temperature
    turned, whatever the reading): its error and the gain a coefficient fitted on it
    carries. On the bare crossing spline's tops (a parabola's where a cycle turns as a
    cosine) the square's swing was low, q read 1.5–8 % high and the error was 3–12 % of
    the column's spread."""
    q = 0.5
    inner = slice(600, -600)
    for seed in range(4):
        T = _room(seed, amp)
        R = np.round(T / q) * q
        col = path_columns(R, [Column("quad", 0.0)], RATE, grid=(q, 0.0))[inner, 0]
        truth = ((T - T.mean()) ** 2)[inner]
        col, truth = col - col.mean(), truth - truth.mean()
        err = float(np.sqrt(np.mean((col - truth) ** 2)) / np.std(truth))
        gain = float(np.dot(col, truth) / np.dot(col, col))
        assert err < 0.035, (seed, err)
        assert abs(gain - 1.0) < 0.012, (seed, gain)


def test_the_candidates_read_a_coarse_log_as_the_one_lag_fit() -> None:
    """One reading of a coarse log: the columns that take the temperature behind the
    readings (the quadratic's square, the relay, the dT/dt reference slope) are built on
    ``derounded``, the one-lag fit's reconstruction, on the log's own step and origin; on
    the 12-bit step on the crossing spline, as before."""
    T = _room(3, 0.9)
    for q, o in ((0.25, 0.0), (0.5, 0.0), (0.1125, 32.0)):
        R = np.round((T - o) / q) * q + o
        grid = (q, o)
        v = derounded(R, grid)
        np.testing.assert_array_equal(behind_readings(R, grid), v)
        X = path_columns(R, [Column("quad", 60.0), Column("relay", 60.0, 0.1),
                             Column("slope", 0.0)], RATE, grid=grid)
        u = lag_filter(v, 60.0, RATE)
        quad = (u - u.mean()) ** 2
        np.testing.assert_allclose(X[:, 0], quad - quad.mean(), rtol=0, atol=1e-12)
        slope = np.gradient(v, 1.0 / RATE)
        np.testing.assert_allclose(X[:, 2], slope - slope.mean(), rtol=0, atol=1e-12)
    q = 0.0625
    R = np.round(T / q) * q
    np.testing.assert_array_equal(behind_readings(R), crossing_reconstruction(R, q))
