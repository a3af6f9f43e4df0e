"""Records of co-located sensors from a generator written apart from core/sim (numpy only):
for the coverage of ``avard separate``'s intervals and the bias of its fit.

Every noise is a circulant Gaussian process: white noise filtered in the frequency domain by
the square root of a two-sided PSD S(f) = N² + B²/(2π|f|) + K²/(2πf)² (the IEEE terms:
velocity random walk N, bias instability B, rate random walk K), so its covariance is known
exactly, and so is the expected Allan variance at any m (no closed form that holds only
between cut-offs): with g the Allan filter of m-averages (length 2m) and G its DFT,

    E σ²(m) = 1/(2L) Σ_k σ_k² |G_k|²,   |G(ω)|² = 4 sin⁴(mω/2) / (m² sin²(ω/2)),   σ_k² = S(f_k)·f_s

A record is the common input c (the bed: white plus a slow random walk) plus each sensor's
own noise eᵢ, every part drawn independently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Noise:
    """The IEEE terms of one noise (SI: N m/s/√s, B m/s², K m/s²/√s)."""

    n: float
    b: float = 0.0
    k: float = 0.0

    def bin_variance(self, length: int, rate_hz: float) -> NDArray[np.float64]:
        """σ_k² = S(f_k)·f_s at the DFT bins of a ``length``-sample circulant record (the DC
        bin 0: the Allan filter does not see it)."""
        f = np.abs(np.fft.fftfreq(length, d=1.0 / rate_hz))
        s = np.full(length, self.n**2)
        w = 2 * np.pi * np.where(f > 0, f, 1.0)             # bin 0 is zeroed below
        s = s + self.b**2 / w + self.k**2 / w**2
        s[0] = 0.0
        return s * rate_hz

    def draw(self, rng: np.random.Generator, length: int, rate_hz: float) -> NDArray:
        w = rng.standard_normal(length)
        return np.fft.ifft(np.fft.fft(w) * np.sqrt(self.bin_variance(length, rate_hz))).real

    def avar(self, m: NDArray[np.int64], length: int, rate_hz: float) -> NDArray[np.float64]:
        """The expected Allan variance at averaging factors ``m`` (exact for this process)."""
        sk = self.bin_variance(length, rate_hz)
        half = np.pi * np.arange(length) / length        # ω/2
        out = []
        for mm in np.atleast_1d(m):
            with np.errstate(divide="ignore", invalid="ignore"):
                g2 = 4 * np.sin(mm * half) ** 4 / (mm**2 * np.sin(half) ** 2)
            g2[0] = 0.0
            out.append(np.sum(sk * g2) / (2 * length))
        return np.array(out)


@dataclass(frozen=True)
class CoLocated:
    """One record: ``y`` (S, L) the sensors' outputs (m/s², one axis), the common input's and
    each sensor's noise, and the ratio of the common ADEV at τ = 1 s to the sensors' mean
    white level."""

    y: NDArray[np.float64]
    rate_hz: float
    common: Noise
    sensors: tuple[Noise, ...]
    ratio: float


def draw_record(rng: np.random.Generator, n_sensors: int, *, length: int = 1 << 17,
                rate_hz: float = 20.0, ratio: float | None = None) -> CoLocated:
    """Sensors with different N, B, K (an ADXL355-like white level 0.5–2× 25 µg/√Hz), and a
    common input ``ratio`` (default log-uniform 0.1–10) times their mean white level at 1 s,
    white with a slow random walk."""
    sensors = []
    for _ in range(n_sensors):
        n = 2.5e-4 * rng.uniform(0.5, 2.0)
        b = n * rng.uniform(0.05, 0.2)
        sensors.append(Noise(n, b, b * rng.uniform(0.02, 0.1)))
    if ratio is None:
        ratio = float(10 ** rng.uniform(-1.0, 1.0))
    level = ratio * float(np.mean([s.n for s in sensors]))
    common = Noise(level, 0.0, level * 0.01)
    c = common.draw(rng, length, rate_hz)
    y = np.array([c + s.draw(rng, length, rate_hz) for s in sensors])
    return CoLocated(y, rate_hz, common, tuple(sensors), ratio)
