"""The regressor columns of each candidate built from the driving channel, and the grid points
(``Trial``) that name them."""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
from avard.core.explain.thermal_fit import lag_filter
from avard.core.explain.thermal_fit.rounding import DS18B20_STEP_K
from avard.core.explain.thermal_fit.scan import _lag_grid
from avard.core.explain.thermal_paths.settings import (
    HYSTERESIS_LEADS_S,
    LAG_GRID_S,
    NUISANCE,
    RATE_SMOOTH_S,
    WIDTHS_K,
)
from numpy.typing import NDArray


class Column(NamedTuple):
    kind: str  # "u", "start", "quad", "rate", "slope", "relay", "warmup", "given"
    lag: float
    width: float = 0.0


def _relay(v: NDArray, w: float) -> NDArray[np.float64]:
    """A non-ideal relay of width ``w`` (K), the Preisach elementary hysteron: +1 after ``v``
    rose ``w`` above its last minimum, −1 after it fell ``w`` below its last maximum (starts
    at +1, its extremum ``v[0]``).

    Switch by switch, not sample by sample: from a switch on, the running extremum (the
    last one carried in) and the first sample ``w`` beyond it are found by numpy over a
    window that grows until it holds the next switch (a slow temperature switches twice a
    cycle: a Python loop per sample was most of the hysteresis candidate's cost). The
    sample loop is kept in the tests as the reference it equals."""
    x = np.asarray(v, dtype=float)
    n = len(x)
    out = np.empty(n)
    if not n:
        return out
    state, ext, i, win = 1.0, float(x[0]), 0, 256
    while i < n:
        seg = x[i:i + win]
        if state > 0:
            run = np.maximum(np.maximum.accumulate(seg), ext)
            hit = np.flatnonzero(run - seg > w)
        else:
            run = np.minimum(np.minimum.accumulate(seg), ext)
            hit = np.flatnonzero(seg - run > w)
        if not len(hit):
            out[i:i + len(seg)] = state
            ext, i, win = float(run[-1]), i + len(seg), win * 2
            continue
        j = int(hit[0])
        out[i:i + j] = state
        state, ext = -state, float(seg[j])
        out[i + j] = state
        i, win = i + j + 1, 256
    return out


def crossing_reconstruction(T: NDArray, q: float = DS18B20_STEP_K) -> NDArray[np.float64]:
    """The temperature behind readings rounded to ``q``, the rounding treated as an error in
    the regressor: knots at the times the readings cross a mid-level (k + ½)q (linear between
    neighbouring samples, where the true temperature crossed the rounding's threshold), a
    natural cubic spline through them, clipped to the reading's own cell [r − q/2, r + q/2]
    where a sample is a plain reading (a turn between two crossings of one level is a bulge
    the spline puts inside the cell), held at the first and last knot beyond them."""
    T = np.asarray(T, dtype=float)
    t = np.arange(len(T), dtype=float)
    a, b = T[:-1], T[1:]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    kt: list[float] = []
    kv: list[float] = []
    for i in np.flatnonzero(hi - lo > 1e-9).tolist():
        for j in range(math.ceil(lo[i] / q - 0.5), math.floor(hi[i] / q - 0.5) + 1):
            m = (j + 0.5) * q
            if lo[i] <= m <= hi[i]:
                kt.append(i + (m - a[i]) / (b[i] - a[i]))
                kv.append(m)
    if len(kt) < 4:
        return T.copy()
    o = np.argsort(kt)
    x, v = np.asarray(kt)[o], np.asarray(kv)[o]
    keep = np.concatenate([[True], np.diff(x) > 0.5])
    x, v = x[keep], v[keep]
    n, h = len(x), np.diff(x)
    # the natural spline's second derivatives: a tridiagonal system, solved as banded
    diag = np.ones(n)
    diag[1:-1] = 2 * (h[:-1] + h[1:])
    lower = np.concatenate([h[:-1], [0.0]])
    upper = np.concatenate([[0.0], h[1:]])
    r = np.zeros(n)
    r[1:-1] = 6 * (np.diff(v[1:]) / h[1:] - np.diff(v[:-1]) / h[:-1])
    M = _tridiagonal(lower, diag, upper, r)
    k = np.clip(np.searchsorted(x, t) - 1, 0, n - 2)
    x0, x1, hk = x[k], x[k + 1], h[k]
    s = ((M[k] * (x1 - t) ** 3 + M[k + 1] * (t - x0) ** 3) / (6 * hk)
         + (v[k] / hk - M[k] * hk / 6) * (x1 - t) + (v[k + 1] / hk - M[k + 1] * hk / 6) * (t - x0))
    s = np.where(t < x[0], v[0], np.where(t > x[-1], v[-1], s))
    level = np.round(T / q) * q
    plain = np.abs(T - level) < 1e-6
    return np.asarray(np.where(plain, np.clip(s, level - q / 2, level + q / 2), s), dtype=float)


def _tridiagonal(lower: NDArray, diag: NDArray, upper: NDArray,
                 r: NDArray) -> NDArray[np.float64]:
    """Thomas's algorithm: x with lower[i−1]·x[i−1] + diag[i]·x[i] + upper[i]·x[i+1] = r[i]
    (``lower[i−1]`` below the diagonal in row i, ``upper[i]`` above it; diagonally dominant)."""
    n = len(diag)
    c = np.zeros(n)
    d = np.zeros(n)
    c[0], d[0] = upper[0] / diag[0] if n > 1 else 0.0, r[0] / diag[0]
    for i in range(1, n):
        m = diag[i] - lower[i - 1] * c[i - 1]
        c[i] = upper[i] / m if i < n - 1 else 0.0
        d[i] = (r[i] - lower[i - 1] * d[i - 1]) / m
    out = np.empty(n)
    out[-1] = d[-1]
    for i in range(n - 2, -1, -1):
        out[i] = d[i] - c[i] * out[i + 1]
    return out


def path_columns(T: NDArray, cols: list[Column], rate_hz: float,
                 done: dict[Column, NDArray[np.float64]] | None = None,
                 grid: tuple[float, float] = (DS18B20_STEP_K, 0.0)) -> NDArray[np.float64]:
    """The regressors ``cols`` built from the driving channel ``T`` (°C) on the slow view,
    each with its mean removed (the start state's with its own). ``done``: the columns
    already built from this same ``T`` and ``rate_hz`` (the other axes driven by the
    channel), read and added to. ``grid``: ``T``'s readings' (step K, origin)."""
    T = np.asarray(T, dtype=float)
    M = len(T)
    done = {} if done is None else done
    t = np.arange(M) / rate_hz
    cache: dict[float, NDArray] = {}
    smooth: NDArray | None = None

    def u(L: float) -> NDArray:
        if L not in cache:
            cache[L] = lag_filter(T, L, rate_hz)
        return cache[L]

    def behind() -> NDArray:
        nonlocal smooth
        if smooth is None:
            # on the driving channel's own step and origin (the 12-bit default would put a
            # coarse log's knots between its levels), read as the one-lag fit reads it
            from avard.core.explain.thermal_fit.coarse import behind_readings

            smooth = behind_readings(T, grid)
        return smooth

    out = np.empty((M, len(cols)))
    for i, c in enumerate(cols):
        if c in done:
            out[:, i] = done[c]
            continue
        if c.kind == "given":  # pragma: no cover - ``choose_path`` puts them in ``done``
            raise ValueError("a given nuisance column is built by its caller")
        if c.kind == "u":
            x = u(c.lag)
        elif c.kind in NUISANCE:
            x = np.exp(-t / abs(c.lag)) if c.lag else np.zeros(M)
        elif c.kind == "quad":
            # on the temperature behind the readings, as the relay (below): squared, the
            # readings' rounding e is an error 2(u − ū)e + e² in the regressor, locked to the
            # drive's phase (every part of the record shares it, so the jackknife does not see
            # it): on the readings q came out 3 % low on average (11 records of the quadratic
            # row) beside ±3–5 % intervals, and they held the row's truth in 21 of 38 (26 of
            # 38 on the same seeds after)
            v = lag_filter(behind(), c.lag, rate_hz)
            x = (v - v.mean()) ** 2
        elif c.kind == "rate":
            # d/dt of u smoothed forward and back through RATE_SMOOTH_S: jω/(1 + ω²s²), no
            # phase (the forward lag alone delayed the derivative by s, 6° at the HVAC
            # cycle, which the static lag then made up for: L and r 10–20 % off)
            x = (u(c.lag) - lag_filter(u(c.lag), RATE_SMOOTH_S, rate_hz)) / RATE_SMOOTH_S
            x = lag_filter(x[::-1], RATE_SMOOTH_S, rate_hz)[::-1]
        elif c.kind == "slope":
            # dT̂/dt of the temperature behind the readings, unsmoothed: the dT/dt term's
            # reference, what the smoothed "rate" column stands for (``_ungained``); not a
            # regressor of any candidate
            x = np.gradient(lag_filter(behind(), c.lag, rate_hz) if c.lag else behind(),
                            1.0 / rate_hz)
        elif c.kind == "relay":
            # on the temperature behind the readings (their rounding an error in the
            # regressor, not a signal): a relay on the staircase switches at the first
            # reading a step below a turn, up to 0.0625 K and minutes off, and the hysteresis
            # row's odd harmonics that tell it from a lead on one lag lie in that jitter
            x = _relay(lag_filter(behind(), c.lag, rate_hz), c.width)
        else:  # pragma: no cover - the kinds are this module's own
            raise ValueError(c.kind)
        out[:, i] = x - x.mean()
        done[c] = out[:, i].copy()
    return out




class Trial(NamedTuple):
    """One grid point of one candidate: θ, the regressor columns (the first the linear
    coupling's, then the extension's, then the start states), how many are couplings."""

    theta: tuple[float, ...]
    cols: tuple[Column, ...]
    n_terms: int


def _start(*lags: float) -> tuple[Column, ...]:
    return tuple(Column("start", L) for L in sorted({abs(x) for x in lags if x}))


def quadratic_leads(record_s: float, rate_hz: float) -> tuple[float, ...]:
    """The negative lags (the logged sensor lagging the die) the quadratic tries: the
    extensions' grid (``LAG_GRID_S``) mirrored, as far as the one-lag fit's own search
    reaches on this record (``thermal_fit._lag_grid``: its lead-lag range), each through the
    same lead-lag filter (``lag_filter``). With only the one-lag fit's lag on that side, a
    die 60 s ahead of the log left the quadratic at that lag's −290 to −380 s, q 0.27–0.37
    of the truth on 3 of 6 records."""
    reach = -float(np.min(_lag_grid(record_s, rate_hz)))
    return tuple(-x for x in LAG_GRID_S if 0 < x <= reach)


def trials(kind: str, lags: list[float], leads: tuple[float, ...] = ()) -> list[Trial]:
    """The grid of ``kind`` over ``lags`` (the extensions' grid and the one-lag fit's lag);
    the quadratic also over ``leads`` (``quadratic_leads``)."""
    pos = sorted({x for x in lags if x >= 0})
    if kind == "one_lag":
        return [Trial((L,), (Column("u", L), *_start(L)), 1) for L in lags]
    if kind == "two_path":
        return [Trial((a, b), (Column("u", a), Column("u", b), *_start(a, b)), 2)
                for a, b in itertools.combinations(pos, 2)]
    if kind == "quadratic":
        return [Trial((L,), (Column("u", L), Column("quad", L), *_start(L)), 2)
                for L in sorted(set(lags) | set(leads))]
    if kind == "rate":
        return [Trial((L,), (Column("u", L), Column("rate", 0.0), *_start(L)), 2) for L in pos]
    if kind == "hysteresis":
        both = sorted(set(lags) | {-x for x in HYSTERESIS_LEADS_S})
        return [Trial((L, w), (Column("u", L), Column("relay", L, w), *_start(L)), 2)
                for L in both for w in WIDTHS_K]
    raise ValueError(kind)
