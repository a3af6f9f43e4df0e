"""An accelerometer noise generator written apart from avard's simulator (core/noise_gen,
core/simulate), for checking detection and intervals against something avard did not make.

White rate noise from numpy's normal generator; flicker (bias instability) as a sum of
first-order Gauss–Markov processes with time constants spaced evenly on a log scale, whose
summed spectrum is 1/f between the shortest and the longest; rate random walk as the cumulative
sum of white increments. IEEE Std 952 / 1293 conventions (AVAR of each term):
N²/τ, (2 ln 2/π)·B² on the flicker floor, K²τ/3, R²τ²/2.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter


def white(n: int, rate_hz: float, N: float, rng: np.random.Generator) -> np.ndarray:
    """Velocity random walk N (m/s/√s): per-sample σ = N·√fs, so AVAR = N²/τ."""
    return rng.normal(scale=N * math.sqrt(rate_hz), size=n)


def rate_random_walk(n: int, rate_hz: float, K: float, rng: np.random.Generator) -> np.ndarray:
    """Rate random walk K (m/s²/√s): increments of variance K²·τ0, so AVAR = K²τ/3."""
    return np.cumsum(rng.normal(scale=K / math.sqrt(rate_hz), size=n))


def flicker(n: int, rate_hz: float, B: float, rng: np.random.Generator, *,
            t_min: float = 0.05, t_max: float = 1e6, per_decade: int = 3) -> np.ndarray:
    """Bias instability B (m/s²): Σ of Gauss–Markov processes x_k = φ x_{k−1} + √(1−φ²)·s·w_k
    with time constants T log-spaced, ``per_decade`` per decade from t_min to t_max. Each has
    the one-sided PSD 4 s² T/(1 + (2π f T)²); with equal s² the sum tends to
    s²·d/(f ln 10) (d per decade), set equal to the one-sided flicker PSD h₋₁/f with
    h₋₁ = B²/π (AVAR 2 ln2·h₋₁ = (2 ln2/π)·B², NIST SP 1065 table 7)."""
    dt = 1.0 / rate_hz
    decades = math.log10(t_max / t_min)
    count = round(decades * per_decade) + 1
    s2 = B * B * math.log(10.0) / (math.pi * per_decade)
    out = np.zeros(n)
    for T in np.geomspace(t_min, t_max, count):
        phi = math.exp(-dt / T)
        w = rng.normal(scale=math.sqrt(s2 * (1.0 - phi * phi)), size=n)
        w[0] = rng.normal(scale=math.sqrt(s2))  # start in the stationary distribution
        out += lfilter([1.0], [1.0, -phi], w)
    return out


def study_record(rng: np.random.Generator, *, hours: float = 4.0, rate_hz: float = 100.0,
                 N: float = 1.5e-4, k_range: tuple[float, float] = (1e-6, 4e-6),
                 b_range: tuple[float, float] = (2e-5, 4e-5)) -> dict:
    """One record of the K-against-ramp study (issue 12): white + flicker + rate random walk,
    no ramp, K and B drawn uniformly; the fully overlapping ADEV at octave τ and avard's fit.
    Returns the truth and what the fit said about K and R."""
    from avard.core.allan.deviations import oavar
    from avard.core.model.fit import fit_noise

    n = int(hours * 3600 * rate_hz)
    K = float(rng.uniform(*k_range))
    B = float(rng.uniform(*b_range))
    y = white(n, rate_hz, N, rng) + flicker(n, rate_hz, B, rng) + \
        rate_random_walk(n, rate_hz, K, rng)
    ms = 2 ** np.arange(int(math.log2(n // 4)) + 1)
    fit = fit_noise(oavar(y, rate_hz, ms / rate_hz))
    k, r = fit.terms["rate_random_walk"], fit.terms["rate_ramp"]
    return {"K": K, "B": B, "ramp": r.present, "k_present": k.present, "k_lo": k.lo,
            "k_hi": k.hi, "k_upper": k.upper, "either": k.note is not None,
            "b_lo": fit.terms["bias_instability"].lo, "b_hi": fit.terms["bias_instability"].hi}


def study_summary(rows: list[dict]) -> dict:
    """False-ramp share, K absent and its upper limit below the truth, 68 % coverage of K."""
    absent = [r for r in rows if not r["k_present"]]
    present = [r for r in rows if r["k_present"]]
    return {
        "records": len(rows),
        "ramp_claimed": sum(r["ramp"] for r in rows),
        "ramp_or_walk": sum(r["either"] for r in rows),
        "k_absent": len(absent),
        "k_upper_below_truth": sum(r["k_upper"] is not None and r["k_upper"] < r["K"]
                                   for r in absent),
        "k_present": len(present),
        "k_covered": sum(r["k_lo"] <= r["K"] <= r["k_hi"] for r in present),
    }


def flicker_spectral(n: int, rate_hz: float, B: float, rng: np.random.Generator) -> np.ndarray:
    """Bias instability B (m/s²) with the one-sided PSD B²/(π f) at every Fourier frequency
    of the record up to Nyquist (h₋₁ = B²/π, NIST SP 1065 table 7): white Gaussian noise
    shaped in the frequency domain (a circular record; no power below 1/T). Unlike
    :func:`flicker`, whose shortest Gauss–Markov member rolls the spectrum off above
    1/(2π t_min) (or aliases it back when t_min < 1/fs), it is 1/f across the whole band, which
    a white level read next to strong flicker at 5–40 Hz needs."""
    spec = np.fft.rfft(rng.normal(size=n))
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    gain = np.zeros_like(f)
    # E|rfft(w)|² = n, so |X|² = n·S₁·fs/2 gives the one-sided PSD S₁ = 2|X|²/(n fs)
    gain[1:] = np.sqrt(B * B / (math.pi * f[1:]) * rate_hz / 2.0)
    return np.fft.irfft(spec * gain, n)
