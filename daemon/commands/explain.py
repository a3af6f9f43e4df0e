"""Model versus measurement: where the five-term IEEE noise model disagrees with the data, the
physical cause, the extended model and what it gains on held-out data.

Examples:

    avard explain run1.npz                        # terminal summary, held out: second half
    avard explain run1.npz --holdout run2.npz     # the other run is the held-out data
    avard explain run1.npz --json                 # machine-readable, SI units
    avard explain run1.npz --report out/          # Markdown report with plots
    avard explain run1.npz --channels x,z

Causes tested: temperature, sinusoid, bias_step, warmup, rate_ramp, gauss_markov,
quantization, filter. A cause is reported only when it passes its stated test and its gain
holds on held-out data. See docs/explain.md.
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
from avard.core.outputs import check_output_dir, require_plot_extra
from avard.daemon.commands._options import add_channels_argument, split_channels

NAME = "explain"
HELP = "find where the noise model misfits the data, name the cause, measure the gain"

log = logging.getLogger("avard.explain")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", help="measured or simulated record (.npz, .csv or a recording)")
    parser.add_argument("--holdout", metavar="FILE",
                        help="held-out record of the same sensor (default: the second half of "
                             "DATA)")
    parser.add_argument("--json", action="store_true",
                        help="print the result as JSON (SI units) instead of the summary")
    parser.add_argument("--report", metavar="DIR",
                        help="write report.md with plots into DIR (needs matplotlib)")
    add_channels_argument(parser)
    parser.add_argument("--rate", dest="rate_hz", type=float, default=None, metavar="HZ",
                        help="sample rate in Hz when the file does not say")


def load(path: str, rate_hz: float | None = None) -> Any:
    """Load a record through the one reader every command uses (avard.core.readers)."""
    from avard.core.readers import load_record

    p = Path(path)
    if not p.exists():
        raise DataError(f"{path} does not exist; give the path of a recorded or simulated file")
    return load_record(p, rate_hz=rate_hz)


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


def run(args: argparse.Namespace) -> int:
    from avard.core.explain import explain
    from avard.core.explain_report import summary, write_report

    if args.report:  # before the analysis: a bad folder costs a second, not minutes
        check_output_dir(args.report, what=f"--report {args.report}", create=True)
        require_plot_extra(f"--report {args.report}")
    rec = load(args.data, args.rate_hz)
    ho = load(args.holdout, args.rate_hz) if args.holdout else None
    channels = split_channels(args.channels)
    ex = explain(rec, holdout=ho, channels=channels)
    if args.report:
        path = write_report(ex, args.report)
        log.info("report written to %s", path)
    if args.json:
        json.dump(_jsonable(ex.to_json()), sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(summary(ex))
        if args.report:
            print(f"\nreport: {Path(args.report) / 'report.md'}")
    return 0
