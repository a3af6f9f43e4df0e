"""The time-domain causes of `avard explain`: a warm-up transient and a bias step.

Both act on seconds to hours, so they are fitted on the slow view of the record (block means
of about a second, :class:`avard.core.explain.engine.SlowView`), further averaged to about 4096
blocks here. Each detector returns a :class:`Candidate`: parameters (SI units), its test
statistic against the threshold, and a sentence of evidence a reader can check by hand. The
signal it describes then enters analyze's GLS fit as one more AVAR component
(``fit_noise(extra_avar=...)``), under the same presence test as the noise terms.

- ``bias_step``: the largest difference of adjacent window means, robustly scaled by the
  spread of all such differences (their std is √(2·AVAR(w)), NIST SP 1065 eq. 6); test ≥ 6 and
  a step fits the record better than a warm-up exponential.
- ``warmup``: the same contrast at the record start for an exponential settling, with the
  time constant from a least-squares fit of [1, t, e^(−t/T)]; test ≥ 6 and it fits better than
  a step.

Temperature is :mod:`avard.core.explain.thermal_fit`; sinusoids are analyze's line finder
(``report.find_lines``); rate ramp, the chip's low-pass and the LSB rounding are terms of
analyze's model (``fit.fit_noise``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Causes explain tests beside analyze's model, and their parameters (SI units).
CAUSES = ("temperature", "warmup", "bias_step", "gauss_markov", "sinusoid")
PARAMS = {
    "temperature": ("coefficient", "lag_s"),
    "warmup": ("time_constant_s", "size"),
    "bias_step": ("time_s", "size"),
    "gauss_markov": ("sigma", "time_constant_s"),
    "sinusoid": ("frequency_hz", "amplitude"),
}
UNITS = {"coefficient": "m/s²/K", "lag_s": "s", "time_constant_s": "s", "size": "m/s²",
         "time_s": "s", "frequency_hz": "Hz", "amplitude": "m/s²", "sigma": "m/s²"}

Z_STEP = 6.0

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
    detail: dict[str, Any] = field(default_factory=dict)
    #: channel name of the temperature witness (temperature cause only)
    witness: str | None = None


@dataclass
class Finding:
    """One cause's outcome in ``avard explain``: parameters (SI) with 68 % intervals where it
    has them, its own test (statistic against threshold, evidence), and whether its AVAR
    component is present in the GLS fit beside the noise terms (``claimed`` needs both)."""

    cause: str
    claimed: bool
    params: dict[str, float]
    intervals: dict[str, list[float]]
    statistic: float
    threshold: float
    evidence: str
    present_in_fit: bool = False
    scale: list[float | None] = field(default_factory=list)
    channel: str | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"cause": self.cause, "claimed": self.claimed,
                             "params": self.params, "intervals": self.intervals,
                             "statistic": self.statistic, "threshold": self.threshold,
                             "present_in_fit": self.present_in_fit, "evidence": self.evidence}
        if self.channel is not None:
            d["channel"] = self.channel
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
    """The signal a passed transient candidate describes, on n samples at ``rate_hz``."""
    p = cand.params
    if cand.cause == "warmup":
        return warmup_signal(n, rate_hz, p["time_constant_s"], p["size"])
    if cand.cause == "bias_step":
        return step_signal(n, rate_hz, p["time_s"], p["size"])
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
    from avard.core.report import LINE_HALF_WIDTH, LINE_LOBE, line_threshold, welch_nperseg

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



def _noise_cov(t: NDArray, block_s: float, n_white: float, b_inst: float, k_rrw: float
               ) -> NDArray:
    """Covariance ((m/s²)²) of block means (length ``block_s``, centres ``t``) of white,
    flicker and random-walk rate noise: N²/block on the diagonal; flicker as noise_gen's
    ladder of Gauss–Markov processes (Σ σ_k² e^(−|Δt|/T_k)); random walk K²·min(t_i, t_j)
    (its start value is the offset column)."""
    from avard.core.sim.noise_gen import flicker_ladder

    dtt = np.abs(np.subtract.outer(t, t))
    c = np.diag(np.full(len(t), n_white**2 / block_s))
    if b_inst > 0:
        for T, s in flicker_ladder([b_inst], block_s, 10 * float(t[-1] + block_s), 2.0):
            c += float(np.asarray(s)[0]) ** 2 * np.exp(-dtt / T)
    if k_rrw > 0:
        c += k_rrw**2 * np.minimum.outer(t, t)
    return c


def refine_warmup(y: NDArray, rate_hz: float, cand: Candidate, noise: dict[str, float],
                  max_blocks: int = 1024) -> Candidate:
    """The warm-up's time constant and size by generalised least squares of [1, t, e^(−t/T)]
    with the noise covariance of analyze's fitted N, B, K (``noise``), T on a grid within a
    factor 2 of the detector's; the test (window contrast) is unchanged. Ordinary least
    squares weighs every block alike, and the random walk's slow wander then pulls T."""
    b = max(1, len(y) // max_blocks)
    yb = block_means(y, b)
    dt = b / rate_hz
    t = (np.arange(len(yb)) + 0.5) * dt
    C = _noise_cov(t, dt, noise.get("N", 0.0), noise.get("B", 0.0), noise.get("K", 0.0))
    from scipy.linalg import solve_triangular

    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        return cand
    T0 = cand.params["time_constant_s"]
    Ts = np.geomspace(T0 / 2, T0 * 2, 41)
    # whiten the data, the offset and drift, and every trial exponential in one solve
    cols = np.column_stack([yb, np.ones_like(t), t, np.exp(-t[:, None] / Ts[None, :])])
    w = solve_triangular(L, cols, lower=True)
    wy, base = w[:, 0], w[:, 1:3]
    best = (math.inf, T0, cand.params["size"])
    for i, T in enumerate(Ts):
        a = np.column_stack([base, w[:, 3 + i]])
        coef, *_ = np.linalg.lstsq(a, wy, rcond=None)
        r = wy - a @ coef
        chi = float(r @ r)
        if chi < best[0]:
            best = (chi, float(T), float(coef[2]))
    _, T, size = best
    return Candidate(cand.cause, cand.passed, {"time_constant_s": T, "size": size},
                     cand.statistic, cand.threshold,
                     cand.evidence + f"; generalised least squares with analyze's noise model: "
                     f"time constant {T:.4g} s, size {size:.3g} m/s²")
