"""``avard analyze --stat … / --dynamic``: the statistics beyond the fit's OADEV, for a record.

Called after the analysis (``engine.analyze``), which it does not change: when neither option
is given nothing here runs, so analyze keeps its speed and memory. With them, one more pass
over the record (``source.blocks``) averages each channel as it streams, by the
smallest factor that keeps it within ``longtau.MAX_POINTS`` (4 M samples a channel for the
statistics whose cost is N per τ; those whose cost is N·m per τ get 4096 averages, made from
the first), so the memory is bounded whatever the record's length (3 channels: 100 MB) and the
statistics start at τ = r·τ0 (the result's ``stride``). "oadev" is the analysis's own OADEV
(full rate), not recomputed. A recording with gaps is split where the service split it; the
statistics use its longest segment, and say so (no difference straddles a gap).

``--dynamic``: the sliding-window OADEV (``allan.dynamic``) of each channel on the first
averages, window ``window_s`` (default an eighth of the record) and step (default a quarter of
the window); and, when the record logs temperatures, the ADEV by temperature
(``dynamic.temperature_binned_adev``) on the same averages against the mean of the record's
temperature channels averaged alike (``by_temperature``, or ``by_temperature_note`` saying why
there is none).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from avard.core.allan.deviations import AllanResult
from avard.core.allan.dynamic import (
    DynamicAllan,
    TemperatureAllan,
    dynamic_adev,
    temperature_binned_adev,
)
from avard.core.allan.extension import decimate
from avard.core.allan.longtau import (
    MAX_POINTS,
    STATISTICS,
    THEO_STAND_IN,
    statistic,
    theo_edf_source,
)
from avard.core.errors import DataError
from avard.core.io.source import RecordSource
from numpy.typing import NDArray

__all__ = ["ChannelStatistics", "StatisticsReport", "StatisticsRequest", "compute_statistics",
           "statistics_csv", "statistics_table"]

# units of each statistic's deviation for acceleration input (TDEV and TTOT are τ × ADEV)
_UNIT = {"tdev": "m/s", "ttot": "m/s"}


@dataclass(frozen=True)
class StatisticsRequest:
    """What ``--stat`` and ``--dynamic`` ask for."""

    names: tuple[str, ...] = ()
    dynamic: bool = False
    window_s: float | None = None
    step_s: float | None = None
    quantiles: str = "exact"
    edf_convention: str = "sp1065"

    @property
    def wanted(self) -> bool:
        return bool(self.names) or self.dynamic


@dataclass(frozen=True)
class ChannelStatistics:
    """One channel's statistics (by name, in the order asked) and its dynamic ADEV."""

    results: Mapping[str, AllanResult]
    dynamic: DynamicAllan | None = None
    by_temperature: TemperatureAllan | None = None
    by_temperature_note: str | None = None


@dataclass(frozen=True)
class StatisticsReport:
    """Per channel its statistics; ``averaging`` the factor r of each cost class
    ("linear", "quadratic"); ``segment`` (samples used, segments in the record)."""

    rate_hz: float
    channels: Mapping[str, ChannelStatistics]
    averaging: Mapping[str, int] = field(default_factory=dict)
    segment: tuple[int, int] = (0, 1)

    def to_dict(self) -> dict:
        """The ``--json`` "statistics" entry: SI units, NaN written as null by the caller."""
        out: dict = {"averaging": dict(self.averaging), "samples_used": self.segment[0],
                     "segments_in_record": self.segment[1], "channels": {}}
        for name, ch in self.channels.items():
            d: dict = {}
            for stat, res in ch.results.items():
                r = res.to_dict()
                r.pop("cov", None)
                r["statistic"] = stat
                r["dev"] = np.asarray(res.dev).tolist()
                r["dev_lo"] = np.asarray(res.dev_lo).tolist()
                r["dev_hi"] = np.asarray(res.dev_hi).tolist()
                r["unit"] = _UNIT.get(stat, "m/s²")
                sources = edf_sources(stat, res, self.segment[0])
                if sources:
                    r["edf_source"] = sources
                d[stat] = r
            entry: dict = {"statistics": d}
            if ch.dynamic is not None:
                entry["dynamic_adev"] = ch.dynamic.to_dict()
            if ch.by_temperature is not None:
                entry["adev_by_temperature"] = ch.by_temperature.to_dict()
            elif ch.by_temperature_note is not None:
                entry["adev_by_temperature"] = {"note": ch.by_temperature_note}
            out["channels"][name] = entry
        return out


class _Averager:
    """r-averages of a stream of blocks (n, C), written into one array sized from the record's
    length (no list of pieces concatenated at the end, which doubled the peak), with each
    segment's span and the remainder carried."""

    def __init__(self, c: int, r: int, n_samples: int) -> None:
        self.r = r
        self.c = c
        self.out = np.empty((n_samples // r + 1, c))
        self.pos = 0
        self.start = 0  # first average of the open segment
        self.spans: list[tuple[int, int]] = []
        self.rest = np.zeros((0, c))

    def push(self, a: NDArray[np.float64], end: bool) -> None:
        if self.rest.shape[0]:
            a = np.concatenate([self.rest, a])
        k = a.shape[0] // self.r * self.r
        if k:
            avg = decimate(a[:k], self.r)
            if self.pos + avg.shape[0] > self.out.shape[0]:
                raise DataError("the record is longer than its sample count said; run "
                                "analyze again (a file that grew while being read?)")
            self.out[self.pos:self.pos + avg.shape[0]] = avg
            self.pos += avg.shape[0]
        self.rest = a[k:].copy()
        if end:
            self.close()

    def close(self) -> None:
        if self.pos > self.start:
            self.spans.append((self.start, self.pos))
        self.start, self.rest = self.pos, np.zeros((0, self.c))

    def longest(self) -> tuple[NDArray[np.float64], int]:
        self.close()
        if not self.spans:
            raise DataError("the record holds no complete average for the statistics")
        s0, s1 = max(self.spans, key=lambda s: s[1] - s[0])
        return self.out[s0:s1], len(self.spans)


def _hold(t: NDArray[np.float64], last: NDArray[np.float64] | None
          ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each temperature column held at its last reading (an .npz logs a reading only where
    one was made, NaN between), carried across blocks in ``last``; NaN before the first."""
    if last is None or last.shape[0] != t.shape[1]:
        last = np.full(t.shape[1], np.nan)
    ext = np.vstack([last[None, :], t])
    ok = np.isfinite(ext)
    idx = np.where(ok, np.arange(ext.shape[0])[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    held = np.take_along_axis(ext, idx, axis=0)
    held[~np.isfinite(held)] = np.nan
    return held[1:], held[-1].copy()


def compute_statistics(source: RecordSource, request: StatisticsRequest, *, rate_hz: float,
                       names: Sequence[str], n_samples: int,
                       oadev: Mapping[str, AllanResult] | None = None,
                       block: int = 1 << 16,
                       ) -> StatisticsReport:
    """The statistics of ``request`` for the channels ``names`` of ``source`` (read once
    more: ``rate_hz`` and ``n_samples`` as the analysis found them; ``oadev`` its OADEV per
    channel, reused for "oadev")."""
    from avard.core.analysis.engine import _select

    if not source.rereadable:
        raise DataError(f"{source.info.source}: the statistics read the record once more, "
                        "and this stream cannot be read again")
    cols = _select(list(source.info.names), list(names))
    r_lin = max(1, -(-int(n_samples) // MAX_POINTS["linear"]))
    avg = _Averager(len(cols), r_lin, int(n_samples))
    want_t = request.dynamic and bool(source.info.temperature_names)
    t_avg = _Averager(1, r_lin, int(n_samples)) if want_t else None
    last: NDArray[np.float64] | None = None
    for a, t, end in source.blocks(block, columns=cols, temperature=want_t, verify=False):
        avg.push(np.asarray(a, dtype=np.float64), end)
        if t_avg is not None:
            tt = np.asarray(t, dtype=np.float64) if t is not None else np.full((len(a), 1),
                                                                                np.nan)
            held, last = _hold(tt, last)
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows stay NaN
                t_avg.push(np.nanmean(held, axis=1, keepdims=True), end)
    data, n_segments = avg.longest()
    temp = t_avg.longest()[0][:, 0] if t_avg is not None else None
    n_used = data.shape[0] * r_lin
    r_quad = r_lin * max(1, -(-data.shape[0] // MAX_POINTS["quadratic"]))
    small = decimate(data, r_quad // r_lin)
    rate_lin, rate_quad = rate_hz / r_lin, rate_hz / r_quad
    out: dict[str, ChannelStatistics] = {}
    for j, name in enumerate(names):
        results: dict[str, AllanResult] = {}
        for stat in request.names:
            if stat == "oadev" and oadev is not None and name in oadev:
                results[stat] = oadev[name]
                continue
            quad = STATISTICS[stat].cost == "quadratic"
            y, rate, r = (small[:, j], rate_quad, r_quad) if quad else \
                (data[:, j], rate_lin, r_lin)
            res = statistic(stat, y, rate, "octave", quantiles=request.quantiles,
                            edf_convention=request.edf_convention, names=[name])
            results[stat] = replace(res, rate_hz=float(rate_hz), m=res.m * r,
                                    stride=res.stride * r)
        dyn, by_t, note = None, None, None
        if request.dynamic:
            span = data.shape[0] / rate_lin
            window = request.window_s if request.window_s is not None else span / 8
            dyn = dynamic_adev(data[:, j], rate_lin, window, request.step_s)
            if temp is None:
                note = "the record logs no temperature"
            else:
                try:
                    by_t = temperature_binned_adev(data[:, j], temp, rate_lin)
                except DataError as exc:  # no reading yet, or a temperature that stood still
                    note = str(exc)
        out[name] = ChannelStatistics(results, dyn, by_t, note)
    return StatisticsReport(rate_hz=float(rate_hz), channels=out,
                            averaging={"linear": r_lin, "quadratic": r_quad},
                            segment=(n_used, n_segments))


def _g(v: float) -> str:
    return "—" if not math.isfinite(v) else f"{v:.4g}"


def edf_sources(stat: str, res: AllanResult, samples: int) -> list[str]:
    """Per τ of a Theo-family result, where its EDF comes from (``longtau.theo_edf_source``:
    SP 1065's forms or the stand-in); [] for the other statistics and TheoH's OADEV part
    ("SP 1065" there: Greenhall–Riley)."""
    if stat not in ("theo1", "theobr", "theoh") or not len(res.tau):
        return []
    r = int(res.stride[0])
    n_phase = samples // r + 1
    out = []
    for k in range(len(res.tau)):
        m = int(res.m[k]) // r
        theo_part = abs(float(res.tau[k]) * res.rate_hz / r - 0.75 * m) < 1e-6 * m
        a = float(res.alpha[k] if np.ndim(res.alpha) == 1 else np.min(res.alpha[k]))
        out.append(theo_edf_source(int(a), m, n_phase) if theo_part and math.isfinite(a)
                   else "SP 1065")
    return out


def statistics_table(rep: StatisticsReport) -> str:
    """The text table: per channel and statistic, τ, the deviation, its 68 % bounds, EDF, α."""
    lines = ["", "Statistics (SI; bounds 68.3 % from the EDF of NIST SP 1065 / Stable32; "
             "docs/allan.md):"]
    if rep.segment[1] > 1:
        lines.append(f"  the longest of the record's {rep.segment[1]} segments "
                     f"({rep.segment[0]} samples): no difference straddles a gap")
    for name, ch in rep.channels.items():
        for stat, res in ch.results.items():
            r = int(res.stride[0]) if len(res.stride) else 1
            note = f", on {r}-sample averages" if r > 1 and stat != "oadev" else ""
            lines.append(f"  channel {name}: {stat} ({STATISTICS[stat].title}{note}), "
                         f"{_UNIT.get(stat, 'm/s²')}")
            lines.append(f"    {'tau_s':>11} {'dev':>11} {'lo':>11} {'hi':>11} {'edf':>9} "
                         f"{'alpha':>5}")
            sources = edf_sources(stat, res, rep.segment[0])
            for k in range(len(res.tau)):
                a = float(res.alpha[k])
                mark = "*" if sources and sources[k] == THEO_STAND_IN else " "
                lines.append(f"    {res.tau[k]:>11.4g} {_g(float(res.dev[k])):>11} "
                             f"{_g(float(res.dev_lo[k])):>11} {_g(float(res.dev_hi[k])):>11} "
                             f"{_g(float(res.edf[k])):>9}{mark}"
                             f"{'' if not math.isfinite(a) else int(a):>5}")
            if THEO_STAND_IN in sources:
                lines.append(f"    * EDF: {THEO_STAND_IN}, a conservative stand-in")
        if ch.dynamic is not None:
            d = ch.dynamic
            lines.append(f"  channel {name}: dynamic ADEV, window {d.window_s:.4g} s, step "
                         f"{d.step_s:.4g} s, {len(d.t_s)} windows ({d.independent} "
                         "independent): Bartlett's p that every window has one variance")
            for k in range(len(d.tau)):
                p = float(d.p_value[k])
                verdict = "changes" if d.changes[k] else "consistent"
                ratio = float(np.nanmax(d.dev[:, k]) / np.nanmin(d.dev[:, k]))
                lines.append(f"    τ {d.tau[k]:>9.4g} s: p = {_g(p):>9} ({verdict}), "
                             f"largest/smallest window ADEV {ratio:.3g}")
        if ch.by_temperature is not None:
            b = ch.by_temperature
            lines.append(f"  channel {name}: ADEV by temperature, {len(b.edges) - 1} bins of "
                         "equal count (°C: " + ", ".join(f"{e:.3g}" for e in b.edges)
                         + "): Bartlett's p that every bin has one variance")
            for k in range(len(b.tau)):
                p = float(b.p_value[k])
                verdict = "depends on temperature" if b.changes[k] else "consistent"
                devs = " ".join(_g(float(v)) for v in b.dev[:, k])
                lines.append(f"    τ {b.tau[k]:>9.4g} s: p = {_g(p):>9} ({verdict}), ADEV "
                             f"per bin {devs} m/s²")
        elif ch.by_temperature_note is not None:
            lines.append(f"  channel {name}: no ADEV by temperature: {ch.by_temperature_note}")
    return "\n".join(lines)


def statistics_csv(rep: StatisticsReport) -> str:
    """channel, statistic, tau_s, dev, dev_lo, dev_hi (SI: m/s², m/s for TDEV/TTOT), edf,
    alpha, averaging (samples per average the statistic ran on), unit."""
    rows = ["channel,statistic,tau_s,dev,dev_lo,dev_hi,edf,alpha,averaging,unit"]
    for name, ch in rep.channels.items():
        for stat, res in ch.results.items():
            for k in range(len(res.tau)):
                vals = [res.tau[k], res.dev[k], res.dev_lo[k], res.dev_hi[k], res.edf[k]]
                a = float(res.alpha[k])
                rows.append(",".join([name, stat] + ["" if not math.isfinite(float(v)) else
                                                     f"{float(v):.9g}" for v in vals]
                                     + ["" if not math.isfinite(a) else str(int(a)),
                                        str(int(res.stride[k])), _UNIT.get(stat, "m/s²")]))
    return "\n".join(rows) + "\n"


def plot_statistics(rep: StatisticsReport, path: str | Path, *, dpi: int = 130) -> Path:
    """One log-log panel per channel, every statistic with its 68 % bounds (TDEV and TTOT,
    in m/s, are left out: another unit)."""
    from avard.core.plot import pyplot, save_figure

    plt = pyplot()
    names = list(rep.channels)
    fig, axes = plt.subplots(1, len(names), figsize=(6.0 * len(names), 5.0), squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        for stat, res in rep.channels[name].results.items():
            if stat in _UNIT:
                continue
            dev = np.asarray(res.dev)
            err = np.vstack([dev - np.asarray(res.dev_lo), np.asarray(res.dev_hi) - dev])
            ax.errorbar(res.tau, dev, yerr=np.nan_to_num(err), fmt="o-", ms=3, capsize=2,
                        label=stat)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("τ (s)")
        ax.set_ylabel("deviation (m/s²)")
        ax.set_title(f"channel {name}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Allan-family deviations with 68.3 % intervals", fontsize=11)
    return save_figure(fig, path, dpi=dpi)


def plot_dynamic(rep: StatisticsReport, path: str | Path, *, dpi: int = 130) -> Path:
    """The dynamic ADEV as a τ × time colour map per channel (log10 ADEV, m/s²), with the
    τ where the windows disagree (Bartlett p < 1 %) marked on the right."""
    from avard.core.plot import pyplot, save_figure

    plt = pyplot()
    names = [n for n, ch in rep.channels.items() if ch.dynamic is not None]
    if not names:
        raise DataError("no dynamic ADEV to plot: give --dynamic")
    fig, axes = plt.subplots(1, len(names), figsize=(6.5 * len(names), 4.8), squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        d = rep.channels[name].dynamic
        assert d is not None
        hours = d.t_s / 3600.0
        with np.errstate(divide="ignore"):
            z = np.log10(d.dev.T)
        mesh = ax.pcolormesh(hours, d.tau, z, shading="nearest", cmap="viridis")
        ax.set_yscale("log")
        ax.set_xlabel("window centre (h)")
        ax.set_ylabel("τ (s)")
        changed = [f"{t:.3g}" for t, c in zip(d.tau, d.changes, strict=True) if c]
        ax.set_title(f"{name}: window {d.window_s / 3600:.3g} h; windows differ at τ = "
                     f"{', '.join(changed) or 'none'} s (p < 1 %)", fontsize=9)
        fig.colorbar(mesh, ax=ax, label="log10 ADEV (m/s²)")
    return save_figure(fig, path, dpi=dpi)
