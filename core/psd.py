"""The power spectral density beside the Allan variance (IEEE Std 1293 names both).

``avard analyze`` already streams every channel through a Welch accumulator
(``report.WelchAccumulator``: Hann window, 50 % overlap, mean removed per segment) to find
sinusoids. This module turns its averaged periodogram into what a user reads:

* the one-sided PSD in (m/s²)²/Hz with its chi-squared band: each bin of an average of K
  Hann segments at 50 % overlap is S·χ²(ν)/ν with ν ≈ 1.8·K (Welch 1967; the same ν the
  line finder uses);
* the white-noise density read from the spectrum's white region, compared with N from the
  Allan-variance fit: for white rate noise of coefficient N (AVAR N²/τ) the one-sided PSD is
  2N², so N_psd = √(S̄/2). The white region is where the fitted model's white part is at least
  90 % of the model spectrum (one-sided forms of ``model.term_psd``: Q 8 f_s Q² sin²(πf/f_s),
  N 2N², B B²/(π f), K 2K²/(2π f)²), away from the lines found and from the top fifth of the
  band (anti-alias and sensor filter), and below half the sensor's low-pass corner when it
  is known. Adjacent Hann bins are correlated, so the EDF of a mean
  over n bins is taken as ν·n/2 (conservative);
* the lines found (``report.find_lines``), unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from avard.core.errors import DataError
from numpy.typing import NDArray
from scipy.stats import chi2

__all__ = ["ChannelPsd", "WhiteDensity", "channel_psd", "plot_psd", "white_density"]

UNIT = "(m/s^2)^2/Hz"
WHITE_SHARE = 0.9  # the white part must be this share of the model spectrum
LINE_GUARD_BINS = 4  # bins left out on each side of a line found


@dataclass(frozen=True)
class WhiteDensity:
    """N read from the spectrum (m/s/√s = m/s²/√Hz) with its interval at ``ci``, the band it
    was read in (Hz) and the bins averaged; ``agrees`` with the fit's N when their intervals
    overlap (None without a fitted N)."""

    value: float
    lo: float
    hi: float
    f_lo_hz: float
    f_hi_hz: float
    n_bins: int
    fit_n: float | None = None
    fit_lo: float | None = None
    fit_hi: float | None = None

    @property
    def agrees(self) -> bool | None:
        if self.fit_lo is None or self.fit_hi is None:
            return None
        return self.lo <= self.fit_hi and self.fit_lo <= self.hi

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "lo": self.lo, "hi": self.hi, "unit": "m/s^2/sqrt(Hz)",
                "f_lo_hz": self.f_lo_hz, "f_hi_hz": self.f_hi_hz, "n_bins": self.n_bins,
                "fit_value": self.fit_n, "fit_lo": self.fit_lo, "fit_hi": self.fit_hi,
                "agrees": self.agrees}


@dataclass
class ChannelPsd:
    """One channel's one-sided Welch PSD: f (Hz), psd and its band lo/hi ((m/s²)²/Hz) at
    ``ci``, segments averaged, the white density (None when no white region was found) and
    the lines found."""

    f: NDArray[np.float64]
    psd: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    n_segments: int
    ci: float
    white: WhiteDensity | None = None
    lines: list[dict[str, float]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        def _l(a: NDArray) -> list[float | None]:
            return [float(v) if math.isfinite(v) else None for v in a]

        return {"unit": UNIT, "ci": self.ci, "n_segments": self.n_segments,
                "f_hz": _l(self.f), "psd": _l(self.psd), "lo": _l(self.lo), "hi": _l(self.hi),
                "white_density": None if self.white is None else self.white.to_dict(),
                "lines": [dict(ln) for ln in self.lines]}


def _nu(n_segments: int) -> float:
    return max(2.0, 1.8 * n_segments)


def channel_psd(f: NDArray, psd: NDArray, n_segments: int, *, ci: float = 0.683,
                lines: list[dict[str, float]] | None = None) -> ChannelPsd:
    """The band of a Welch PSD of one channel: S·ν/χ²_{(1±ci)/2}(ν)."""
    if n_segments < 1:
        raise DataError("the spectrum needs at least one full Welch segment; the record is "
                        "too short for --psd")
    nu = _nu(n_segments)
    lo = psd * nu / chi2.ppf(0.5 + ci / 2.0, nu)
    hi = psd * nu / chi2.ppf(0.5 - ci / 2.0, nu)
    return ChannelPsd(np.asarray(f, float), np.asarray(psd, float), lo, hi, int(n_segments),
                      ci, None, list(lines or []))


def _model_one_sided(f: NDArray, values: dict[str, float | None], rate_hz: float
                     ) -> tuple[NDArray, NDArray]:
    """(white part, total) of the fitted terms' one-sided PSD at f (Hz), (m/s²)²/Hz."""
    fs = float(rate_hz)
    white = np.full_like(f, 2.0 * (values.get("velocity_random_walk") or 0.0) ** 2)
    total = white.copy()
    q = values.get("quantization") or 0.0
    b = values.get("bias_instability") or 0.0
    k = values.get("rate_random_walk") or 0.0
    total += 2.0 * 4.0 * fs * q * q * np.sin(np.pi * f / fs) ** 2
    pos = f > 0  # the red terms diverge at 0 Hz, which no white region contains
    fp = np.where(pos, f, 1.0)
    total += np.where(pos, b * b / (np.pi * fp) + 2.0 * k * k / (2.0 * np.pi * fp) ** 2, np.inf)
    return white, total


def white_density(cp: ChannelPsd, fit: Any, rate_hz: float, *,
                  filter_corner_hz: float | None = None) -> WhiteDensity | None:
    """N from the white region of the spectrum, with its interval, compared with the fit's N
    (``fit.terms['velocity_random_walk']``). None when the fit has no N or no bin is white."""
    e = fit.terms["velocity_random_walk"]
    if not e.present or e.value is None:
        return None
    f = cp.f
    white, total = _model_one_sided(f, fit.values(), rate_hz)
    ok = (f > 0) & (white >= WHITE_SHARE * total) & (f <= 0.4 * rate_hz)
    if filter_corner_hz:
        ok &= f <= 0.5 * filter_corner_hz
    df = f[1] - f[0] if len(f) > 1 else 1.0
    for ln in cp.lines:
        ok &= np.abs(f - ln["frequency_hz"]) > LINE_GUARD_BINS * df
    n = int(ok.sum())
    if n < 4:
        return None
    mean = float(np.mean(cp.psd[ok]))
    nu = _nu(cp.n_segments) * n / 2.0  # adjacent Hann bins are correlated: half the bins
    lo = mean * nu / chi2.ppf(0.5 + cp.ci / 2.0, nu)
    hi = mean * nu / chi2.ppf(0.5 - cp.ci / 2.0, nu)
    sel = f[ok]
    return WhiteDensity(math.sqrt(mean / 2.0), math.sqrt(lo / 2.0), math.sqrt(hi / 2.0),
                        float(sel[0]), float(sel[-1]), n, e.value, e.lo, e.hi)


def plot_psd(an: Any, path: str | Path, *, dpi: int = 130) -> Path:
    """The PSD figure (per channel: log-log PSD with its band, the white density read from
    it, the lines found), written next to the ADEV figure."""
    from avard.core.plot import pyplot, save_figure

    plt = pyplot()
    names = [n for n, ch in an.channels.items() if ch.psd is not None]
    if not names:
        raise DataError("no spectrum to plot: the record is too short for a Welch segment")
    cols = min(len(names), 3)
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 5.0 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names, strict=False):
        cp = an.channels[name].psd
        keep = cp.f > 0
        ax.fill_between(cp.f[keep], cp.lo[keep], cp.hi[keep], color="#9ecae1", lw=0,
                        label=f"{cp.ci:.0%} band")
        ax.loglog(cp.f[keep], cp.psd[keep], color="#08519c", lw=0.8, label="Welch PSD")
        if cp.white is not None:
            w = cp.white
            ax.hlines(2 * w.value**2, w.f_lo_hz, w.f_hi_hz, color="#d62728",
                      label=f"white: N = {w.value:.4g} m/s²/√Hz")
        for ln in cp.lines:
            ax.axvline(ln["frequency_hz"], color="#ff7f0e", lw=0.6, ls=":")
        ax.set_xlabel("frequency f (Hz)")
        ax.set_ylabel("one-sided PSD ((m/s²)²/Hz)")
        ax.set_title(f"channel {name}")
        ax.legend(fontsize=8)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    fig.suptitle(f"{Path(an.source).name}: power spectral density (Welch, Hann, 50 % overlap)",
                 fontsize=11)
    return save_figure(fig, path, dpi=dpi)
