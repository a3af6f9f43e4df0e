"""One detector per physical cause of model-versus-measurement misfit (the `avard explain` core).

Each detector looks at one channel of rate data y (m/s²) and returns a :class:`Candidate`: the
cause's parameters (SI units), the test statistic, the threshold it must pass and a sentence of
evidence a reader can check by hand. A cause is a *finding* only when its stated test passes;
the thresholds are set so that records without that effect pass with probability well below
1e-3 (checked by the null records of the hidden-effect tests).

The causes and their tests:

- ``temperature``: regression of Allan differences of y on Allan differences of a lagged
  temperature channel, c(τ, L) = Cov_A(y, T_L; τ) / AVAR_T(τ) (the Allan covariance over the
  temperature's Allan variance), searched over lags L and averaging times τ; test |z| ≥ 6
  with the standard error from the non-overlapping count of differences.
- ``sinusoid``: a periodogram line (Hann window) standing ≥ 40× above the local spectral
  background (probability e⁻⁴⁰ per bin for a Gaussian spectrum), and an Allan bump that the
  AVAR resolves: the line's AVAR at τ ≈ 0.371/f0 (IEEE 952 eq. C.21) ≥ 2 σ of the estimate.
- ``bias_step``: the largest difference of adjacent window means, robustly scaled by the
  spread of all such differences (their std is √(2·AVAR(w)), NIST SP 1065 eq. 6); test ≥ 6 and
  a step fits the record better than a warm-up exponential.
- ``warmup``: the same contrast at the record start for an exponential settling, with the
  time constant from a least-squares fit of [1, t, e^(−t/T)]; test ≥ 6 and it fits better than
  a step.
- ``rate_ramp``: the mean of non-overlapping Allan differences at τ = T/16…T/64 is R·τ for a
  linear drift and zero for every stationary or random-walk noise; Student t ≥ 6.
- ``gauss_markov``: an AVAR bump (IEEE 952 eq. C.25) that the five terms cannot make:
  EDF-weighted χ² falls by ≥ 50 and to ≤ 1/3 when the component is added, and the component
  carries ≥ 1/2 of the model AVAR at its peak.
- ``quantization``: all values on a grid k·LSB + offset, and the rounding noise LSB²/12 is
  ≥ 1 % of the white per-sample variance (otherwise it is real but irrelevant).
- ``filter``: the shortest averaging times fall below the white line: a low-pass white-noise
  AVAR (core.model.lowpass_white_avar, 2nd-order Butterworth) fits the τ ≤ 64·τ0 points better
  than white noise by Δχ² ≥ 50 and bends AVAR(τ0) by ≥ 5 %.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from . import model
from .edf import edf_greenhall

CAUSES = (
    "temperature",
    "sinusoid",
    "bias_step",
    "warmup",
    "rate_ramp",
    "gauss_markov",
    "quantization",
    "filter",
)

#: Causes that are removed from the data (deterministic in time); the others enter the model.
REMOVED = ("temperature", "bias_step", "warmup", "rate_ramp")

#: Parameter names per cause, SI units (as in the `avard explain --json` output).
PARAMS = {
    "temperature": ("coefficient", "lag_s"),
    "sinusoid": ("frequency_hz", "amplitude"),
    "bias_step": ("time_s", "size"),
    "warmup": ("time_constant_s", "size"),
    "rate_ramp": ("slope",),
    "gauss_markov": ("sigma", "time_constant_s"),
    "quantization": ("lsb",),
    "filter": ("bandwidth_hz",),
}

UNITS = {
    "coefficient": "m/s^2/K",
    "lag_s": "s",
    "frequency_hz": "Hz",
    "amplitude": "m/s^2",
    "time_s": "s",
    "size": "m/s^2",
    "time_constant_s": "s",
    "slope": "m/s^3",
    "sigma": "m/s^2",
    "lsb": "m/s^2",
    "bandwidth_hz": "Hz",
}

Z_TEMPERATURE = 6.0
SPECTRAL_RATIO = 40.0
Z_STEP = 6.0
T_RAMP = 6.0
GM_DCHI2 = 50.0
FILTER_DCHI2 = 50.0


@dataclass
class Candidate:
    """The outcome of one cause's test on one channel."""

    cause: str
    passed: bool
    params: dict[str, float] = field(default_factory=dict)
    statistic: float = 0.0
    threshold: float = 0.0
    evidence: str = ""
    #: extra detail for the report (arrays for plots); never serialised to JSON
    detail: dict = field(default_factory=dict)
    #: channel name of the temperature witness (temperature cause only)
    witness: str | None = None


# --------------------------------------------------------------------------------------------
# Allan variance helpers (NIST SP 1065 eq. 12), vectorised per averaging factor


def tau_grid(n: int, rate_hz: float, *, min_diffs: int = 4) -> NDArray:
    """Averaging factors m = 1, 2, 3, 4, 6, 8, 12, … (2^k and 3·2^(k−1): about two per octave,
    each divisible by a power of two near m/8 so that the strided estimator below is exact),
    up to where at least ``min_diffs`` non-overlapping second differences remain."""
    m_max = max(1, n // (2 + min_diffs))
    out = [1]
    k = 1
    while True:
        for m in (2**k, 3 * 2 ** (k - 1)):
            if m <= m_max:
                out.append(m)
        if 2**k > m_max:
            break
        k += 1
    return np.unique(np.array(out, dtype=np.int64))


def stride_for(m: int) -> int:
    """Stride between second differences: the largest power of two ≤ m/8 that divides m.
    Greenhall & Riley: at stride m/8 the EDF is ≥ 98 % of full overlap (allan.md)."""
    s = 1
    while s * 2 <= m / 8 and m % (s * 2) == 0:
        s *= 2
    return s


def oavar(y: NDArray, rate_hz: float, m: NDArray) -> NDArray:
    """Overlapping AVAR of rate data y at τ = m/rate_hz (NIST SP 1065 eq. 12):
    σ²(τ) = Σ (x[i+2m] − 2x[i+m] + x[i])² / (2τ²·count), x = τ0·cumsum(y), with i stepping by
    :func:`stride_for` (m) (partially overlapping, unbiased, ≥ 98 % of the full-overlap EDF).

    The mean is removed before integrating so that the phase stays small (it cancels in
    second differences anyway) and float64 keeps its digits."""
    y = np.asarray(y, dtype=np.float64)
    x = np.concatenate(([0.0], np.cumsum(y - y.mean())))
    out = np.empty(len(m))
    for i, mi in enumerate(np.asarray(m, dtype=np.int64)):
        s = stride_for(int(mi))
        xs = x[::s] if s > 1 else x
        k = int(mi) // s
        # in place: one temporary instead of three (this loop is the pipeline's hot spot)
        d = np.subtract(xs[2 * k:], xs[k:-k])
        d -= xs[k:-k]
        d += xs[: len(xs) - 2 * k]
        # x in sample units: τ0 cancels, σ² = Σd²/(2 m² count) in (m/s²)²
        out[i] = np.dot(d, d) / (2.0 * float(mi) ** 2 * len(d))
    return out


def local_alpha(var: NDArray, m: NDArray) -> NDArray:
    """Power-law exponent α per point from the local AVAR slope μ (σ² ∝ τ^μ, α = −μ − 1),
    rounded and clamped to white (0), flicker (−1) or random-walk (−2) FM; used for the EDF."""
    lv, lm = np.log(np.maximum(var, 1e-300)), np.log(m.astype(float))
    mu = np.gradient(lv, lm) if len(m) > 2 else np.full(len(m), -1.0)
    return np.clip(np.rint(-mu - 1.0), -2, 0).astype(int)


def avar_edf(var: NDArray, m: NDArray, n: int) -> NDArray:
    """EDF of each AVAR point of :func:`oavar` (Greenhall & Riley 2003 with its stride)."""
    alpha = local_alpha(var, m)
    return np.array([_edf_cached(int(a), int(mi), stride_for(int(mi)), n + 1)
                     for a, mi in zip(alpha, m, strict=False)])


@lru_cache(maxsize=4096)
def _edf_cached(alpha: int, m: int, stride: int, n_phase: int) -> float:
    return edf_greenhall(alpha, 2, m, stride, n_phase)


def block_means(y: NDArray, b: int) -> NDArray:
    """Means of consecutive blocks of b samples (the tail that does not fill a block is
    dropped); for (n, k) input the means are taken per column."""
    n = (len(y) // b) * b
    if y.ndim == 1:
        return y[:n].reshape(-1, b).mean(axis=1)
    return y[:n].reshape(-1, b, y.shape[1]).mean(axis=1)


def _robust_std(x: NDArray) -> float:
    """1.4826·MAD: the std of a Gaussian sample, blind to the few outliers a step makes."""
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def _block_size(n: int, target_blocks: int = 4096) -> int:
    return max(1, n // target_blocks)


# --------------------------------------------------------------------------------------------
# quantization


def detect_quantization(y: NDArray, rate_hz: float) -> Candidate:
    """Values on a grid: LSB = the smallest spacing of distinct values; every value must sit
    within 1e-6 LSB of k·LSB + offset. Claimed only if the rounding noise LSB²/12 is ≥ 1 % of
    the white per-sample variance var(Δy)/2 (Widrow: rounding is white when the noise spans
    more than about one LSB)."""
    y = np.asarray(y, dtype=np.float64)
    sample = y[: min(len(y), 1 << 20)]
    u = np.unique(sample)
    if len(u) < 2 or len(u) > max(64, len(sample) // 20):
        return Candidate("quantization", False, statistic=0.0, threshold=0.01,
                         evidence=f"{len(u)} distinct values in {len(sample)} samples: no grid")
    d = np.diff(u)
    lsb = float(np.min(d))
    # the spacing itself may carry float jitter: average the spacings that are one step
    one = d[d < 1.5 * lsb]
    lsb = float(np.mean(one))
    k = (u - u[0]) / lsb
    off_grid = float(np.max(np.abs(k - np.rint(k))))
    white = float(np.var(np.diff(y)) / 2.0)
    ratio = (lsb**2 / 12.0) / white if white > 0 else math.inf
    on_grid = off_grid < 1e-3
    passed = on_grid and ratio >= 0.01
    ev = (f"{len(u)} distinct values, all on a grid of LSB {lsb:.6g} m/s^2 "
          f"(largest offset {off_grid:.1e} LSB); rounding noise LSB^2/12 is "
          f"{100 * ratio:.2g} % of the white per-sample variance (test: >= 1 %)")
    if not on_grid:
        ev = f"{len(u)} distinct values, not on one grid (offset {off_grid:.2f} LSB)"
    return Candidate("quantization", passed, {"lsb": lsb}, ratio, 0.01, ev)


def quantization_avar(tau: NDArray, lsb: float, rate_hz: float) -> NDArray:
    """Rounding rate samples to an LSB adds white noise of variance LSB²/12 per sample:
    AVAR = (LSB²/12)·τ0/τ (a white-FM line; the IEEE 3Q²/τ² term is for quantised *phase*)."""
    return (lsb**2 / 12.0) / (rate_hz * np.asarray(tau, dtype=float))


# --------------------------------------------------------------------------------------------
# sinusoid


def _spectral_lines(y: NDArray, rate_hz: float) -> tuple[NDArray, NDArray, NDArray]:
    """Hann-window periodogram P(f) and its local background: the median of P in log-spaced
    bands, interpolated in log-log and divided by ln 2 (the median of an exponential)."""
    n = len(y)
    w = np.hanning(n)
    z = (y - y.mean()) * w
    p = np.abs(np.fft.rfft(z)) ** 2 / np.sum(w**2)
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    k = np.arange(len(f))
    edges = np.unique(np.rint(np.geomspace(8, len(f) - 1, 120)).astype(int))
    centres, meds = [], []
    for a, b in itertools.pairwise(edges):
        a2 = a
        b2 = max(b, a + 24)  # at least 24 bins per band so the median is stable
        seg = p[a2:b2]
        if len(seg) >= 8:
            centres.append(math.sqrt(max(a2, 1) * b2))
            meds.append(np.median(seg))
    bg = np.exp(np.interp(np.log(np.maximum(k, 1)), np.log(centres), np.log(meds))) / math.log(2)
    return f, p, bg


def detect_sinusoid(y: NDArray, rate_hz: float, tau: NDArray, model_var: NDArray,
                    edf: NDArray, exclude_hz: tuple[tuple[float, float], ...] = ()
                    ) -> Candidate:
    """Spectral line test plus Allan-bump visibility (see module doc)."""
    n = len(y)
    f, p, bg = _spectral_lines(y, rate_hz)
    df = rate_hz / n
    ratio = p / bg
    valid = (f >= 20.0 / (n / rate_hz)) & (f <= 0.45 * rate_hz)
    for f_lo, f_hi in exclude_hz:  # lines already claimed (and their Hann main lobe)
        valid &= (f < f_lo - 4 * df) | (f > f_hi + 4 * df)
    if not np.any(valid):
        return Candidate("sinusoid", False, evidence="record too short for a spectral test")
    kk = np.flatnonzero(valid)
    k = int(kk[np.argmax(ratio[kk])])
    r = float(ratio[k])
    # Gaussian interpolation of the Hann main lobe (log power is a parabola near the peak)
    if 0 < k < len(p) - 1:
        a, b, c = np.log(p[k - 1: k + 2])
        den = a - 2 * b + c
        delta = 0.5 * (a - c) / den if den < 0 else 0.0
    else:
        delta = 0.0
    f0 = float((k + np.clip(delta, -0.5, 0.5)) * df)
    t = np.arange(n) / rate_hz
    design = np.column_stack([np.ones(n), t, np.cos(2 * np.pi * f0 * t),
                              np.sin(2 * np.pi * f0 * t)])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    amp = float(math.hypot(coef[2], coef[3]))
    # A line broadened by a wandering frequency (a real disturbance rarely is a pure tone)
    # spreads its power over many bins: take the bins ≥ 3× background within ±1 % of the
    # peak, and from their excess power A = √(4 Σ(P − bg)/n) (Parseval with the Hann window).
    # Lines closer than 1 % of f0 (or 4 bins) are taken as one disturbance.
    half = max(4, math.ceil(0.01 * f0 / df))
    lo_k, hi_k = max(k - half, 1), min(k + half, len(p) - 1)
    seg = slice(lo_k, hi_k + 1)
    excess = np.where(ratio[seg] >= 3.0, np.maximum(p[seg] - bg[seg], 0.0), 0.0)
    amp_spec = float(math.sqrt(4.0 * excess.sum() / n))
    sig = np.flatnonzero(ratio[seg] >= 10.0)
    width = (sig[-1] - sig[0] + 1) * df if len(sig) else df
    broad = amp_spec > 1.2 * amp
    if broad:
        amp = amp_spec
        f0 = float(np.sum(f[lo_k: hi_k + 1] * excess) / max(excess.sum(), 1e-300))
    tau_peak = 0.371 / f0
    j = int(np.argmin(np.abs(np.log(tau / tau_peak))))
    bump = float(model.sinusoid_avar(tau[j: j + 1], amp, f0)[0])
    bump_sigma = bump / (model_var[j] * math.sqrt(2.0 / edf[j]))
    passed = r >= SPECTRAL_RATIO and bump_sigma >= 2.0
    ev = (f"periodogram line at {f0:.6g} Hz stands {r:.3g}x above the local background "
          f"(test: >= {SPECTRAL_RATIO:g}); "
          + (f"a broadened line {width:.3g} Hz wide, amplitude from its power {amp:.3g} m/s^2"
             if broad else f"least-squares amplitude {amp:.3g} m/s^2")
          + f"; its Allan "
          f"bump at tau = {tau[j]:.3g} s is {bump_sigma:.3g} sigma of the AVAR estimate "
          f"(test: >= 2)")
    return Candidate("sinusoid", passed, {"frequency_hz": f0, "amplitude": amp}, r,
                     SPECTRAL_RATIO, ev, detail={"bump_sigma": bump_sigma,
                                                  "band_hz": (float(f[lo_k]), float(f[hi_k]))})


# --------------------------------------------------------------------------------------------
# temperature


def detect_temperature(y: NDArray, rate_hz: float, temps: NDArray | None,
                       names: list[str], *, max_lag_s: float | None = None) -> Candidate:
    """Allan-covariance regression with a thermal lag (see module doc).

    For each temperature channel, lag L (blocks) and averaging factor m (blocks), the
    overlapping Allan differences Δy_i = ȳ_m[i+m] − ȳ_m[i] and ΔT_i (T delayed by L) give
    c = ΣΔyΔT / ΣΔT² = Cov_A(y,T)/AVAR_T. Differences m apart overlap, so the standard error
    uses the non-overlapping count: se² = s²·m / ΣΔT² with s² the residual variance.
    """
    if temps is None or temps.size == 0:
        return Candidate("temperature", False, evidence="no temperature channel in the data")
    n = len(y)
    b = _block_size(n)
    dt = b / rate_hz
    yb = block_means(y, b)
    tb = block_means(np.asarray(temps, dtype=float).reshape(n, -1), b)
    M = len(yb)
    if max_lag_s is None:
        max_lag_s = min(0.125 * n / rate_hz, 1800.0)
    lmax = int(min(M // 8, max_lag_s / dt))
    best = (0.0, 0.0, 0, 0, 0, 0.0)  # |z|, c, L, m, channel, se
    best_comb = 0.0
    ms = [2**s for s in range(0, int(math.log2(max(M // 32, 1))) + 1)]
    for ch in range(tb.shape[1]):
        T = tb[:, ch]
        if np.ptp(T) <= 0:
            continue
        per_m = []
        for m in ms:
            cy = np.concatenate(([0.0], np.cumsum(yb)))
            ct = np.concatenate(([0.0], np.cumsum(T)))
            ay = (cy[m:] - cy[:-m]) / m
            at = (ct[m:] - ct[:-m]) / m
            dy = ay[m:] - ay[:-m]
            dT = at[m:] - at[:-m]
            dy = dy - dy.mean()
            dT = dT - dT.mean()
            nd = len(dy)
            if nd < 8 * m + lmax:
                continue
            # cross[L] = Σ_i dy[i+L]·dT[i] for L = 0…lmax via FFT correlation
            nfft = 1 << math.ceil(math.log2(2 * nd))
            cross = np.fft.irfft(np.fft.rfft(dy, nfft) * np.conj(np.fft.rfft(dT, nfft)), nfft)
            L = np.arange(0, lmax + 1)
            sxy = cross[L]
            c2t = np.concatenate(([0.0], np.cumsum(dT**2)))
            c2y = np.concatenate(([0.0], np.cumsum(dy**2)))
            stt = c2t[nd - L]  # dT[0 : nd−L]
            syy = c2y[nd] - c2y[L]  # dy[L : nd]
            with np.errstate(divide="ignore", invalid="ignore"):
                c = sxy / stt
                s2 = np.maximum(syy - c * sxy, 0.0) / (nd - L - 1)
                se = np.sqrt(s2 * m / stt)
                z = c / se
            z = np.where(np.isfinite(z), z, 0.0)
            per_m.append((m, z, c, se))
        if not per_m:
            continue
        # the lag is chosen on Σ z² over all τ (every scale votes, the slow ones loudest),
        # the coefficient is read at the τ where it is most significant for that lag
        comb = sum(z**2 for _, z, _, _ in per_m)
        i = int(np.argmax(comb))
        if comb[i] > best_comb:
            best_comb = float(comb[i])
            j = int(np.argmax([abs(z[i]) for _, z, _, _ in per_m]))
            m, z, c, se = per_m[j]
            best = (float(abs(z[i])), float(c[i]), i, m, ch, float(se[i]))
    z, c, L, m, ch, se = best
    if z == 0.0:
        return Candidate("temperature", False, evidence="temperature channels are constant")
    lag = L * dt
    passed = z >= Z_TEMPERATURE
    name = names[ch] if ch < len(names) else f"T{ch}"
    ev = (f"Allan-covariance regression of y on temperature '{name}' delayed {lag:.4g} s at "
          f"tau = {m * dt:.4g} s: coefficient {c:.4g} +/- {se:.2g} m/s^2/K, |z| = {z:.3g} "
          f"(test: >= {Z_TEMPERATURE:g}; lag chosen on the sum of z^2 over {len(ms)} tau, "
          f"searched 0..{lmax * dt:.4g} s)")
    return Candidate("temperature", passed, {"coefficient": c, "lag_s": lag}, z, Z_TEMPERATURE,
                     ev, detail={"channel": ch, "tau_s": m * dt, "se": se}, witness=name)


def temperature_signal(temps: NDArray, ch: int, coefficient: float, lag_s: float,
                       rate_hz: float) -> NDArray:
    """c·(T(t − lag) − mean): the acceleration the temperature explains, at the sample rate.
    The first lag seconds repeat the first temperature reading (nothing earlier is known)."""
    T = np.asarray(temps, dtype=float).reshape(len(temps), -1)[:, ch]
    k = round(lag_s * rate_hz)
    Td = np.concatenate((np.full(min(k, len(T)), T[0]), T[: len(T) - k])) if k > 0 else T
    return coefficient * (Td - Td.mean())


# --------------------------------------------------------------------------------------------
# bias step and warm-up (transients)


def _window_contrast(yb: NDArray, w: int) -> NDArray:
    """d_k = mean(yb[k:k+w]) − mean(yb[k−w:k]) for k = w … M−w."""
    c = np.concatenate(([0.0], np.cumsum(yb)))
    k = np.arange(w, len(yb) - w + 1)
    return ((c[k + w] - c[k]) - (c[k] - c[k - w])) / w


def _fit_sse(yb: NDArray, cols: list[NDArray]) -> tuple[float, NDArray]:
    a = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(a, yb, rcond=None)
    r = yb - a @ coef
    return float(r @ r), coef


def _best_step(yb: NDArray, t: NDArray) -> tuple[float, int]:
    """Exact least squares of [1, t, H(t − t_s)] over every split t_s: (SSE, split block).

    With r the residual of y on [1, t] and h_k the residual of the step H_k, the SSE falls by
    (r·H_k)²/(h_k·h_k); both are cumulative sums, so all splits cost O(M)."""
    M = len(yb)
    a = np.column_stack([np.ones(M), t])
    coef, *_ = np.linalg.lstsq(a, yb, rcond=None)
    r = yb - a @ coef
    tc = t - t.mean()
    stt = float(tc @ tc)
    k = np.arange(8, M - 8)
    rs = np.concatenate((np.cumsum(r[::-1])[::-1], [0.0]))  # Σ_{i≥k} r_i
    ts = np.concatenate((np.cumsum(tc[::-1])[::-1], [0.0]))
    cnt = M - k
    hh = cnt - cnt**2 / M - ts[k] ** 2 / stt
    gain = rs[k] ** 2 / np.maximum(hh, 1e-12)
    i = int(np.argmax(gain))
    return float(r @ r - gain[i]), int(k[i])


def _best_warmup(yb: NDArray, t: NDArray, dt: float) -> tuple[float, float, float]:
    """Least-squares [1, t, e^(−t/T)] over a log grid of T: (SSE, T in s, size at t = 0)."""
    M = len(yb)
    best = (math.inf, 0.0, 0.0)
    for T in np.geomspace(2 * dt, M * dt / 8, 80):
        sse, coef = _fit_sse(yb, [np.ones(M), t, np.exp(-t / T)])
        if sse < best[0]:
            best = (sse, float(T), float(coef[2]))
    # refine on a finer grid around the best
    for T in np.geomspace(best[1] / 1.1, best[1] * 1.1, 21):
        sse, coef = _fit_sse(yb, [np.ones(M), t, np.exp(-t / T)])
        if sse < best[0]:
            best = (sse, float(T), float(coef[2]))
    return best


def _transient_fits(y: NDArray, rate_hz: float) -> dict:
    n = len(y)
    b = _block_size(n)
    dt = b / rate_hz
    yb = block_means(y, b)
    t = (np.arange(len(yb)) + 0.5) * dt
    step_sse, split = _best_step(yb, t)
    warm_sse, warm_T, warm_size = _best_warmup(yb, t, dt)
    return {"b": b, "dt": dt, "yb": yb, "t": t, "step": (step_sse, split),
            "warmup": (warm_sse, warm_T, warm_size)}


def detect_bias_step(y: NDArray, rate_hz: float, fits: dict | None = None) -> Candidate:
    """Window-contrast step test at windows of 1/2/4 % of the record (see module doc)."""
    fits = fits or _transient_fits(y, rate_hz)
    yb, dt = fits["yb"], fits["dt"]
    M = len(yb)
    best = (0.0, 0, 0)
    for frac in (0.01, 0.02, 0.04):
        w = max(2, round(frac * M))
        if 2 * w >= M:
            continue
        d = _window_contrast(yb, w)
        s = _robust_std(d)
        if s <= 0:
            continue
        z = np.abs(d - np.median(d)) / s
        i = int(np.argmax(z))
        if z[i] > best[0]:
            best = (float(z[i]), i + w, w)
    z, k, w = best
    step_sse, split = fits["step"]
    warm_sse = fits["warmup"][0]
    # the contrast finds where; the least-squares split says exactly where when it agrees
    if abs(split - k) > w:
        split = k
    # size from windows of 2 % of the record either side: long enough to average the white
    # noise, short enough that random walk and flicker do not wander far
    ws = max(2, min(round(0.02 * M), split, M - split))
    size = float(np.mean(yb[split: split + ws]) - np.mean(yb[split - ws: split]))
    better = step_sse <= warm_sse
    passed = z >= Z_STEP and better
    ev = (f"largest contrast of adjacent {w * dt:.4g} s windows is {z:.3g} robust sigma at "
          f"t = {split * dt:.5g} s (test: >= {Z_STEP:g}); step size {size:.3g} m/s^2; "
          f"a step fits {'better' if better else 'worse'} than a warm-up exponential "
          f"(SSE {step_sse:.3g} vs {warm_sse:.3g})")
    return Candidate("bias_step", passed, {"time_s": split * dt, "size": size}, z, Z_STEP, ev)


def detect_warmup(y: NDArray, rate_hz: float, fits: dict | None = None) -> Candidate:
    """Exponential settling at the start (see module doc)."""
    fits = fits or _transient_fits(y, rate_hz)
    yb, dt = fits["yb"], fits["dt"]
    M = len(yb)
    warm_sse, T, size = fits["warmup"]
    # at most M/16 blocks per window, so that ≥ 14 independent contrasts set the robust σ
    # (with a handful, overlapping windows under random walk make the MAD meaningless)
    w = max(2, min(round(T / dt), M // 16))
    if 2 * w >= M:
        return Candidate("warmup", False, evidence="settling time too long for the record")
    d = _window_contrast(yb, w)
    s = _robust_std(d)
    # d[0] is the contrast at k = w: mean(yb[w:2w]) − mean(yb[:w]), same sign as all d_k
    z0 = abs(float(d[0]) - float(np.median(d))) / s if s > 0 else 0.0
    better = warm_sse < fits["step"][0]
    passed = z0 >= Z_STEP and better
    ev = (f"the first {w * dt:.4g} s differ from the next by {z0:.3g} robust sigma "
          f"(test: >= {Z_STEP:g}); least-squares exponential: time constant {T:.4g} s, size "
          f"{size:.3g} m/s^2; it fits {'better' if better else 'worse'} than a step "
          f"(SSE {warm_sse:.3g} vs {fits['step'][0]:.3g})")
    return Candidate("warmup", passed, {"time_constant_s": T, "size": size}, z0, Z_STEP, ev)


def step_signal(n: int, rate_hz: float, time_s: float, size: float, t0_s: float = 0.0) -> NDArray:
    """size·H(t − time_s) on samples t = t0 + i/rate_hz."""
    t = t0_s + np.arange(n) / rate_hz
    return np.where(t >= time_s, size, 0.0)


def warmup_signal(n: int, rate_hz: float, time_constant_s: float, size: float,
                  t0_s: float = 0.0) -> NDArray:
    """size·e^(−t/T) from the record start."""
    t = t0_s + np.arange(n) / rate_hz
    return size * np.exp(-t / time_constant_s)


# --------------------------------------------------------------------------------------------
# rate ramp


def detect_rate_ramp(y: NDArray, rate_hz: float) -> Candidate:
    """Mean of non-overlapping Allan differences at τ = T/16, T/32, T/64 (see module doc)."""
    n = len(y)
    best = (0.0, 0)
    for parts in (16, 32, 64):
        b = n // parts
        if b < 1:
            continue
        a = block_means(y, b)
        d = np.diff(a)
        sd = float(np.std(d, ddof=1))
        if sd <= 0:
            continue
        tstat = float(np.mean(d) / (sd / math.sqrt(len(d))))
        if abs(tstat) > abs(best[0]):
            best = (tstat, parts)
    tstat, parts = best
    t = np.arange(n) / rate_hz
    slope = float(np.polyfit(t, y, 1)[0])
    passed = abs(tstat) >= T_RAMP
    ev = (f"non-overlapping Allan differences at tau = T/{parts} = {n / parts / rate_hz:.4g} s "
          f"have mean/standard error t = {tstat:.3g} (test: |t| >= {T_RAMP:g}); least-squares "
          f"slope {slope:.4g} m/s^3")
    return Candidate("rate_ramp", passed, {"slope": slope}, abs(tstat), T_RAMP, ev)


def ramp_signal(n: int, rate_hz: float, slope: float, t0_s: float = 0.0) -> NDArray:
    return slope * (t0_s + np.arange(n) / rate_hz)


# --------------------------------------------------------------------------------------------
# AVAR-space causes: Gauss–Markov bump and the sensor's low-pass filter


def chi2(v_meas: NDArray, v_model: NDArray, edf: NDArray) -> float:
    """EDF-weighted χ² of AVAR estimates: Σ (ν/2)(σ̂²/σ² − 1)², each term ~1 when the model is
    right (var(σ̂²) ≈ 2σ⁴/ν, allan.md)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        r = v_meas / v_model - 1.0
    r = np.where(np.isfinite(r), r, 1e6)
    return float(np.sum(0.5 * edf * r * r))


def detect_gauss_markov(tau: NDArray, v: NDArray, edf: NDArray, fit_fn, record_s: float
                        ) -> Candidate:
    """Bump test: ``fit_fn(extra_columns) -> (model AVAR, coefficients)`` refits the five terms
    plus the given columns; a GM column is tried for T on a log grid (see module doc)."""
    base_model, _ = fit_fn([])
    c_base = chi2(v, base_model, edf)
    best = (math.inf, 0.0, 0.0, None)
    t_lo = max(2.0 * tau[0], tau[0])
    t_hi = record_s / 50.0
    if t_hi <= t_lo:
        return Candidate("gauss_markov", False, evidence="record too short for a bump test")
    for T in np.geomspace(t_lo, t_hi, 36):
        col = model.gauss_markov_avar(tau, 1.0, T)
        mv, coef = fit_fn([col])
        c = chi2(v, mv, edf)
        if c < best[0]:
            best = (c, float(T), float(coef[-1]), mv)
    # refine between the neighbouring grid points (the grid steps by ~25 %)
    step = (t_hi / t_lo) ** (1.0 / 35.0)
    for T in np.geomspace(best[1] / step, best[1] * step, 13):
        col = model.gauss_markov_avar(tau, 1.0, T)
        mv, coef = fit_fn([col])
        c = chi2(v, mv, edf)
        if c < best[0]:
            best = (c, float(T), float(coef[-1]), mv)
    c_gm, T, s2, mv = best
    sigma = math.sqrt(max(s2, 0.0))
    if sigma == 0.0 or mv is None:
        return Candidate("gauss_markov", False, {"sigma": 0.0, "time_constant_s": T},
                         0.0, GM_DCHI2, "no Gauss-Markov component improves the fit")
    j = int(np.argmin(np.abs(np.log(tau / (1.893 * T)))))
    gm_peak = float(model.gauss_markov_avar(tau[j: j + 1], sigma, T)[0])
    share = gm_peak / float(mv[j])
    dchi = c_base - c_gm
    passed = dchi >= GM_DCHI2 and c_gm <= c_base / 3.0 and share >= 0.5
    ev = (f"adding a Gauss-Markov bump (sigma {sigma:.3g} m/s^2, correlation time {T:.4g} s) "
          f"lowers the EDF-weighted chi^2 from {c_base:.4g} to {c_gm:.4g} (test: drop >= "
          f"{GM_DCHI2:g} and to <= 1/3); it carries {100 * share:.3g} % of the model AVAR at "
          f"tau = {tau[j]:.3g} s (test: >= 50 %)")
    return Candidate("gauss_markov", passed, {"sigma": sigma, "time_constant_s": T}, dchi,
                     GM_DCHI2, ev)


def detect_filter(tau: NDArray, v: NDArray, edf: NDArray, rate_hz: float,
                  fixed: NDArray) -> Candidate:
    """Short-τ bend (see module doc): on τ ≤ 64·τ0 fit θ₁·W(τ) + θ₂ + fixed, with W the white
    line N²/τ or the low-pass white AVAR at a corner on a log grid."""
    m = np.rint(tau * rate_hz).astype(int)
    sel = m <= 64
    if np.count_nonzero(sel) < 5:
        return Candidate("filter", False, evidence="too few short averaging times")
    ts, vs, es, fx = tau[sel], v[sel], edf[sel], fixed[sel]

    def fit(col: NDArray) -> tuple[float, NDArray, NDArray]:
        a = np.column_stack([col, np.ones_like(ts)])
        w = np.sqrt(es / 2.0) / vs
        from scipy.optimize import nnls

        coef, _ = nnls(a * w[:, None], (vs - fx) * w)
        mv = a @ coef + fx
        return chi2(vs, mv, es), coef, mv

    c_white, _coef_w, _ = fit(1.0 / ts)
    best = (math.inf, 0.0, None)
    for fc in np.geomspace(rate_hz / 200.0, 0.45 * rate_hz, 48):
        col = model.lowpass_white_avar(ts, 1.0, rate_hz, fc)
        c, coef, _ = fit(col)
        if c < best[0]:
            best = (c, float(fc), coef)
    c_lp, fc, coef = best
    # refine the corner by a golden-section-like local grid
    for fc2 in np.geomspace(fc / 1.15, min(fc * 1.15, 0.49 * rate_hz), 15):
        col = model.lowpass_white_avar(ts, 1.0, rate_hz, fc2)
        c, coef2, _ = fit(col)
        if c < c_lp:
            c_lp, fc, coef = c, float(fc2), coef2
    bend = float(model.lowpass_white_avar(ts[:1], 1.0, rate_hz, fc)[0] * ts[0])
    dchi = c_white - c_lp
    passed = dchi >= FILTER_DCHI2 and bend <= 0.95
    ev = (f"at tau <= {ts[-1]:.3g} s a low-pass (2nd-order Butterworth) white-noise AVAR with "
          f"bandwidth {fc:.4g} Hz fits better than the white line: chi^2 {c_white:.4g} -> "
          f"{c_lp:.4g} (test: drop >= {FILTER_DCHI2:g}); AVAR(tau0) is {100 * bend:.3g} % of "
          f"the white line (test: <= 95 %)")
    return Candidate("filter", passed, {"bandwidth_hz": fc}, dchi, FILTER_DCHI2, ev)
