"""θ refined continuously for the intervals of a candidate that may be chosen, and the response
at the drive's line."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable
from typing import NamedTuple

import numpy as np
from avard.core.allan.beta import t_two_sided
from avard.core.explain.thermal_fit.rounding import DS18B20_STEP_K
from avard.core.explain.thermal_fit.sums import OctaveSums, octave_sums_by_part
from avard.core.explain.thermal_paths.columns import Column, Trial, _start, path_columns
from avard.core.explain.thermal_paths.deviance import (
    _blocks,
    _dev,
    _fit,
    _solve,
    _ungained,
    _View,
    _Weights,
)
from avard.core.explain.thermal_paths.profile import _about, _jk_se
from avard.core.explain.thermal_paths.rounding import _path_gain2, sawtooth_avar
from avard.core.explain.thermal_paths.scores import _NAMES
from avard.core.explain.thermal_paths.settings import ONE_LINE_SHARE, PATH_NAMES, T68
from numpy.typing import ArrayLike, NDArray

#: The candidates whose θ is refined on a local grid before their intervals are made
#: (``_refine``): the ones whose coefficients trade with θ along a ridge, so that a θ
#: re-chosen on the coarse grid in each delete-a-part fit jumps a whole grid step and drags
#: the coefficients with it (two paths on seed 30000: ±4.9e-3 with θ re-chosen on the grid,
#: ±3.5e-5 with θ fixed, on a coefficient of 1.0e-3).
REFINED = ("two_path", "rate")
#: The local grid's reach, in coarse grid steps either side of the best lag, and how many
#: local steps a coarse one is split into: two paths trade their lags and coefficients
#: along a ridge that a window of one coarse step each side cut off (the record's own
#: optimum at the window's edge on seed 30000, so every part was clipped there too).
FINE_REACH, FINE_SPLIT = 2, 3
#: The lags' scale (s) of the local grid's spacing: even in ln(1 + L/scale), i.e. in lag
#: near 0 (where the grid starts at 0 s) and in ln L above it.
FINE_SCALE_S = 10.0

def _warp(lag: float) -> float:
    return math.log1p(lag / FINE_SCALE_S)


def _unwarp(s: float) -> float:
    return FINE_SCALE_S * math.expm1(s)


def _path_cols(kind: str, theta: tuple[float, ...]) -> tuple[Column, ...]:
    """The regressor columns of a ``REFINED`` candidate at θ (as ``trials``)."""
    if kind == "rate":
        return (Column("u", theta[0]), Column("rate", 0.0), *_start(theta[0]))
    return (Column("u", theta[0]), Column("u", theta[1]), *_start(*theta))


def _fine_trials(kind: str, theta: tuple[float, ...], lags: list[float]) -> list[Trial]:
    """The local grid of ``kind`` around its coarse optimum θ: per lag, from ``FINE_REACH``
    coarse grid points below to as many above (as far as the grid goes), each coarse step
    split in ``FINE_SPLIT`` evenly in ``_warp``; two paths keep L1 < L2."""
    pos = sorted({x for x in lags if x >= 0})
    axes = []
    for x in theta:
        k = pos.index(x)
        span = pos[max(k - FINE_REACH, 0):k + FINE_REACH + 1]
        vals = {round(_unwarp(w), 3) for a, b in itertools.pairwise(span)
                for w in np.linspace(_warp(a), _warp(b), FINE_SPLIT + 1)}
        axes.append(sorted(vals | {x}))
    pts: list[tuple[float, ...]] = (
        [(a,) for a in axes[0]] if kind == "rate" else
        [(a, b) for a in axes[0] for b in axes[1] if a < b])
    return [Trial(p, _path_cols(kind, p), 2) for p in pts]


def _smoothing(r_one: NDArray, halves: list[OctaveSums],
               weigh_r: Callable[[OctaveSums, NDArray], _View], Ts: NDArray, rate: float,
               tau: NDArray, cols: tuple[Column, ...], beta: NDArray,
               step: float = DS18B20_STEP_K) -> float:
    """What a linear path (``cols``, ``beta``) gains on the held-out halves over one lag by
    passing less of the readings' rounding: Σ_k ν_k·min(1, (R₁ − R)₊/s_k) over both halves,
    R₁ the rounding AVAR (m/s²)² through the one-lag coupling (``r_one``), R through the
    path's own |H|² (``sawtooth_avar``, ``_path_gain2``): at most the one lag's whole share
    (``_View.rounding_share``). Two paths whose first is at lag 0 pass the rounding as one
    lag does and gain little by smoothing (a compressor record's two paths were refused for
    a share of 34 that a one-lag lead-lag of −144 s passes, up to 4× the readings' own);
    two lags of opposite sign at 240 and 480 s beside a one lag of 125 s pass less of it,
    and the rounding they do not pass is 24 of the held-out deviance where
    they won by 18 (one lag's whole share 116)."""
    r = sawtooth_avar(Ts, rate, tau, gain2=_path_gain2(cols, beta), step=step)
    less = np.maximum(0.0, np.asarray(r_one, dtype=float) - r)
    return float(sum(weigh_r(h, less).rounding_share(1.0) for h in halves))


def _vertex(ts: list[Trial], devs: NDArray, betas: NDArray
            ) -> tuple[tuple[float, ...], NDArray[np.float64]]:
    """θ and the coefficients at the least deviance over the local grid ``ts``, refined
    continuously: along each lag in turn (the others at the best point), a parabola in
    ``_warp`` through the best point and its two neighbours on that lag, its vertex where
    it is convex (within one local step: beyond that it is the next point's to claim), the
    coefficients moved by the same parabolas through theirs (they vary smoothly with θ).
    Lag by lag, not a joint quadratic: two paths' deviance is a ridge, on which a joint
    quadratic is seldom convex. At the grid point where a lag has no neighbour on a side
    (the local grid's edge: a bound, not an interpolation)."""
    i = int(np.argmin(devs))
    th = list(ts[i].theta)
    beta = np.array(betas[i], dtype=float)
    for d in range(len(th)):
        js = _about(ts, i, d)
        if js is None:
            continue
        x = np.array([_warp(ts[j].theta[d]) for j in js]) - _warp(ts[i].theta[d])
        f = devs[js]
        V = np.column_stack([np.ones(3), x, x * x])
        _, a1, a2 = np.linalg.solve(V, f)
        if a2 <= 0:
            continue
        xv = float(np.clip(-a1 / (2 * a2), x[0], x[2]))
        cb = np.linalg.solve(V, betas[js])
        beta += cb[1] * xv + cb[2] * xv * xv
        th[d] = _unwarp(_warp(ts[i].theta[d]) + xv)
    if len(th) == 2 and th[0] >= th[1]:
        return ts[i].theta, np.asarray(betas[i], dtype=float)
    return tuple(th), beta


class _Refined(NamedTuple):
    theta: tuple[float, ...]
    beta: NDArray[np.float64]
    beta_lo: NDArray[np.float64]
    beta_hi: NDArray[np.float64]
    theta_lo: NDArray[np.float64]
    theta_hi: NDArray[np.float64]
    #: the coefficients and θ over the local grid's points within the profile Δ of its best
    profile: NDArray[np.float64]
    profile_theta: NDArray[np.float64]
    #: the local grid's least deviance on the whole record
    least: float
    #: the dT/dt term's r − c·L (``net_rate``) and its 68 % interval; () for two paths
    net: tuple[float, ...] = ()
    #: two paths: the response at the drive (``drive_response``: period, gain and its 68 %
    #: interval, phase and its 68 % interval, the line's share of the channel,
    #: ``drive_line``); () otherwise
    drive: tuple[float, ...] = ()
    #: a dT/dt term: its column's gain (γ_lag, γ_rate) at the best local grid point, which
    #: ``beta`` and the profile are read through (``_ungained``); () otherwise
    gain: tuple[float, ...] = ()
    #: the coefficients as fitted to the columns (``beta`` before the gain), the signal's
    fitted: NDArray[np.float64] | None = None


def _refine(kind: str, theta: tuple[float, ...], lags: list[float], ys: NDArray, Ts: NDArray,
            rate: float, edges: NDArray, cut: NDArray[np.bool_], weigh: _Weights,
            delta: float, columns: dict[Column, NDArray[np.float64]] | None,
            period_s: float = math.nan, share: float = math.nan,
            min_tau: float = 0.0, extra: tuple[Column, ...] = (),
            grid: tuple[float, float] = (DS18B20_STEP_K, 0.0)) -> _Refined:
    """θ of a ``REFINED`` candidate refined continuously (``_vertex`` on ``_fine_trials``)
    on the whole record and in every delete-a-part fit, from one more pass of the Allan
    covariance over the local grid's regressors: the coefficients' 68 % interval is then
    the larger of the jackknife with θ fixed and with θ re-chosen, both at the estimator's
    resolution, not the coarse grid's, and θ's is the jackknife of θ re-chosen. ``extra``:
    the nuisance warm-up columns beside every point (``choose_path``); ``grid``: the
    driving channel's readings' (step K, origin)."""
    fine = [t._replace(cols=t.cols + extra) for t in _fine_trials(kind, theta, lags)]
    # a dT/dt term's reference beside them (``_ungained``)
    slope = (Column("slope", 0.0),) if kind == "rate" else ()
    cols = sorted({c for t in fine for c in t.cols} | set(slope))
    where = {c: j + 1 for j, c in enumerate(cols)}
    # a copy: the local grid's columns are this axis's own, not worth keeping for others
    X = np.column_stack([ys, path_columns(Ts, cols, rate, dict(columns or {}), grid)])
    parts = octave_sums_by_part(X, edges, cut)
    whole = sum(parts[1:], start=parts[0])
    idx = [[where[c] for c in t.cols] for t in fine]
    n = 2
    # the coefficients' octaves: a dT/dt term's from its rate floor (``_rate_floor``), θ and
    # the deviance still on every τ the candidates were compared on (the short τ hold what
    # places L along the ridge: with them left out too, L slid to 60–120 s and c 9–25 % high)
    parts_c = parts
    if kind == "rate":
        m_min = _rate_floor(Ts, rate, whole, where[Column("u", theta[0])],
                            where[Column("rate", 0.0)], theta[0], min_tau, grid[0])
        parts_c = [_from_octave(p, m_min) for p in parts]
    whole_c = sum(parts_c[1:], start=parts_c[0])

    def read(vc: _View, ix: list[int], f: NDArray) -> NDArray[np.float64]:
        # the coefficients as reported: a dT/dt term's through its smoothing's gain
        return _ungained(vc, ix, f, where[slope[0]])[:n] if slope else f[:n]

    def best(v: _View, vc: _View
             ) -> tuple[tuple[float, ...], NDArray[np.float64], NDArray, NDArray]:
        fits = [_fit(v, ix) for ix in idx]
        devs = np.array([_dev(v, ix, b) for ix, b in zip(idx, fits, strict=True)])
        coef = np.array([read(vc, ix, f) for ix, f in zip(
            idx, fits if vc is v else [_fit(vc, ix) for ix in idx], strict=True)])
        th, b = _vertex(fine, devs, coef)
        return th, b, devs, coef

    vw = weigh(whole)
    vwc = vw if parts_c is parts else weigh(whole_c)
    th, b, devs, fits = best(vw, vwc)
    vjk = [weigh(whole - p) for p in parts]
    vjk_c = vjk if parts_c is parts else [weigh(whole_c - p) for p in parts_c]
    g = int(np.argmin(devs))
    # the coefficients that go with the columns (the signal's), and the gain read through
    gain: tuple[float, ...] = ()
    fitted = b
    if slope:
        gain = tuple(float(x) for x in _solve(vwc, _blocks(vwc, idx[g]),
                                              vwc.cov[:, idx[g], where[slope[0]]])[:2])
        fitted = _vertex(fine, devs, np.array([_fit(vwc, ix)[:n] for ix in idx]))[1]
    se_fixed = _jk_se(np.array([read(v, idx[g], _fit(v, idx[g])) for v in vjk_c]))
    jk = [best(v, vc)[:2] for v, vc in zip(vjk, vjk_c, strict=True)]
    se_re = _jk_se(np.array([x[1] for x in jk]))
    if kind == "two_path" and share < ONE_LINE_SHARE:
        # the parts hold unequal shares of what tells c₁ and c₂ (the record's start, where
        # the plate settles, tells the lags most): the jackknife weighted by each part's
        # leverage (``_leverage_jk_se``), θ fixed and θ free to first order (the fit
        # linearised in the lags: re-chosen in a part without the start, θ slid along the
        # ridge by 2–6 times what the whole record's fit scatters over records). Not on a
        # drive of one line: there c₁ and c₂ are not resolved whatever their interval, and
        # the first order of a ridge is no measure of it (c₁'s standard error, which sizes
        # the removed signal's uncertainty, moved alone along it)
        se_fixed = _t68_scaled(_leverage_jk_se(vw, vjk, _unit_map(idx[g], X.shape[1]), n))
        se_re = _t68_scaled(_leverage_jk_se(
            vw, vjk, _slope_map(fine, g, where, fits[g], X.shape[1]), n))
    tse = _jk_se(np.array([x[0] for x in jk])) * T68
    se = np.maximum(se_fixed, se_re) * T68
    flat = devs <= devs.min() + delta
    thetas = np.array([t.theta for t in fine])
    net: tuple[float, ...] = ()
    if kind == "rate":
        # r − c·L, what the response resolves where r and L apart trade (``net_rate``): its
        # jackknife with θ re-chosen, widened to the local profile's points
        m = net_rate(b, th)
        net = (m, *_widened(m, [net_rate(x[1], x[0]) for x in jk],
                            [net_rate(f, t) for f, t in zip(fits[flat], thetas[flat],
                                                            strict=True)]))
    drive: tuple[float, ...] = ()
    if kind == "two_path" and math.isfinite(period_s):
        # the response at the drive's period, what a drive of one line resolves whatever the
        # split: its jackknife with θ re-chosen, widened to the local profile's points
        g0 = drive_response(b, th, period_s)
        gj = np.array([drive_response(x[1], x[0], period_s) for x in jk])
        gp = np.array([drive_response(f, t, period_s) for f, t in
                       zip(fits[flat], thetas[flat], strict=True)])
        a, ph = float(abs(g0)), float(np.angle(g0))
        a_lo, a_hi = _widened(a, np.abs(gj), np.abs(gp))
        # the phase's spread about the record's own (no wrap: the parts' phases sit close)
        d_lo, d_hi = _widened(0.0, np.angle(gj * np.conj(g0)), np.angle(gp * np.conj(g0)))
        drive = tuple(float(x) for x in (period_s, a, a_lo, a_hi, ph, ph + d_lo, ph + d_hi,
                                         share))
    return _Refined(th, b, b - se, b + se, np.asarray(th) - tse, np.asarray(th) + tse,
                    fits[flat], thetas[flat], float(devs.min()), net, drive, gain, fitted)


def _unit_map(idx: list[int], width: int) -> NDArray[np.float64]:
    """The map from the columns of X (``width``, y first) to the regressors ``idx``."""
    M = np.zeros((width, len(idx)))
    M[idx, np.arange(len(idx))] = 1.0
    return M


def _slope_map(fine: list[Trial], g: int, where: dict[Column, int], beta: NDArray,
               width: int) -> NDArray[np.float64]:
    """The two paths' fit at the local grid's point ``g`` linearised in its lags: the map
    from the columns of X to (u(L1), u(L2), c₁·∂u/∂L1, c₂·∂u/∂L2, the rest of ``g``'s
    regressors), each slope a difference of the u columns at ``g``'s neighbours along that
    lag (one-sided at the local grid's edge). Its information is that of every parameter
    the fit estimates, the lags too."""
    t = fine[g]
    idx = [where[c] for c in t.cols]
    M = _unit_map(idx, width)
    slopes = []
    for d in range(2):
        line = sorted({u.theta[d] for u in fine
                       if all(u.theta[e] == t.theta[e] for e in range(2) if e != d)})
        k = line.index(t.theta[d])
        lo, hi = line[max(k - 1, 0)], line[min(k + 1, len(line) - 1)]
        col = np.zeros(width)
        if hi > lo:
            col[where[Column("u", hi)]] += beta[d] / (hi - lo)
            col[where[Column("u", lo)]] -= beta[d] / (hi - lo)
        slopes.append(col)
    return np.column_stack([M[:, :2], *slopes, M[:, 2:]])


def _gls_on(v: _View, M: NDArray, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The first ``n`` coefficients of the GLS of view ``v``'s y on the regressors ``M``
    maps X's columns to (those the view does not see left out, as ``_solve``), and their
    variances up to one scale (the inverse information's diagonal); infinite variances
    where one of the ``n`` is not seen."""
    S = np.einsum("k,kij->ij", v.weights, v.cov)
    A, r = M.T @ S @ M, M.T @ S[:, 0]
    d = A.diagonal()
    live = np.flatnonzero(d > 1e-14 * max(float(d.max()), 1e-300))
    if not set(range(n)) <= set(live.tolist()):
        return np.zeros(n), np.full(n, np.inf)
    sc = np.sqrt(d[live])
    inv = np.linalg.pinv(A[np.ix_(live, live)] / np.outer(sc, sc), rcond=1e-10)
    beta = inv @ (r[live] / sc) / sc
    return (np.asarray(beta[:n], dtype=float),
            np.asarray(np.diagonal(inv)[:n] / d[:n], dtype=float))


def _leverage_jk_se(whole: _View, parts: list[_View], M: NDArray,
                    n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The delete-a-part jackknife standard error of the first ``n`` coefficients of the GLS
    on the regressors ``M`` maps X's columns to (``_gls_on``; "whole", "parts": the views of
    the record and of it without each part), each part's squared deviation weighted by its
    leverage's complement 1 − h_g = var(whole)/var(without part g): Σ_g (1 − h_g)(β_(−g) −
    β̂)², the weighted jackknife (Wu 1986, Ann. Statist. 14, 1261–1295) for a part. With
    equal parts this is the ordinary jackknife ((G − 1)/G Σ); where one part holds a large
    share of the information (a record's start tells two paths' lags most) deleting it
    moves the fit by about var_(−g) − var, not by its share of var, and the ordinary
    jackknife counts that whole. Each term is one squared deviation of expectation h_g·var
    (linear theory: (var/var_(−g))·(var_(−g) − var)), so the sum is divided by Σ h_g (1 with
    equal parts, and where the parts' information adds; 1.2–1.6 for two paths' θ-free fit,
    where the start's regressors are the first part's alone) and has ν = (Σ h_g)²/Σ h_g²
    degrees of freedom (Satterthwaite): G − 1 with equal parts, down to 1 where one part
    holds all. Returns (the standard errors, ν)."""
    value, full = _gls_on(whole, M, n)
    out, lev, lev2 = np.zeros(n), np.zeros(n), np.zeros(n)
    for v in parts:
        est, drop = _gls_on(v, M, n)
        keep = np.where(np.isfinite(drop) & (drop > 0), np.clip(full / drop, 0.0, 1.0), 0.0)
        out += keep * (est - value) ** 2
        lev, lev2 = lev + (1 - keep), lev2 + (1 - keep) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        nu = np.clip(np.nan_to_num(lev**2 / lev2, nan=1.0), 1.0, len(parts) - 1)
    return (np.asarray(np.sqrt(out / np.maximum(lev, 1e-12)), dtype=float),
            np.asarray(nu, dtype=float))


def _t68_scaled(se_nu: tuple[NDArray, NDArray]) -> NDArray[np.float64]:
    """A standard error with ν degrees of freedom (``_leverage_jk_se``) scaled by
    t(ν)/``T68``, so ``T68`` times it is t(ν)'s 68 % half-width."""
    se, nu = se_nu
    t = np.array([t_two_sided(0.32, float(x)) for x in nu]) / T68
    return np.asarray(se * t, dtype=float)


def _widened(value: float, parts: ArrayLike, points: Iterable[float]) -> tuple[float, float]:
    """``value``'s 68 % interval as ``_refine`` makes a derived quantity's: the jackknife of
    its delete-a-part values ``parts`` (θ re-chosen in each), widened to take in its values
    at the local profile's points ``points``."""
    se = float(_jk_se(np.asarray(parts, dtype=float)[:, None])[0]) * T68
    return float(min(value - se, *points)), float(max(value + se, *points))


def drive_response(beta: NDArray, theta: tuple[float, ...] | NDArray,
                   period_s: float) -> complex:
    """A two-path fit's response at the period ``period_s`` (s), m/s²/K: G(ω) =
    c₁/(1 + jωL1) + c₂/(1 + jωL2), ω = 2π/period; arg G > 0 is a lead on the logged
    channel. At one drive line the record sets this one complex number, whatever the split
    into c₁, c₂, L1, L2 along their ridge."""
    w = 2 * math.pi / period_s
    return complex(sum(float(c) / (1 + 1j * w * float(L))
                       for c, L in zip(beta[:2], theta[:2], strict=True)))


def drive_line(T: NDArray, rate_hz: float) -> tuple[float, float]:
    """(the period (s) of the logged channel's strongest line, the share of the channel's
    variance in it): the periodogram's peak of ``T`` (slow view, its mean and trend removed,
    a Hann window) between a third of the record and four samples, refined by a parabola
    through the peak's bins in ln power; the share is the power of the window's main lobe
    about the peak (±2 bins) over all but the mean's. (NaN, NaN) when the channel is too
    short or flat."""
    x = np.asarray(T, dtype=float)
    x = x[np.isfinite(x)]
    n = len(x)
    if n < 16:
        return math.nan, math.nan
    t = np.arange(n)
    x = x - np.polyval(np.polyfit(t, x, 1), t)
    p = np.abs(np.fft.rfft(x * np.hanning(n))) ** 2
    k = np.arange(len(p))
    ok = (k >= 3) & (k <= n / 4)
    if not ok.any() or not np.any(p[ok] > 0):
        return math.nan, math.nan
    i = int(k[ok][np.argmax(p[ok])])
    f = float(i)
    if 0 < i < len(p) - 1 and np.all(p[i - 1:i + 2] > 0):
        a, b, c = np.log(p[i - 1:i + 2])
        den = a - 2 * b + c
        if den < 0:
            f = i + 0.5 * (a - c) / den
    share = float(p[max(i - 2, 1):i + 3].sum() / p[1:].sum())
    return float(n / (f * rate_hz)), share


def _rate_floor(Ts: NDArray, rate: float, whole: OctaveSums, iu: int, ir: int, lag: float,
                min_tau: float, step: float = DS18B20_STEP_K) -> int:
    """The shortest octave (samples) a dT/dt term's refined coefficients read: the first from
    ``min_tau`` (the linear column's rounding floor) where the readings' rounding is no
    larger a share of the rate column's Allan variance than it is of the linear column's
    (columns ``iu``, ``ir`` of ``whole``) at that floor, by the same model
    (``sawtooth_avar``). A derivative passes the rounding's short periods ×ω² where the
    drive's is small: at the linear column's floor (205 s on the dT/dt row) the rounding's
    modelled share of the rate column's Allan variance was 9× its share of the linear
    column's, an error in the regressor that every part of the record shares (the
    jackknife does not see it) and that pulled r − c·L 3 % low (errors in variables)."""
    ms = whole.ms
    tau = ms / rate
    cov = whole.cov()
    with np.errstate(invalid="ignore", divide="ignore"):
        share_u = sawtooth_avar(Ts, rate, tau, lag, step=step) / cov[:, iu, iu]
        share_r = sawtooth_avar(Ts, rate, tau, gain2=_path_gain2(
            (Column("rate", 0.0),), np.ones(1)), step=step) / cov[:, ir, ir]
    from_floor = np.flatnonzero(tau >= min_tau * (1 - 1e-9))
    if not len(from_floor) or not np.isfinite(share_u[from_floor[0]]):
        return int(ms[0])
    k0 = int(from_floor[0])
    ok = [k for k in from_floor.tolist() if share_r[k] <= share_u[k0]]
    return int(ms[ok[0]]) if ok else int(ms[k0])


def _from_octave(s: OctaveSums, m_min: int) -> OctaveSums:
    """The sums ``s`` with the octaves shorter than ``m_min`` samples counted empty."""
    return OctaveSums(s.ms, np.where(s.ms >= m_min, s.n, 0), s.s2)


def net_rate(beta: NDArray, theta: tuple[float, ...] | NDArray) -> float:
    """The dT/dt term's coupling net of the static lag's share, r − c·L (m/s² per K/s):
    c·lag(T, L) = c·T − c·L·dT/dt + O(ω²L²), so at a true static lag near 0 a lag L and a
    dT/dt term r trade along r − c·L = const on every drive (the Fisher information of
    (c, r, L) is singular there: ``min_detectable_path``) and only the second order, c·ω²L²
    (1–2 % of c at L = 30 s on a 20-min cycle), tells them apart; the readings' rounding
    bends the response by as much, and L settled at 12–35 s with r 20–50 % high. This
    combination, the response's dT/dt coefficient at low frequency, is what the data
    resolve; it is r where the static lag is 0."""
    return float(beta[1]) - float(beta[0]) * float(theta[0])


def _settles_past_half(kind: str, theta: tuple[float, ...], n_blocks: int,
                       rate_hz: float) -> str | None:
    """Why the extension ``kind`` at ``theta`` cannot be held out on a slow view of
    ``n_blocks`` at ``rate_hz`` (None when it can): explain's held-out measure leaves each
    held-out half's first ``holdout.HELD_SETTLE_LAGS`` longest lags out (the lag filter's
    unknown start state) and needs ``holdout.MIN_PART_POINTS`` blocks after them (resc24b)."""
    from avard.core.explain.holdout import HELD_SETTLE_LAGS, MIN_PART_POINTS

    lags = [abs(v) for v, name in zip(theta, _NAMES[kind][1], strict=False)
            if name.endswith("_s")]
    longest = max(lags, default=0.0)
    left = n_blocks // 2 - math.ceil(HELD_SETTLE_LAGS * longest * rate_hz)
    if left >= MIN_PART_POINTS:
        return None
    return (f"{PATH_NAMES[kind]} not chosen: its lag {longest:.4g} s leaves "
            f"{max(left, 0)} blocks of each held-out half once its first "
            f"{HELD_SETTLE_LAGS:g} lags (the unknown start state) are out, fewer than the "
            f"{MIN_PART_POINTS} a held-out test needs")
