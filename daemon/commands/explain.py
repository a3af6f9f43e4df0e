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
from types import SimpleNamespace
from typing import Any

import numpy as np
from avard.core.errors import DataError

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
    parser.add_argument("--channels", help="comma-separated channel names (default: all)")
    parser.add_argument("--rate-hz", type=float, default=None,
                        help="sample rate in Hz when the file does not say")


def _load_npz(path: Path, rate_hz: float | None) -> Any:
    """Minimal .npz reader (accel, rate_hz, axes/names, temperature_c, temperature_names)
    for when avard.core.readers is not available."""
    try:
        with np.load(path, allow_pickle=False) as z:
            keys = set(z.files)
            if "accel" not in keys:
                raise DataError(f"{path} has no 'accel' array; an explain input needs accel "
                                "(N, C) in m/s^2")
            accel = np.asarray(z["accel"], dtype=np.float64)
            rate = rate_hz if rate_hz is not None else (
                float(z["rate_hz"]) if "rate_hz" in keys else None)
            names = [str(a) for a in z["axes"]] if "axes" in keys else (
                [str(a) for a in z["names"]] if "names" in keys else None)
            temps = np.asarray(z["temperature_c"], dtype=np.float64) \
                if "temperature_c" in keys else None
            tnames = [str(a) for a in z["temperature_names"]] \
                if "temperature_names" in keys else []
    except (OSError, ValueError) as exc:
        raise DataError(f"cannot read {path}: {exc}; give an .npz with an 'accel' array") \
            from exc
    if rate is None:
        raise DataError(f"{path} does not say its sample rate; pass --rate-hz")
    if accel.ndim == 1:
        accel = accel[:, None]
    if names is None or len(names) != accel.shape[1]:
        names = ["x", "y", "z"][: accel.shape[1]] if accel.shape[1] <= 3 else \
            [f"ch{i}" for i in range(accel.shape[1])]
    return SimpleNamespace(accel=accel, rate_hz=rate, names=names, temperature_c=temps,
                           temperature_names=tnames, source=str(path))


def load(path: str, rate_hz: float | None = None) -> Any:
    """Load a record through avard.core.readers when present, else the .npz reader here."""
    p = Path(path)
    if not p.exists():
        raise DataError(f"{path} does not exist; give the path of a recorded or simulated file")
    try:
        from avard.core.readers import load_record
    except ImportError:
        return _load_npz(p, rate_hz)
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

    rec = load(args.data, args.rate_hz)
    ho = load(args.holdout, args.rate_hz) if args.holdout else None
    channels = [c.strip() for c in args.channels.split(",")] if args.channels else None
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
