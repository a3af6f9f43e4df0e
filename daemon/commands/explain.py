"""Model versus measurement: where avard analyze's fit of a record leaves the measurement,
the physical cause, tested at one false-alarm level per axis (temperature through a
first-order lag or a richer thermal path — two paths, quadratic, dT/dt, hysteresis —, a
warm-up, bias steps, up-then-down excursions, a drift, a Gauss–Markov process, one periodic
disturbance), the model extended by it with the gain on held-out data, the
temperature-compensated Allan deviation, and per axis "explained" or "unexplained".

Examples:

    avard explain run1.npz                        # terminal summary (held out: its halves)
    avard explain run1.npz --holdout run2.npz     # run2 (same sensor) is the held-out data
    avard explain run1.npz --json                 # machine-readable, SI units
    avard explain run1.npz --report out/          # Markdown report with plots
    avard explain run1.npz --channels x,z
    avard explain run1.npz --filter-corner none   # the same options as avard analyze's

The base model is exactly `avard analyze`'s fit of the same file. The held-out gain is how
much better the extended model predicts data it was not fitted on: by default the record's
two halves predict each other; with --holdout the models fitted on DATA predict FILE. The
record is streamed once; progress goes to stderr when it is a terminal. See docs/explain.md.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
from avard.core.errors import DataError
from avard.core.io.outputs import check_output_dir, require_plot_extra, same_file
from avard.daemon.commands._options import (
    add_channels_argument,
    add_model_arguments,
    add_run_argument,
    add_sensor_argument,
    add_temperature_units_argument,
    analyze_options,
)

NAME = "explain"
HELP = "find where the noise model misfits the data, name the cause, measure the gain"

log = logging.getLogger("avard.explain")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", help="measured or simulated record (.npz, .csv or a recording)")
    parser.add_argument("--holdout", metavar="FILE",
                        help="a second record of the same sensor (same rate and channels) "
                             "that the models fitted on DATA predict (default: the halves of "
                             "DATA predict each other)")
    parser.add_argument("--json", action="store_true",
                        help="print the result as JSON (SI units) instead of the summary")
    parser.add_argument("--report", metavar="DIR",
                        help="write report.md with plots into DIR (needs matplotlib)")
    add_channels_argument(parser)
    add_sensor_argument(parser)
    add_run_argument(parser)
    parser.add_argument("--rate", dest="rate_hz", type=float, default=None, metavar="HZ",
                        help="sample rate in Hz when the file does not say")
    add_model_arguments(parser)
    parser.add_argument("--temperature", metavar="CHANNEL",
                        help="use only this temperature channel for the thermal model, and "
                             "report its compensated ADEV whatever its test says")
    add_temperature_units_argument(parser)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, float | np.floating):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _progress() -> tuple[Any, Any]:
    """(sample progress, stage message) writers to stderr, or (None, None) off a terminal."""
    if not sys.stderr.isatty():
        return None, None
    last = [-1]

    def show(done: int, total: int | None) -> None:
        pct = int(100 * done / total) if total else -1
        if total and pct == last[0]:
            return
        last[0] = pct
        sys.stderr.write(f"\rexplain: reading {pct:3d} %" if total else
                         f"\rexplain: {done} samples")
        sys.stderr.flush()

    def stage(msg: str) -> None:
        sys.stderr.write(f"\rexplain: {msg}\033[K\n")
        sys.stderr.flush()

    return show, stage


def run(args: argparse.Namespace) -> int:
    from avard.core.explain.engine import explain_file
    from avard.core.explain.options import ExplainOptions
    from avard.core.explain.report import summary, write_report
    from avard.core.io.source import open_record

    if args.report:  # before the analysis: a bad folder costs a second, not minutes
        # DIR itself is made, as `mkdir DIR` would; a missing parent is more likely a typo
        check_output_dir(Path(args.report).resolve().parent, what=f"--report {args.report}")
        check_output_dir(args.report, what=f"--report {args.report}", create=True)
        require_plot_extra(f"--report {args.report}")
    if not Path(args.data).exists():
        raise DataError(f"{args.data} does not exist; give the path of a recorded or "
                        "simulated file")
    if args.holdout and not Path(args.holdout).exists():
        raise DataError(f"--holdout {args.holdout} does not exist; give the path of a second "
                        "record of the same sensor")
    if args.holdout and same_file(args.data, args.holdout):
        # the models then "predicted" the very samples they were fitted on: a held-out gain
        # with nothing held out
        raise DataError(f"--holdout {args.holdout} is the record explained ({args.data}): give "
                        "a second record of the same sensor, or leave --holdout out (the "
                        "record's halves then predict each other)")
    # both records opened (and a recording scanned) before any analysis
    options = ExplainOptions(**vars(analyze_options(args)), temperature=args.temperature)
    source = open_record(args.data, rate_hz=args.rate_hz, runs=args.run,
                         sensor=args.sensor)
    holdout = (None if args.holdout is None
               else open_record(args.holdout, rate_hz=args.rate_hz, sensor=args.sensor))
    progress, stage = _progress()
    ex = explain_file(source, options, holdout=holdout, progress=progress, stage=stage)
    if args.temperature in ex.temperature_unused:
        # the one channel asked for cannot drive the thermal model: an explanation without
        # it would answer another question than the one asked
        raise DataError(f"--temperature {args.temperature}: the channel has "
                        f"{ex.temperature_unused[args.temperature]} in this record, so the "
                        "thermal causes cannot be tested on it; name another channel, or "
                        "leave --temperature out")
    if args.report:
        path = write_report(ex, args.report)
        sys.stderr.write(f"avard explain: wrote the report to {path}\n")
    if args.json:
        json.dump(_jsonable(ex.to_dict()), sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(summary(ex))
        if args.report:
            print(f"\nreport: {Path(args.report) / 'report.md'}")
    return 0
