"""The power spectral density beside the Allan variance (IEEE Std 1293 names both).

``avard analyze`` already streams every channel through a Welch accumulator
(``spectrum.WelchAccumulator``: Hann window, 50 % overlap, mean removed per segment) to find
sinusoids. This module turns its averaged periodogram into what a user reads:

* the one-sided PSD in (m/s²)²/Hz with its chi-squared band: each bin of an average of K
  Hann segments at 50 % overlap is S·χ²(ν)/ν with ν ≈ 1.8·K (Welch 1967; the same ν the
  line finder uses);
* the white-noise density read from the spectrum's white region, compared with N from the
  Allan-variance fit: for white rate noise of coefficient N (AVAR N²/τ) the one-sided PSD is
  2N² (times the sensor filter's |G|² when modelled). The white region is where the fitted
  N component is at least ``WHITE_SHARE`` of the fitted model spectrum (the one-sided forms
  of the fit's own component spectra, ``Component.psd``: Q 8 f_s Q² sin²(πf/f_s), N 2N²|G|²,
  B B²/(π f)·|G|², K 2K²/(2π f)², Gauss–Markov, the LSB rounding), away from the lines found,
  below 0.4 f_s and half the sensor's low-pass corner when it is known. The other components'
  fitted spectrum is subtracted there, not ignored (``white_density``): a plain mean of the
  region read N 2.6 % high on a B/N ≈ 1.9 √Hz record whose interval was 0.6 % wide;
* the lines found (``spectrum.find_lines``), unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core.errors import DataError
from numpy.typing import NDArray
from scipy.stats import chi2, norm

if TYPE_CHECKING:
    from avard.core.model.fit import NoiseFit

__all__ = ["ChannelPsd", "WhiteDensity", "channel_psd", "plot_psd", "psd_panel",
           "white_density"]

UNIT = "(m/s^2)^2/Hz"
# the N component must be this share of the fitted spectrum: the rest is subtracted, and a
# band where it dominated would lean on the model's shape more than on the data
WHITE_SHARE = 0.8
LINE_GUARD_BINS = 4  # bins left out on each side of a line found


@dataclass(frozen=True)
class WhiteDensity:
    """N read from the spectrum (m/s/√s = m/s²/√Hz) with its interval at ``ci``, the band it
    was read in (Hz) and the bins averaged; ``agrees`` with the fit's N when their intervals
    overlap (None without a fitted N). ``others_share``: the part of the band's weighted power
    the fit attributes to the other components, subtracted before N is read."""

    value: float
    lo: float
    hi: float
    f_lo_hz: float
    f_hi_hz: float
    n_bins: int
    fit_n: float | None = None
    fit_lo: float | None = None
    fit_hi: float | None = None
    others_share: float | None = None

    @property
    def agrees(self) -> bool | None:
        if self.fit_lo is None or self.fit_hi is None:
            return None
        return self.lo <= self.fit_hi and self.fit_lo <= self.hi

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "lo": self.lo, "hi": self.hi, "unit": "m/s^2/sqrt(Hz)",
                "f_lo_hz": self.f_lo_hz, "f_hi_hz": self.f_hi_hz, "n_bins": self.n_bins,
                "fit_value": self.fit_n, "fit_lo": self.fit_lo, "fit_hi": self.fit_hi,
                "others_share": self.others_share, "agrees": self.agrees}


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


def _band_nu_per_bin(n_segments: int) -> float:
    """EDF per bin of a sum over many adjacent bins of a Welch PSD (Hann, 50 % overlap, K
    segments of L samples). Over a wide band the summed periodogram of a segment is Σ w²x²
    (Parseval), so for white noise ν = (K Σw²)² / (K Σw⁴ + 2(K−1) Σ wₙ²wₙ₊L/₂²); with the Hann
    sums 3L/8, 35L/128 and 3L/128 that is 18K²L/(41K − 6) over L/2 bins. Per bin 0.88 K:
    adjacent bins share about half their information (a single bin has ν ≈ 1.8 K)."""
    k = max(1, int(n_segments))
    return 36.0 * k * k / (41.0 * k - 6.0)


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


def _one_sided_unit_spectra(f: NDArray, fit: NoiseFit) -> NDArray[np.float64]:
    """Each fitted component's one-sided PSD per unit θ at f > 0 (Hz), (m/s²)²/Hz per θ:
    rows follow ``fit.components``; deterministic components (sinusoids, ramp) are zero.
    From the two-sided discrete form of ``Component.psd`` (cycles/sample): S₁(f) = 2 S(f/fs)/fs."""
    fs = float(fit.rate_hz)
    out = np.zeros((len(fit.components), len(f)))
    for k, comp in enumerate(fit.components):
        fn = comp.psd(fs)
        if fn is not None:
            out[k] = 2.0 * fn(f / fs) / fs
    return out


def white_density(cp: ChannelPsd, fit: NoiseFit, rate_hz: float, *,
                  filter_corner_hz: float | None = None) -> WhiteDensity | None:
    """N from the spectrum's white region, with its interval, compared with the fit's N
    (``fit.terms['velocity_random_walk']``). None when the fit has no N or no bin is white.

    The other fitted components (flicker, quantization, rate random walk, Gauss–Markov, the
    fixed LSB rounding) still add power inside any band: with B/N ≈ 1.9 √Hz flicker adds 11 %
    to the white level at 5 Hz and 4 % at 16 Hz (a plain mean read N 2.6 % high), and the chip's
    low-pass (ODR/4) takes 3 % off it at half its corner. So θ_N = N² is read as a
    one-parameter weighted least-squares fit of the bins,

        θ̂_N = Σ aᵢ (Sᵢ − Oᵢ) / Σ aᵢ uᵢ,   aᵢ = uᵢ / Mᵢ²,

    with uᵢ the N component's unit spectrum (filter included), Oᵢ the other components'
    fitted spectrum and Mᵢ the fitted total (var Sᵢ ∝ Mᵢ²). Its interval joins in quadrature
    the Welch scatter of T = Σ aᵢSᵢ (Satterthwaite ν_T = ν_b(Σ aᵢMᵢ)²/Σ(aᵢMᵢ)², ν_b the
    EDF per bin of a band sum, ``_band_nu_per_bin``) and the uncertainty of the subtraction
    Σ aᵢOᵢ from the fit's covariance of the other θ. Terms the fit found absent are not
    subtracted. Like the fit's, the N reported includes the fixed rounding noise.
    """
    e = fit.terms["velocity_random_walk"]
    if not e.present or e.value is None:
        return None
    labels = [c.label for c in fit.components]
    if "velocity_random_walk" not in labels:
        return None
    j = labels.index("velocity_random_walk")
    f = cp.f
    pos = f > 0
    unit = np.zeros((len(labels), len(f)))
    unit[:, pos] = _one_sided_unit_spectra(f[pos], fit)
    theta = np.asarray(fit.theta, float)
    parts = theta[:, None] * unit
    total = parts.sum(axis=0)
    ok = pos & (parts[j] >= WHITE_SHARE * total) & (f <= 0.4 * rate_hz)
    if filter_corner_hz:
        ok &= f <= 0.5 * filter_corner_hz
    df = f[1] - f[0] if len(f) > 1 else 1.0
    for ln in cp.lines:
        ok &= np.abs(f - ln["frequency_hz"]) > LINE_GUARD_BINS * df
    n = int(ok.sum())
    if n < 4:
        return None
    u, m, s = unit[j, ok], total[ok], cp.psd[ok]
    a = u / (m * m)
    # sums of products as element-wise work (no BLAS thread pool for a few thousand bins)
    g = np.sum(unit[:, ok] * a, axis=1)  # Σ aᵢ u_k,ᵢ per component k
    g[j] = 0.0  # the other components only
    d = float(np.sum(a * u))
    t = float(np.sum(a * s))
    o = float(np.sum(theta * g))
    # Welch scatter: Satterthwaite's EDF of the weighted sum of correlated bins
    nu_bin = _band_nu_per_bin(cp.n_segments)
    nu_t = nu_bin * float(np.sum(a * m)) ** 2 / float(np.sum((a * m) ** 2))
    t_lo = t * nu_t / chi2.ppf(0.5 + cp.ci / 2.0, nu_t)
    t_hi = t * nu_t / chi2.ppf(0.5 - cp.ci / 2.0, nu_t)
    cov = np.asarray(fit.theta_cov, float)
    sub = 0.0
    if cov.shape == (len(labels), len(labels)):
        var_o = float(np.einsum("k,kl,l->", g, cov, g))
        sub = float(norm.ppf(0.5 + cp.ci / 2.0)) * math.sqrt(max(var_o, 0.0))
    fixed_white = sum(theta[k] for k, c in enumerate(fit.components)
                      if c.cause == "white" and c.fixed_value is not None)
    est = (t - o) / d
    lo = (t - o - math.hypot(t - t_lo, sub)) / d
    hi = (t - o + math.hypot(t_hi - t, sub)) / d

    def _n(theta_n: float) -> float:
        return math.sqrt(max(theta_n, 0.0) + fixed_white)

    sel = f[ok]
    return WhiteDensity(_n(est), _n(lo), _n(hi), float(sel[0]), float(sel[-1]), n,
                        e.value, e.lo, e.hi, o / (t if t > 0 else 1.0))


def plot_psd(an: Any, path: str | Path, *, dpi: int = 130) -> Path:
    """The PSD figure (per channel: log-log PSD with its band, the spectrum of the AVAR fit's
    model, the white level read from it, the lines found), written next to the ADEV
    figure."""
    from avard.core.plot import pyplot, save_figure

    plt = pyplot()
    names = [n for n, ch in an.channels.items() if ch.psd is not None]
    if not names:
        raise DataError("no spectrum to plot: the record is too short for a Welch segment")
    cols = min(len(names), 3)
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 5.0 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names, strict=False):
        psd_panel(ax, an.channels[name])
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    fig.suptitle(f"{Path(an.source).name}: power spectral density (Welch, Hann, 50 % overlap)",
                 fontsize=11)
    return save_figure(fig, path, dpi=dpi)


def psd_panel(ax: Any, ch: Any) -> None:
    """One channel's panel of :func:`plot_psd` (``ch``: a ``results.ChannelAnalysis``)."""
    cp = ch.psd
    keep = cp.f > 0
    f = cp.f[keep]
    ax.fill_between(f, cp.lo[keep], cp.hi[keep], color="#9ecae1", lw=0,
                    label=f"{cp.ci:.0%} band")
    ax.loglog(f, cp.psd[keep], color="#08519c", lw=0.8, label="Welch PSD")
    fit = ch.fit
    if len(fit.components):
        # what the white density's reading subtracts: the model of the Allan fit, as spectrum
        model = np.einsum("k,kf->f", np.asarray(fit.theta, float), _one_sided_unit_spectra(f, fit))
        ax.loglog(f, model, color="k", lw=1.0, ls="--", label="spectrum of the AVAR fit")
    if cp.white is not None:
        w = cp.white
        ax.hlines(2 * w.value**2, w.f_lo_hz, w.f_hi_hz, color="#d62728",
                  label=f"white read here: N = {w.value:.4g} m/s²/√Hz")
    for ln in cp.lines:
        ax.axvline(ln["frequency_hz"], color="#ff7f0e", lw=0.6, ls=":")
    ax.set_xlabel("frequency f (Hz)")
    ax.set_ylabel("one-sided PSD ((m/s²)²/Hz)")
    ax.set_title(f"channel {ch.name}")
    ax.legend(fontsize=8)
