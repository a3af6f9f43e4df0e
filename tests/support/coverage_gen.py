"""Rate-noise records with a closed-form Allan variance, written apart from avard (numpy only).

The coverage benchmark (benchmarks/bench_coverage.py) checks avard's printed OADEV intervals
against records from this generator, so nothing here comes from avard: not core/sim, not
core/model, not tests/core/independent_noise.py (which uses scipy). Each process is made by
the most direct method there is, and its truth is computed from that method, not from a
formula for an ideal process:

* white: numpy's normal generator, variance s² per sample: AVAR(m) = s²/m exactly;
* random walk: the cumulative sum of white increments of variance q² per sample; the
  difference of two adjacent m-averages weighs the increments 1, 2, …, m, …, 2, 1 (over m),
  so AVAR(m) = q²(2m² + 1)/(6m) exactly;
* flicker: a random Fourier series on a period of ``PERIODS`` record lengths, each
  frequency f_j = j/(L τ0) with independent normal cosine and sine amplitudes of variance
  P_j = h/f_j · Δf (a one-sided 1/f spectrum of level h, AVAR ≈ 2 ln 2 · h on its floor). The
  record is the first N of the L samples. The Allan variance of this process is exactly
  ½ Σ_j P_j |H_m(f_j)|², with |H_m(f)|² = 4 sin²(π f m τ0)·[sin(π f m τ0)/(m sin(π f τ0))]²
  the response of the difference of two adjacent m-averages (``flicker_avar``);
* a slow sinusoid of random phase and a linear drift are added noise-free; their part of
  the truth is the ensemble mean of the exact OADEV of the noise-free signal, which the
  caller computes (the drift's is the same for every record: (d·m)²/2 per sample²).

Units are the caller's: everything is per sample (τ0 = 1) unless a rate is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# the flicker's period, in record lengths: its lowest frequency is 1/(PERIODS·T)
PERIODS = 4


@dataclass(frozen=True)
class Mix:
    """Levels of one mix, per sample (τ0 = 1): white variance ``s2``, random-walk increment
    variance ``q2``, flicker level ``h`` (one-sided PSD h/f, f in cycles per sample),
    sinusoid amplitude and period (samples), drift per sample."""

    s2: float
    h: float
    q2: float
    sine_amplitude: float = 0.0
    sine_period: float = 0.0
    drift: float = 0.0


def _flicker_power(n: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(f_j, P_j) of the flicker's Fourier series: f_j = j/L, P_j = h/f_j · (1/L)."""
    length = PERIODS * n
    f = np.arange(1, length // 2) / length
    return f, h / f / length


def flicker(n: int, h: float, rng: np.random.Generator) -> np.ndarray:
    """n samples of the flicker series (see the module docstring), by one inverse FFT."""
    length = PERIODS * n
    f, p = _flicker_power(n, h)
    z = np.zeros(length // 2 + 1, dtype=complex)
    amp = np.sqrt(p) * length / 2.0
    z[1:length // 2] = amp * (rng.normal(size=f.size) - 1j * rng.normal(size=f.size))
    return np.fft.irfft(z, length)[:n]


def flicker_avar(n: int, h: float, ms: np.ndarray) -> np.ndarray:
    """The flicker series' exact AVAR at averaging factors ``ms`` (module docstring)."""
    f, p = _flicker_power(n, h)
    out = np.empty(len(ms))
    for k, m in enumerate(np.asarray(ms, dtype=float)):
        x = np.pi * f
        avg = np.sin(x * m) / (m * np.sin(x))
        out[k] = 0.5 * float(np.sum(p * 4.0 * np.sin(x * m) ** 2 * avg**2))
    return out


def noise_avar(mix: Mix, n: int, ms: np.ndarray) -> np.ndarray:
    """Exact AVAR of white + flicker + random walk at averaging factors ``ms``."""
    m = np.asarray(ms, dtype=float)
    return mix.s2 / m + flicker_avar(n, mix.h, m) + mix.q2 * (2 * m * m + 1) / (6 * m)


def record(mix: Mix, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(noisy record, its noise-free part) of n samples."""
    y = rng.normal(scale=math.sqrt(mix.s2), size=n)
    y += flicker(n, mix.h, rng)
    y += np.cumsum(rng.normal(scale=math.sqrt(mix.q2), size=n))
    t = np.arange(n, dtype=float)
    clean = np.zeros(n)
    if mix.sine_amplitude:
        phase = rng.uniform(0.0, 2 * np.pi)
        clean += mix.sine_amplitude * np.sin(2 * np.pi * t / mix.sine_period + phase)
    if mix.drift:
        clean += mix.drift * t
    return y + clean, clean
