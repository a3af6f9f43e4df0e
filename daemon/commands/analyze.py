"""Fit the IEEE noise terms to a record and print them with their 68 % intervals.

Examples:

    avard analyze lab.npz                       # table per axis, SI units
    avard analyze data.csv --rate 125 --channels x z
    avard analyze lab.npz --json > lab.json     # machine-readable (shape in docs/analysis.md)
    avard analyze lab.npz --plot lab.png --export kalibr imu.yaml --export csv adev.csv
    avard analyze lab.npz --psd --plot lab.png      # + spectrum: lab_psd.png, white density
    avard analyze /var/lib/avard --run RUN          # one run of a recording
    avard analyze lab.npz --stat oadev,totdev,theoh --dynamic --plot lab.png  # + lab_stats.png,
                                                    # lab_dynamic.png (docs/allan.md)

DATA is an .npz (accel in m/s², rate_hz), a .csv (header row; t column or --rate), or an avard
recording (directory or .avr segment). Every one is streamed (a recording too: walked frame by
frame), so its size is not limited by memory; a recording's lost, duplicated or missing
segments are said, and runs at rates that differ are refused together (--run takes one);
progress goes to stderr when it is a terminal.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

from avard.core.allan.noise_id import NOISE_IDS
from avard.core.analysis.engine import analyze
from avard.core.analysis.formats import adev_csv, format_table, kalibr_yaml, psd_csv
from avard.core.analysis.statistics import statistics_csv, statistics_table
from avard.core.errors import DataError
from avard.core.io.outputs import (
    check_output_file,
    check_outputs_apart,
    check_plot_output,
    finite_for_json,
)
from avard.core.io.source import open_record
from avard.daemon.commands._options import (
    add_channels_argument,
    add_model_arguments,
    add_run_argument,
    add_sensor_argument,
    add_temperature_units_argument,
    analyze_options,
)
from avard.daemon.commands._progress import progress_printer
from avard.daemon.commands._statistics import (
    add_statistics_arguments,
    plot_extras,
    run_statistics,
    statistics_request,
)

NAME = "analyze"
HELP = "fit noise terms (Q, N, B, K, R, sinusoids) with 68 % intervals to a record"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", metavar="DATA", help=".npz, .csv, or a recording (dir/.avr)")
    parser.add_argument("--rate", type=float, default=None, metavar="HZ",
                        help="sample rate in Hz (overrides the file's; needed for a csv "
                             "without a t column)")
    add_channels_argument(parser)
    add_sensor_argument(parser)
    add_run_argument(parser)
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--plot", metavar="FILE.png", help="write the ADEV figure (needs the "
                        "plot extra: matplotlib)")
    parser.add_argument("--export", nargs=2, action="append", default=[],
                        metavar=("FORMAT", "FILE"),
                        help="write 'kalibr FILE.yaml' (noise density, random walk, rate), "
                             "'csv FILE.csv' (the ADEV table) or 'psd FILE.csv' (the spectra, "
                             "needs --psd); repeatable")
    parser.add_argument("--psd", action="store_true",
                        help="also the one-sided Welch PSD per channel ((m/s²)²/Hz, with its "
                             "band), the white density read from it against the fit's N; with "
                             "--plot a second figure NAME_psd.png")
    add_model_arguments(parser)
    parser.add_argument("--workers", default="auto", metavar="N",
                        help="processes for the OADEV of an .npz file, cut by time and added "
                             "up exactly (same result as 1): a whole number, or auto "
                             "(default: 1 on a machine under 2 GB or for records under 2**22 "
                             "samples, else the cores, at most 4)")
    parser.add_argument("--quantiles", choices=("exact", "stable32"), default="exact",
                        help="chi-squared quantiles of the intervals: exact (default) or as "
                             "Stable32 computes them (reproduces its printed bounds)")
    parser.add_argument("--noise-id", choices=NOISE_IDS, default="avard",
                        help="noise identification behind each interval's EDF: avard "
                             "(default: the noise types acceleration data can hold, the "
                             "least EDF the identification cannot rule out), powerlaw "
                             "(every power-law type, for phase data) or stable32 (Stable32's "
                             "exact rules, reproduces its printed alpha; see docs/analysis.md)")
    parser.add_argument("--temperature", metavar="CHANNEL",
                        help="temperature channel to compensate: fit its first-order lag and "
                             "coefficient (m/s²/K) per axis and add the temperature-"
                             "compensated ADEV (see docs/explain.md)")
    add_temperature_units_argument(parser)
    add_statistics_arguments(parser)


def _write(path: str, text: str) -> None:
    p = Path(path)
    if not p.parent.exists():
        raise DataError(f"cannot write {p}: folder {p.parent} does not exist")
    try:
        p.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise DataError(f"cannot write {p}: {exc.strerror}") from exc


def _comp_line(name: str, v: dict | None, channel: str = "", unused: str | None = None,
               refused: bool = False) -> str:
    """One line per axis: the verdict of the temperature test first, then the coefficient and
    the lag, each with its 68 % interval (the lag's marked open when it reaches the longest
    lag tried). Without a fit, why: ``unused`` the reason the temperature ``channel`` was not
    used (``Explanation.temperature_unused``), ``refused`` when the input screen refused its
    log as a whole (a log whose readings are a DS18B20's in °F), which the user can overrule
    with ``--temperature-units``."""
    if v is None:
        if unused is None:
            return (f"channel {name}: no temperature fit (the channel is constant or the "
                    "record too short)")
        line = f"channel {name}: no temperature fit: temperature channel '{channel}' not used "
        line += f"by the screen ({unused})" if refused else f"({unused})"
        if refused:
            # the screen's verdict, not the user's: say how to overrule it
            line += ("; if the log is in °F, --temperature-units F converts it to °C before "
                     "every rule; if it is °C, --temperature-units C takes it as °C")
        return line
    lo, hi = v["coefficient_interval"]
    llo, lhi = v["lag_interval_s"]
    z, zt = v["z"], v["threshold"]
    verdict = (f"detected (z {z:.3g} ≥ {zt:g})" if v["passed"]
               else f"not detected (z {z:.3g} < {zt:g})")
    upper = f"≥ {lhi:.4g} s, the longest lag tried" if v.get("lag_interval_open") \
        else f"{lhi:.4g} s"
    return (f"channel {name}: temperature coupling {verdict}: "
            f"{v['coefficient_mps2_per_k']:.4g} m/s²/K [{lo:.4g}, {hi:.4g}] (68 %) from "
            f"'{v['channel']}' through a first-order lag of {v['lag_s']:.4g} s "
            f"[{llo:.4g} s, {upper}] (68 %); compensated ADEV "
            + (v["compensated_withheld"] if v.get("compensated_withheld") else "in --json"))


def run(args: argparse.Namespace) -> int:
    for fmt, _ in args.export:
        if fmt not in ("kalibr", "csv", "psd", "stats"):
            raise DataError(f"--export {fmt}: unknown format; use 'kalibr FILE.yaml', "
                            "'csv FILE.csv', 'psd FILE.csv' or 'stats FILE.csv'")
        if fmt == "psd" and not args.psd:
            raise DataError("--export psd needs --psd (the spectrum is computed with it)")
        if fmt == "stats" and not args.stat:
            raise DataError("--export stats needs --stat (the statistics to write)")
    request = statistics_request(args)
    if args.rate is not None and not (math.isfinite(args.rate) and args.rate > 0):
        raise DataError(f"--rate {args.rate}: a sample rate must be a positive number of Hz")
    # outputs before the analysis, so a bad path costs a second, not the whole run
    for fmt, path in args.export:
        check_output_file(path, what=f"--export {fmt} {path}",
                          suffixes=(".yaml", ".yml") if fmt == "kalibr" else (".csv",))
    if args.plot:
        check_plot_output(args.plot, what=f"--plot {args.plot}")
    check_outputs_apart([*((f"--export {fmt} {path}", path) for fmt, path in args.export),
                         *([(f"--plot {args.plot}", args.plot)] if args.plot else [])],
                        [args.data])
    _workers(args.workers)  # checked before the work
    if args.temperature and (args.quantiles != "exact" or args.noise_id != "avard"):
        raise DataError("--quantiles stable32 and --noise-id stable32 are not available with "
                        "--temperature; run analyze without --temperature to compare with "
                        "Stable32")
    options = analyze_options(args)
    source = open_record(args.data, rate_hz=args.rate, runs=args.run, sensor=args.sensor)
    if args.temperature:
        # the same analysis (explain's base is analyze of the same source with the same
        # options) plus the thermal fit on the named channel
        from avard.core.explain.engine import explain_file
        from avard.core.explain.options import ExplainOptions

        ex = explain_file(source, ExplainOptions(**vars(options), temperature=args.temperature,
                                                 heldout=False),
                          progress=progress_printer())
        an = ex.analysis
        comp = {k: c.compensation_dict() for k, c in ex.channels.items()}
        unused = ex.temperature_unused.get(args.temperature)
        refused = ex.screen is not None and args.temperature in ex.screen.refused
    else:
        an = analyze(source, replace(options, workers=_workers(args.workers)),
                     progress=progress_printer())
        comp = {}
        unused, refused = None, False
    stats = run_statistics(source, an, request)
    if args.json:
        d = an.to_dict()
        for k, v in comp.items():
            d["channels"][k]["temperature_compensation"] = finite_for_json(v)
        if stats is not None:
            d["statistics"] = finite_for_json(stats.to_dict())
        sys.stdout.write(json.dumps(d, indent=1, allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_table(an) + "\n")
        for k, v in comp.items():
            sys.stdout.write(_comp_line(k, v, args.temperature, unused, refused) + "\n")
        if stats is not None:
            sys.stdout.write(statistics_table(stats) + "\n")
    writers = {"kalibr": kalibr_yaml, "csv": adev_csv, "psd": psd_csv}
    for fmt, path in args.export:
        if fmt == "stats":
            assert stats is not None  # --export stats needs --stat (checked above)
            _write(path, statistics_csv(stats))
        else:
            _write(path, writers[fmt](an))
    if args.plot:
        from avard.core.plot import plot_analysis

        plot_analysis(an, args.plot)
        if args.psd:
            from avard.core.analysis.psd import plot_psd

            p = Path(args.plot)
            plot_psd(an, p.with_name(f"{p.stem}_psd{p.suffix}"))
        plot_extras(stats, args.plot)
    return 0


def _workers(text: str) -> int | str:
    """--workers: 'auto' or a whole number >= 1."""
    if text == "auto":
        return "auto"
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise DataError(f"--workers {text}: give a whole number of processes >= 1, or auto")
    return n
