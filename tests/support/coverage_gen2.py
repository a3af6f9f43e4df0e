"""A second coverage generator for issue 24, written apart from the project (adv25).

numpy only; imports nothing of avard's and nothing of ``tests/support/coverage_gen.py``.

Rate data y (e.g. acceleration) sampled at one sample per unit "sample time"; all levels
are per sample, so a record at any rate is the same sequence with τ = m / rate.

Processes (each independent, summed):

* white FM: y_w[k] = s·e_k, e ~ N(0, 1).                 AVAR(m) = s²/m.
* flicker FM: Kasdin–Walter fractional integration of order d = 1/2,
  y_f = σ_f (1 − B)^(−1/2) e, i.e. y_f[n] = σ_f Σ_k h_k e[n−k], h_0 = 1,
  h_k = h_{k−1}(k − 1/2)/k. The filter is run over a burn-in of ``BURN`` record lengths
  before the record starts, so the record's increments x = (1 − B)y_f are (to ≲1e-3 of the
  AVAR at m ≤ N/5, see ``burn_bias``) the stationary ARFIMA(0, −1/2, 0) process, whose
  autocovariance is exact: γ(0) = σ_f²Γ(2)/Γ(3/2)² = 4σ_f²/π, γ(k) = γ(k−1)(k − 3/2)/(k + 1/2).
  The Allan difference ȳ_{p+m} − ȳ_p = Σ_j v_j x_{p+j}, v_j = min(j, 2m − j)/m, j = 1 … 2m−1,
  so AVAR(m) = ½ Σ_{j,l} v_j v_l γ(j − l) = ½ Σ_k γ(k) c_v(k), c_v the autocorrelation of v.
* random walk FM: y_r = q·cumsum(e).  Its increments are white (γ = q²δ), so the same sum
  gives AVAR(m) = ½ q² Σ v_j² = q²(2m² + 1)/(6m).
* a slow sinusoid A sin(2πk/P + φ), φ uniform on [0, 2π): the Allan difference of the
  m-averages is A|W(f)| sin(2πf p + const), |W(f)| = 2 sin²(πmf)/(m sin πf), f = 1/P; the
  mean over φ of its square is ½ at every p, so the ensemble mean of the exact OADEV of the
  noise-free part is A² sin⁴(πm/P)/(m² sin²(π/P)) exactly, at any record length.
* a linear drift d·k: every Allan difference is d·m, so its OADEV is (d m)²/2 exactly.

``noise_avar`` is the closed form of the three noises; ``signal_avar`` of the noise-free
part. ``check_truth`` compares them with the mean over generated records (own OADEV, numpy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

BURN = 2  # burn-in of the flicker filter, in record lengths


@dataclass(frozen=True)
class Levels:
    """Per-sample levels of one mix."""

    s2: float  # white variance
    f2: float  # flicker innovation variance σ_f²
    q2: float  # random-walk step variance
    amplitude: float = 0.0  # sinusoid amplitude
    period: float = 0.0  # sinusoid period, samples
    drift: float = 0.0  # per sample


def _pow2_at_least(n: int) -> int:
    return 1 << (int(n) - 1).bit_length()


def kasdin_h(n: int) -> np.ndarray:
    """The first n coefficients of (1 − B)^(−1/2)."""
    k = np.arange(1, n, dtype=float)
    return np.concatenate([[1.0], np.cumprod((k - 0.5) / k)])


def increment_acov(kmax: int) -> np.ndarray:
    """Autocovariance γ(0 … kmax) of (1 − B)^(1/2) e (unit innovation): the flicker's
    increments."""
    k = np.arange(1, kmax + 1, dtype=float)
    return (4.0 / math.pi) * np.concatenate([[1.0], np.cumprod((k - 1.5) / (k + 0.5))])


def flicker_unit_avar(ms: np.ndarray) -> np.ndarray:
    """Exact AVAR at averaging factors ``ms`` of the stationary-increment flicker with unit
    innovation variance: ½ Σ_k γ(k) c_v(k)."""
    ms = np.asarray(ms, dtype=np.int64)
    gam = increment_acov(int(2 * ms.max()))
    out = np.empty(len(ms))
    for i, m in enumerate(ms):
        j = np.arange(1, 2 * m, dtype=float)
        v = np.minimum(j, 2 * m - j) / m
        nfft = _pow2_at_least(4 * m)
        fv = np.fft.rfft(v, nfft)
        c = np.fft.irfft(fv * np.conj(fv), nfft)[: 2 * m - 1]  # c_v(0 … 2m−2)
        g = gam[: 2 * m - 1]
        out[i] = 0.5 * (g[0] * c[0] + 2.0 * np.dot(g[1:], c[1:]))
    return out


def burn_bias(n: int, m: float) -> float:
    """Bound on the AVAR missing from the flicker because its filter starts BURN·n samples
    before the record, relative to the unit flicker plateau: the innovations before the
    start reach the Allan difference with weight ≈ m·|ψ_{B+s}|, ψ_k ≈ k^(−3/2)/(2√π), so the
    missing variance is ≈ ½ m²/(8π B²) against a plateau of ≈ 2 ln 2/π."""
    b = BURN * n
    return 0.5 * m * m / (8 * math.pi * b * b) / (2 * math.log(2) / math.pi)


def noise_avar(lv: Levels, ms: np.ndarray) -> np.ndarray:
    """Closed-form AVAR of the generated white + flicker + random walk at ``ms``."""
    m = np.asarray(ms, dtype=float)
    return lv.s2 / m + lv.f2 * flicker_unit_avar(ms) + lv.q2 * (2 * m * m + 1) / (6 * m)


def signal_avar(lv: Levels, ms: np.ndarray) -> np.ndarray:
    """Ensemble mean of the exact OADEV of the noise-free part (random-phase sinusoid and
    drift; their cross term averages to zero over the phase)."""
    m = np.asarray(ms, dtype=float)
    out = 0.5 * (lv.drift * m) ** 2
    if lv.amplitude:
        f = 1.0 / lv.period
        out = out + lv.amplitude**2 * np.sin(np.pi * m * f) ** 4 / (m * m * np.sin(np.pi * f) ** 2)
    return out


def truth(lv: Levels, ms: np.ndarray) -> np.ndarray:
    return noise_avar(lv, ms) + signal_avar(lv, ms)


def levels(n: int, tau_wf: float, tau_fr: float, rate: float, sine_period: float = 0.0,
           sine_gain: float = 0.0, drift_at: float = 0.0) -> Levels:
    """Levels for an n-sample record: white s² = 1; the flicker AVAR equals the white's at
    τ = tau_wf and the random walk's (≈ q²m/3) at tau_fr. ``sine_gain``: the sinusoid's AVAR
    at τ = P/2 is that many times the noise's there; ``drift_at``: the drift's AVAR equals
    the noise's at that fraction of the record (m = drift_at·n)."""
    m_wf, m_fr = tau_wf * rate, tau_fr * rate
    floor = 1.0 / m_wf
    f2 = floor / float(flicker_unit_avar(np.array([round(m_wf)]))[0])
    q2 = 3.0 * floor / m_fr
    lv = Levels(1.0, f2, q2)
    amp = 0.0
    if sine_period:
        half = max(1, round(sine_period / 2))
        noise = float(noise_avar(lv, np.array([half]))[0])
        unit = float(signal_avar(Levels(0, 0, 0, 1.0, sine_period), np.array([half]))[0])
        amp = math.sqrt(sine_gain * noise / unit)
    d = 0.0
    if drift_at:
        m = max(1, round(drift_at * n))
        d = math.sqrt(2.0 * float(noise_avar(lv, np.array([m]))[0])) / m
    return Levels(lv.s2, lv.f2, lv.q2, amp, sine_period, d)


def record(lv: Levels, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One record (n samples) and its noise-free part."""
    y = math.sqrt(lv.s2) * rng.standard_normal(n)
    if lv.f2:
        total = (BURN + 1) * n
        e = rng.standard_normal(total)
        nfft = _pow2_at_least(2 * total)
        yf = np.fft.irfft(np.fft.rfft(e, nfft) * np.fft.rfft(kasdin_h(total), nfft), nfft)
        y += math.sqrt(lv.f2) * yf[total - n: total]
    if lv.q2:
        y += math.sqrt(lv.q2) * np.cumsum(rng.standard_normal(n))
    k = np.arange(n, dtype=float)
    clean = lv.drift * k
    if lv.amplitude:
        clean = clean + lv.amplitude * np.sin(2 * np.pi * k / lv.period
                                              + rng.uniform(0, 2 * np.pi))
    return y + clean, clean


def oadev_var(y: np.ndarray, ms: np.ndarray) -> np.ndarray:
    """Own fully overlapping Allan variance of rate samples at averaging factors ``ms``."""
    c = np.concatenate([[0.0], np.cumsum(y - y.mean())])
    out = np.empty(len(ms))
    for i, m in enumerate(np.asarray(ms, dtype=np.int64)):
        d = c[2 * m:] - 2 * c[m:-m] + c[: -2 * m]
        out[i] = 0.5 * np.mean(d * d) / (m * m)
    return out


def check_truth(lv: Levels, n: int, ms: np.ndarray, records: int,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean over ``records`` generated records of the own OADEV, against the closed form:
    (ratio mean/closed form, the ratio's standard error, the closed form)."""
    est = np.array([oadev_var(record(lv, n, rng)[0], ms) for _ in range(records)])
    t = truth(lv, ms)
    return est.mean(axis=0) / t, est.std(axis=0, ddof=1) / math.sqrt(records) / t, t
