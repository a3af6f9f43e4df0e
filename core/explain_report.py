"""Terminal summary and Markdown report (with PNG plots) of an `avard explain` result.

The report shows, per channel: the measured Allan deviation with its 68.3 % χ² interval and the
band the base model says it should fall in (NIST SP 1065 eq. 40 with the estimator's EDF), the
base and extended models, the misfit ranges in sigmas, and for every cause the test that was
run, its statistic against its threshold and the evidence sentence. matplotlib is imported
only when plots are written (it is the optional ``plot`` extra).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .explain import ChannelExplanation, Explanation, band
from .model import SYMBOLS, TERMS
from .plot import pyplot, save_figure


def _fmt_term(t: dict) -> str:
    if t["value"] is None:
        return "–"
    lo = t["lo"] if t["lo"] is not None else 0.0
    return f"{t['value']:.4g} [{lo:.3g}, {t['hi']:.3g}] {t['unit']}"


def _fmt_gain(g: float | None) -> str:
    if g is None:
        return "n/a"
    return f"{g:.3g}"


def term_changes(ch: ChannelExplanation) -> list[tuple[str, str, str]]:
    """(term, base, extended) per IEEE coefficient, formatted with units and intervals."""
    b, e = ch.base.terms(), ch.extended.terms()
    return [(name, _fmt_term(b[name]), _fmt_term(e[name])) for name in TERMS]


def summary(ex: Explanation) -> str:
    """Plain-text summary for the terminal (SI units)."""
    lines = [f"avard explain: {ex.source or 'data'} at {ex.rate_hz:g} Hz"
             + (f", held out: {ex.holdout_source}" if ex.holdout_source else
                ", held out: second half of the record")]
    for name, ch in ex.channels.items():
        lines.append("")
        lines.append(f"channel {name}: base model chi2/dof {ch.base.chi2_dof:.3g}, extended "
                     f"{ch.extended.chi2_dof:.3g}; gain {_fmt_gain(ch.gain)} on the fitted data, "
                     f"{_fmt_gain(ch.holdout_gain)} held out")
        if ch.misfit:
            for r in ch.misfit:
                lines.append(f"  misfit {r['direction']} the base model at tau "
                             f"{r['tau_range_s'][0]:.3g}..{r['tau_range_s'][1]:.3g} s, "
                             f"up to {r['max_sigma']:+.3g} sigma")
        else:
            lines.append("  the base model fits within 3 sigma at every tau")
        if not ch.findings:
            lines.append("  findings: none (no cause passed its test)")
        for f in ch.findings:
            params = ", ".join(f"{k} {v:.4g}" for k, v in f["params"].items())
            lines.append(f"  FOUND {f['cause']}: {params} (SI units), tau "
                         f"{f['tau_range_s'][0]:.3g}..{f['tau_range_s'][1]:.3g} s")
            lines.append(f"        {f['evidence']}")
        for d in ch.dropped:
            lines.append(f"  rejected on held-out data: {d}")
        lines.append("  IEEE coefficients (base -> extended, 68.3 % interval):")
        for term, b, e in term_changes(ch):
            lines.append(f"    {SYMBOLS[term]} {term:21s} {b}  ->  {e}")
    return "\n".join(lines)


def _plot_channel(ch: ChannelExplanation, path: Path) -> None:
    plt = pyplot()
    m = ch.measured
    lo_b, hi_b = band(m, ch.base_model)
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    ax.fill_between(m.tau, np.sqrt(lo_b), np.sqrt(hi_b), color="0.85",
                    label="base model band (68.3 %)")
    ax.errorbar(m.tau, np.sqrt(m.var), yerr=[np.sqrt(m.var) - np.sqrt(m.lo),
                                             np.sqrt(m.hi) - np.sqrt(m.var)],
                fmt="o", ms=3, color="k", label="measured ADEV")
    ax.loglog(m.tau, np.sqrt(ch.base_model), "-", color="C0", label="base model (5 IEEE terms)")
    if ch.findings:
        ax.loglog(m.tau, np.sqrt(ch.extended_model), "--", color="C3",
                  label="extended model (" + ", ".join(f["cause"] for f in ch.findings) + ")")
    for r in ch.misfit:
        ax.axvspan(r["tau_range_s"][0] / 1.2, r["tau_range_s"][1] * 1.2, color="C1", alpha=0.12)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time tau (s)")
    ax.set_ylabel("Allan deviation (m/s^2)")
    ax.set_title(f"channel {ch.name}: measurement, base and extended model")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def _plot_residuals(ch: ChannelExplanation, path: Path) -> None:
    plt = pyplot()
    m = ch.measured
    s = np.sqrt(2.0 / m.edf)
    zb = (m.var - ch.base_model) / (ch.base_model * s)
    ze = (m.var - ch.extended_model) / (ch.extended_model * s)
    fig, ax = plt.subplots(figsize=(7.5, 3.2))
    ax.semilogx(m.tau, zb, "o-", ms=3, label="base")
    ax.semilogx(m.tau, ze, "s--", ms=3, label="extended")
    ax.axhspan(-3, 3, color="0.9")
    ax.set_xlabel("averaging time tau (s)")
    ax.set_ylabel("misfit (sigma)")
    ax.set_yscale("symlog", linthresh=3)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def _plot_temperature(ex: Explanation, path: Path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.0))
    for name, m in ex.temperature.items():
        ax.loglog(m.tau, np.sqrt(m.var), "o-", ms=3, label=name)
    ax.set_xlabel("averaging time tau (s)")
    ax.set_ylabel("Allan deviation (K)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def write_report(ex: Explanation, outdir: str | Path) -> Path:
    """Write ``report.md`` and one pair of PNG plots per channel into ``outdir``."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    md = ["# avard explain report", "",
          f"Data: `{ex.source or 'data'}`, {ex.rate_hz:g} Hz. Held out: "
          + (f"`{ex.holdout_source}`." if ex.holdout_source else "the second half of the record."),
          "",
          "Units are SI: Allan deviation in m/s², averaging time τ in s. Gains are ratios of "
          "EDF-weighted χ² per degree of freedom, base over extended (above 1: the extension "
          "describes the data better). The band is the base model's 68.3 % χ² interval "
          "with the estimator's equivalent degrees of freedom (Greenhall & Riley).", ""]
    for name, ch in ex.channels.items():
        safe = "".join(c if c.isalnum() else "_" for c in name)
        adev_png, res_png = f"adev_{safe}.png", f"misfit_{safe}.png"
        _plot_channel(ch, out / adev_png)
        _plot_residuals(ch, out / res_png)
        md += [f"## Channel {name}", "",
               f"![ADEV of {name}]({adev_png})", "", f"![misfit of {name}]({res_png})", "",
               "| | base | extended |", "|---|---|---|",
               f"| χ²/dof on the fitted data | {ch.base.chi2_dof:.3g} | "
               f"{ch.extended.chi2_dof:.3g} |"]
        if ch.holdout_chi2:
            md.append(f"| χ²/K held out | {ch.holdout_chi2['base']:.3g} | "
                      f"{ch.holdout_chi2['extended']:.3g} |")
        md += ["", f"Gain on the fitted data **{_fmt_gain(ch.gain)}**, held out "
               f"**{_fmt_gain(ch.holdout_gain)}**.", "", "### Misfit of the base model", ""]
        if ch.misfit:
            md += ["| τ range (s) | direction | largest deviation (σ) |", "|---|---|---|"]
            md += [f"| {r['tau_range_s'][0]:.3g} – {r['tau_range_s'][1]:.3g} | "
                   f"{r['direction']} | {r['max_sigma']:+.3g} |" for r in ch.misfit]
        else:
            md.append("Within 3 σ at every τ.")
        md += ["", "### Findings", ""]
        if ch.findings:
            md += ["| cause | parameters (SI) | τ range (s) |", "|---|---|---|"]
            for f in ch.findings:
                params = ", ".join(f"{k} = {v:.4g}" for k, v in f["params"].items())
                md.append(f"| {f['cause']} | {params} | {f['tau_range_s'][0]:.3g} – "
                          f"{f['tau_range_s'][1]:.3g} |")
        else:
            md.append("None: no cause passed its test.")
        if ch.dropped:
            md += ["", "Not claimed (the gain did not hold on held-out data):", ""]
            md += [f"- {d}" for d in ch.dropped]
        md += ["", "### Evidence per cause (every test that ran)", "",
               "| cause | passed | statistic | threshold | evidence |", "|---|---|---|---|---|"]
        for t in ch.tests:
            stat = f"{t.statistic:.3g}" if math.isfinite(t.statistic) else "–"
            ev = t.evidence.replace("|", "\\|")  # |z| and |t| would end the table cell
            md.append(f"| {t.cause} | {'yes' if t.passed else 'no'} | {stat} | "
                      f"{t.threshold:g} | {ev} |")
        md += ["", "### IEEE coefficients (68.3 % interval)", "",
               "| term | base | extended |", "|---|---|---|"]
        md += [f"| {SYMBOLS[t]} {t} | {b} | {e} |" for t, b, e in term_changes(ch)]
        md.append("")
    if ex.temperature:
        _plot_temperature(ex, out / "temperature_adev.png")
        md += ["## Temperature channels", "",
               "Allan deviation of each temperature channel (K): the witness the temperature "
               "cause is tested against.", "", "![temperature ADEV](temperature_adev.png)", ""]
    path = out / "report.md"
    path.write_text("\n".join(md), encoding="utf-8")
    return path
