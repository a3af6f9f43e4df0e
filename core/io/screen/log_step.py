"""A temperature log's reading step (a DS18B20 at 9–12 bits, a °F log, a coarse printer) found
from its values and times, and how a coarse log is said."""

from __future__ import annotations

import numpy as np
from avard.core.io.screen.temperature import DS18B20_ERROR_C, DS18B20_STEP_C, POWER_ON_C
from numpy.typing import NDArray

#: A log printed this coarsely (every value a multiple of it) holds neither grid: its
#: rounding is wider than both the °C grid's and the °F grid's steps
COARSE_PRINT = 0.1
#: A value is on a grid within this (°C or °F): a logger printing 2 decimals rounds a grid
#: point by up to 0.005, and the float rounding of its text adds a little.
PRINT_TOL = 0.006


def _grid_share(v: NDArray[np.float64], origin: float, step: float, tol: float) -> float:
    """The share of the distinct values ``v`` within ``tol`` of the grid origin + k·step."""
    r = (v - origin) / step
    return float(np.mean(np.abs(r - np.rint(r)) * step <= tol))


def is_coarse(step: float) -> bool:
    """Whether readings on ``step`` (K) are coarser than the DS18B20's 12-bit 0.0625 K, the
    step the thermal model's 12-bit path assumes (its straight-line de-rounding, its
    regressor as logged)."""
    return step > DS18B20_STEP_C * (1.0 + 1e-6)


#: Candidate steps (K) of a temperature log's readings, coarsest first: the DS18B20's four
#: resolutions (9–12 bits) in °C, the same read in °F and taken as °C (1.8× each), a logger
#: printing to 0.1 or 0.01.
LOG_STEPS_K = (0.9, 0.5, 0.45, 0.25, 0.225, 0.125, 0.1125, 0.1, 0.0625, 0.01)
#: The DS18B20's resolutions (K), 9 to 12 bits, and each one's bits.
DS18B20_BITS = {0.5: 9, 0.25: 10, 0.125: 11, 0.0625: 12}
#: A step holds a log when at least this share of its distinct values lie on its grid.
LOG_STEP_SHARE = 0.95
#: ... and its on-grid distinct values hold this many pairs exactly one step apart. A room's
#: temperature is continuous, so a finer log's readings pass every level between two they
#: visit: neighbours one coarse step apart with no reading between them are the coarse
#: step's mark, where two or three values alone could be a stable room's dwell on any grid.
LOG_STEP_NEIGHBOURS = 2
#: The least number of distinct values that can show a step of the values' own spacing
#: (one no candidate holds): fewer could be any spacing by chance.
LOG_STEP_OWN_VALUES = 8
#: Readings at most this far apart (s) that differ by a whole coarse step show it in time
#: when their distinct values cannot (a stable room on two or three levels): a room or a
#: plate does not move 0.1 K in a few seconds, so a log whose every change between such
#: readings is one step q (and at least ``LOG_STEP_NEIGHBOURS`` of them) reads on q; a
#: finer log of the same room passes the levels between (``log_step``'s ``times``).
LOG_STEP_JUMP_S = 5.0


def _on_step(u: NDArray[np.float64], q: float, neighbours: int = LOG_STEP_NEIGHBOURS
             ) -> tuple[float, float] | None:
    """(q, origin) when the distinct values ``u`` hold the grid origin + k·q (module
    constants ``LOG_STEP_*``), None when they do not; the origin their most common
    remainder (0 for a grid through 0 within the print)."""
    # on the grid within a 2-decimal print (``PRINT_TOL``), a fine step within a tenth of it
    tol = min(PRINT_TOL, q / 10.0)
    r = np.mod(u, q)
    bins, counts = np.unique(np.rint(r / tol).astype(np.int64), return_counts=True)
    m0 = float(bins[int(np.argmax(counts))]) * tol
    dm = np.abs(r - m0)
    best: tuple[float, NDArray[np.float64]] | None = None
    for origin in (0.0, float(np.median(r[np.minimum(dm, q - dm) <= tol]))):
        d = np.abs(r - origin)
        on = u[np.minimum(d, q - d) <= tol]
        if best is None or len(on) > len(best[1]):
            best = (origin, on)
    assert best is not None
    origin, on = best
    if len(on) < LOG_STEP_SHARE * len(u):
        return None
    if np.count_nonzero(np.abs(np.diff(on) - q) <= 2 * tol) < neighbours:
        return None
    return q, (0.0 if min(origin, q - origin) <= tol else round(origin, 4))


def log_step(values: NDArray, times: NDArray | None = None) -> tuple[float, float] | None:
    """(step K, origin) of a temperature log's readings, judged on its distinct values (the
    error and power-on values left out): the coarsest candidate (``LOG_STEPS_K``) whose grid
    holds them (``_on_step``); failing every candidate, the values' own spacing (their
    median difference, with at least ``LOG_STEP_OWN_VALUES`` values) if it holds them.

    A log too stable to show its step in its distinct values (two or three levels: a
    12-bit log dwelling on levels 0.125 apart has the same set) is judged in time where the
    readings' ``times`` (s) are given (``_step_in_time``): every change between readings at
    most ``LOG_STEP_JUMP_S`` apart whole coarse steps, most of them one, at least
    ``LOG_STEP_NEIGHBOURS`` times, is that step. Failing that, a log on the 12-bit grid
    keeps the DS18B20's 0.0625 K; None when the log is on no grid (a logger's fine or
    unrounded values)."""
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v) & (v != DS18B20_ERROR_C) & (v != POWER_ON_C)
    v = v[ok]
    u = np.unique(np.round(v, 6))
    if len(u) == 0:
        return (DS18B20_STEP_C, 0.0)
    for q in LOG_STEPS_K:
        found = _on_step(u, q)
        if found is not None:
            return found
    if times is not None:
        found = _step_in_time(v, np.asarray(times, dtype=float)[ok], u)
        if found is not None:
            return found
    if _grid_share(u, 0.0, DS18B20_STEP_C, PRINT_TOL) >= LOG_STEP_SHARE:
        return (DS18B20_STEP_C, 0.0)
    if len(u) >= LOG_STEP_OWN_VALUES:
        q = round(float(np.median(np.diff(u))), 4)
        if q > 0.0:
            return _on_step(u, q)
    return None


def _step_in_time(v: NDArray[np.float64], t: NDArray[np.float64], u: NDArray[np.float64]
                  ) -> tuple[float, float] | None:
    """(q, origin) of readings ``v`` at times ``t`` (s), distinct values ``u``, where every
    change between readings at most ``LOG_STEP_JUMP_S`` apart is a whole number of one
    coarse candidate step q (within the print) and most of them one q, at least
    ``LOG_STEP_NEIGHBOURS`` of them, and the values hold q's grid (``_on_step`` without its
    neighbour pairs); None otherwise. (A genuine fast move, a door or a touch, jumps more
    than one step between neighbouring readings now and then; a finer log's room never
    jumps a coarse step at all.)"""
    if len(v) < 2:
        return None
    d = np.abs(np.diff(v))[np.diff(t) <= LOG_STEP_JUMP_S]
    d = d[d > PRINT_TOL]
    if len(d) < LOG_STEP_NEIGHBOURS:
        return None
    for q in LOG_STEPS_K:
        if not is_coarse(q):
            continue
        k = np.round(d / q)
        tol = 2 * min(PRINT_TOL, q / 10.0)
        if (np.all((k >= 1) & (np.abs(d - k * q) <= k * tol))
                and np.count_nonzero(k == 1) > len(d) / 2):
            return _on_step(u, q, neighbours=0)
    return None


def _coarse_what(grid: tuple[float, float]) -> str:
    """What a coarse grid may be: "a 0.25 K step (a DS18B20 at 10 bits?)"."""
    q, origin = grid
    fbits = {round(1.8 * k, 4): b for k, b in DS18B20_BITS.items()}
    what = (f"a DS18B20 at {DS18B20_BITS[q]} bits?" if q in DS18B20_BITS and origin == 0.0
            else f"a DS18B20 at {fbits[round(q, 4)]} bits read in °F and taken as °C?"
            if round(q, 4) in fbits else "a log printed to 0.1?" if q == COARSE_PRINT
            else "another logger's resolution?")
    return f"a {q:g} K step ({what})"


def coarse_text(grid: tuple[float, float]) -> str:
    """A coarse grid in words, for a log's note: "readings on a 0.25 K step (a DS18B20 at 10
    bits?), coarser than the 12-bit 0.0625 K: the thermal model takes the temperature
    behind them from their crossings and its rounding on that step"."""
    return (f"readings on {_coarse_what(grid)}, coarser than the 12-bit "
            f"{DS18B20_STEP_C:g} K: the thermal model takes the temperature behind them from "
            "their crossings and its rounding on that step")


def coarse_cause(grid: tuple[float, float]) -> str:
    """A coarse grid as a possible cause of an unexplained axis's misfit, in words."""
    return (f"it reads on {_coarse_what(grid)}, coarser than the 12-bit "
            f"{DS18B20_STEP_C:g} K: the temperature behind its readings, reconstructed from "
            "their crossings, may be off by more than the model carries")
