"""Table 3 of the paper, taken at its word: closed-form consistency checks, and the simulated
``paper-table3`` record analysed with the noise fit (docs/table3.md is made from this by
docs/scripts/table3_note.py).

Closed forms (IEEE 952 Annex C; ``avard.core.model.terms``): AVAR = N²/τ + (2 ln2/π)·B² + K²τ/3.
The slope method reads B as min ADEV / 0.6643, which is only right when the N and K lines pass
well below the floor; the minimum of the three-term model is the number to compare.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from avard.core.allan.deviations import AllanResult
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.io.source import RecordBlock, RecordFormat, RecordInfo, StreamSource
from avard.core.model.fit import NoiseFit, slope_method
from avard.core.model.terms import BI_FACTOR
from avard.core.sim.presets import (
    DATASHEET_N,
    G0,
    TABLE3_B,
    TABLE3_K_PRINTED,
    TABLE3_N,
    SimConfig,
)
from avard.core.sim.simulate import SensorSimulator, n_samples

AXES = ("x", "y", "z")
#: The paper's reported maximum estimation error (Section 4): 4.7 % at long cluster times.
PAPER_MAX_ERROR = 0.047
#: Datasheet noise density range (µg/√Hz, one-sided) and the white coefficient it implies.
DATASHEET_ND_UG = (22.5, 25.0)
DATASHEET_N_RANGE = tuple(nd * 1e-6 * G0 / math.sqrt(2.0) for nd in DATASHEET_ND_UG)


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
    ci: float = 0.683, find_sinusoids: bool = True,
    progress: Callable[[int, int | None], None] | None = None,
) -> list[AxisAnalysis]:
    """Simulate ``hours`` of ``config`` and analyse it exactly as ``avard analyze`` does a
    simulated record (``analyze`` of a ``StreamSource``: streaming Allan accumulator, line search,
    fit with the chip filter modelled at ODR/4 from two samples on), without writing the
    record to disk; read each axis with the slope method too."""
    sim = SensorSimulator(config, seed)
    total = n_samples(config, hours)

    def blocks() -> Iterator[RecordBlock]:
        done = 0
        while done < total:
            c = sim.next(min(chunk, total - done))
            done += len(c)
            yield c.counts * config.lsb_mps2, None, False       # what the sensor reports, m/s²

    # a simulated ADXL355: its LSB and its low-pass corner (ODR/4) travel with the blocks
    info = RecordInfo(source=f"simulated {config.preset}", format=RecordFormat.STREAM,
                      rate_hz=config.rate_hz, names=tuple(config.axes), n_samples=total,
                      lsb_mps2=config.lsb_mps2, sensor_name=config.preset,
                      sensor_model="ADXL355", filter_corner_hz=config.rate_hz / 4.0)
    an = analyze(StreamSource(info, blocks()),
                 AnalyzeOptions(find_sinusoids=find_sinusoids, ci=ci), progress=progress)
    out = []
    for a, axis in enumerate(config.axes):
        ca = an.channels[axis]
        truth = {"velocity_random_walk": config.velocity_random_walk[a],
                 "bias_instability": config.bias_instability[a],
                 "rate_random_walk": config.rate_random_walk[a],
                 "quantization": config.quantization[a],
                 "rate_ramp": config.rate_ramp[a]}
        out.append(AxisAnalysis(axis, truth, ca.fit, slope_method(ca.allan), ca.allan))
    return out


@dataclass
class TermOutcome:
    """One term of one axis of one analysed record against its truth."""

    seed: int
    axis: str
    term: str
    truth: float
    present: bool
    value: float | None
    lo: float | None
    hi: float | None
    upper: float | None              # one-sided upper limit when absent

    @property
    def inside(self) -> bool:
        """The reported interval holds the truth (present terms with a non-zero truth)."""
        return bool(self.present and self.lo is not None and self.hi is not None
                    and self.lo <= self.truth <= self.hi)

    @property
    def z(self) -> float | None:
        """(value − truth) in units of the interval's half-width."""
        if not self.present or self.value is None or self.lo is None or self.hi is None:
            return None
        half = 0.5 * (self.hi - self.lo)
        return (self.value - self.truth) / half if half > 0 else None


def outcomes_over_seeds(
    config: SimConfig, hours: float, seeds: Sequence[int],
    progress: Callable[[int, int], None] | None = None,
) -> list[TermOutcome]:
    """Analyse one record per seed and compare every term with the truth: the check that the
    reported 68 % intervals hold the truth as often as they claim (one record can only say
    whether one draw fell inside)."""
    out = []
    for i, seed in enumerate(seeds):
        for an in analyse_record(config, hours, seed):
            for term, true in an.truth.items():
                te = an.fit.terms[term]
                out.append(TermOutcome(seed, an.axis, term, true, te.present, te.value, te.lo,
                                       te.hi, te.upper))
        if progress is not None:
            progress(i + 1, len(seeds))
    return out


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
