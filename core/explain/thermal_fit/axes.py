"""The fit of each axis (``fit_thermal``, ``fit_thermal_axes``): distinct lags, the thermal paths
beside one lag and the pick between them."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.explain.thermal_paths import PathFit
    from avard.core.explain.thermal_paths.columns import Column
from avard.core.explain.thermal_fit.channel import _choose_channel, _coef_slope
from avard.core.explain.thermal_fit.coarse import channel_grids, coarse_regressor
from avard.core.explain.thermal_fit.fit import ThermalFit, coarse_gain_se
from avard.core.explain.thermal_fit.holes import Holes, hole_mask
from avard.core.explain.thermal_fit.jackknife import _jackknife_se, _jackknife_views, coefficient_se
from avard.core.explain.thermal_fit.lag import _with_lag_jackknife, best_lag, lag_interval
from avard.core.explain.thermal_fit.octaves import CouplingTest, coupling_test, octave_spectra
from avard.core.explain.thermal_fit.rounding import rounding_floor_tau
from avard.core.explain.thermal_fit.scan import (
    OPEN_END_MARGIN,
    ScanPoint,
    _axes_reference,
    _lag_grid,
    _merge,
    _refine,
    _scan,
)
from avard.core.explain.thermal_fit.settings import JACKKNIFE_GROUPS, SCAN_POINTS
from avard.core.explain.thermal_fit.signals import allan2, lag_filter, without_start
from avard.core.explain.thermal_fit.sums import min_tau_for

#: Lags closer than this (relative) are one lag to the scan.
SAME_LAG_REL = 1e-9


def _distinct(cands: set[float], have: set[float]) -> list[float]:
    """The lags of ``cands`` (sorted) that are neither in ``have`` nor the same as one of
    them or as each other to ``SAME_LAG_REL``. Overlapping refinements of several axes give
    one lag twice up to rounding (geometric steps from different ends: 2002.8092465883267
    and …287 s on a 12 h quiet-lab record). Scanned twice, the two held the same z to
    1e-12: which of them took the largest z (and so where the next refinement went) was
    decided by rounding, and a parabola through the best lag and such a neighbour
    (``_peak``) put its vertex where rounding put it (the other channel's lag 1970 or
    2003 s by the order of a sum, on that record; 3 of 8 records moved their lag or a
    held-out χ² when a sum's rounding changed)."""
    out: list[float] = []
    ref = np.array(sorted(have), dtype=float)
    for v in sorted(cands):
        if np.any(np.abs(ref - v) <= SAME_LAG_REL * np.maximum(np.abs(ref), abs(v))):
            continue
        if out and abs(out[-1] - v) <= SAME_LAG_REL * max(abs(v), abs(out[-1])):
            continue
        out.append(v)
    return out


def fit_thermal(y: NDArray, temps: NDArray, names: list[str], rate_hz: float) -> ThermalFit:
    """The thermal model of one axis ``y``: :func:`fit_thermal_axes` for a single column."""
    return fit_thermal_axes(np.asarray(y, dtype=float)[:, None], temps, names, rate_hz)[0]


def fit_thermal_axes(Y: NDArray, temps: NDArray, names: list[str], rate_hz: float,
                     holes: Holes | None = None, lag_intervals: bool = True,
                     paths: bool = False,
                     warmups: dict[int, tuple[float, ...]] | None = None,
                     grids: Sequence[tuple[float, float] | None] | None = None
                     ) -> list[ThermalFit]:
    """The thermal model of every axis of ``Y`` (M, C) (slow view at ``rate_hz``) against the
    temperature channels ``temps`` (M, k) °C named ``names`` (see module doc). ``holes``: per
    channel, the blocks its log says nothing about (the input screen's dropouts, stuck runs,
    masked readings), left out of its regression with the lag's settling after them.
    ``lag_intervals`` False: no jackknife of the lag (the held-out halves need only the
    estimates); the lag's interval is then the estimate itself. ``paths``: for each axis
    whose coupling passes its test, the thermal path beyond one lag chosen by held-out
    likelihood (``thermal_paths.choose_path``) on its driving channel, beside the warm-ups
    ``warmups`` (``with_paths``). ``grids``: each channel's (step K, origin) (None, or a
    None entry: the 12-bit default; ``screen.ScreenLog.rounding_grid``): each channel's
    regressor, rounding floor and coefficient's interval on its own step, so a coarse log
    leaves a finer channel's fit as it is."""
    holes = holes or {}
    Y = np.asarray(Y, dtype=float)
    gs = channel_grids(grids, np.asarray(temps).reshape(len(Y), -1).shape[1])
    # the rounding floors stay the readings' own (``coarse_regressor``)
    raw, temps = temps, coarse_regressor(temps, gs, holes)
    record_s = len(Y) / rate_hz
    # the lag scan runs on at most SCAN_POINTS block means (a 60 h record: 8 s blocks; the
    # lags sought are minutes); the chosen lag is then fitted on the whole slow view
    f = 1 << max(0, math.ceil(math.log2(len(Y) / SCAN_POINTS)))
    m = (len(Y) // f) * f
    Ys = Y[:m].reshape(-1, f, Y.shape[1]).mean(axis=1)
    Ts = temps[:m].reshape(-1, f, temps.shape[1]).mean(axis=1)
    rate_s = rate_hz / f
    grid = _lag_grid(record_s, rate_s)
    scans: dict[int, list[list[ScanPoint]]] = {}
    ref = _axes_reference(Ys, rate_s)
    for j in range(temps.shape[1]):
        hj = [(a // f, b // f) for a, b in holes.get(j, [])]
        floor = rounding_floor_tau(raw[:m].reshape(-1, f, raw.shape[1]).mean(axis=1)[:, j],
                                   rate_s, step=gs[j][0])
        per_axis = [sorted(sc, key=lambda p: p.lag)
                    for sc in _scan(Ys, Ts[:, j], grid, rate_s, hj, ref, floor)]
        # coarse to fine: twice between the neighbouring lags of each axis's best
        for n_fine in (13, 9):
            fine: set[float] = set()
            for sc in per_axis:
                lags = [p.lag for p in sc]
                fine.update(_refine(lags, lags[int(np.argmax([p.z for p in sc]))], n_fine))
            new = _distinct(fine, {p.lag for sc in per_axis for p in sc})
            if new:
                extra = _scan(Ys, Ts[:, j], new, rate_s, hj, ref, floor)
                per_axis = [_merge(a, b) for a, b in zip(per_axis, extra, strict=True)]
        if lag_intervals:
            per_axis = _with_lag_jackknife(per_axis, grid, Ys, Ts[:, j], rate_s, hj, ref,
                                           floor)
        scans[j] = per_axis
    floors = {j: rounding_floor_tau(raw[:, j], rate_hz, step=gs[j][0]) for j in scans}
    # each channel's held-out regressors (``holdout.channel_heldout``), built once for every
    # axis that scores the channel at the same lag (the same slow view of the same channel)
    columns: dict[int, dict[Column, NDArray[np.float64]]] = {}
    fits = [_pick(Y[:, a], temps, names, rate_hz, {j: scans[j][a] for j in scans}, holes,
                  floors, columns, {j: g[0] for j, g in enumerate(gs)})
            for a in range(Y.shape[1])]
    fits = [coarse_gain_se(replace(ft, grid=gs[ft.channel_index]), raw, temps) for ft in fits]
    # the readings as logged: the path choice reconstructs them on each channel's grid itself
    return with_paths(fits, Y, raw, holes, floors, warmups) if paths else fits


def with_paths(fits: list[ThermalFit], Y: NDArray, temps: NDArray, holes: Holes | None = None,
               floors: dict[int, float] | None = None,
               warmups: dict[int, tuple[float, ...]] | None = None,
               given: dict[int, tuple[NDArray, ...]] | None = None) -> list[ThermalFit]:
    """``fits`` (``fit_thermal_axes`` of the columns of ``Y``) each with the thermal path
    chosen on its driving channel (``thermal_paths.choose_path``), on every axis: a response
    the one lag cannot follow (quadratic, hysteresis) may fail the one-lag test and pass its
    own. ``floors``: each channel's rounding floor (τ s), computed when not given;
    ``warmups``: per axis, the time constants (s) of the warm-ups found on it, fitted as
    nuisance beside every candidate; ``given``: per axis, the signals of the transients found
    on it, each a nuisance column of free size beside every candidate (``choose_path``)."""
    Y = np.asarray(Y, dtype=float)
    if floors is None:
        # each driving channel's on its own step (``ThermalFit.grid``)
        floors = {f.channel_index: rounding_floor_tau(temps[:, f.channel_index], f.rate_hz,
                                                      step=f.grid[0]) for f in fits}
    # the path regressors of a channel, built once for all the axes it drives (the same
    # slow view of the same channel: the same columns)
    columns: dict[int, dict[Column, NDArray[np.float64]]] = {}
    out = []
    for a, f in enumerate(fits):
        out.append(_with_path(f, Y[:, a], temps, holes, floors,
                              columns.setdefault(f.channel_index, {}),
                              (warmups or {}).get(a, ()), (given or {}).get(a, ())))
    return out


def _with_path(fit: ThermalFit, y: NDArray, temps: NDArray, holes: Holes | None,
               floors: dict[int, float], columns: dict[Column, NDArray[np.float64]] | None = None,
               warmups: tuple[float, ...] = (), given: tuple[NDArray, ...] = ()) -> ThermalFit:
    """``fit`` with the thermal path chosen on its driving channel; when the path is not one
    lag, its linear coupling's coefficient and first lag stand in for the one lag's."""
    from dataclasses import replace

    pf = path_of(fit, y, temps, holes, floors, columns, warmups, given)
    if pf.kind == "one_lag":
        return replace(fit, path=pf) if fit.passed else fit
    s = pf.chosen
    # an extension passed its own test (its extra term's z at the paths' share, held out
    # better than one lag and than nothing): on an axis whose one-lag z failed, that test is
    # the claim's
    test = {} if fit.passed else {"z": s.z_extra, "threshold": pf.z_threshold}
    # the path's se is its regression's: a coarse log's gain uncertainty (``coarse_gain_se``)
    # is added to it as to the one lag's
    b, se = float(s.beta[0]), float(s.beta_se[0])
    return replace(fit, path=pf, coefficient=b, coef_se=math.hypot(se, fit.gain_rel * b),
                   lag_s=float(s.theta[0]), lag_lo=float(s.theta_lo[0]),
                   lag_hi=float(s.theta_hi[0]), lag_open=s.open_end, **test)


def path_of(fit: ThermalFit, y: NDArray, temps: NDArray, holes: Holes | None,
            floors: dict[int, float] | None = None,
            columns: dict[Column, NDArray[np.float64]] | None = None,
            warmups: tuple[float, ...] = (), given: tuple[NDArray, ...] = ()) -> PathFit:
    """The path choice (``thermal_paths.choose_path``'s ``PathFit``) of axis ``y`` on
    ``fit``'s driving channel, started from ``fit``'s one lag; ``floors`` each channel's
    rounding floor (computed when not given)."""
    from avard.core.explain.thermal_paths import choose_path

    j = fit.channel_index
    if floors is None or j not in floors:
        floors = {**(floors or {}), j: rounding_floor_tau(temps[:, j], fit.rate_hz,
                                                          step=fit.grid[0])}
    keep = hole_mask(len(y), (holes or {}).get(j, []), max(abs(fit.lag_s), 60.0),
                     fit.rate_hz)
    ref = fit.allan
    edf = np.asarray(ref.edf, dtype=float)
    edf = edf[:, 0] if edf.ndim == 2 else edf
    # an extension that explain's held-out measure cannot test is refused only where it would
    # be the claim's whole basis (the one lag failed its own test): on a null axis a slow
    # relay at 1837 s on 4 h passed its extra term's z untested; where the one lag is
    # claimed, a second path through a long lag is the better reading and the verdict says
    # whether the held-out test could run
    return choose_path(y, temps[:, j], fit.rate_hz, fit.lag_s, np.asarray(ref.tau, float),
                       edf, floors.get(j, 0.0), keep, columns, warmups,
                       held_only=not fit.passed, given=given, grid=fit.grid)


def _pick(y: NDArray, temps: NDArray, names: list[str], rate_hz: float,
          best: dict[int, list[ScanPoint]], holes: Holes | None = None,
          floors: dict[int, float] | None = None,
          columns: dict[int, dict[Column, NDArray[np.float64]]] | None = None,
          steps: dict[int, float] | None = None) -> ThermalFit:
    """The driving channel and lag of one axis from its scans, with the profile interval;
    ``columns``: per channel, the held-out regressors other axes built (``_choose_channel``);
    ``steps``: each channel's reading step (K; default the 12-bit)."""
    zmax = {j: max(s.z for s in sc) for j, sc in best.items()}

    def at_end(sc: list[ScanPoint]) -> bool:
        k = int(np.argmax([s.z for s in sc]))
        return k in (0, len(sc) - 1)

    # a channel whose lag sits at the end of the search (open) is preferred over one with an
    # interior optimum only when its z² is larger by OPEN_END_MARGIN
    def rank(j: int) -> float:
        return zmax[j] ** 2 - (OPEN_END_MARGIN if at_end(best[j]) else 0.0)

    jb = max(zmax, key=rank)
    compared: dict[str, dict[str, float]] = {}
    note = ""
    # a channel whose readings never stand above their own rounding at any τ (rounding
    # floor infinite: a plate that barely moves) has no τ to regress on: it cannot drive
    usable = {j: sc for j, sc in best.items()
              if math.isfinite((floors or {}).get(j, 0.0))}
    if len(usable) > 1:
        jb, compared, note = _choose_channel(y, temps, names, rate_hz, usable, holes, floors,
                                             columns, steps)
    elif len(usable) == 1:
        jb = next(iter(usable))
    scan = best[jb]
    k = int(np.argmax([s.z for s in scan]))
    # the lag its interval is about (the estimator the leave-one-out lags are), not the grid
    # point: the fine grid's step (≈ 1 s at −60 s) is as large as the lag's spread there
    L = best_lag(scan, k)
    mt = min_tau_for(L, (floors or {}).get(jb, 0.0))
    u = lag_filter(temps[:, jb], L, rate_hz)
    yu = without_start(np.column_stack([y, u]), L, rate_hz)
    keep = hole_mask(len(y), (holes or {}).get(jb, []), L, rate_hz)
    res = allan2(yu[:, 0], yu[:, 1], rate_hz, keep)
    ms = np.rint(np.asarray(res.tau, dtype=float) * rate_hz).astype(np.int64)
    # the test's analytic se from this regressor's own octave covariance (once per axis:
    # the scan compares lags and channels under one common covariance, ``_rho``, which a
    # regressor's own made unequal: a 20-min lag on the ambient channel lost to the plate
    # through 59 s, its smoother regressor's octaves more alike)
    # a channel below its rounding at every τ (an infinite floor: a half of a record whose
    # drive is a step or two of the readings) leaves the test no τ: nothing to test
    test = (coupling_test(res, octave_spectra(yu[:, 1], ms, mt * rate_hz), mt)
            if math.isfinite(mt) else CouplingTest(0.0, math.inf, 0, math.inf))
    c = test.c
    # the record's parts once, for ĉ's jackknife and the test combination's
    views = _jackknife_views(yu[:, 0], yu[:, 1], rate_hz, JACKKNIFE_GROUPS, keep, res)
    se_jk = _jackknife_se(*views, mt)[1]
    # the test reads its own combination of the octaves (``coupling_test``), with its own
    # jackknife: the larger of the two se, as the jackknife's parts may be shorter than the
    # noise's correlation at the regressor's period, where it is too small itself; the
    # interval is ĉ's, with the spectrum's level from the AVAR's slope (``coefficient_se``)
    c_t, se_t, se_jk_t = c, test.se, se_jk
    if test.weights:
        c_t, se_t = test.c_test, test.se_test
        se_jk_t = _jackknife_se(*views, mt, test.weights)[1]
    se_test = max(se_jk_t, se_t)
    z = abs(c_t) / se_test if se_test > 0 and math.isfinite(c_t) else 0.0
    se = coefficient_se(se_jk, test.se_interval)
    lag_lo, lag_hi, open_lo, open_hi = lag_interval(scan, k)
    # ĉ is the coefficient at the chosen lag; the lag is an estimate too, and for a lag long
    # against the cycle (ωL ≫ 1) the two trade off (c/√(1 + ω²L²) is what the data fix):
    # the coefficient's interval carries the lag's by the delta method, dĉ/dL from the scan
    # (the test's z stays the fixed-lag one: the lag search is in its threshold)
    if 0 < k < len(scan) - 1 and not (open_lo or open_hi):
        se = math.hypot(se, _coef_slope(scan, k, lag_lo, lag_hi) * 0.5 * (lag_hi - lag_lo))
    others = {}
    for j, sc in best.items():
        if j != jb:
            kk = int(np.argmax([s.z for s in sc]))
            others[names[j]] = {"z": sc[kk].z, "lag_s": sc[kk].lag, "coefficient": sc[kk].c,
                                **compared.get(names[j], {})}
    return ThermalFit(names[jb], jb, c, se, L, min(lag_lo, L), max(lag_hi, L), z, rate_hz,
                      others, res, lag_open=open_hi or (open_lo and scan[0].lag < 0),
                      threshold=test.threshold, threshold_dof=test.dof,
                      scan_z=scan[k].z, channel_choice=compared.get(names[jb], {}),
                      channel_note=note)
