"""The lag's estimate and its 68 % interval (``best_lag``, ``lag_interval``) and the stated minimum
detectable tempco."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core.allan.beta import t_two_sided
from avard.core.explain.causes import noise_psd
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.scan import ScanPoint, _scan
from avard.core.explain.thermal_fit.settings import READ_TIME_S, Z_TEMPERATURE

#: Coarse-grid lags either side of an axis's best lag that its lag's jackknife spans: the
#: leave-one-out best lags must have room to move (between the first neighbours only, a lag
#: of 0 s known to ±20 s at the HVAC period had a window of −16…−10 s, and the picks piled at
#: its ends).
JACKKNIFE_SPAN = 2
#: … and at least the lags round the best whose z is within this fraction of the largest: the
#: lag's uncertainty is in seconds, the coarse grid geometric, so near 0 two neighbours span
#: a few seconds where the z² over the lags is flat over tens.
JACKKNIFE_Z_DROP = 0.05


def _with_lag_jackknife(per_axis: list[list[ScanPoint]], grid: NDArray, Ys: NDArray,
                        T: NDArray, rate_hz: float, holes: list[tuple[int, int]], ref: Any,
                        floor: float) -> list[list[ScanPoint]]:
    """Each axis's scan with the parts' z (``ScanPoint.zg``) on the lags of its own window:
    those within ``JACKKNIFE_SPAN`` coarse-grid lags of its best, widened to the run of lags
    round it whose z is within ``JACKKNIFE_Z_DROP`` of the best's. One scan of the parts'
    sums serves the union of the windows (they cost a scan each: not the whole grid), each
    axis takes the points of its own window only (the union's other stretches made its
    leave-one-out lags jump between two windows). The points' own (lag, ĉ, se, z) stay the
    scan's: the estimate is not changed by its interval."""
    g = sorted(float(v) for v in grid)
    windows = []
    for sc in per_axis:
        k = int(np.argmax([p.z for p in sc]))
        b, z_min = sc[k].lag, (1.0 - JACKKNIFE_Z_DROP) * sc[k].z
        below = [v for v in g if v < b][-JACKKNIFE_SPAN:] or [b]
        above = [v for v in g if v > b][:JACKKNIFE_SPAN] or [b]
        lo, hi = k, k
        while lo > 0 and sc[lo - 1].z >= z_min:
            lo -= 1
        while hi < len(sc) - 1 and sc[hi + 1].z >= z_min:
            hi += 1
        # as far either side as the farther run end: the run stops at a jump of z (a
        # negative lag's shortest τ moving an octave), which the parts' regressions,
        # on one shortest τ, do not have
        w = max(b - below[0], above[-1] - b, b - sc[lo].lag, sc[hi].lag - b)
        windows.append((b - w, b + w))
    lags = sorted({p.lag for sc, (w0, w1) in zip(per_axis, windows, strict=True)
                   for p in sc if w0 <= p.lag <= w1})
    jk = _scan(Ys, T, lags, rate_hz, holes, ref, floor, parts=True)
    out = []
    for sc, parts, (w0, w1) in zip(per_axis, jk, windows, strict=True):
        zg = {p.lag: p.zg for p in parts if w0 <= p.lag <= w1}
        out.append([p._replace(zg=zg[p.lag]) if p.lag in zg else p for p in sc])
    return out


#: The lag estimator's kernel reaches from the largest z to the farther of the lags either
#: side where z² has fallen to this fraction of its largest (``_kernel_width``): the
#: profile's top, where 1/z² is a parabola in the lag. Wider, the quadratic reads the
#: profile's flanks, which are not symmetric (a lag acts through its phase, atan(ωL)): on
#: the typical-tempco records, whose z² is flat within 2 % over hundreds of seconds, a kernel
#: to where z² halves put 3 of 40 lags beyond 20 % of the truth (1 of 40 at this width, as
#: the three-point vertex).
LAG_KERNEL_DROP = 0.98
#: Times the kernel is re-centred on its own vertex.
LAG_KERNEL_STEPS = 3


def _lag_support(scan: list[ScanPoint]) -> list[ScanPoint]:
    """The lags the lag estimator reads: those that carry the parts' z (the jackknife's
    window, ``_with_lag_jackknife``), so the record and its leave-one-out parts are read on
    the same lags; all of them when there are fewer than three (no jackknife)."""
    sub = [p for p in scan if len(p.zg)]
    return sub if len(sub) >= 3 else list(scan)


def _kernel_width(x: NDArray, f: NDArray, k: int) -> float:
    """The kernel's half-width: from ``x[k]`` (the least ``f`` = 1/z²) to the farther of the
    nearest lags either side where ``f`` has risen to ``f[k]/LAG_KERNEL_DROP`` (the end of
    ``x`` where it never does), at least the next lag either side."""
    lim = f[k] / LAG_KERNEL_DROP
    lo = np.flatnonzero(f[:k] >= lim)
    hi = np.flatnonzero(f[k + 1:] >= lim)
    dl = x[k] - (x[lo[-1]] if len(lo) else x[0])
    dh = (x[k + 1 + hi[0]] if len(hi) else x[-1]) - x[k]
    step = max(x[min(k + 1, len(x) - 1)] - x[k], x[k] - x[max(k - 1, 0)])
    return float(max(dl, dh, step)) * (1.0 + 1e-9)


def _lag_vertex(x: NDArray, z: NDArray, k: int, h: float) -> tuple[float, bool]:
    """(lag, at an end): the vertex of the local quadratic of 1/z² over the lags ``x``, a
    biweight kernel of half-width ``h`` centred at ``x[k]`` and re-centred on its own vertex
    ``LAG_KERNEL_STEPS`` times; "at an end" when the vertex leaves ``x`` (kept on its end)
    or the quadratic opens downwards (then the lag of the largest z).

    1/z² is what the lag's profile likelihood moves with: a regression of y on the lagged
    channel leaves the share 1/(1 + z²/ν) ≈ ν/z² of the axis's variance, −2 ln L = ν ln of
    it, and a lag off by δ adds ∝ δ² to that share. It is a parabola round its least where
    z² itself is a sharp peak (1/(a + bδ²)): a parabola in z² over the jackknife's window
    (−95…−25 s round a −60 s lag) sat 10–20 s off the peak, and a three-point vertex sits on
    the fine grid's jags (z² is jagged at the grid's step: the readings' rounding smoothed a
    little more or less). The kernel weighs the points the data hold the lag by, smoothly,
    so the same function of the data serves the record and each leave-one-out part."""
    z = np.asarray(z, dtype=float)
    f = 1.0 / np.maximum(z * z, 1e-300)
    c = float(x[k])
    i = int(np.argmax(z))
    for _ in range(LAG_KERNEL_STEPS):
        u = (x - c) / h
        w = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
        on = w > 0
        if np.count_nonzero(on) < 3:
            break
        xs, fs, ws = x[on], f[on], np.sqrt(w[on])
        xm, sc = float(np.mean(xs)), float(np.ptp(xs)) or 1.0
        t = (xs - xm) / sc
        # scaled by the least f: 1/z² spans 1e-5…1e-2 between records
        A = np.column_stack([t * t, t, np.ones_like(t)]) * ws[:, None]
        qa, qb, _qc = np.linalg.lstsq(A, fs / f[i] * ws, rcond=None)[0]
        if not qa > 0:
            return float(x[i]), i in (0, len(x) - 1)
        c = xm - sc * qb / (2.0 * qa)
        if not x[0] < c < x[-1]:
            return float(np.clip(c, x[0], x[-1])), True
    return float(c), False


def _lag_estimate(scan: list[ScanPoint]) -> tuple[float, NDArray[np.float64], int, float]:
    """(lag, the support's lags, the index there of the largest z, kernel half-width) of a
    scan: ``_lag_vertex`` on ``_lag_support``."""
    sub = _lag_support(scan)
    x = np.array([p.lag for p in sub], dtype=float)
    z = np.array([p.z for p in sub], dtype=float)
    k = int(np.argmax(z))
    h = _kernel_width(x, 1.0 / np.maximum(z * z, 1e-300), k)
    return _lag_vertex(x, z, k, h)[0], x, k, h


def best_lag(scan: list[ScanPoint], k: int) -> float:
    """The axis's lag from its scan: the vertex of the local quadratic of 1/z² round the
    largest z (``_lag_vertex``), on the lags its jackknife reads, the same estimator each
    leave-one-out part's lag is (``lag_interval``). Not the grid point (the fine grid's
    step, ≈ 1 s at −60 s, is as wide as the lag's spread there), and not a different
    estimator from the interval's: a three-point vertex reported beside the jackknife of a
    window's parabola sat about the interval's half-width from its centre, and the
    negative-lag records' intervals held the truth in 50 %. ``k`` (the grid index of the
    largest z) is not used: the support's own largest is."""
    return _lag_estimate(scan)[0]


def lag_interval(scan: list[ScanPoint], k: int) -> tuple[float, float, bool, bool]:
    """(low, high, open low, open high): the lag's 68 % interval, the best lag (``best_lag``)
    ± t₀.₈₄(G−1) times its delete-a-group jackknife standard error: the same estimator on
    the z of the record with each of its ``JACKKNIFE_GROUPS`` parts left out (``ScanPoint.
    zg``, ``_with_lag_jackknife``), the same lags and kernel width, se² = (G−1)/G·Σ(L_(−g) −
    mean)², a t quantile for its G − 1 degrees of freedom, with the readings' time uncertainty
    ``READ_TIME_S`` added in quadrature (no part moves it); never narrower than half the grid's
    step either side of the lag (the lags tried resolve no finer); without the parts' z the
    estimate alone. A leave-one-out lag on the support's end carries that end of the
    interval to the support's end at least; open when that is the first or last lag tried.

    Not the profile of the analytic z² over the lags: the regressor carries noise the axis
    does not (the readings' rounding, the logger's own noise), and smoothing it away by a
    longer trial lag raises z² by a share of z² itself (≈ 500 at z 22), far above the Δ = 1
    that draws the interval: a true lag 0 came out at 26 s [24.7, 28.8] (68 %), and the
    intervals of 32 records held the true lag in none. The jackknife measures how far the
    best lag moves with the data, whatever moves it."""
    lags = [p.lag for p in scan]
    best, sl, kk, h = _lag_estimate(scan)
    sub = [p for p in scan if len(p.zg)]
    if len(sub) < 3:
        return best, best, k == 0, k == len(scan) - 1
    zg = np.array([p.zg for p in sub])  # (lags, G)
    G = zg.shape[1]
    picks = [_lag_vertex(sl, zg[:, g], kk, h) for g in range(G)]
    lg = np.array([p[0] for p in picks])
    se = math.sqrt((G - 1) / G * float(np.sum((lg - lg.mean()) ** 2)))
    se *= t_two_sided(0.32, G - 1)  # t₀.₈₄ of the jackknife's G − 1 dof
    # the readings' own time: a systematic no part of the record moves, so no jackknife sees
    se = math.hypot(se, READ_TIME_S)
    # the grid's resolution: half way to the lags tried either side of the estimate
    i = int(np.searchsorted(lags, best))
    below = best - lags[i - 1] if i > 0 else 0.0
    above = lags[i] - best if i < len(lags) and lags[i] > best else (
        lags[i + 1] - best if i + 1 < len(lags) else 0.0)
    lo, hi = best - max(se, 0.5 * below), best + max(se, 0.5 * above)
    # a leave-one-out lag on the support's end says the lag may be beyond it: that end of
    # the interval reaches the support's end at least, and is open when that is the
    # search's end
    at_lo = any(p[1] and p[0] <= sl[0] for p in picks)
    at_hi = any(p[1] and p[0] >= sl[-1] for p in picks)
    lo = min(lo, float(sl[0])) if at_lo else lo
    hi = max(hi, float(sl[-1])) if at_hi else hi
    open_lo = k == 0 or (at_lo and sl[0] <= lags[0])
    open_hi = k == len(scan) - 1 or (at_hi and sl[-1] >= lags[-1])
    return lo, hi, open_lo, open_hi


def min_detectable_tempco(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                          amplitude_c: float, period_s: float, lag_s: float,
                          z: float = Z_TEMPERATURE, lag_rel: float | None = None) -> float:
    """Smallest coefficient (m/s²/K) the temperature test detects (z ≥ ``z`` on average) for a
    logged ±``amplitude_c`` sinusoid of ``period_s`` reaching the sensor through a first-order
    lag ``lag_s``, on noise N (m/s/√s), B (m/s²), K (m/s²·√s) over ``record_s``. With
    ``lag_rel``, the coefficient at which the lag's standard error is ``lag_rel``·lag instead.

    Derivation: the sensor sees a sinusoid of amplitude a = c·A/√(1 + ω²L²). A sinusoid's
    amplitude in noise of one-sided PSD S(f0) over T is known to σ_a = √(2·S(f0)/T), and with
    NIST SP 1065 Table 5, S(f) = 2N² + B²/(πf) + K²/(2π²f²) (white, flicker, random-walk rate
    noise whose AVAR is N²/τ, (2 ln2/π)B², K²τ/3). So z = a/σ_a and
    c_min = z·σ_a·√(1 + ω²L²)/A. The phase −atan(ωL) carries the lag: σ_φ = 1/z, hence
    σ_L/L = (1 + ω²L²)/(ωL·z).
    """
    s_f0 = noise_psd(1.0 / period_s, n_white, b_inst, k_rrw)
    sigma_a = math.sqrt(2 * s_f0 / record_s)
    wl = 2 * math.pi * lag_s / period_s
    if lag_rel is not None:
        z = (1 + wl**2) / (wl * lag_rel) if wl > 0 else math.inf
    return z * sigma_a * math.hypot(1.0, wl) / amplitude_c
