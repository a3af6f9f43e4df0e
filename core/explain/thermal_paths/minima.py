"""The stated minimum detectable effect of each thermal path (docs/explain.md)."""

from __future__ import annotations

import math

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
    vals = [at(float(L))[0] for L in lags]
    i = int(np.argmin(vals))
    # golden-section on the bracket around the best grid point (λ is smooth in L')
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

    lo, hi = 0.0, r0
    while sep(hi) < z * z:
        lo, hi = hi, 2 * hi
        if hi > 1e6 * r0:
            return math.inf
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        if sep(mid) < z * z:
            lo = mid
        else:
            hi = mid
    return hi
