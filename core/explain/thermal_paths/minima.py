"""The stated minimum detectable effect of each thermal path (docs/explain.md)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from avard.core.explain.causes import noise_psd
from numpy.typing import NDArray


def _response_derivatives(kind: str, w: float, lag_s: float, lag2_s: float,
                          lags_known: bool) -> NDArray[np.complex128]:
    """∂G/∂p of a linear path's complex response G(ω) at ``w`` (rad/s), one row per
    parameter p the GLS fit estimates: two_path (c₁, c₂ and, with the lags unknown, c₁·L1
    and c₂·L2); rate (c, r and c·L). A lag enters as its coefficient times it (∂G/∂L_i
    divided by c_i): the other parameters' standard errors do not depend on how a nuisance
    column is scaled, so the minimum holds for any non-zero c_i."""
    h1, h2 = 1.0 / (1 + 1j * w * lag_s), 1.0 / (1 + 1j * w * lag2_s)
    if kind == "two_path":
        rows = [h1, h2] + ([] if lags_known else [-1j * w * h1**2, -1j * w * h2**2])
    else:
        rows = [h1, 1j * w] + ([] if lags_known else [-1j * w * h1**2])
    return np.array(rows, dtype=complex)


def min_detectable_path(kind: str, n_white: float, b_inst: float, k_rrw: float,
                        record_s: float, amplitude_c: float, period_s: float,
                        lag_s: float = 0.0, lag2_s: float = 0.0,
                        z: float = 5.0, lines: tuple[tuple[float, float], ...] = (),
                        lags_known: bool = False) -> float:
    """The smallest extra term of candidate ``kind`` the GLS fit detects at ``z`` on average,
    for a ±``amplitude_c`` sinusoid of ``period_s`` at the die (after the first path
    ``lag_s``) and the further drive ``lines`` ((amplitude at the die K, period s) each), with
    the linear coupling fitted beside it: the Fisher information of the fit's parameters on
    the noise PSD S(f) (N, B, K, NIST SP 1065 Table 5), one sinusoidal component of
    amplitude a known to σ_a(f) = √(2 S(f)/T) per quadrature.

    - two_path (m/s²/K, the second coefficient), rate (m/s² per K/s): every parameter the
      fit estimates unknown, the lags too (``lags_known``: only the coefficients, the
      minimum before, optimistic): with ∂G/∂p the response's derivatives at each line
      (``_response_derivatives``), I = Σ_lines (a/σ_a(f))²·Re(∂G ∂Gᴴ), e_min =
      z·√((I⁻¹)_ee). On one drive line the response is one complex number, 2 real ones,
      and two paths (c₁, c₂, L1, L2) or a dT/dt term (c, r, L: r − c·L and c(1 + ω²L²) are
      all one line tells) have more: I is singular and the minimum infinite (``math.inf``):
      there is no finite minimum with the lags unknown, the record's other content (its
      wander, its start) is all that tells them;
    - quadratic (m/s²/K²): (u − ū)² is −(a²/2)·cos 2ω t, e_min = z·σ_a(2f0)·2/a²;
    - hysteresis (m/s²): a ±h square wave switching a phase φ after each turn of the drive,
      odd harmonics 4h/(πk)·e^(−ikφ): h_min = z/√(Σ_k odd ≥ 3 (4/(πk))²/σ_a(k f0)²). The
      fundamental tells nothing of h: the fit estimates the linear coupling's gain and phase
      (c, L) and the switch's phase (L, w) beside h, and at f0 the relay's fundamental and
      the coupling are one sinusoid with a free gain and phase (2 numbers, 4 unknowns); only
      the harmonics fix h (and φ, orthogonal to it at each harmonic), and with them the
      coupling. The fundamental in the sum, as before, made the minimum 1/1.26 of this on the
      benchmark's drive: the minimum of a fit that knew the switch and the coupling.
    """
    f0 = 1.0 / period_s

    def sig(f: float) -> float:
        return math.sqrt(2 * noise_psd(f, n_white, b_inst, k_rrw) / record_s)

    a = amplitude_c
    if kind in ("two_path", "rate"):
        info: NDArray[np.float64] | None = None
        for amp, period in ((a, period_s), *lines):
            d = _response_derivatives(kind, 2 * math.pi / period, lag_s, lag2_s, lags_known)
            add = (amp / sig(1.0 / period)) ** 2 * np.real(np.outer(d, d.conj()))
            info = add if info is None else info + add
        assert info is not None
        ev = np.linalg.eigvalsh(info)
        if ev[0] <= 1e-10 * ev[-1]:
            return math.inf
        return z * math.sqrt(float(np.linalg.inv(info)[1, 1]))
    if kind == "quadratic":
        return z * sig(2 * f0) * 2 / a**2
    if kind == "hysteresis":
        s = sum((4 / (math.pi * k)) ** 2 / sig(k * f0) ** 2 for k in range(3, 40, 2))
        return z / math.sqrt(s)
    raise ValueError(kind)


def _one_lag_response(w: NDArray, lag_s: float) -> NDArray[np.complex128]:
    """One lag's response at ``w`` (rad/s), as the one-lag column builds it
    (``thermal_fit.lag_filter``): 1/(1 + jωL) for L ≥ 0, the lead-lag (1 + 2jωa)/(1 + jωa),
    a = −L, for L < 0."""
    if lag_s >= 0:
        return np.asarray(1.0 / (1 + 1j * w * lag_s), dtype=complex)
    a = -lag_s
    return np.asarray((1 + 2j * w * a) / (1 + 1j * w * a), dtype=complex)


def _sep_lags(top: float) -> NDArray[np.float64]:
    """The one-lag readings' lags (s) the separation searches, either sign, to ``top``."""
    pos = np.geomspace(0.5, top, 241)
    return np.concatenate([-pos[::-1], [0.0], pos])


def _closest_lag(at: Callable[[float], tuple[float, float]], lags: NDArray
                 ) -> tuple[float, float, float]:
    """(λ, L', c') at the one-lag reading closest by ``at`` over ``lags``: the best grid
    point, then a golden-section search on the bracket around it (λ is smooth in L'), kept
    only where it improves on the grid point."""
    vals = [at(float(L))[0] for L in lags]
    i = int(np.argmin(vals))
    lo, hi = float(lags[max(i - 1, 0)]), float(lags[min(i + 1, len(lags) - 1)])
    g = (math.sqrt(5) - 1) / 2
    for _ in range(60):
        m1, m2 = hi - g * (hi - lo), lo + g * (hi - lo)
        if at(m1)[0] < at(m2)[0]:
            hi = m2
        else:
            lo = m1
    L = 0.5 * (lo + hi)
    lam, cp = at(L)
    if vals[i] < lam:
        L = float(lags[i])
        lam, cp = at(L)
    return lam, L, cp


def rate_lag_separation(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                        lines: tuple[tuple[float, float], ...], coefficient: float,
                        rate: float) -> tuple[float, float, float]:
    """How far a coupling ``coefficient`` (m/s²/K) plus a dT/dt term ``rate`` (m/s² per
    K/s) at a lag of 0 is from every one-lag reading c'·H(ω, L') (L' of either sign, the
    one-lag column's lead-lag for L' < 0), on the drive ``lines`` ((amplitude at the die K,
    period s) each): (λ, L', c') with λ = min over (c', L') of Σ_lines (a/σ_a(f))²·|c + jωr −
    c'·H(ω, L')|², the non-centrality (z²) of the GLS fit's test of the dT/dt term against
    the closest one-lag reading, and that reading. σ_a(f) = √(2 S(f)/T) per quadrature as in
    ``min_detectable_path``."""
    a = np.array([x[0] for x in lines], dtype=float)
    w = np.array([2 * math.pi / x[1] for x in lines], dtype=float)
    s2 = np.array([2 * noise_psd(1.0 / x[1], n_white, b_inst, k_rrw) / record_s
                   for x in lines])
    q = a * a / s2
    G = coefficient + 1j * w * rate

    def at(L: float) -> tuple[float, float]:
        h = _one_lag_response(w, L)
        cp = float(np.sum(q * np.real(G * h.conj())) / np.sum(q * np.abs(h) ** 2))
        return float(np.sum(q * np.abs(G - cp * h) ** 2)), cp

    # (to far beyond the lag c·T + r·dT/dt is to first order, r/c, and the drive's periods)
    lags = _sep_lags(1e3 * max(abs(rate / coefficient) if coefficient else 0.0,
                               float(np.max(1.0 / w))))
    return _closest_lag(at, lags)


def min_detectable_rate(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                        lines: tuple[tuple[float, float], ...], coefficient: float,
                        lead: bool, z: float = 5.0) -> float:
    """The stated minimum of a dT/dt term (m/s² per K/s, its size |r|) beside a coupling
    ``coefficient`` at a lag of 0, on the drive ``lines`` ((amplitude at the die K, period s)
    each): the smallest |r| whose separation from every one-lag reading
    (``rate_lag_separation``) reaches z², with r/c > 0 (``lead``: c·T + r·dT/dt is a lead,
    T ahead) or r/c < 0 (a lag). ``math.inf`` when none up to 10⁶× the term's minimum
    against zero reaches it.

    Why not the Fisher information of r in the fit (c, r, L): at a lag of 0 the lag's
    derivative −jωc is the dT/dt term's jω times −c at every frequency, so the information is
    singular on any drive (``min_detectable_path("rate")`` is ``math.inf`` there); the
    minimum "with the lags known" is r against zero (what r − c·L resolves), which a one-lag
    reading holds to first order: c·T(t − L) ≈ c·T − c·L·dT/dt. What tells the term from one
    lag is the second order (one lag's gain falls as 1/√(1 + ω²L²) where c + jωr's rises; a
    lead-lag's phase is at most asin(1/3)), which this non-centrality measures on every line
    at once. On one line a lag (r/c < 0) is every phase one lag reaches: ``math.inf``."""
    w = np.array([2 * math.pi / x[1] for x in lines], dtype=float)
    a = np.array([x[0] for x in lines], dtype=float)
    s2 = np.array([2 * noise_psd(1.0 / x[1], n_white, b_inst, k_rrw) / record_s
                   for x in lines])
    r0 = z / math.sqrt(float(np.sum((a * w) ** 2 / s2)))  # against zero
    sgn = 1.0 if lead == (coefficient > 0) else -1.0

    def sep(r: float) -> float:
        return rate_lag_separation(n_white, b_inst, k_rrw, record_s, lines, coefficient,
                                   sgn * r)[0]

    return _bisect_size(sep, r0, z)


# --------------------------------------------------------------------------- as explain's fit
# runs it: the Allan covariance at the octave τ from the channel's rounding floor up
# (docs/log/2026-11-28-cand26b.md, the derivation)

#: The DS18B20's 12-bit step (K), repeated here so the derivation reads whole (and the
#: adversary's generator can copy it): the default of the log's own ``step`` below.
_Q_STEP = 0.0625


def _g(x: NDArray) -> NDArray[np.float64]:
    """The AVAR of a unit-amplitude sinusoid at f·τ = ``x``: sin⁴(πx)/(πx)²."""
    px = np.pi * np.asarray(x, dtype=float)
    return np.asarray(np.sin(px) ** 4 / px**2, dtype=float)


def rounding_time(lines: tuple[tuple[float, float], ...], step: float = _Q_STEP) -> float:
    """How long (s) one rounding error of the logged channel lasts (``thermal_fit.
    rounding_correlation_s``): the log's ``step`` (K) over the rms slope of the ``lines``
    ((amplitude K, period s) of the logged channel), never under 1 s."""
    slope = math.sqrt(sum((2 * math.pi / p * a) ** 2 / 2 for a, p in lines))
    return max(step / slope, 1.0) if slope > 0 else math.inf


def rounding_floor(lines: tuple[tuple[float, float], ...], rate_hz: float, record_s: float,
                   snr: float = 10.0, step: float = _Q_STEP) -> float:
    """The channel's rounding floor (s) on a drive of ``lines`` ((amplitude K, period s) of the
    logged channel), as ``thermal_fit.rounding_floor_tau`` finds it on the record: the first
    octave τ (2ʲ/``rate_hz``) where the drive's AVAR Σ a²·sin⁴(πfτ)/(πfτ)² reaches ``snr``
    times the rounding's (q²/12)·t_c/τ, q the log's ``step`` (K; a coarse log's own)."""
    tc = rounding_time(lines, step)
    tau = 1.0 / rate_hz
    while 2 * tau <= record_s:
        v = sum(a * a * float(_g(np.array(tau / p))) for a, p in lines)
        if v >= snr * step**2 / 12 * tc / tau:
            return tau
        tau *= 2
    return math.inf


def _edf(x: NDArray, parts: tuple[NDArray, NDArray, NDArray]) -> NDArray[np.float64]:
    """The overlapping AVAR's EDF at T/τ = ``x`` for white, flicker and random-walk FM (NIST
    SP 1065 §5.2's simple formulas, M ≫ m), the terms' AVAR ``parts`` mixed as
    ν = (Σ σᵢ²)²/Σ(σᵢ⁴/νᵢ)."""
    nu = (1.5 * x - 2.0, 5 * x * x / (4 * (x + 3)), x - 3 + 4 / x)
    tot = sum(parts)
    den = sum(p * p / np.maximum(n, 1.0) for p, n in zip(parts, nu, strict=True))
    return np.asarray(np.maximum(tot * tot / den, 1.0), dtype=float)


def fit_weights(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                periods: NDArray, floor_s: float, rounding_c2tc: float = 0.0
                ) -> NDArray[np.float64]:
    """What explain's deviance D = Σ_k ν_k ln r_k sees of a sinusoidal component of unit
    amplitude at each of ``periods`` (s): W(f) = Σ_k ν_k·sin⁴(πfτ_k)/(πfτ_k)²/r_k over the
    octave τ_k = floor_s·2ʲ ≤ record/2, r_k the one-lag residual's AVAR (the noise's N²/τ +
    (2 ln 2/π)B² + K²τ/3 and the readings' rounding through the coupling,
    ``rounding_c2tc`` = c²·(q²/12)·t_c, over τ), ν_k its EDF (``_edf``). W·|ΔY|² is the
    deviance a residual sinusoid of amplitude |ΔY| adds: the GLS fit's Fisher information
    per unit amplitude², line by line."""
    p = np.asarray(periods, dtype=float)
    out = np.zeros(p.size)
    if not math.isfinite(floor_s) or floor_s <= 0:
        return out
    tau = floor_s
    while 2 * tau <= record_s:
        x = record_s / tau
        white = (n_white**2 + rounding_c2tc) / tau
        parts = (np.array(white), np.array(2 * math.log(2) / math.pi * b_inst**2),
                 np.array(k_rrw**2 * tau / 3))
        r = float(sum(parts))
        nu = float(_edf(np.array(x), parts))
        out += nu * _g(tau / p) / r
        tau *= 2
    return out


def one_lag_separation_fit(periods: NDArray, drive: NDArray, response: NDArray,
                           weights: NDArray, sig2: NDArray | None = None
                           ) -> tuple[float, float, float]:
    """min over one-lag readings c'·H(ω, L') (``_one_lag_response``, L' of either sign) of
    Σ_lines W·|Y − c'·H·U|²: the deviance by which the hidden ``response`` Y (complex, m/s², per
    line) beats the closest one-lag reading of the ``drive`` U (complex, K, per line), in the
    fit's own metric ``weights`` W (``fit_weights``); (λ, L', c').

    With ``sig2`` (σ_a² per quadrature at each line, √(2S(f)/T)²) λ is instead the
    non-centrality of the fit's own estimate of that residual: the fit weighs the lines by W,
    the noise at each line is σ², so the residual's size is estimated to a variance
    Σ W²σ²|ΔY|²/(Σ W|ΔY|²)² and λ = (Σ W|ΔY|²)²/Σ W²σ²|ΔY|² (≤ Σ|ΔY|²/σ², the whole
    spectrum's, equal where W ∝ 1/σ²: the Cauchy–Schwarz bound). The closest reading is
    still the one the fit picks, in W."""
    w = 2 * math.pi / np.asarray(periods, dtype=float)
    U = np.asarray(drive, dtype=complex)
    Y = np.asarray(response, dtype=complex)
    q = np.asarray(weights, dtype=float)
    if not np.any(q > 0):
        return 0.0, 0.0, 0.0

    def at(L: float) -> tuple[float, float]:
        h = _one_lag_response(w, L) * U
        den = float(np.sum(q * np.abs(h) ** 2))
        cp = float(np.sum(q * np.real(Y * h.conj())) / den) if den > 0 else 0.0
        return float(np.sum(q * np.abs(Y - cp * h) ** 2)), cp

    lags = _sep_lags(1e3 * float(np.max(1.0 / w)))
    lam, L, cp = _closest_lag(at, lags)
    if sig2 is None:
        return lam, L, cp
    d2 = np.abs(Y - cp * _one_lag_response(w, L) * U) ** 2
    den = float(np.sum(q * q * np.asarray(sig2, dtype=float) * d2))
    return (float(np.sum(q * d2)) ** 2 / den if den > 0 else 0.0), L, cp


def relay_harmonics(drive: NDArray, width_k: float, k_max: int = 39) -> NDArray[np.complex128]:
    """The complex amplitudes (harmonics 1…``k_max``, per unit h) of a ±1 relay that switches
    once the periodic drive has moved ``width_k`` (K) back from its last extreme (the weekend
    generator's and the adversary's play operator), the drive given by its complex harmonic
    amplitudes ``drive`` (harmonic k at index k − 1, K), the same phase convention."""
    m = 1 << 12
    th = np.arange(2 * m) / m  # two periods: the second is the steady one
    U = np.asarray(drive, dtype=complex)
    ks = np.arange(1, U.size + 1)
    u = np.real(np.exp(2j * np.pi * np.outer(th, ks)) @ U)
    s, ref = 1.0, float(u[0])
    out = np.empty(u.size)
    for i, ui in enumerate(u.tolist()):
        if s > 0:
            ref = max(ref, ui)
            if ui < ref - width_k:
                s, ref = -1.0, ui
        else:
            ref = min(ref, ui)
            if ui > ref + width_k:
                s, ref = 1.0, ui
        out[i] = s
    c = 2 * np.fft.fft(out[m:]) / m
    return np.asarray(c[1:k_max + 1], dtype=complex)


def _sig2(n_white: float, b_inst: float, k_rrw: float, record_s: float,
          periods: NDArray) -> NDArray[np.float64]:
    """σ_a² = 2S(f)/T per quadrature at each of ``periods`` (``min_detectable_path``'s)."""
    return np.array([2 * noise_psd(1.0 / p, n_white, b_inst, k_rrw) / record_s
                     for p in np.asarray(periods, dtype=float)])


def _bisect_size(lam: Callable[[float], float], start: float, z: float) -> float:
    """The smallest size s > 0 with ``lam(s)`` ≥ z² (doubling from ``start``, then
    bisection); ``math.inf`` past 10⁶·start."""
    lo, hi = 0.0, start
    while lam(hi) < z * z:
        lo, hi = hi, 2 * hi
        if hi > 1e6 * start:
            return math.inf
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lam(mid) < z * z else (lo, mid)
    return hi


def min_detectable_rate_fit(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                            lines: tuple[tuple[float, float], ...], coefficient: float,
                            lead: bool, floor_s: float, rounding_c2tc: float = 0.0,
                            z: float = 5.0) -> float:
    """The stated minimum of a dT/dt term (|r|, m/s² per K/s) against one lag as explain's fit
    sees it: the smallest |r| (r/c > 0 if ``lead``) whose residual over the closest one-lag
    reading the fit picks (lines weighed by ``fit_weights``, τ from the rounding floor
    ``floor_s`` up) the fit estimates at z (``one_lag_separation_fit`` with σ²: the fit's
    weights, the noise's variance at each line). The drive ``lines`` ((amplitude at the die K,
    period s) each) are taken in phase (a lag is judged line by line, their relative phases
    do not enter). ``math.inf`` where none does (one line and a lag)."""
    per = np.array([p for _, p in lines], dtype=float)
    U = np.array([a for a, _ in lines], dtype=complex)
    W = fit_weights(n_white, b_inst, k_rrw, record_s, per, floor_s, rounding_c2tc)
    s2 = _sig2(n_white, b_inst, k_rrw, record_s, per)
    w = 2 * math.pi / per
    sgn = 1.0 if lead == (coefficient > 0) else -1.0
    if not np.any(W > 0):
        return math.inf
    start = z / math.sqrt(float(np.sum(np.abs(U * w) ** 2 / s2)))  # against zero

    def lam(r: float) -> float:
        return one_lag_separation_fit(per, U, (coefficient + 1j * w * sgn * r) * U, W, s2)[0]

    return _bisect_size(lam, start, z)


def min_detectable_hysteresis_fit(n_white: float, b_inst: float, k_rrw: float,
                                  record_s: float, period_s: float, drive: NDArray,
                                  coefficient: float, width_k: float, floor_s: float,
                                  rounding_c2tc: float = 0.0, z: float = 5.0,
                                  k_max: int = 39) -> float:
    """The stated minimum of a relay (h, m/s²) against one lag as explain's fit sees it: the
    smallest h whose residual over the closest one-lag reading of c·T + h·relay the fit picks
    (lines weighed by ``fit_weights``, τ from ``floor_s`` up) the fit estimates at z
    (``one_lag_separation_fit`` with σ², the accelerometer's noise and the readings'
    rounding through the coupling, ``rounding_c2tc`` = c²(q²/12)t_c, as white noise: the
    one-lag column carries it into the residual). The drive is periodic,
    ``drive`` its complex harmonics at the die (k = 1, 2, …; K), ``width_k`` how far it moves
    back from an extreme before the relay switches (``relay_harmonics``). The relay's
    fundamental counts where it puts the response beyond one lag's reach (a coupling of the
    other sign), its harmonics beyond what the drive's own harmonics through one lag take;
    ``math.inf`` where none does."""
    U = np.zeros(k_max, dtype=complex)
    d = np.asarray(drive, dtype=complex)[:k_max]
    U[:d.size] = d
    R = relay_harmonics(U, width_k, k_max)
    per = period_s / np.arange(1, k_max + 1)
    W = fit_weights(n_white, b_inst, k_rrw, record_s, per, floor_s, rounding_c2tc)
    # the noise the estimate faces: the accelerometer's and the readings' rounding through
    # the coupling (the one-lag column is built on the rounded readings, so c·lag(rounding)
    # is in the residual, white above t_c), the same N² + c²(q²/12)t_c the weights use
    # (docs/log/2026-11-29-hyst29.md)
    s2 = _sig2(math.sqrt(n_white**2 + rounding_c2tc), b_inst, k_rrw, record_s, per)
    if not np.any(W > 0):
        return math.inf
    start = z / math.sqrt(float(np.sum(np.abs(R) ** 2 / s2)))  # against zero, in W

    def lam(h: float) -> float:
        return one_lag_separation_fit(per, U, coefficient * U + h * R, W, s2)[0]

    return _bisect_size(lam, start, z)
