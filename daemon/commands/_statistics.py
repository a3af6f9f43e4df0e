"""``avard analyze --stat … --dynamic``: the options and their outputs, apart from the command
so the analysis pipeline stays as it is (core/analysis/statistics.py computes them).

``--stat oadev,totdev,theoh`` chooses the statistics printed (table, ``--json``'s
"statistics", ``--export stats FILE.csv``, ``--plot``'s NAME_stats.png); ``--estimator`` stays
the one the fit uses. ``--dynamic [--window S --step S]`` adds the sliding-window ADEV (JSON,
table with Bartlett's p per τ, NAME_dynamic.png with ``--plot``).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from avard.core.allan.longtau import EDF_CONVENTIONS, STATISTICS, parse_statistics
from avard.core.analysis.statistics import (
    StatisticsReport,
    StatisticsRequest,
    compute_statistics,
    plot_dynamic,
    plot_statistics,
)
from avard.core.errors import DataError
from avard.core.io.source import RecordSource


def add_statistics_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--stat", metavar="LIST",
                        help="statistics to print beside the fit, comma-separated: "
                             f"{','.join(STATISTICS)} (EDF and 68 %% bounds each; long "
                             "records are averaged first, see docs/allan.md)")
    parser.add_argument("--edf-convention", choices=EDF_CONVENTIONS, default="sp1065",
                        help="EDF of MTOT/TTOT: NIST SP 1065's Table 8 (default) or as "
                             "Stable32 prints it (docs/allan.md)")
    parser.add_argument("--dynamic", action="store_true",
                        help="also the dynamic ADEV (sliding-window OADEV, τ ≤ window/4) with "
                             "a test per τ that the windows agree")
    parser.add_argument("--window", type=float, metavar="S",
                        help="dynamic ADEV window in seconds (default: an eighth of the record)")
    parser.add_argument("--step", type=float, metavar="S",
                        help="dynamic ADEV step in seconds (default: a quarter of the window)")


def statistics_request(args: argparse.Namespace) -> StatisticsRequest:
    """The request of the options, checked before any work (one clear error)."""
    names = tuple(parse_statistics(args.stat)) if args.stat is not None else ()
    for opt in ("window", "step"):
        v = getattr(args, opt)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise DataError(f"--{opt} {v}: give a positive number of seconds")
        if v is not None and not args.dynamic:
            raise DataError(f"--{opt} sets the dynamic ADEV: add --dynamic")
    return StatisticsRequest(names=names, dynamic=bool(args.dynamic), window_s=args.window,
                             step_s=args.step, quantiles=args.quantiles,
                             edf_convention=args.edf_convention)


def run_statistics(source: RecordSource, an: Any, request: StatisticsRequest
                   ) -> StatisticsReport | None:
    """The statistics of the analysed record (None when none were asked for)."""
    if not request.wanted:
        return None
    return compute_statistics(source, request, rate_hz=an.rate_hz, names=list(an.channels),
                              n_samples=an.n_samples,
                              oadev={k: c.allan for k, c in an.channels.items()
                                     if c.estimator == "oadev"})


def plot_extras(rep: StatisticsReport | None, plot: str | None) -> None:
    """NAME_stats.png and NAME_dynamic.png beside ``--plot NAME.png``."""
    if rep is None or not plot:
        return
    p = Path(plot)
    if any(ch.results for ch in rep.channels.values()):
        plot_statistics(rep, p.with_name(f"{p.stem}_stats{p.suffix}"))
    if any(ch.dynamic is not None for ch in rep.channels.values()):
        plot_dynamic(rep, p.with_name(f"{p.stem}_dynamic{p.suffix}"))
