"""The analysis figure: log-log Allan deviation per channel with its 68 % intervals, the fitted
model and each term's own line. matplotlib is the optional ``plot`` extra: imported here only
when a figure is asked for, with a clear message when it is missing."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from avard.core.errors import AvardError
from avard.core.model.fit.results import ROUNDING
from avard.core.model.terms import SYMBOLS, TERMS, UNITS

_COLOURS = {"quantization": "#9467bd", "velocity_random_walk": "#1f77b4",
            "bias_instability": "#2ca02c", "rate_random_walk": "#d62728",
            "rate_ramp": "#8c564b"}


def pyplot() -> Any:
    """matplotlib.pyplot on the file-only Agg backend (no display on a Pi or in CI); an
    ``AvardError`` saying how to install the ``plot`` extra when matplotlib is missing."""
    try:
        import matplotlib
    except ImportError as exc:
        raise AvardError("plotting needs matplotlib: pip install 'avard[plot]'") from exc
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _label(term: str, e: Any) -> str:
    # enough significant digits that the interval's ends differ from the value
    width = max(e.hi - e.lo, 1e-300)
    digits = max(3, min(8, math.ceil(-math.log10(width / e.value)) + 2)) if e.value else 3
    f = f"{{:.{digits}g}}"
    return (f"{SYMBOLS[term]} = {f.format(e.value)} [{f.format(e.lo)}, {f.format(e.hi)}] "
            f"{UNITS[term].replace('^2', '²').replace('^3', '³').replace('sqrt(s)', '√s')}")


def plot_analysis(an: Any, path: str | Path, *, dpi: int = 130) -> Path:
    """Write the figure for an ``report.Analysis`` to ``path`` (png/pdf/svg by suffix)."""
    plt = pyplot()
    names = list(an.channels)
    n = len(names)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 6.2 * rows), squeeze=False,
                             sharey=False)
    for ax, name in zip(axes.ravel(), names, strict=False):
        _panel(ax, an.channels[name])
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    fig.suptitle(f"{Path(an.source).name}: Allan deviation, {an.n_samples} samples at "
                 f"{an.rate_hz:g} Hz (68 % intervals)", fontsize=11)
    return save_figure(fig, path, dpi=dpi)


def save_figure(fig: Any, path: str | Path, *, dpi: int) -> Path:
    """Lay out, write (format by suffix) and close ``fig``; a path that cannot be written is
    an ``AvardError`` naming it."""
    fig.tight_layout()
    out = Path(path)
    try:
        fig.savefig(out, dpi=dpi)
    except (OSError, ValueError) as exc:
        raise AvardError(f"cannot write the plot to {out}: {exc}") from exc
    finally:
        pyplot().close(fig)
    return out


def _panel(ax: Any, ch: Any) -> None:
    from avard.core.analysis.results import ESTIMATOR_LABELS

    a, fit = ch.allan, ch.fit
    measured = f"measured {ESTIMATOR_LABELS.get(ch.estimator, ch.estimator)}"
    ok = np.isfinite(a.dev) & (a.dev > 0)
    tau, dev = a.tau[ok], a.dev[ok]
    lo = np.where(np.isfinite(a.dev_lo[ok]), a.dev_lo[ok], dev)
    hi = np.where(np.isfinite(a.dev_hi[ok]), a.dev_hi[ok], dev)
    used = (tau >= fit.tau_min_s * (1 - 1e-9)) & (tau <= fit.tau_max_s * (1 + 1e-9))
    ax.errorbar(tau[used], dev[used], yerr=[dev[used] - lo[used], hi[used] - dev[used]],
                fmt="o", ms=4, color="k", capsize=2, lw=1, label=f"{measured} (fitted)",
                zorder=5)
    if (~used).any():
        ax.errorbar(tau[~used], dev[~used], yerr=[dev[~used] - lo[~used], hi[~used] - dev[~used]],
                    fmt="o", ms=4, mfc="white", color="0.5", capsize=2, lw=1,
                    label=f"{measured} (not fitted)", zorder=4)
    # whole numbers of samples: the filtered-white curve is defined at integer m only
    rate = fit.rate_hz
    t = np.unique(np.rint(np.geomspace(tau.min(), tau.max(), 400) * rate)) / rate
    ax.loglog(t, np.sqrt(fit.model_avar(t)), color="#ff7f0e", lw=2, label="fitted model",
              zorder=3)
    parts = fit.component_avars(t)
    if ROUNDING in parts and "velocity_random_walk" in parts:
        # N is reported as the output's white level: the filtered part plus the rounding
        parts["velocity_random_walk"] = parts["velocity_random_walk"] + parts.pop(ROUNDING)
    for term in TERMS:
        e = fit.terms[term]
        if e.present and term in parts:
            ax.loglog(t, np.sqrt(parts[term]), "--", lw=1.2, color=_COLOURS[term],
                      label=_label(term, e))
    other = {lab: v for lab, v in parts.items() if lab not in TERMS and lab != ROUNDING}
    if other:
        # the extra components (sinusoids, Gauss–Markov) as one line: their sum
        freqs = [f"{float(lab.split()[1]):.3g}" for lab in other if lab.startswith("sinusoid")]
        lab = (f"sinusoids at {', '.join(freqs[:3])}{' …' if len(freqs) > 3 else ''} Hz"
               if len(freqs) == len(other) else "extra components")
        ax.loglog(t, np.sqrt(sum(other.values())), ":", lw=1.2, color="0.35", label=lab)
    ax.axvspan(fit.tau_min_s, fit.tau_max_s, color="#ff7f0e", alpha=0.06, lw=0,
               label=f"fitted τ range ({fit.tau_min_s:.3g}–{fit.tau_max_s:.3g} s)")
    ymin = max(dev.min() / 3, np.nanmin(lo) / 1.5)
    ax.set_ylim(ymin, hi.max() * 2)
    ax.set_xlim(tau.min() / 1.5, tau.max() * 1.5)
    absent = [SYMBOLS[t] for t in TERMS if not fit.terms[t].present]
    chi = f"{fit.chi2_dof:.2f}" if math.isfinite(fit.chi2_dof) else "n/a"
    ax.set_title(f"channel {ch.name}: χ²/dof = {chi}"
                 + (f"; absent: {', '.join(absent)}" if absent else ""), fontsize=10)
    ax.set_xlabel("averaging time τ (s)")
    ax.set_ylabel("Allan deviation σ(τ) (m/s²)")
    ax.grid(True, which="major", alpha=0.35)
    ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2,
              frameon=False)


def plot_population(analyses: Any, pop: Any, path: str | Path, *, dpi: int = 130) -> Path:
    """``avard fleet --plot``: per axis every sensor's ADEV (outliers in colour and named),
    the population's median and its 16–84 % band across the sensors at each τ (the sensors'
    curves interpolated log-log onto the first one's τ)."""
    plt = pyplot()
    names = list(next(iter(analyses.values())).channels)
    flagged = {(o.sensor, o.channel) for o in pop.outliers}
    cols = min(len(names), 3)
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 5.2 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names, strict=False):
        ref_tau = None
        curves = []
        for sensor, an in analyses.items():
            ch = an.channels.get(name)
            if ch is None:
                continue
            tau, dev = np.asarray(ch.allan.tau), np.asarray(ch.allan.dev)
            out = (sensor, name) in flagged
            ax.loglog(tau, dev, color="#d62728" if out else "0.6", lw=1.4 if out else 0.8,
                      label=f"{sensor} (outlier)" if out else None)
            if ref_tau is None:
                ref_tau = tau
            ok = (ref_tau >= tau[0]) & (ref_tau <= tau[-1])
            curve = np.full(len(ref_tau), np.nan)
            curve[ok] = np.exp(np.interp(np.log(ref_tau[ok]), np.log(tau), np.log(dev)))
            curves.append(curve)
        if ref_tau is not None and curves:
            stack = np.array(curves)
            with np.errstate(all="ignore"):
                med = np.nanmedian(stack, axis=0)
                lo, hi = np.nanpercentile(stack, [16, 84], axis=0)
            ax.fill_between(ref_tau, lo, hi, color="#1f77b4", alpha=0.2,
                            label="16–84 % of the sensors")
            ax.loglog(ref_tau, med, color="#1f77b4", lw=2, label="median")
        ax.set_xlabel("τ (s)")
        ax.set_ylabel("Allan deviation (m/s²)")
        ax.set_title(f"axis {name}: {len(analyses)} sensors")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    fig.suptitle("fleet: Allan deviation of the population (SI units)", fontsize=11)
    return save_figure(fig, path, dpi=dpi)
