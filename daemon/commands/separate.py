"""Separate each co-located sensor's own noise from what the bed does (docs/separate.md).

Examples:

    avard separate a.npz b.npz                  # two sensors: Groslambert covariance
    avard separate a.npz b.npz c.npz --json     # three: the three-cornered hat
    avard separate rec_a rec_b --plot sep.png --channels z
    avard separate /var/lib/avard                 # a rig's recording: its 2 or 3 sensors
    avard separate /var/lib/avard --sensor left --sensor far

Two or three records of sensors bolted to one bed (.npz, .csv, avard recordings), taken at the
same time: they are aligned by time when every record has its start time (recordings), else
by index, and refused when they do not overlap. Per τ and axis: each sensor's self-noise ADEV
and the common-mode ADEV with their 68 % intervals (an upper limit where the estimate cannot
be told from 0), the IEEE terms fitted to each self-noise, and where the bed's input lies
below each sensor's own noise. Units: SI (m/s², s).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace

import numpy as np
from avard.core.analysis.separate import (
    Separation,
    align,
    aligned_runs,
    is_multi_run,
    read_sensor,
    separate,
    separate_runs,
)
from avard.core.errors import AvardError, DataError
from avard.core.io.outputs import check_plot_output, finite_for_json
from avard.daemon.commands._options import add_channels_argument, filter_corner, split_channels

NAME = "separate"
HELP = ("each co-located sensor's self-noise and the common (bed) input, from 2 or 3 records "
        "taken together")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("records", nargs="+", metavar="DATA",
                        help="2 or 3 records of co-located sensors (.npz, .csv, recording)")
    parser.add_argument("--names", nargs="+", metavar="NAME",
                        help="the sensors' names, in the order of the records (default: the "
                             "recordings' sensor.name, else the file names)")
    parser.add_argument("--rate", type=float, default=None, metavar="HZ",
                        help="sample rate in Hz of every record (needed for a csv without a t "
                             "column)")
    add_channels_argument(parser)
    parser.add_argument("--sensor", action="append", metavar="NAME", default=None,
                        help="a rig's recording (a directory of one recording per sensor) "
                             "stands for its sensors; --sensor NAME (repeated) takes only "
                             "these of them")
    parser.add_argument("--filter-corner", type=filter_corner, default="none", metavar="HZ",
                        help="sensor low-pass corner to model in the self-noise fit: Hz, "
                             "'auto' (ODR/4 for avard's own ADXL355 records) or 'none' "
                             "(default)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--plot", metavar="FILE.png",
                        help="self-noise and common-mode ADEV on one figure (needs the plot "
                             "extra: matplotlib)")


def load_and_separate(paths: list[str], *, names: list[str] | None = None,
                      rate_hz: float | None = None, channels: list[str] | None = None,
                      filter_corner_hz: float | str | None = None,
                      sensors: list[str] | None = None) -> Separation:
    """Read, align and separate (what ``run`` prints). A rig's recording stands for its
    sensors' recordings (``sensors``: only these of them)."""
    paths = rig_records(paths, sensors)
    if len(paths) not in (2, 3):
        raise DataError(f"separate takes 2 or 3 records of co-located sensors, not "
                        f"{len(paths)}")
    if names is not None and len(names) != len(paths):
        raise DataError(f"--names: {len(names)} names for {len(paths)} records")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise DataError(f"--rate {rate_hz}: a sample rate must be a positive number of Hz")
    _refuse_one_record_twice(paths)
    records = [read_sensor(p, rate_hz=rate_hz) for p in paths]
    _refuse_one_record_twice(paths, records)
    sensor_names = names or _names_of(paths, [r.sensor_name for r in records])
    runs = None
    if is_multi_run(records):          # a restart or a loss in a recording: run by run
        if channels:
            missing = [c for c in channels if not all(c in r.names for r in records)]
            if missing:
                raise DataError(f"--channels {', '.join(missing)}: not a channel every "
                                "record has")
            records = [replace(r, accel=r.accel[:, [r.names.index(c) for c in channels]],
                               names=tuple(channels)) for r in records]
        runs = aligned_runs(records)
    aligned = align(records, channels) if runs is None else None
    corner: float | None
    if filter_corner_hz == "auto":
        from avard.core.io.source import open_record

        # the record source's one rule (RecordInfo.filter_corner_hz: ODR/4 for an ADXL355's
        # records); the engine's old helper was gone and 'auto' raised an ImportError
        corners = {open_record(p, rate_hz=rate_hz).info.filter_corner_hz for p in paths}
        corner = corners.pop() if len(corners) == 1 else None
    else:
        corner = filter_corner_hz if isinstance(filter_corner_hz, float) else None
    if runs is not None:
        return separate_runs(runs, records[0].rate_hz, sensors=sensor_names,
                             axes=records[0].names, fit=True, filter_corner_hz=corner,
                             sources=paths)
    assert aligned is not None
    return separate(aligned.accels, aligned.rate_hz, sensors=sensor_names, axes=aligned.axes,
                    filter_corner_hz=corner, notes=aligned.notes, sources=paths)


def _refuse_one_record_twice(paths: list[str], records: list | None = None) -> None:
    """One record given twice (the same file, or a copy: the same samples) is no pair of
    sensors: separated from itself it gave a self-noise of exactly 0 and a 'common input'
    that was the sensor's own noise, as a result, with exit status 0."""
    import numpy as np
    from avard.core.io.outputs import repeated_path

    def refuse(a: str, b: str, why: str) -> None:
        raise DataError(f"{a} and {b} are {why}: separate needs the records of 2 or 3 "
                        "different sensors on one bed")

    if records is None:
        # a missing or unreadable path is no repeat: its read says what is wrong with it
        twice = repeated_path(paths)
        if twice is not None:
            refuse(str(twice[0]), str(twice[1]), "the same file")
        return
    for i in range(len(paths)):
        for j in range(i + 1, len(paths)):
            ra, rb = records[i], records[j]
            if ra.accel.shape == rb.accel.shape and np.array_equal(ra.accel, rb.accel):
                refuse(paths[i], paths[j], "the same samples (a copy of one record?)")


def _names_of(paths: list[str], recorded: list[str | None]) -> list[str]:
    """The sensors' names as their recordings call them (sensor.name), else the file names,
    else sensor1, sensor2, …"""
    from pathlib import Path

    if all(recorded) and len(set(recorded)) == len(recorded):
        return [str(n) for n in recorded]
    stems = [Path(p.rstrip("/")).stem or p for p in paths]
    if len(set(stems)) == len(stems):
        return stems
    return [f"sensor{i + 1}" for i in range(len(paths))]


def format_separation(sep: Separation) -> str:
    """The table: per axis and τ, common-mode and each sensor's self-noise ADEV [68 %]."""
    out = [f"{sep.method}: {len(sep.sensors)} sensors ({', '.join(sep.sensors)}), "
           f"{sep.n_samples} samples at {sep.rate_hz:.10g} Hz; ADEV in m/s², "
           f"[{100 * sep.ci:.1f} % interval], '≤' an upper limit"]
    out += [f"note: {n}" for n in sep.notes]
    for ax in sep.axes:
        out.append(f"\naxis {ax.axis}")
        head = f"{'tau [s]':>10} {'common':>30}" + "".join(f" {n:>30}" for n in sep.sensors)
        out.append(head)
        for k, t in enumerate(ax.tau):
            row = f"{t:>10.4g} {_cell(ax.common, k):>30}"
            row += "".join(f" {_cell(p, k):>30}" for p in ax.self_noise)
            out.append(row)
        for i, name in enumerate(sep.sensors):
            v = ax.verdicts[i]
            runs = v.below_runs()
            if runs:
                spans = []
                for a, b in runs:
                    least = v.factor_at_least[a:b + 1]
                    span = (f"{ax.tau[a]:.4g} s" if a == b
                            else f"{ax.tau[a]:.4g}–{ax.tau[b]:.4g} s")
                    if np.all(np.isfinite(least)):
                        span += f" (ADEV at least ×{float(np.min(least)):.3g} below)"
                    spans.append(span)
                rest = sum(1 for st in v.state if st == "not resolved")
                above = sum(1 for st in v.state if st == "above")
                out.append(f"{name}: the common input is below its own noise at τ = "
                           + ", ".join(spans)
                           + (f"; not resolved at {rest} other τ" if rest else "")
                           + (f"; above it at {above} τ" if above else ""))
            else:
                out.append(f"{name}: at no τ is the common input resolved below its own noise"
                           + ("" if "above" not in v.state else
                              f" (above it at {v.state.count('above')} τ)"))
            fit = ax.fits[i] if ax.fits else None
            if fit is None:
                problem = ax.fit_problems[i] if ax.fit_problems else "not fitted"
                out.append(f"{name}: no fit of the self-noise ({problem})")
            else:
                terms = [f"{t} {e.value:.4g} {e.unit} [{e.lo:.3g}, {e.hi:.3g}]"
                         for t, e in fit.terms.items()
                         if e.present and e.value is not None and e.lo is not None
                         and e.hi is not None]
                out.append(f"{name}: self-noise fit: " + ("; ".join(terms) or "no term found"))
    return "\n".join(out)


def _cell(p: object, k: int) -> str:
    from avard.core.analysis.separate import Part

    assert isinstance(p, Part)
    if p.upper_limit[k]:
        return f"≤ {math.sqrt(p.hi[k]):.3e}"
    return f"{math.sqrt(max(p.var[k], 0.0)):.3e} [{math.sqrt(p.lo[k]):.2e}, " \
           f"{math.sqrt(p.hi[k]):.2e}]"


def rig_records(paths: list[str], sensors: list[str] | None) -> list[str]:
    """Each rig's recording among ``paths`` replaced by its sensors' recordings (those named
    in ``sensors`` when given: each must be in some rig's recording, refused otherwise)."""
    from avard.core.io.source import rig_of, sensor_path

    out: list[str] = []
    found: set[str] = set()
    rigs: list[str] = []
    for p in paths:
        names = rig_of(p)
        if not names:
            out.append(p)
            continue
        rigs += [f"{p}: {', '.join(names)}"]
        for n in _rig_order(p, names):
            if sensors is None or n in sensors:
                out.append(str(sensor_path(p, n)))
                found.add(n)
    if sensors is not None:
        if not rigs:
            raise DataError("--sensor picks sensors of a rig's recording; none is given")
        missing = [n for n in sensors if n not in found]
        if missing:
            raise DataError(f"--sensor {missing[0]}: no such sensor in the rig's recording "
                            f"({'; '.join(rigs)})")
    return out


def _rig_order(path: str, names: tuple[str, ...]) -> tuple[str, ...]:
    """The rig's own order of its sensors (its headers' ``rig.sensors``: the first is the
    reference the live separation aligns to, so ``avard separate`` pairs the same samples),
    else name order."""
    from avard.core.io.source import RecordingSource, sensor_path

    try:
        for rec in RecordingSource(sensor_path(path, names[0])).records():
            if rec.get("kind") == "header":
                order = [n for n in (rec.get("rig") or {}).get("sensors", []) if n in names]
                return (*order, *(n for n in names if n not in order))
    except (AvardError, OSError):
        pass
    return names


def plot_separation(sep: Separation, path: str) -> None:
    """Self-noise and common-mode ADEV with their intervals, one panel per axis; upper
    limits drawn as downward markers."""
    from avard.core.plot import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(1, len(sep.axes), figsize=(5.5 * len(sep.axes), 4.5),
                             squeeze=False)
    for panel, ax in zip(axes[0], sep.axes, strict=True):
        for label, part, style in ([("common mode", ax.common, "k")] +
                                   [(f"{n} self-noise", p, f"C{i}")
                                    for i, (n, p) in enumerate(zip(sep.sensors, ax.self_noise,
                                                                   strict=True))]):
            ok = ~part.upper_limit
            dev = part.dev
            err = [dev[ok] - part.lo[ok] ** 0.5, part.hi[ok] ** 0.5 - dev[ok]]
            panel.errorbar(ax.tau[ok], dev[ok], yerr=err, fmt="o-", ms=3, color=style,
                           label=label, capsize=2)
            if (~ok).any():
                panel.plot(ax.tau[~ok], part.hi[~ok] ** 0.5, "v", color=style, ms=5,
                           label=f"{label} (upper limit)")
        panel.set_xscale("log")
        panel.set_yscale("log")
        panel.set_xlabel("τ [s]")
        panel.set_ylabel("Allan deviation [m/s²]")
        panel.set_title(f"axis {ax.axis}: {sep.method}")
        panel.grid(True, which="both", alpha=0.3)
        panel.legend(fontsize=7)
    save_figure(fig, path, dpi=130)


def run(args: argparse.Namespace) -> int:
    if args.plot:   # before the work, so a bad path costs a second
        check_plot_output(args.plot, what=f"--plot {args.plot}")
    sep = load_and_separate(args.records, names=args.names, rate_hz=args.rate,
                            channels=split_channels(args.channels),
                            filter_corner_hz=args.filter_corner, sensors=args.sensor)
    if args.json:
        text = json.dumps(finite_for_json(sep.to_dict()), indent=1, allow_nan=False)
        sys.stdout.write(text + "\n")
    else:
        sys.stdout.write(format_separation(sep) + "\n")
    if args.plot:
        plot_separation(sep, args.plot)
    return 0
