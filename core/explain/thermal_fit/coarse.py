"""The temperature behind a log's readings: the de-rounded channel (straight lines between
crossings at 12 bits, the crossing spline on a coarser step) and each channel's grid."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from avard.core.io.screen.log_step import is_coarse
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.rounding import DS18B20_STEP_K


def derounded(T: NDArray, grid: tuple[float, float] | None = None,
              tops: bool = True, real: NDArray[np.bool_] | None = None
              ) -> NDArray[np.float64]:
    """The logged channel ``T`` (slow view, readings interpolated between their times) with
    its readings' rounding smoothed out: where the readings dwell on one 0.0625 K step (a
    run of equal values), the temperature passed the threshold between two neighbouring
    runs' levels half way between them, so those crossings, (time, mid-level), are knots of
    a straight-line interpolation, with the turning points' runs at their middles and the
    first and last readings as they are; ``T`` itself where it holds fewer than two runs.
    NaN stays NaN.

    ``grid``: the readings' (step, origin), default the 12-bit (0.0625, 0). On a
    step coarser than the 12-bit one the straight lines miss the turns by up to half a
    step for as long as the readings dwell there (through a lag, a misfit at τ of the
    dwell), so the readings' mid-level crossings carry a spline clipped to each reading's
    cell instead (``thermal_paths.columns.crossing_reconstruction``), and before the first
    crossing and after the last (``_crossing_ends``) the spline's slope goes on within the
    reading's cell: held at the first knot's mid-level, the record's first dwell sat up to
    half a coarse step off for minutes, a start the lag filter carries into the τ of the
    lag, where the coupling is read. A gap (NaN)
    is bridged on the samples' own times, as the straight lines are: the spline is built on
    the whole index with the gap's values a straight line between its neighbours (not on
    the finite samples squeezed together, which ran it across the gap as if no time had
    passed), and the gap stays NaN. ``real``: the samples that are readings, where ``T``
    holds a gap already bridged (the slow view interpolates its holes: ``SlowView.finish``),
    the gap then as a NaN's (None: every finite sample). On a coarse step the turns' tops
    are a cycle's (``_turn_tops``) unless ``tops`` is False (the spline's own, a
    parabola's: the other reading ``coarse_gain_se`` weighs it against)."""
    T = np.asarray(T, dtype=float)
    q, origin = (DS18B20_STEP_K, 0.0) if grid is None else grid
    if is_coarse(q):
        from avard.core.explain.thermal_paths.columns import crossing_reconstruction

        out = T.copy()
        ok = np.flatnonzero(np.isfinite(T))
        if len(ok) >= 4:
            # on the kept samples' own times: the gap bridged in a straight line (its values
            # are off the grid, so the reconstruction does not clip them to a cell)
            v = np.interp(np.arange(ok[0], ok[-1] + 1), ok, T[ok]) - origin
            r = _crossing_ends(v, crossing_reconstruction(v, q), q)
            seen = np.isfinite(T[ok[0]:ok[-1] + 1])
            if real is not None:
                seen &= np.asarray(real, dtype=bool)[ok[0]:ok[-1] + 1]
            r = (_turn_tops(v, r, q, seen) if tops else r) + origin
            out[ok] = r[ok - ok[0]]
        return out
    out = T.copy()
    ok = np.flatnonzero(np.isfinite(T))
    if len(ok) < 4:
        return out
    v = T[ok]
    same = np.diff(v) == 0.0
    # runs of equal values: starts and ends (inclusive) of each run of ``same``
    edge = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
    if len(starts) < 2:
        return out
    at = 0.5 * (ok[ends[:-1]] + ok[starts[1:]])
    level = 0.5 * (v[ends[:-1]] + v[starts[1:]])
    # runs more than one step apart are a temperature moving faster than the readings dwell:
    # there the readings between them are the knots, as they are (the rounding is small
    # beside the change; a straight line across a fast stretch bent the record's start)
    lv = v[starts]
    jump = np.abs(np.diff(lv))
    fast = jump > 1.5 * float(np.median(jump))
    if np.any(fast):
        keep_mid = ~fast
        at, level = at[keep_mid], level[keep_mid]
        inner = np.concatenate([np.arange(ends[p], starts[p + 1] + 1)
                                for p in np.flatnonzero(fast)])
        at = np.concatenate([at, ok[inner].astype(float)])
        level = np.concatenate([level, v[inner]])
    # a run whose neighbours are both on one side of it is a turning point: the
    # temperature went past the threshold and back, by up to a step: its level at its
    # middle
    turn = np.flatnonzero((lv[1:-1] - lv[:-2]) * (lv[1:-1] - lv[2:]) > 0) + 1
    # the record's ends at their own readings (held at the first crossing's mid-level, the
    # first run was a step of q/2 at the start: a warm-up to the transients' search)
    at = np.concatenate([at, 0.5 * (ok[starts[turn]] + ok[ends[turn]]), [ok[0], ok[-1]]])
    level = np.concatenate([level, lv[turn], [v[0], v[-1]]])
    o = np.argsort(at, kind="stable")
    at, level = at[o], level[o]
    out[ok] = np.interp(ok, at, level)
    return out


def behind_readings(T: NDArray, grid: tuple[float, float] | None = None,
                    real: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """The temperature behind the readings ``T`` (slow view, °C) on their ``grid`` (step K,
    origin; None: the 12-bit (0.0625, 0)), as every reading of the log takes it: the thermal
    path candidates' columns that are not linear in the readings (the quadratic's square, the
    relay, the dT/dt term's reference slope: ``thermal_paths.columns.path_columns``) and the
    relay's switch-time floor (``PathFit.relay_floor``). On a coarse step it is ``derounded``,
    the one-lag fit's own reading (the crossing spline, its ends carried on its slope, each
    turn's top a cycle's, ``_turn_tops``): the bare spline bulges at a turn as a parabola
    where a cycle turns as a cosine, the swing it gives is low by as much as the tops carry
    of it, and a square or a relay's switches read on it inherit that error while the one
    lag beside them does not. On the 12-bit step it is the crossing spline
    (``crossing_reconstruction``), the candidates' reading there, which the straight lines of
    ``derounded`` (the one-lag signal's) are not: a turn within one 0.0625 K step is a small
    part of any swing a coupling is read on. ``real``: the samples that are readings where
    ``T`` bridges a gap (``derounded``)."""
    from avard.core.explain.thermal_paths.columns import crossing_reconstruction

    q, o = (DS18B20_STEP_K, 0.0) if grid is None else grid
    if is_coarse(q):
        return derounded(T, (q, o), real=real)
    T = np.asarray(T, dtype=float)
    return np.asarray(crossing_reconstruction(T - o, q) + o, dtype=float)


def channel_grids(grids: Sequence[tuple[float, float] | None] | None, k: int
                  ) -> list[tuple[float, float]]:
    """Each of ``k`` temperature channels' (step K, origin): ``grids``' (None, or a None
    entry: the DS18B20's 12-bit (0.0625, 0))."""
    return [(DS18B20_STEP_K, 0.0) if g is None else g
            for g in (list(grids) if grids is not None else [None] * k)]


def coarse_regressor(temps: NDArray, grids: Sequence[tuple[float, float] | None] | None = None,
                     holes: Mapping[int, Sequence[tuple[int, int]]] | None = None
                     ) -> NDArray[np.float64]:
    """The temperature channels (M, k) the thermal regression reads, each on its own grid
    (``grids``, per column; ``channel_grids``): as logged on the 12-bit step, the crossing
    reconstruction (``derounded``) on a coarser one, column by column (a coarse log leaves a
    finer one as logged). A
    coarse quantiser's gain at the drive is not 1 (its describing function: above 1 where
    the drive swings a few steps), an error in the variable no τ floor removes, which put
    ĉ low by that gain, more the coarser the step; the reconstruction follows the drive's
    amplitude. The rounding floors (``rounding_floor_tau``) stay the raw readings': the
    sawtooth they model is the readings', and on the smooth reconstruction a slower slope
    made the floor of a 0.5 K log infinite (no τ left to the regression). ``holes``: per
    column, the blocks (first, last sample) its log says nothing about (``Holes``): the slow
    view bridged them, and ``derounded`` reads them as gaps (``real``)."""
    temps = np.asarray(temps, dtype=float)
    T = temps.reshape(len(temps), -1)
    gs = channel_grids(grids, T.shape[1])
    if not any(is_coarse(g[0]) for g in gs):
        return temps
    out = np.column_stack([derounded(T[:, j], g, real=_readings(len(T), (holes or {}).get(j)))
                           if is_coarse(g[0]) else T[:, j] for j, g in enumerate(gs)])
    return out.reshape(temps.shape)


def _readings(n: int, holes: Sequence[tuple[int, int]] | None) -> NDArray[np.bool_] | None:
    """The samples of ``n`` outside ``holes`` (first, last sample of each); None: no hole."""
    if not holes:
        return None
    keep = np.ones(n, dtype=bool)
    for a, b in holes:
        keep[max(0, a):max(0, min(n, b + 1))] = False
    return keep


#: Samples beyond the first (last) crossing whose slope the reconstruction carries back
#: (forward) to the record's start (end): about a minute of a 1.6 s slow view, the time a
#: room's cycle takes between neighbouring crossings of a coarse step.
CROSSING_END_SPAN = 40


def _crossing_ends(v: NDArray, R: NDArray, q: float) -> NDArray[np.float64]:
    """``R`` (the crossing reconstruction of readings ``v`` on step ``q``) before the readings'
    first change of level and after their last: the slope of ``R`` over
    ``CROSSING_END_SPAN`` samples beyond it, carried to the record's end, within the
    reading's cell there (the temperature was in it, and reached its edge at the crossing)."""
    lev = np.round(v / q)
    ch = np.flatnonzero(np.diff(lev) != 0)
    out = np.array(R, dtype=float)
    if len(ch) < 2:
        return out
    i0, i1 = int(ch[0]) + 1, int(ch[-1])
    j = min(len(R) - 1, i0 + CROSSING_END_SPAN)
    s = (R[j] - R[i0]) / max(j - i0, 1)
    c = lev[0] * q
    out[:i0] = np.clip(R[i0] + s * (np.arange(i0) - i0), c - q / 2, c + q / 2)
    j = max(0, i1 - CROSSING_END_SPAN)
    s = (R[i1] - R[j]) / max(i1 - j, 1)
    c = lev[-1] * q
    out[i1 + 1:] = np.clip(R[i1] + s * (np.arange(i1 + 1, len(R)) - i1), c - q / 2, c + q / 2)
    return out


def _turn_tops(v: NDArray, R: NDArray, q: float,
               real: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """``R`` (the crossing reconstruction of readings ``v`` on step ``q``) with each turn's
    top (a run of readings on one level whose neighbours both lie on one side of it) raised
    as a cycle's top, not a parabola's. Between the two crossings of the threshold θ that
    bound the turn, D apart, the natural spline bulges as a cubic with its crossing slopes
    s, about s·D/4 above θ, which is exact for a parabola; a cycle of period P turns as a
    cosine, whose top above θ is 2(1 − cos α)/(α sin α) times that, α = πD/P (1 for a short
    dwell, more the longer the dwell is beside the cycle: where the swing spans a step or
    two the tops carry much of it, and the spline's left the swing low and ĉ as much
    high). P is the time between the
    turn's neighbouring turns of the same sense, two turns away (twice the nearest turn's
    distance at the record's ends); α is held below π/2 (a dwell of half the cycle: the
    threshold at the cycle's middle, where a cosine's slope is largest). The top stays
    inside the reading's cell. ``real``: the samples that are readings (not a gap's bridge);
    a turn whose span or neighbouring runs reach into a gap is left as the spline has it
    (its dwell and crossings are the bridge's, not the room's)."""
    lev = np.round(v / q)
    out = np.array(R, dtype=float)
    ch = np.flatnonzero(np.diff(lev) != 0)
    if len(ch) < 3:
        return out
    starts = np.concatenate([[0], ch + 1])
    ends = np.concatenate([ch, [len(v) - 1]])
    lv = lev[starts]
    k = np.arange(1, len(lv) - 1)
    turn = k[(lv[k] - lv[k - 1]) * (lv[k] - lv[k + 1]) > 0]
    if len(turn) < 2:
        return out
    mid = 0.5 * (starts[turn] + ends[turn])
    # which runs are turns, and the gap samples before each index, built once: a flickering
    # log has a turn at almost every run, and a lookup rebuilt per turn was quadratic
    is_turn = np.zeros(len(lv), dtype=bool)
    is_turn[turn] = True
    if real is not None:
        holes = np.concatenate([[0], np.cumsum(~np.asarray(real, dtype=bool))])
    for i, r in enumerate(turn.tolist()):
        a, b = int(starts[r]), int(ends[r])
        if real is not None and holes[int(ends[r + 1]) + 1] > holes[int(starts[r - 1])]:
            continue
        if i >= 1 and i + 1 < len(turn):
            period = mid[i + 1] - mid[i - 1]
        else:
            period = 2.0 * (mid[i + 1] - mid[i] if i == 0 else mid[i] - mid[i - 1])
        if not period > 0:
            continue
        alpha = min(math.pi * (b - a + 1) / period, 0.499 * math.pi)
        side = np.sign(lv[r] - lv[r - 1])
        theta = (lv[r] - 0.5 * side) * q
        bulge = side * (out[a:b + 1] - theta)
        # the cosine's top: through θ at ±D/2 and through θ − q at the outer crossings,
        # D' apart, where the neighbouring runs are plain steps down (not turns, not ends)
        a0, b1 = int(starts[r - 1]), int(ends[r + 1])
        outer = (not is_turn[r - 1] and not is_turn[r + 1]
                 and r - 1 > 0 and r + 1 < len(lv) - 1)
        alpha2 = math.pi * (b1 - a0 + 1) / period
        if outer and alpha < alpha2 < math.pi:
            h = q * (1.0 - math.cos(alpha)) / (math.cos(alpha) - math.cos(alpha2))
        else:
            h = 2.0 * (1.0 - math.cos(alpha)) / (alpha * math.sin(alpha)) * float(bulge.max())
        peak = float(bulge.max())
        f = h / peak if peak > 0 else 1.0
        top = theta + f * (out[a:b + 1] - theta)
        c = lv[r] * q
        out[a:b + 1] = np.clip(top, c - q / 2, c + q / 2)
    return out
