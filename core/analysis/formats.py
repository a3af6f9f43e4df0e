"""``avard analyze``'s outputs other than the JSON: the text table, the ADEV and PSD csv
files and kalibr's IMU yaml (written by hand: no yaml dependency). All values SI."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from avard.core.analysis.results import ESTIMATORS, Analysis, ChannelAnalysis
from avard.core.analysis.spectrum import line_groups
from avard.core.errors import FitError
from avard.core.model.fit.results import RAMP_OR_WALK
from avard.core.model.terms import SYMBOLS, TERMS, UNITS

if TYPE_CHECKING:
    from avard.core.analysis.slow_sine import SlowSearch

# ---------------------------------------------------------------------------------------------
# text, csv, kalibr


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.4g}"


def _lines_text(found: list[dict[str, float]]) -> str:
    """The line finder's lines as its periodic disturbances (``spectrum.line_groups``, as
    explain reports them): one entry per disturbance, its amplitude with the 68 % interval,
    a drifting line's band, harmonics, sidebands and how many lines it gathers (a pump swept
    over 0.02 Hz was printed as 7 separate sinusoids)."""
    parts = []
    for g in line_groups(found):
        iv = (f" [{g.amplitude_lo:.3g}, {g.amplitude_hi:.3g}]"
              if math.isfinite(g.amplitude_lo) and math.isfinite(g.amplitude_hi) else "")
        extra = []
        if g.band_hz is not None:
            extra.append(f"drifting over {g.band_hz[0]:.5g}–{g.band_hz[1]:.5g} Hz")
        if len(g.harmonics) > 1:
            extra.append("harmonics " + ", ".join(str(k) for k in g.harmonics))
        if g.modulation_hz is not None:
            extra.append(f"sidebands ±{g.modulation_hz:.4g} Hz")
        if g.members > 1:
            extra.append(f"{g.members} lines, one disturbance")
        parts.append(f"{g.frequency_hz:.4g} Hz × {g.amplitude:.3g}{iv} m/s²"
                     + (f" ({'; '.join(extra)})" if extra else ""))
    return ", ".join(parts)


def format_table(an: Analysis) -> str:
    """Human-readable report: per channel the five terms (value, 68 % interval, SI unit, or
    'absent'), the sinusoids, the τ range used and the fit quality."""
    lines = [f"{an.source}: {an.n_samples} samples at {an.rate_hz:g} Hz "
             f"({an.n_samples / an.rate_hz / 3600:.3g} h). Units SI; intervals 68.3 %."]
    fc = an.meta.get("filter_corner_hz")
    lines.append("sensor low-pass modelled at " + (f"{fc:g} Hz" if fc else
                 "— (not modelled: filter-bent short τ left out)"))
    lines.append(f"Allan deviation: {ESTIMATORS[an.estimator]}, octave τ; intervals from "
                 "Greenhall–Riley EDF with the noise type identified per τ (as Stable32); "
                 "its values per τ (m/s², with interval, EDF, α): --json or --export csv FILE")
    cut = an.meta.get("oadev_cut")
    if cut:
        lines.append(f"OADEV stops at τ = {cut['tau_max_s']:.4g} s, short of N/4 "
                     f"({cut['tau_full_s']:.4g} s): its history would need "
                     f"{cut['bytes_needed'] / 2**20:.0f} MiB, more than a quarter of the free "
                     "memory; --estimator cascade reaches N/4 in kilobytes")
    screen = an.meta.get("screen")
    if screen is not None:
        lines += screen.lines()
    rec = an.recording_summary()
    if rec is not None:
        line = (f"recording: {rec['segments']} segment(s), split at each of its "
                f"{rec['gap_records']} gap records and at every restart (never averaged across)")
        if rec["samples_lost"]:
            spans = ", ".join(f"[{x['i0']}, {x['i0'] + x['n']})" for x in rec["losses"][:5])
            more = " …" if len(rec["losses"]) > 5 else ""
            line += (f"; {rec['samples_lost']} samples lost (damage or missing segments) at "
                     f"{spans}{more}")
        if rec["samples_duplicated"]:
            line += f"; {rec['samples_duplicated']} duplicated samples counted once"
        lines.append(line)
    for name, ch in an.channels.items():
        fit = ch.fit
        lines.append("")
        lines.append(f"channel {name}")
        if fc and fit.filter_corner_hz is None:  # fit_noise found no such filter here
            lines.append(f"  no low-pass at {fc:g} Hz in this channel's curve: fitted "
                         "without the filter model")
        lines.append(f"  {'term':<24}{'value':>12}  {'68 % interval':<25}{'unit'}")
        for t in TERMS:
            e = fit.terms[t]
            label = f"{t} ({SYMBOLS[t]})"
            if e.present:
                lines.append(f"  {label:<24}{_fmt(e.value):>12}  "
                             f"{'[' + _fmt(e.lo) + ', ' + _fmt(e.hi) + ']':<25}{UNITS[t]}")
            else:
                ub = f"absent (< {_fmt(e.upper)} {UNITS[t]})" if e.upper else "absent"
                lines.append(f"  {label:<24}{ub:>12}")
            # the ramp-or-walk note is on both K and R: said once, under K
            if e.note and (e.note != RAMP_OR_WALK or t == "rate_random_walk"):
                lines.append(f"    {e.note}")
        lines.extend(_drift_lines(ch))
        if ch.lines:
            lines.append(f"  sinusoids: {_lines_text(ch.lines)}")
        else:
            lines.append("  sinusoids: none found")
        if ch.slow is not None:
            lines.append(f"  slow sinusoid (below the line search): {_slow_text(ch.slow)}")
            if ch.slow_fit is not None:
                lines.append(_beside_slow_text(ch))
        if ch.psd is not None:
            lines.extend(_psd_lines(ch))
        chi = "n/a" if not math.isfinite(fit.chi2_dof) else f"{fit.chi2_dof:.2f}"
        lines.append(f"  fitted τ {fit.tau_min_s:.4g} s … {fit.tau_max_s:.4g} s "
                     f"({fit.n_points} points), χ²/dof = {chi} (dof {fit.dof})")
        if math.isfinite(fit.chi2_dof) and fit.dof > 0:
            from avard.core.allan.chi2 import chi2_sf  # the χ² upper tail, without scipy

            p = float(chi2_sf(fit.chi2_dof * fit.dof, fit.dof))
            if p < 0.001:
                lines.append(f"  note: the five-term model does not describe this curve "
                             f"(p = {p:.1g}); see `avard explain` for what else is in it")
    return "\n".join(lines)


def _drift_lines(ch: ChannelAnalysis) -> list[str]:
    """Where R came from, and a drift found short of its level (``drift_summary``)."""
    d = ch.drift_summary()
    out = []
    if d["rate_ramp_from"] == "time_domain":
        out.append("  R from the time domain: the block means' slope, tested against a "
                   "random walk, resolved apart from the AVAR (K refitted without it)")
    if d["floor"] > 0:
        out.append(f"  drift: a ramp of at least {_fmt(d['floor'])} {d['unit']} (68 %) the "
                   "time domain finds short of its level; not claimed, but counted in the "
                   "intervals at long τ")
    if out and d["interval_noise"] not in (None, "refit_less_line"):
        out.append(f"  drift: the slope's interval under {_interval_noise(d)}")
    return out


def _interval_noise(d: dict[str, object]) -> str:
    """The noise the drift's slope interval was computed under, in words."""
    from avard.core.analysis.drift import INTERVAL_NOISE

    key = str(d["interval_noise"])
    return INTERVAL_NOISE.get(key, key)


def _psd_lines(ch: ChannelAnalysis) -> list[str]:
    cp = ch.psd
    out = [f"  PSD: one-sided Welch, {cp.n_segments} segments, {len(cp.f)} bins to "
           f"{cp.f[-1]:.4g} Hz, (m/s²)²/Hz with its {cp.ci:.1%} band (--json, --export psd)"]
    w = cp.white
    if w is None:
        out.append("  PSD white density: no white region to read it in")
    else:
        verdict = "agrees with" if w.agrees else "DIFFERS from"
        out.append(f"  PSD white density N = {_fmt(w.value)} [{_fmt(w.lo)}, {_fmt(w.hi)}] "
                   f"m/s²/√Hz ({w.f_lo_hz:.3g}–{w.f_hi_hz:.3g} Hz, {w.n_bins} bins): {verdict}"
                   f" the fit's N [{_fmt(w.fit_lo)}, {_fmt(w.fit_hi)}]")
    return out


def psd_csv(an: Analysis) -> str:
    """The spectra as csv: channel, f_hz, psd, psd_lo, psd_hi ((m/s²)²/Hz, one-sided)."""
    rows = ["channel,f_hz,psd_m2ps4_per_hz,psd_lo,psd_hi"]
    for name, ch in an.channels.items():
        cp = ch.psd
        if cp is None:
            continue
        for k in range(len(cp.f)):
            vals = (cp.f[k], cp.psd[k], cp.lo[k], cp.hi[k])
            rows.append(",".join([name] + [("" if not math.isfinite(v) else f"{v:.9g}")
                                           for v in vals]))
    return "\n".join(rows) + "\n"


def adev_csv(an: Analysis) -> str:
    """The ADEV table as csv: channel, tau_s, adev, adev_lo, adev_hi (m/s²), edf, model (m/s²:
    the fitted model's ADEV), used (1 if the point was in the fit), alpha (noise exponent the
    interval assumes), estimator ("oadev" or "cascade", see ``ESTIMATORS``)."""
    rows = ["channel,tau_s,adev_mps2,adev_lo_mps2,adev_hi_mps2,edf,model_adev_mps2,used,alpha,"
            "estimator"]
    for name, ch in an.channels.items():
        a = ch.allan
        model = np.sqrt(ch.fit.model_avar(a.tau))
        for k in range(len(a.tau)):
            used = int(ch.fit.tau_min_s * (1 - 1e-9) <= a.tau[k] <= ch.fit.tau_max_s * (1 + 1e-9))
            vals = [a.tau[k], a.dev[k], a.dev_lo[k], a.dev_hi[k], a.edf[k], model[k]]
            alpha = a.alpha[k]
            rows.append(",".join([name] + [("" if not math.isfinite(v) else f"{v:.9g}")
                                           for v in vals]
                                 + [str(used), "" if not math.isfinite(alpha) else
                                    str(int(alpha)), ch.estimator]))
    return "\n".join(rows) + "\n"


def kalibr_yaml(an: Analysis, *, rostopic: str = "/imu0") -> str:
    """kalibr's IMU noise file: accelerometer_noise_density = N (m/s²/√Hz), _random_walk = K
    (m/s³/√Hz), update_rate (Hz). kalibr takes one value for all axes: the largest over the
    channels (conservative). An axis without a detected K contributes its upper limit; if no
    channel gives anything, a comment says so and the value is 0."""
    ns = [c.fit.terms["velocity_random_walk"].value for c in an.channels.values()]
    ks = []
    for c in an.channels.values():
        e = c.fit.terms["rate_random_walk"]
        ks.append(e.value if e.present else e.upper)
    n_val = max((v for v in ns if v is not None), default=None)
    k_val = max((v for v in ks if v is not None), default=None)
    if n_val is None:
        raise FitError("no channel has a velocity random walk N; kalibr needs one")
    k_note = ("largest K over the axes" if any(c.fit.terms["rate_random_walk"].present
                                                for c in an.channels.values())
              else "K not detected: the largest 99 % upper limit over the axes")
    out = [
        f"# accelerometer noise from avard analyze of {an.source}",
        f"# channels: {', '.join(an.channels)}; largest value over them; SI units",
        f"accelerometer_noise_density: {n_val:.6e}   # N, m/s^2/sqrt(Hz)",
        f"accelerometer_random_walk: {0.0 if k_val is None else k_val:.6e}   # {k_note}, "
        "m/s^3/sqrt(Hz)",
        f"rostopic: {rostopic}",
        f"update_rate: {an.rate_hz:.6g}   # Hz",
    ]
    slow = [n for n, c in an.channels.items() if c.slow_fit is not None]
    if slow:
        # the base model's K, which reads a slow sinusoid as noise: conservative for a
        # filter, but not the walk alone (the table's "beside it" line has that)
        out.insert(2, f"# a slow sinusoid was resolved on {', '.join(slow)}: K there includes "
                      "its Allan variance (conservative); `avard analyze` prints K beside it")
    return "\n".join(out) + "\n"


def _beside_slow_text(ch: ChannelAnalysis) -> str:
    """The terms beside a resolved slow sinusoid, in one line: the base model's terms above
    read the sinusoid as noise (its AVAR lands in B, K or R), and a drift it hid from the
    first drift test is tested again on the block means less it."""
    fit = ch.slow_fit
    assert fit is not None
    parts = []
    for t in ("bias_instability", "rate_random_walk", "rate_ramp"):
        e = fit.terms[t]
        # a term's note (not yet resolved, ramp or walk) as the table's own lines carry it,
        # cut to its head: the JSON's terms_beside holds it whole
        tag = f" ({e.note.split(':')[0]})" if e.present and e.note else ""
        parts.append(f"{SYMBOLS[t]} {_fmt(e.value)} [{_fmt(e.lo)}, {_fmt(e.hi)}]{tag}"
                     if e.present else f"{SYMBOLS[t]} absent (< {_fmt(e.upper)})" if e.upper
                     else f"{SYMBOLS[t]} absent")
    d = ch.drift_summary(fit)
    how = (", R from the time domain" if d["rate_ramp_from"] == "time_domain"
           else f", a ramp of at least {_fmt(d['floor'])} (68 %) short of its level"
           if d["floor"] > 0 else "")
    if how and d["interval_noise"] not in (None, "refit_less_line"):
        how += f", its interval under {_interval_noise(d)}"
    return (f"    beside it (the sinusoid removed): {'; '.join(parts)} (SI units{how}); the "
            "terms above are the base model, which reads the sinusoid as noise "
            "(`avard explain` tests what it is)")


def _slow_text(slow: SlowSearch) -> str:
    """The slow-sinusoid search in one line: the sinusoid with its intervals, or why none
    is claimed."""
    s = slow.sine
    if s is None:
        return slow.note
    return (f"{s.frequency_hz:.4g} Hz ({s.frequency_lo_hz:.4g} … {s.frequency_hi_hz:.4g} Hz, "
            f"{s.cycles:.3g} cycles) × {s.amplitude:.3g} m/s² ({s.amplitude_lo:.3g} … "
            f"{s.amplitude_hi:.3g}); counted in the intervals above, not in the terms")
