"""A population of sensors (``avard fleet``): every sensor's noise terms side by side, the
population's robust centre and spread per axis and term, and the sensors whose terms lie
outside it.

The outlier rule: for an axis and a term, among the sensors where the fit found the term
(at least ``MIN_SENSORS`` of them), the centre is the median of their values and the spread
1.4826 × their median absolute deviation (the standard deviation for a normal population,
robust to the outliers themselves). A sensor's term is an outlier when its 68 % interval
lies more than ``OUTLIER_SPREADS`` spreads away from the centre: ``lo > centre + 3·spread``
or ``hi < centre − 3·spread``. Its interval, not its value, is compared, so a term measured
loosely on a short record is not called an outlier for its scatter. When the values agree
better than they are measured (a spread below their median interval half-width, e.g. a
batch of identical sensors) the half-width is the spread: measurement scatter is never
called a population difference. With fewer than ``MIN_SENSORS`` values no rule is applied
and the row says so.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from avard.core.model.terms import TERMS, UNITS

if TYPE_CHECKING:
    from avard.core.analysis.results import Analysis

__all__ = ["MIN_SENSORS", "OUTLIER_SPREADS", "Outlier", "Population", "Spread", "TermValue",
           "population"]

#: How far (in robust spreads) a term's interval must lie from the population's centre.
OUTLIER_SPREADS = 3.0
#: Fewest sensors with a term for the population rule to judge it.
MIN_SENSORS = 3
#: 1.4826 × MAD is the standard deviation of a normal population.
MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class TermValue:
    """One sensor's term on one axis: value with its 68 % interval (SI, ``unit``), or absent
    (``upper``: its upper limit when the fit gives one)."""

    present: bool
    value: float | None
    lo: float | None
    hi: float | None
    upper: float | None
    unit: str


@dataclass(frozen=True)
class SensorAxis:
    """One sensor's axis: its terms, the fit's χ²/dof, the record's hours and losses."""

    sensor: str
    channel: str
    hours: float
    samples_lost: int
    chi2_dof: float
    terms: Mapping[str, TermValue]


@dataclass(frozen=True)
class Spread:
    """The population of one axis and term: its robust centre and spread over ``n`` sensors
    (None where fewer than ``MIN_SENSORS`` have the term)."""

    channel: str
    term: str
    n: int
    of: int
    centre: float | None
    spread: float | None


@dataclass(frozen=True)
class Outlier:
    sensor: str
    channel: str
    term: str
    reason: str


@dataclass(frozen=True)
class Population:
    axes: tuple[SensorAxis, ...]
    spreads: tuple[Spread, ...]
    outliers: tuple[Outlier, ...]

    def to_dict(self) -> dict[str, object]:
        """The ``--json`` shape (SI units; None where a value is absent)."""
        return {
            "rule": (f"a term whose 68 % interval lies more than {OUTLIER_SPREADS:g} robust "
                     "spreads (1.4826 × MAD, at least the median half-width) from the "
                     f"median of the sensors that have it (at least {MIN_SENSORS})"),
            "sensors": [{"sensor": a.sensor, "channel": a.channel, "hours": a.hours,
                         "samples_lost": a.samples_lost,
                         "chi2_dof": a.chi2_dof if math.isfinite(a.chi2_dof) else None,
                         "terms": {t: vars(v) for t, v in a.terms.items()}}
                        for a in self.axes],
            "population": [vars(s) for s in self.spreads],
            "outliers": [vars(o) for o in self.outliers],
        }


def _axes(sensor: str, an: Analysis) -> list[SensorAxis]:
    rec = an.recording_summary()
    lost = 0 if rec is None else int(rec["samples_lost"])
    out = []
    for name, ch in an.channels.items():
        terms = {}
        for t in TERMS:
            e = ch.fit.terms[t]
            terms[t] = TermValue(bool(e.present), e.value if e.present else None,
                                 e.lo if e.present else None, e.hi if e.present else None,
                                 None if e.present else e.upper, UNITS[t])
        out.append(SensorAxis(sensor, name, an.n_samples / an.rate_hz / 3600.0, lost,
                              float(ch.fit.chi2_dof), terms))
    return out


def population(analyses: Mapping[str, Analysis]) -> Population:
    """The population of ``analyses`` (sensor name → its analysis) by the rule above."""
    axes = [a for sensor, an in analyses.items() for a in _axes(sensor, an)]
    channels = sorted({a.channel for a in axes}, key=[a.channel for a in axes].index)
    spreads, outliers = [], []
    for ch in channels:
        mine = [a for a in axes if a.channel == ch]
        for t in TERMS:
            have = [a for a in mine if a.terms[t].present and a.terms[t].value is not None]
            if len(have) < MIN_SENSORS:
                spreads.append(Spread(ch, t, len(have), len(mine), None, None))
                continue
            v = np.array([a.terms[t].value for a in have], dtype=float)
            centre = float(np.median(v))
            spread = MAD_TO_SIGMA * float(np.median(np.abs(v - centre)))
            half = [(hi - lo) / 2 for a in have
                    if (hi := a.terms[t].hi) is not None and (lo := a.terms[t].lo) is not None]
            if half:
                spread = max(spread, float(np.median(half)))
            spreads.append(Spread(ch, t, len(have), len(mine), centre, spread))
            for a in have:
                e = a.terms[t]
                assert e.lo is not None and e.hi is not None
                if e.lo > centre + OUTLIER_SPREADS * spread:
                    outliers.append(Outlier(a.sensor, ch, t, (
                        f"{t} {e.value:.3g} [{e.lo:.3g}, {e.hi:.3g}] {e.unit} lies "
                        f"{(e.lo - centre) / spread:.1f} spreads above the population's "
                        f"{centre:.3g} ± {spread:.2g} ({len(have)} sensors)")))
                elif e.hi < centre - OUTLIER_SPREADS * spread:
                    outliers.append(Outlier(a.sensor, ch, t, (
                        f"{t} {e.value:.3g} [{e.lo:.3g}, {e.hi:.3g}] {e.unit} lies "
                        f"{(centre - e.hi) / spread:.1f} spreads below the population's "
                        f"{centre:.3g} ± {spread:.2g} ({len(have)} sensors)")))
    return Population(tuple(axes), tuple(spreads), tuple(outliers))


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.3g}"


def format_population(pop: Population) -> str:
    """The population table: per sensor and axis N, B, K with their intervals, χ²/dof, hours
    and losses; the population's centre and spread; the outliers with their reasons."""
    short = {"velocity_random_walk": "N", "bias_instability": "B", "rate_random_walk": "K"}
    lines = ["Units SI: N m/s/sqrt(s), B m/s^2, K m/s^2/sqrt(s); intervals 68 %; "
             "'<' an upper limit where the term is absent."]
    head = f"{'sensor':<16}{'axis':<6}" + "".join(f"{s:<28}" for s in short.values()) + \
        f"{'chi2/dof':>9}{'hours':>8}{'lost':>8}  flag"
    lines.append(head)
    flagged = {(o.sensor, o.channel) for o in pop.outliers}
    for a in pop.axes:
        cells = []
        for t in short:
            e = a.terms[t]
            cell = (f"{_fmt(e.value)} [{_fmt(e.lo)}, {_fmt(e.hi)}]" if e.present
                    else f"< {_fmt(e.upper)}" if e.upper else "absent")
            cells.append(f"{cell:<28}")
        chi = f"{a.chi2_dof:.2f}" if math.isfinite(a.chi2_dof) else "n/a"
        flag = "OUTLIER" if (a.sensor, a.channel) in flagged else ""
        lines.append(f"{a.sensor:<16}{a.channel:<6}" + "".join(cells)
                     + f"{chi:>9}{a.hours:>8.3g}{a.samples_lost:>8}  {flag}")
    lines.append("")
    lines.append("population (median ± robust spread over the sensors that have the term):")
    for s in pop.spreads:
        if s.term not in short:
            continue
        if s.centre is None:
            lines.append(f"  {s.channel} {short[s.term]}: {s.n} of {s.of} sensors have it; "
                         f"fewer than {MIN_SENSORS}, not judged")
        else:
            lines.append(f"  {s.channel} {short[s.term]}: {s.centre:.3g} ± {s.spread:.2g} "
                         f"({s.n} of {s.of} sensors)")
    lines.append("")
    if pop.outliers:
        lines.append(f"outliers ({OUTLIER_SPREADS:g} robust spreads from the median):")
        lines.extend(f"  {o.sensor} {o.channel}: {o.reason}" for o in pop.outliers)
    else:
        lines.append("outliers: none")
    return "\n".join(lines)


def population_csv(pop: Population) -> str:
    """One row per sensor, axis and term: value, lo, hi (SI), present, unit, outlier."""
    flagged = {(o.sensor, o.channel, o.term) for o in pop.outliers}
    rows = ["sensor,channel,term,value,lo,hi,upper,present,unit,chi2_dof,hours,samples_lost,"
            "outlier"]
    for a in pop.axes:
        for t, e in a.terms.items():
            vals = ["" if v is None else f"{v:.9g}" for v in (e.value, e.lo, e.hi, e.upper)]
            chi = f"{a.chi2_dof:.6g}" if math.isfinite(a.chi2_dof) else ""
            rows.append(",".join([a.sensor, a.channel, t, *vals, str(int(e.present)), e.unit,
                                  chi, f"{a.hours:.6g}", str(a.samples_lost),
                                  str(int((a.sensor, a.channel, t) in flagged))]))
    return "\n".join(rows) + "\n"
