"""Dynamic Allan deviation: the overlapping ADEV in a sliding window (Stable32's DAVAR).

A window of W samples moves by a step of S samples; in each, the fully overlapping ADEV (NIST
SP 1065 eq. 12, ``deviations.allan_variance``: its EDF, α and bounds) at octave τ up to W/4,
as Stable32's dynamic ADEV limits it. The result is a τ × time map: a stationary record
shows the same curve in every window, a change of noise level shows as a band.

Whether the windows agree is a stated test, not a look at the colours: at each τ, Bartlett's
test of equal variances over the *non-overlapping* windows (every ⌈W/S⌉-th, so the estimates
are independent to a good approximation), each with its own EDF ν_w:

    M = (Σ ν_w) ln v̄ − Σ ν_w ln v_w,  v̄ = Σ ν_w v_w / Σ ν_w,
    C = 1 + (Σ 1/ν_w − 1/Σ ν_w) / (3 (K − 1)),

M/C is χ² with K − 1 degrees of freedom when the K windows share one variance; its tail
probability is the p-value printed per τ (``p_value``). ``max_ratio`` (with its interval) is
the largest window ADEV over the smallest, to read the size of a change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from avard.core.allan.chi2 import chi2_sf
from avard.core.allan.deviations import allan_variance, validate_input
from avard.core.allan.edf import chi2_interval, edf_greenhall
from avard.core.errors import DataError
from numpy.typing import ArrayLike, NDArray

__all__ = ["DynamicAllan", "TemperatureAllan", "dynamic_adev", "temperature_binned_adev"]

# a τ changes between windows when Bartlett's p-value is below this
CHANGE_LEVEL = 0.01


@dataclass(frozen=True)
class DynamicAllan:
    """The windowed OADEV of one channel. Shapes: T windows, K τ.

    ``t_s`` (T,) each window's centre (s from the record's start); ``tau`` (K,) s; ``dev``,
    ``lo``, ``hi`` (T, K) the ADEV and its 68.3 % bounds (input unit); ``edf``, ``alpha`` (T, K);
    ``p_value`` (K,) Bartlett's test over the non-overlapping windows (NaN with fewer than 2);
    ``independent`` the number of those windows."""

    rate_hz: float
    window_s: float
    step_s: float
    t_s: NDArray[np.float64]
    tau: NDArray[np.float64]
    dev: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    edf: NDArray[np.float64]
    alpha: NDArray[np.float64]
    p_value: NDArray[np.float64]
    independent: int

    @property
    def changes(self) -> NDArray[np.bool_]:
        """(K,) True where the windows disagree (p < ``CHANGE_LEVEL``)."""
        return np.asarray(self.p_value < CHANGE_LEVEL)

    def to_dict(self) -> dict:
        out: dict = {"rate_hz": self.rate_hz, "window_s": self.window_s, "step_s": self.step_s,
                     "independent_windows": self.independent, "change_level": CHANGE_LEVEL}
        for key in ("t_s", "tau", "dev", "lo", "hi", "edf", "alpha", "p_value"):
            out[key] = np.asarray(getattr(self, key)).tolist()
        out["changes"] = self.changes.tolist()
        return out


def bartlett(var: NDArray[np.float64], edf: NDArray[np.float64]) -> float:
    """Bartlett's p-value that the variances ``var`` (with EDF ``edf``) are equal."""
    ok = np.isfinite(var) & np.isfinite(edf) & (var > 0) & (edf > 0)
    v, nu = var[ok], edf[ok]
    k = v.size
    if k < 2:
        return math.nan
    total = float(nu.sum())
    pooled = float(np.dot(nu, v)) / total
    m = total * math.log(pooled) - float(np.dot(nu, np.log(v)))
    c = 1.0 + (float(np.sum(1.0 / nu)) - 1.0 / total) / (3.0 * (k - 1))
    return float(chi2_sf(max(m / c, 0.0), k - 1))


def dynamic_adev(y: ArrayLike, rate_hz: float, window_s: float, step_s: float | None = None,
                 ) -> DynamicAllan:
    """The sliding-window OADEV of one channel of rate samples (module docstring).
    ``step_s`` defaults to a quarter of the window."""
    a, _is_int, one_d = validate_input(y, rate_hz)
    if not one_d and a.shape[1] != 1:
        raise DataError("dynamic_adev takes one channel; call it per channel")
    a = a[:, 0].astype(np.float64)
    rate = float(rate_hz)
    if not (math.isfinite(window_s) and window_s > 0):
        raise DataError(f"window {window_s} s must be a positive duration")
    win = round(window_s * rate)
    step = round((step_s if step_s is not None else window_s / 4) * rate)
    if step < 1:
        raise DataError(f"step {step_s} s is shorter than one sample (τ0 = {1 / rate:g} s)")
    if win < 8:
        raise DataError(f"window {window_s} s holds {win} samples; at least 8 are needed "
                        "(τ up to a quarter of the window)")
    if win > a.size:
        raise DataError(f"window {window_s} s is longer than the record "
                        f"({a.size / rate:g} s); use a shorter --window")
    ms = 2 ** np.arange(int(math.log2(win // 4)) + 1)
    starts = np.arange(0, a.size - win + 1, step)
    shape = (starts.size, ms.size)
    var, lo, hi = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    edf, alpha = np.full(shape, np.nan), np.full(shape, np.nan)
    for w, s0 in enumerate(starts.tolist()):
        r = allan_variance(a[s0:s0 + win], rate, ms / rate, kind="oavar")
        var[w], lo[w], hi[w], edf[w], alpha[w] = r.var, r.lo, r.hi, r.edf, r.alpha
    every = max(1, -(-win // step))
    indep = np.arange(0, starts.size, every)
    p = np.array([bartlett(var[indep, k], edf[indep, k]) for k in range(ms.size)])
    return DynamicAllan(rate_hz=rate, window_s=win / rate, step_s=step / rate,
                        t_s=(starts + win / 2) / rate, tau=ms / rate, dev=np.sqrt(var),
                        lo=np.sqrt(lo), hi=np.sqrt(hi), edf=edf, alpha=alpha, p_value=p,
                        independent=int(indep.size))


@dataclass(frozen=True)
class TemperatureAllan:
    """ADEV of one channel with its Allan differences grouped by temperature. Shapes: B bins,
    K τ. ``edges`` (B + 1,) °C; ``dev``, ``lo``, ``hi`` (B, K) ADEV and 68.3 % bounds (input
    unit; NaN where a bin holds fewer than ``MIN_DIFFERENCES``); ``count`` (B, K) the
    non-overlapping differences in each bin; ``p_value`` (K,) Bartlett's test that the bins
    share one variance (NaN with fewer than 2 usable bins)."""

    rate_hz: float
    edges: NDArray[np.float64]
    tau: NDArray[np.float64]
    dev: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    count: NDArray[np.int64]
    p_value: NDArray[np.float64]

    @property
    def changes(self) -> NDArray[np.bool_]:
        """(K,) True where the temperature bins disagree (p < ``CHANGE_LEVEL``)."""
        return np.asarray(self.p_value < CHANGE_LEVEL)

    def to_dict(self) -> dict:
        out: dict = {"rate_hz": self.rate_hz, "change_level": CHANGE_LEVEL, "unit_edges": "°C"}
        for key in ("edges", "tau", "dev", "lo", "hi", "count", "p_value"):
            out[key] = np.asarray(getattr(self, key)).tolist()
        out["changes"] = self.changes.tolist()
        return out


# a bin's variance from fewer differences than this is not printed
MIN_DIFFERENCES = 4


def temperature_binned_adev(y: ArrayLike, temperature_c: ArrayLike, rate_hz: float,
                            bins: int = 4, max_tau_fraction: float = 0.125,
                            ) -> TemperatureAllan:
    """ADEV by temperature: at each octave τ, the *non-overlapping* Allan differences
    d_i = ȳ_{i+1} − ȳ_i of m-averages (NIST SP 1065 eq. 10), each tagged with the mean
    temperature over the 2m samples it spans, grouped into ``bins`` bins of equal count
    (quantiles of the record's temperature, so every bin is populated); AVAR of a bin =
    Σd²/(2n). Non-overlapping differences of white FM are independent, so a bin of n of them
    has EDF n; the redder types' differences are positively correlated and hold fewer, so
    the EDF is taken as the smaller of n and Greenhall–Riley's for random-walk FM at that n
    (``edf.edf_greenhall``, α = −2, stride m): never more than the data support. Bartlett's
    test (``bartlett``) says whether the bins share one variance at each τ. τ stop at
    ``max_tau_fraction`` of the record (8 averages), so every bin holds differences.

    ``temperature_c``: one temperature per sample (°C; interpolate the logged DS18B20 reads
    onto the samples first); NaN where there is no reading, and a difference whose span holds
    one is left out of every bin (``count`` says how many each bin holds)."""
    a, _is_int, one_d = validate_input(y, rate_hz)
    if not one_d and a.shape[1] != 1:
        raise DataError("temperature_binned_adev takes one channel; call it per channel")
    a = a[:, 0].astype(np.float64)
    t = np.asarray(temperature_c, dtype=np.float64)
    if t.shape != a.shape:
        raise DataError(f"temperature has {t.shape} values for {a.shape} samples; give one "
                        "temperature per sample (interpolate the logged reads)")
    finite = np.isfinite(t)
    if not np.any(finite):
        raise DataError("the temperature holds no reading (all NaN); nothing to bin by")
    if int(bins) < 2:
        raise DataError(f"bins={bins}: at least 2 temperature bins are needed")
    rate = float(rate_hz)
    edges = np.quantile(t[finite], np.linspace(0.0, 1.0, int(bins) + 1))
    if np.any(np.diff(edges) <= 0):
        raise DataError("the temperature does not vary enough for "
                        f"{bins} bins of equal count; use fewer bins")
    m_max = int(a.size * max_tau_fraction)
    if m_max < 1:
        raise DataError(f"{a.size} samples are too few for a temperature-binned ADEV")
    ms = 2 ** np.arange(int(math.log2(m_max)) + 1)
    cy = np.concatenate([[0.0], np.cumsum(a - a.mean())])
    ct = np.concatenate([[0.0], np.cumsum(np.where(finite, t, 0.0))])
    cf = np.concatenate([[0], np.cumsum(finite)])
    shape = (int(bins), ms.size)
    var = np.full(shape, np.nan)
    lo, hi = np.full(shape, np.nan), np.full(shape, np.nan)
    count = np.zeros(shape, dtype=np.int64)
    edf = np.full(shape, np.nan)
    for k, m in enumerate(ms.tolist()):
        n_avg = a.size // m
        avg = (cy[m:n_avg * m + 1:m] - cy[0:n_avg * m:m]) / m
        d = np.diff(avg)
        starts = np.arange(d.size) * m
        temp = (ct[starts + 2 * m] - ct[starts]) / (2 * m)
        which = np.clip(np.searchsorted(edges, temp, side="right") - 1, 0, int(bins) - 1)
        # a difference whose span lacks a reading is in no bin
        which[(cf[starts + 2 * m] - cf[starts]) < 2 * m] = -1
        for b in range(int(bins)):
            sel = d[which == b]
            count[b, k] = sel.size
            if sel.size < MIN_DIFFERENCES:
                continue
            v = float(sel @ sel) / (2.0 * sel.size)
            nu = min(float(sel.size),
                     edf_greenhall(-2, 2, m, m, (sel.size + 1) * m + 1))
            var[b, k], edf[b, k] = v, nu
            bounds = chi2_interval(np.array([v]), np.array([nu]), 0.683)
            lo[b, k], hi[b, k] = float(bounds[0][0]), float(bounds[1][0])
    p = np.array([bartlett(var[:, k], edf[:, k]) for k in range(ms.size)])
    return TemperatureAllan(rate_hz=rate, edges=edges, tau=ms / rate, dev=np.sqrt(var),
                            lo=np.sqrt(lo), hi=np.sqrt(hi), count=count, p_value=p)
