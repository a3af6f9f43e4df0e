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
from avard.core.errors import DataError
from numpy.typing import ArrayLike, NDArray

__all__ = ["DynamicAllan", "dynamic_adev"]

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
