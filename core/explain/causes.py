"""The time-domain causes of `avard explain`: their parameters, signals, stated minima and
the generalised least squares (``_Gls``) of block means they are fitted by.

They act on seconds to hours, so they are fitted on the slow view of the record (block means
of about a second, :class:`avard.core.explain.engine.SlowView`). A :class:`Candidate` holds
one: parameters (SI units), its test statistic against the threshold, and a sentence of
evidence a reader can check by hand. The signal it describes is removed from the axis and
analyze's GLS fit is made again on what is left (the extended model).

The search explain runs is :mod:`avard.core.explain.transients` (several steps, excursions,
a warm-up, a drift; one false-alarm budget, :mod:`avard.core.explain.alarm`). Here:

- ``detect_bias_step`` / ``detect_warmup``: the window-contrast detectors (the largest
  difference of adjacent window means, robustly scaled, test ≥ 6), used where one quick
  look is asked (the thermal lag's start state, the hold-out's leftover step); their
  ``min_detectable_step`` / ``_warmup`` are the stated minima the docs give (power, never a
  floor);
- ``_Gls`` and the profile helpers ``_weight_interval``, ``_profile_interval``,
  ``_size_interval``, ``_vertex``: the generalised least squares of block means with the
  noise model and the 68 % intervals from its profiles, which the compound fit
  (:mod:`avard.core.explain.transients`) uses; ``refine_transients`` (one warm-up and one
  step fitted together) is its simplest use, kept as the reference its tests hold the GLS's
  white-noise fast path and intervals to;
- ``transient_floor``: what the logged temperature's 0.0625 K resolution makes through the
  fitted coupling; a transient below it is not claimed on a thermally coupled axis;

Temperature is :mod:`avard.core.explain.thermal_fit`; sinusoids are analyze's line finder
(``spectrum.find_lines``, which also groups a periodic disturbance's lines); rate ramp, the
chip's low-pass and the LSB rounding are terms of analyze's model (``fit.fit_noise``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

import numpy as np
from avard.core.model.triangular import LowerSolver
from numpy.typing import NDArray

#: Causes explain tests beside analyze's model, and their parameters (SI units).
CAUSES = ("temperature", "warmup", "bias_step", "excursion", "drift", "gauss_markov",
          "sinusoid", "periodic")
PARAMS = {
    "temperature": ("coefficient", "lag_s"),
    "warmup": ("time_constant_s", "size"),
    "bias_step": ("time_s", "size"),
    "excursion": ("start_s", "end_s", "size"),
    "drift": ("rate",),
    "periodic": ("frequency_hz", "amplitude", "harmonics", "modulation_hz", "frequency_lo_hz",
                 "frequency_hi_hz"),
    "gauss_markov": ("sigma", "time_constant_s"),
    "sinusoid": ("frequency_hz", "amplitude"),
}
UNITS = {"coefficient": "m/s²/K", "lag_s": "s", "time_constant_s": "s", "size": "m/s²",
         "time_s": "s", "start_s": "s", "end_s": "s", "rate": "m/s³", "frequency_hz": "Hz",
         "amplitude": "m/s²", "sigma": "m/s²", "harmonics": "", "modulation_hz": "Hz",
         "frequency_lo_hz": "Hz", "frequency_hi_hz": "Hz"}

Z_STEP = 6.0


def transient_span(cause: str, params: dict[str, float]) -> tuple[float, float] | None:
    """The time (s) a transient acts over: a step's time, an excursion's two edges, a
    warm-up's first three time constants; None for any other cause (or a transient without
    its times)."""
    if cause == "bias_step" and "time_s" in params:
        return float(params["time_s"]), float(params["time_s"])
    if cause == "excursion" and "start_s" in params and "end_s" in params:
        return float(params["start_s"]), float(params["end_s"])
    if cause == "warmup":
        return 0.0, 3.0 * float(params.get("time_constant_s", 0.0))
    return None

@dataclass
class Candidate:
    """The outcome of one cause's test on one channel."""

    cause: str
    passed: bool
    params: dict[str, float] = field(default_factory=dict)
    statistic: float = 0.0
    threshold: float = 0.0
    evidence: str = ""
    #: 68 % intervals of the parameters ([lo, hi], SI units), where the fit gives them
    intervals: dict[str, list[float]] = field(default_factory=dict)
    #: extra detail for the report (arrays for plots); never serialised to JSON
    detail: dict[str, Any] = field(default_factory=dict)
    #: channel name of the temperature witness (temperature cause only)
    witness: str | None = None


@dataclass
class Finding:
    """One cause's outcome in ``avard explain``: parameters (SI) with 68 % intervals where it
    has them and its own test (statistic against threshold, evidence). A claimed signal is
    removed before the noise refit; a claimed Gauss–Markov process is one of the extended
    fit's components."""

    cause: str
    claimed: bool
    params: dict[str, float]
    intervals: dict[str, list[float]]
    statistic: float
    threshold: float
    evidence: str
    scale: list[float | None] = field(default_factory=list)
    channel: str | None = None
    #: the extended model misfits (``verdict``): the parameters are a rejected model's best
    model_dependent: bool = False
    #: the intervals withheld because held-out data reject the model (None: not withheld)
    intervals_if_model_held: dict[str, list[float]] | None = None
    #: the temperature cause's thermal path (``thermal_paths.CANDIDATES``), else None
    mechanism: str | None = None
    #: other thermal paths the record supports as well as ``mechanism`` (it cannot tell
    #: them apart)
    alternatives: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"cause": self.cause, "claimed": self.claimed,
                             "params": self.params, "intervals": self.intervals,
                             "statistic": self.statistic, "threshold": self.threshold,
                             "evidence": self.evidence,
                             "model_dependent": self.model_dependent}
        if self.intervals_if_model_held is not None:
            d["intervals_if_model_held"] = self.intervals_if_model_held
        if self.channel is not None:
            d["channel"] = self.channel
        if self.mechanism is not None:
            d["mechanism"] = self.mechanism
        if self.alternatives:
            d["mechanism_alternatives"] = list(self.alternatives)
        return d


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


def transient_fits(y: NDArray, rate_hz: float) -> dict:
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
    fits = fits or transient_fits(y, rate_hz)
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
    fits = fits or transient_fits(y, rate_hz)
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



def cause_signal(cand: Candidate, n: int, rate_hz: float) -> NDArray:
    """The signal a passed transient candidate (a warm-up, a step, an excursion, a drift)
    describes, on n samples at ``rate_hz``."""
    p = cand.params
    if cand.cause == "warmup":
        return warmup_signal(n, rate_hz, p["time_constant_s"], p["size"])
    if cand.cause == "bias_step":
        return step_signal(n, rate_hz, p["time_s"], p["size"])
    if cand.cause == "excursion":
        return (step_signal(n, rate_hz, p["start_s"], p["size"])
                - step_signal(n, rate_hz, p["end_s"], p["size"]))
    if cand.cause == "drift":  # about the record's middle (the offset is the noise's)
        t = np.arange(n) / rate_hz
        return np.asarray(p["rate"] * (t - 0.5 * n / rate_hz))
    raise ValueError(f"{cand.cause} is not a time-domain transient")  # a bug


def _noise_avar(tau: float | NDArray, n_white: float, b_inst: float, k_rrw: float
                ) -> NDArray:
    """AVAR of white, flicker and random-walk rate noise (N²/τ + (0.664 B)² + K²τ/3)."""
    t = np.asarray(tau, dtype=float)
    return np.asarray(n_white**2 / t + (0.6643 * b_inst) ** 2 + k_rrw**2 * t / 3.0)


def noise_psd(f: float, n_white: float, b_inst: float, k_rrw: float) -> float:
    """One-sided PSD ((m/s²)²/Hz) at f of white, flicker and random-walk rate noise whose
    AVAR is N²/τ + (2 ln2/π)B² + K²τ/3: 2N² + B²/(πf) + K²/(2π²f²) (NIST SP 1065 Table 5:
    h₀ = 2N², h₋₁ = B²/π, h₋₂ = K²/(2π²))."""
    return 2 * n_white**2 + b_inst**2 / (math.pi * f) + k_rrw**2 / (2 * math.pi**2 * f**2)


#: Hann window: worst-case power of a line between two bins relative to one on a bin
#: (scalloping loss 1.42 dB)
HANN_SCALLOP = 0.718


def min_detectable_sinusoid(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                            rate_hz: float, frequency_hz: float) -> float:
    """Smallest sinusoid amplitude A (m/s², of A·sin 2πft) that analyze's line finder
    (``report.find_lines``) finds on average at ``frequency_hz``, on noise N, B, K over
    ``record_s`` at ``rate_hz``.

    Welch with analyze's segment (``report.welch_nperseg``: L samples, Δf = fs/L, K ≈
    2·n/L − 1 segments at 50 % overlap): a Hann-windowed line puts A²·L/(3·fs) = A²/(3Δf)
    into its peak bin ((Σw)²/Σw² = 2L/3), times ``HANN_SCALLOP`` when it falls between
    bins; the noise there is S(f0) (:func:`noise_psd`). The finder asks the bin/background
    ratio to exceed ``report.line_threshold`` (F(ν, ν_bg) at a 1 % chance of one false line
    per spectrum), so on average A_min² = 3·Δf·S(f0)·(thr − 1)/HANN_SCALLOP."""
    from avard.core.analysis.spectrum import (
        LINE_HALF_WIDTH,
        LINE_LOBE,
        line_threshold,
        welch_nperseg,
    )

    n = int(record_s * rate_hz)
    L = welch_nperseg(n)
    segs = max(1, 2 * n // L - 1)
    thr = float(line_threshold(L // 2 + 1, segs, 2 * (LINE_HALF_WIDTH - LINE_LOBE)))
    df = rate_hz / L
    s0 = noise_psd(frequency_hz, n_white, b_inst, k_rrw)
    return math.sqrt(3.0 * df * s0 * (thr - 1.0) / HANN_SCALLOP)


def min_detectable_warmup(n_white: float, b_inst: float, k_rrw: float,
                          time_constant_s: float) -> float:
    """Smallest warm-up size (m/s²) the test passes on average: the contrast of the first
    two windows of T is size·(1 − 2/e + 1/e²) = 0.40·size; the spread of such contrasts is
    √(2·AVAR(T)) (NIST SP 1065 eq. 6); the test wants 6 of them."""
    k = 1.0 - 2.0 * math.exp(-1.0) + math.exp(-2.0)
    return float(Z_STEP * math.sqrt(2.0 * _noise_avar(time_constant_s, n_white, b_inst,
                                                      k_rrw)) / k)


def min_detectable_step(n_white: float, b_inst: float, k_rrw: float, record_s: float
                        ) -> float:
    """Smallest bias step (m/s²) the test passes on average: the contrast of adjacent
    windows of 1, 2 or 4 % of the record across the step is its size; their spread
    √(2·AVAR(window)); the test wants 6 of them at the best window."""
    w = np.array([0.01, 0.02, 0.04]) * record_s
    return float(Z_STEP * np.min(np.sqrt(2.0 * _noise_avar(w, n_white, b_inst, k_rrw))))


#: The DS18B20's 12-bit reading step (K), the default of the rounding floors below.
DS18B20_STEP_K = 0.0625


def gauss_markov_rounding_floor(coefficient: float, step: float = DS18B20_STEP_K) -> float:
    """The σ (m/s²) a Gauss–Markov bump on a thermally coupled axis must exceed to be claimed:
    |c|·0.0625 K/√12, the RMS of the logged temperature's rounding error carried through the
    fitted coupling. The thermal model removes c·lag(T_logged); its residual keeps
    c·lag(rounding error), and while a slow cycle turns the temperature the rounding error is
    a sawtooth whose period is the time to cross one reading step (≈ 80 s for ±0.215 °C over
    30 min), correlated like a Gauss–Markov process of that time (a plate-logged 2-minute-lag
    record of the benchmark, seed 99000: σ 3.9e-5 m/s², T 96 s, with c = 4.9e-3 m/s²/K, whose
    rounding RMS is 8.9e-5). The lag only shrinks it, so this bounds it from above.
    ``step``: the driving log's reading step (K; ``ThermalFit.grid``), 0.0625 K at 12 bits."""
    return abs(coefficient) * step / math.sqrt(12.0)


def transient_floor(cand: Candidate, noise: dict[str, float], record_s: float,
                    coefficient: float = 0.0, step: float = DS18B20_STEP_K
                    ) -> tuple[float, str]:
    """The smallest size (m/s²) a passed transient may have to be claimed, and why: what the
    logged temperature's resolution makes through the fitted coupling, |c|·0.0625 K (the
    DS18B20's step). The thermal model removes c·lag(T_logged), and the logged reading is the
    true temperature rounded, so the residual keeps c·lag(rounding error), which stays within
    ±|c|·0.0625 K/2 and jumps when a slowly turning temperature crosses a reading step; any
    transient of at most |c|·0.0625 K can be that rounding (a 2.7e-4 m/s² "step" 147 s into a
    record with c = 4.6e-3 m/s²/K, where the lag filter's start state is fitted and nothing
    smooths the first readings).

    The cause's *stated minimum* (``min_detectable_warmup``/``_step``) is not a floor: it is
    a statement of power for planning, and it is computed from noise levels a transient
    itself inflates; a detection is decided by its test and its interval
    (``transients.confirm_compound``). ``step``: the driving log's reading step (K;
    ``ThermalFit.grid``), 0.0625 K at 12 bits."""
    q = step
    rounding = abs(coefficient) * q
    return rounding, (f"what the logged temperature's {q:g} K resolution "
                      f"produces through the coupling ({abs(coefficient):.3g} m/s²/K × "
                      f"{q:g} K = {rounding:.3g} m/s²)")


def size_z(cand: Candidate) -> float:
    """|size| in standard errors towards zero: the size over the half of its 68 % interval
    on zero's side (the profile interval is not symmetric); inf without an interval."""
    size = float(cand.params.get("size", 0.0))
    lo, hi = cand.intervals.get("size", [math.nan, math.nan])
    se = size - lo if size > 0 else hi - size
    if not (math.isfinite(se) and se > 0):
        return math.inf if size != 0 else 0.0
    return abs(size) / se


def _noise_cov(t: NDArray, block_s: float, n_white: float, b_inst: float, k_rrw: float,
               gm_sigma: float = 0.0, gm_T: float = 0.0) -> NDArray:
    """Covariance of block means of white, flicker and random-walk rate noise: analyze's
    drift test's (``analysis.drift.block_noise_cov``), one model for both; plus, where the
    axis has one (``gm_sigma`` > 0), a Gauss–Markov process of σ ``gm_sigma`` and time
    constant ``gm_T`` block-averaged the same way: without it the transients' GLS reads the
    process's AVAR bump as random walk, under whose covariance a step is one increment."""
    from avard.core.analysis.drift import _gm_block_cov, block_noise_cov

    c = block_noise_cov(t, block_s, n_white, b_inst, k_rrw)
    if gm_sigma > 0 and gm_T > 0:
        c = c + gm_sigma**2 * _gm_block_cov(np.abs(np.subtract.outer(t, t)), block_s, gm_T)
    return c


# --------------------------------------------------------------------------------------------
# generalised least squares of the transients: parameters and 68 % intervals


#: Points of the profile grids: the warm-up's T (log grid over a factor 8 either side of the
#: detector's) and the step's time (a quarter block apart over ± 4 % of the record).
T_GRID = 81
STEP_GRID_FRACTION = 0.04


def _step_blocks(t: NDArray, dt: float, ts: NDArray | Sequence[float]) -> NDArray:
    """H(t − ts) averaged over each block (centres ``t``, length ``dt``), one column per
    ``ts``: the block holding the step gets the fraction after it, so the fit's χ² is a
    continuous function of the step time, not a staircase of whole blocks."""
    return np.clip((t[:, None] + dt / 2 - np.asarray(ts)[None, :]) / dt, 0.0, 1.0)


def _weight_interval(x: NDArray, chi: NDArray, scale: float) -> tuple[float, float, float]:
    """(16th, 50th, 84th percentile) of the likelihood exp(−(χ² − χ²_min)/(2·scale)) over an
    even grid x, interpolated: the estimate and its central 68 %. For a change point: its
    profile χ² is a jagged two-sided random walk, not a parabola, so Δχ² = 1 around the
    minimum under-covers (31 % on white noise) and the minimum itself may sit on a spike off
    the likelihood's bulk; the normalised likelihood (a flat prior on the grid) covers about
    68 %, a little more (``tests/core/test_causes.py``)."""
    w = np.exp(-(chi - chi.min()) / (2.0 * scale))
    # each grid point's weight is its cell's, half either side of it: the running sum up to
    # and including a point put the whole of its weight below it, which moved every quantile
    # half a grid step early (a step time's interval narrower than the grid step then sat
    # between the best point and the one before it, off the truth)
    cdf = (np.cumsum(w) - 0.5 * w) / w.sum()
    lo, mid, hi = np.interp([0.1587, 0.5, 0.8413], cdf, x)
    return float(lo), float(mid), float(hi)


def _profile_interval(x: NDArray, chi: NDArray, rise: float) -> tuple[float, float]:
    """[lo, hi] of the connected region around the minimum of a profile χ²(x) where it stays
    within ``rise`` of the minimum (Δχ² = 1 for 68 %, one parameter), the edges interpolated
    between grid points; a grid edge where the profile never rises that far."""
    i = int(np.argmin(chi))
    lim = float(chi[i]) + rise
    lo_i = i
    while lo_i > 0 and chi[lo_i - 1] <= lim:
        lo_i -= 1
    hi_i = i
    while hi_i < len(x) - 1 and chi[hi_i + 1] <= lim:
        hi_i += 1

    def cross(a: int, b: int) -> float:  # the x between grid points a (inside), b (outside)
        f = (lim - chi[a]) / (chi[b] - chi[a]) if chi[b] != chi[a] else 0.0
        return float(x[a] + f * (x[b] - x[a]))

    lo = float(x[0]) if lo_i == 0 else cross(lo_i, lo_i - 1)
    hi = float(x[-1]) if hi_i == len(x) - 1 else cross(hi_i, hi_i + 1)
    return lo, hi


@lru_cache(maxsize=8)
def _noise_whitener(n: int, dt: float, n_white: float, b_inst: float, k_rrw: float,
                    gm_sigma: float = 0.0, gm_T: float = 0.0
                    ) -> tuple[NDArray[np.float64] | None, LowerSolver | None]:
    """(σ per block, None) for white noise alone, else (None, the Cholesky factor's solver)
    of the noise covariance (``_noise_cov``) of ``n`` block means ``dt`` s long. A pure
    function of the noise levels and the blocks: an axis's searches ask for the same noise
    more than once (its noise with nothing removed, or with the same transients out), and
    each factorisation of the covariance costs as much as the search's fits, so it is kept
    (the same numbers; the solver is read-only)."""
    t = (np.arange(n) + 0.5) * dt
    c = _noise_cov(t, dt, n_white, b_inst, k_rrw, gm_sigma, gm_T)
    diag = np.diag(c)
    # fast path: white noise alone (B = K = 0) has a diagonal covariance, whitened by
    # dividing by its σ (the Cholesky factor is that diagonal; tests hold them equal)
    if not np.any(c - np.diag(diag)):
        sd = np.sqrt(diag)
        sd.setflags(write=False)
        return sd, None
    return None, LowerSolver(np.linalg.cholesky(c))


class _Gls:
    """GLS of block means (≤ ``max_blocks``) on [1, t] plus the transients' columns, with the
    noise covariance of analyze's fitted N, B, K (and ``GM_sigma``, ``GM_T`` where the noise
    has a Gauss–Markov process: ``_noise_cov``): the data and every column
    are whitened by the covariance's Cholesky factor, so each χ² is a plain least squares.
    Ordinary least squares weighs every block alike, and the random walk's slow wander then
    pulls the warm-up's T (15 % scatter at 3× the minimum) and the step's size."""

    def __init__(self, y: NDArray, rate_hz: float, noise: dict[str, float],
                 max_blocks: int) -> None:
        b = max(1, len(y) // max_blocks)
        self.yb = block_means(y, b)
        self.dt = b / rate_hz
        self.t = (np.arange(len(self.yb)) + 0.5) * self.dt
        # LinAlgError: the caller keeps the detector's values
        self._sd, white = _noise_whitener(len(self.yb), self.dt, noise.get("N", 0.0),
                                          noise.get("B", 0.0), noise.get("K", 0.0),
                                          noise.get("GM_sigma", 0.0), noise.get("GM_T", 0.0))
        if white is not None:
            self._white = white
        self.wy = self.white(self.yb)
        self.wbase = self.white(np.column_stack([np.ones_like(self.t), self.t]))

    def white(self, cols: NDArray) -> NDArray:
        if self._sd is not None:
            return np.asarray(cols / (self._sd if cols.ndim == 1 else self._sd[:, None]))
        return self._white.solve(cols)

    def chi2(self, cols: list[NDArray]) -> tuple[float, NDArray, NDArray]:
        """(χ², coefficients, (AᵀA)⁻¹) of the whitened data on [1, t] + ``cols`` (whitened)."""
        a = np.column_stack([self.wbase, *cols])
        coef, *_ = np.linalg.lstsq(a, self.wy, rcond=None)
        r = self.wy - a @ coef
        return float(r @ r), coef, np.linalg.pinv(a.T @ a)

    def profile(self, wcols: NDArray, fixed: list[NDArray]
                ) -> tuple[NDArray, NDArray, NDArray]:
        """(χ², coefficient, its variance) with each whitened column of ``wcols`` in turn
        beside [1, t] and the ``fixed`` ones. With Q an orthonormal basis of those, r the
        data's residual and c' each column's: χ² = r·r − (c'·r)²/(c'·c'), coefficient
        c'·r/(c'·c'), variance 1/(c'·c') (Frisch–Waugh–Lovell), all at once."""
        q, _ = np.linalg.qr(np.column_stack([self.wbase, *fixed]))
        r = self.wy - q @ (q.T @ self.wy)
        c = wcols - q @ (q.T @ wcols)
        cc = np.maximum(np.einsum("ij,ij->j", c, c), 1e-300)
        cr = c.T @ r
        return float(r @ r) - cr**2 / cc, cr / cc, 1.0 / cc


def _size_interval(chi: NDArray, size: NDArray, var: NDArray, rise: float
                   ) -> tuple[float, float]:
    """68 % interval of a size that is linear given a nonlinear parameter p (T, t_s) profiled
    on a grid: at each p, χ²(size) = χ²(p) + (size − ŝ(p))²/v(p) exactly, so the size's
    profile is their lower envelope; the interval is where it stays within ``rise`` (Δχ² = 1
    times the Birge ratio) of its minimum. The linearised covariance at the best p alone
    under-covered (a warm-up's size held the truth in 60 % of model-exact draws): size and T
    are strongly correlated, and not linearly at 3× the minimum."""
    i = int(np.argmin(chi))
    se = math.sqrt(var[i] * rise)
    grid = np.linspace(size[i] - 8 * se, size[i] + 8 * se, 801)
    env = np.min(chi[:, None] + (grid[None, :] - size[:, None]) ** 2 / var[:, None], axis=0)
    return _profile_interval(grid, env, rise)


def _vertex(x: NDArray, chi: NDArray) -> float:
    """The minimum of a profile χ² on a log grid, by the parabola through the grid minimum and
    its neighbours in log x (a grid point alone is up to half a step off: 2.6 % in T, which
    moved the warm-up's size by most of its standard error)."""
    i = int(np.argmin(chi))
    if i == 0 or i == len(x) - 1:
        return float(x[i])
    a, b, c = np.log(x[i - 1:i + 2])
    fa, fb, fc = chi[i - 1:i + 2]
    den = (b - a) * (fb - fc) - (b - c) * (fb - fa)
    if den == 0:
        return float(x[i])
    v = b - 0.5 * ((b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)) / den
    return float(np.exp(np.clip(v, a, c)))


def _step_profile(g: _Gls, grid: NDArray, chi: NDArray, fixed: list[NDArray]
                  ) -> tuple[NDArray, tuple[NDArray, NDArray, NDArray]]:
    """The step time's profile χ² on a fine grid over where its likelihood on the coarse
    ``grid`` (``chi``) is not negligible: a step many block σ tall is located to a small
    fraction of a block, finer than the coarse grid's quarter block."""
    h = float(grid[1] - grid[0]) if len(grid) > 1 else g.dt / 4
    live = grid[np.exp(-(chi - chi.min()) / 2.0) > 1e-6]
    lo, hi = max(float(live.min()) - h, float(grid[0])), min(float(live.max()) + h,
                                                               float(grid[-1]))
    n = int(np.clip((hi - lo) / (g.dt / 64), 16, 512))
    fine = np.linspace(lo, hi, n)
    return fine, g.profile(g.white(_step_blocks(g.t, g.dt, fine)), fixed)


def refine_transients(y: NDArray, rate_hz: float, noise: dict[str, float],
                      warmup: Candidate | None = None, step: Candidate | None = None,
                      max_blocks: int = 1024) -> list[Candidate]:
    """The passed transients' parameters and 68 % intervals by one generalised least-squares
    fit of [1, t, e^(−t/T), H(t − t_s)] (the columns of the causes given), with the noise
    covariance of analyze's fitted N, B, K (``noise``); the tests (window contrasts) are
    unchanged. Warm-up and step are fitted together, so neither biases the other.

    T and t_s enter nonlinearly: each is profiled on a grid (T over a factor 8 either side of
    the detector's, its minimum by a parabola in log T; t_s over ± 4 % of the record a
    quarter block apart, then finer where its likelihood lives), the other one held at its
    best, two rounds. Intervals (68 %): T where the profile χ² stays within s² of its minimum
    (Δχ² = 1, one parameter); t_s, a change point whose profile is no parabola, the central
    68 % of its profile likelihood (``_weight_interval``; t_s is its median); each size from
    its own profile over T or t_s (``_size_interval``: linear given them, so exact on the
    grid). s² = max(1, χ²/dof), the Birge ratio, widens them when the noise model
    under-describes the record.
    On a covariance that will not factor, the detectors' values are returned unchanged."""
    try:
        g = _Gls(y, rate_hz, noise, max_blocks)
    except np.linalg.LinAlgError:
        return [c for c in (warmup, step) if c is not None]
    t, dt = g.t, g.dt
    record_s = len(g.yb) * dt
    T = warmup.params["time_constant_s"] if warmup is not None else 0.0
    ts = step.params["time_s"] if step is not None else 0.0
    t_grid = (np.geomspace(max(T / 8, 2 * dt), min(T * 8, record_s / 2), T_GRID)
              if warmup is not None else np.zeros(0))
    half = STEP_GRID_FRACTION * record_s
    s_grid = (np.arange(max(ts - half, 8 * dt), min(ts + half, record_s - 8 * dt), dt / 4)
              if step is not None else np.zeros(0))
    w_exp = g.white(np.exp(-t[:, None] / t_grid[None, :])) if warmup is not None else None
    w_step = g.white(_step_blocks(t, dt, s_grid)) if step is not None else None
    chi_t = chi_s = s_fine = sz_t = v_t = sz_s = v_s = np.zeros(0)
    for _round in range(2):
        if w_exp is not None:
            fixed = [] if w_step is None else [g.white(_step_blocks(t, dt, [ts])[:, 0])]
            chi_t, sz_t, v_t = g.profile(w_exp, fixed)
            T = _vertex(t_grid, chi_t)
        if w_step is not None:
            fixed = [] if w_exp is None else [g.white(np.exp(-t / T))]
            s_fine, (chi_s, sz_s, v_s) = _step_profile(g, s_grid, g.profile(w_step, fixed)[0],
                                                       fixed)
            ts = _weight_interval(s_fine, chi_s, 1.0)[1]
        if w_exp is None or w_step is None:
            break
    # the sizes at the best point; their intervals from the profiles (``_size_interval``)
    plain: list[NDArray] = []
    if warmup is not None:
        plain.append(g.white(np.exp(-t / T)))
    if step is not None:
        plain.append(g.white(_step_blocks(t, dt, [ts])[:, 0]))
    chi, coef, _ = g.chi2(plain)
    # T and t_s count as fitted parameters
    dof = max(1, len(g.yb) - 2 - 2 * len(plain))
    s2 = max(1.0, chi / dof)
    out: list[Candidate] = []
    # the test's evidence (a candidate refitted again keeps it, not the earlier refit's)
    tests = {c.cause: c.detail.get("test", c.evidence) for c in (warmup, step) if c is not None}
    both = " (warm-up and step fitted together)" if None not in (warmup, step) else ""
    note = (f"generalised least squares with the fitted noise (N, B, K){both}, "
            f"χ²/dof {chi / dof:.3g}: ")
    if warmup is not None:
        size = float(coef[2])
        lo, hi = _size_interval(chi_t, sz_t, v_t, s2)
        t_lo, t_hi = _profile_interval(t_grid, chi_t, s2)
        out.append(replace(warmup, params={"time_constant_s": T, "size": size},
                           intervals={"time_constant_s": [t_lo, t_hi], "size": [lo, hi]},
                           detail={**warmup.detail, "test": tests["warmup"]},
                           evidence=tests["warmup"] + "; " + note
                           + f"time constant {T:.4g} s [{t_lo:.4g}, {t_hi:.4g}], size "
                           f"{size:.3g} m/s² [{lo:.3g}, {hi:.3g}] (68 %)"))
    if step is not None:
        size = float(coef[-1])
        lo, hi = _size_interval(chi_s, sz_s, v_s, s2)
        s_lo, _, s_hi = _weight_interval(s_fine, chi_s, s2)
        out.append(replace(step, params={"time_s": ts, "size": size},
                           intervals={"time_s": [s_lo, s_hi], "size": [lo, hi]},
                           detail={**step.detail, "test": tests["bias_step"]},
                           evidence=tests["bias_step"] + "; " + note
                           + f"time {ts:.6g} s [{s_lo:.6g}, {s_hi:.6g}], size {size:.3g} m/s² "
                           f"[{lo:.3g}, {hi:.3g}] (68 %)"))
    return out
