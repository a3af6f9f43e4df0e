"""Table 3 of the paper, taken at its word: closed-form consistency checks, and the simulated
``paper-table3`` record analysed with the noise fit (docs/table3.md is made from this by
docs/scripts/table3_note.py).

Closed forms (IEEE 952 Annex C; ``avard.core.model``): AVAR = N²/τ + (2 ln2/π)·B² + K²τ/3.
The slope method reads B as min ADEV / 0.6643, which is only right when the N and K lines pass
well below the floor; the minimum of the three-term model is the number to compare.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .allan import AllanResult
from .fit import NoiseFit, fit_noise, slope_method
from .model import BI_FACTOR
from .presets import (
    DATASHEET_N,
    G0,
    TABLE3_B,
    TABLE3_K_PRINTED,
    TABLE3_N,
    SimConfig,
)
from .simulate import SensorSimulator, n_samples
from .streaming import StreamingAllan

AXES = ("x", "y", "z")
#: The paper's reported maximum estimation error (Section 4): 4.7 % at long cluster times.
PAPER_MAX_ERROR = 0.047
#: Datasheet noise density range (µg/√Hz, one-sided) and the white coefficient it implies.
DATASHEET_ND_UG = (22.5, 25.0)
DATASHEET_N_RANGE = tuple(nd * 1e-6 * G0 / math.sqrt(2.0) for nd in DATASHEET_ND_UG)
#: Shortest τ given to the fit: below ≈6 samples the chip filter also bends the flicker part
#: and the LSB rounding adds unfiltered white noise, neither of which the fit's model holds.
FIT_TAU_MIN_S = 0.05


def adev_minimum(n: float, b: float, k: float) -> tuple[float, float]:
    """(τ at the minimum, minimum ADEV) of √(N²/τ + (2 ln2/π)B² + K²τ/3); with K = 0 the
    curve falls to the floor 0.6643·B as τ → ∞ (reported as τ = inf)."""
    if k <= 0:
        return math.inf, BI_FACTOR * b
    tau = math.sqrt(3.0) * n / k                    # d/dτ (N²/τ + K²τ/3) = 0
    return tau, math.sqrt(n * n / tau + (BI_FACTOR * b) ** 2 + k * k * tau / 3.0)


@dataclass(frozen=True)
class AxisFacts:
    """The printed numbers of one axis and what they imply in the two readings of K."""

    axis: str
    n: float
    b: float
    k_printed: float
    floor: float                  # 0.6643·B, the floor the slope method reads B from
    min_k_per_s: tuple[float, float]      # (τ, min ADEV) with K in m/s²/√s as printed
    min_k_per_h: tuple[float, float]      # with K in m/s²/√h, i.e. K/60 in SI

    @property
    def ratio_per_s(self) -> float:
        return self.min_k_per_s[1] / self.floor

    @property
    def ratio_per_h(self) -> float:
        return self.min_k_per_h[1] / self.floor

    @property
    def n_over_datasheet(self) -> tuple[float, float]:
        return self.n / DATASHEET_N_RANGE[1], self.n / DATASHEET_N_RANGE[0]


def consistency_facts() -> list[AxisFacts]:
    """Per axis: the three-term ADEV minimum against the reported floor, both K readings."""
    out = []
    for a, axis in enumerate(AXES):
        n, b, k = TABLE3_N[a], TABLE3_B[a], TABLE3_K_PRINTED[a]
        out.append(AxisFacts(axis, n, b, k, BI_FACTOR * b, adev_minimum(n, b, k),
                             adev_minimum(n, b, k / 60.0)))
    return out


def kx_over_bx() -> float:
    """K_X / B_X as printed: equals 0.6643 = √(2 ln2/π) to five digits, i.e. the printed K_X
    is the printed floor value 0.6643·B_X itself."""
    return TABLE3_K_PRINTED[0] / TABLE3_B[0]


@dataclass
class AxisAnalysis:
    """One axis of an analysed simulated record."""

    axis: str
    truth: dict[str, float]          # the simulated coefficients (SI)
    fit: NoiseFit
    slope: dict[str, float]          # the slope method's reading of the same curve
    result: AllanResult              # the channel's Allan variance (m/s²)²


def analyse_record(
    config: SimConfig, hours: float, seed: int | None, *, chunk: int = 1 << 17,
    tau_min_s: float = FIT_TAU_MIN_S, ci: float = 0.683,
    progress: Callable[[int, int], None] | None = None,
) -> list[AxisAnalysis]:
    """Simulate ``hours`` of ``config`` into a bounded-memory streaming Allan accumulator
    (partially overlapping, stride m/8), then fit each axis with the chip filter modelled
    (corner ODR/4) over τ ≥ ``tau_min_s``, and read it with the slope method too."""
    sim = SensorSimulator(config, seed)
    acc = StreamingAllan(3, config.rate_hz, names=list(config.axes))
    total = n_samples(config, hours)
    done = 0
    while done < total:
        c = sim.next(min(chunk, total - done))
        acc.update(c.counts * config.lsb_mps2)        # what the sensor reports, m/s²
        done += len(c)
        if progress is not None:
            progress(done, total)
    res = acc.result(ci=ci)
    out = []
    for a, axis in enumerate(config.axes):
        ch = res.channel(a)
        truth = {"velocity_random_walk": config.velocity_random_walk[a],
                 "bias_instability": config.bias_instability[a],
                 "rate_random_walk": config.rate_random_walk[a]}
        fit = fit_noise(ch, filter_corner_hz=config.rate_hz / 4.0,
                        tau_range=(tau_min_s, math.inf), ci=ci)
        out.append(AxisAnalysis(axis, truth, fit, slope_method(ch), ch))
    return out


def record_white(config: SimConfig) -> tuple[float, ...]:
    """The white coefficient the output record holds per axis (m/s/√s): N plus the 20-bit
    rounding, white noise of LSB²/12 per sample added after the chip filter, √(N² + LSB²/(12·fs)).
    At τ ≫ 1/fs the fit cannot tell the two apart; on X and Y of ``paper-table3`` the rounding
    raises N by 0.17 %, several times the 60 h record's 68 % interval on N (±0.03–0.05 %)."""
    q = config.lsb_mps2**2 / (12.0 * config.rate_hz)
    return tuple(math.sqrt(n * n + q) for n in config.velocity_random_walk)


def relative_errors(analysis: AxisAnalysis) -> dict[str, float | None]:
    """(fit − truth)/truth per term; None where the fit reports the term absent or the truth
    is zero."""
    out: dict[str, float | None] = {}
    for term, true in analysis.truth.items():
        te = analysis.fit.terms[term]
        out[term] = None if (not te.present or true == 0) else te.value / true - 1.0
    return out


def datasheet_n() -> float:
    """The white coefficient of the ``adxl355-datasheet`` preset (22.5 µg/√Hz)."""
    return DATASHEET_N


def model_adev(tau: np.ndarray, n: float, b: float, k: float) -> np.ndarray:
    """ADEV of the three-term model (no filter): for plots and tables."""
    return np.sqrt(n * n / tau + (BI_FACTOR * b) ** 2 + k * k * tau / 3.0)
