"""Simulate an ADXL355 + DS18B20 record and write it as .npz (the format ``avard analyze`` reads).

Examples:

    avard simulate --preset quiet-lab --hours 6 --seed 1 --out lab.npz
    avard simulate --preset paper-table3 --hours 60 --seed 3 --out table3.npz
    avard simulate --preset adxl355-datasheet --hours 1 --out x.npz \\
        --set bias_instability=3e-5 --set 'sinusoids=[[2, 1e-4, 0.5]]'
    avard simulate --list            # every parameter of a preset with its value and unit

The record is generated and written chunk by chunk, so a 60-hour record does not need 60 hours
of memory. Units are SI throughout (m/s², s, Hz, °C).
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time

from avard.core.errors import DataError, OutputError
from avard.core.io.outputs import check_output_file, free_bytes
from avard.core.sim.presets import PRESETS, make_config, parse_override
from avard.core.sim.sim_io import draw_seed, npz_size, write_npz
from avard.daemon.config import check_seed
from avard.daemon.service.stop_signals import stop_signals_unwind

NAME = "simulate"
#: INFO lines by default: a long-running command says what it does as it goes
NARRATES = True
HELP = "simulate a sensor record (preset + overrides) into an .npz file"

log = logging.getLogger("avard.simulate")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--preset", default="quiet-lab", choices=sorted(PRESETS),
                        help="starting parameter set (default quiet-lab)")
    parser.add_argument("--hours", type=float, default=1.0, help="record length in hours")
    parser.add_argument("--seed", type=int, default=None,
                        help="random seed (same seed and parameters: same record; default: a "
                             "fresh one, printed and stored in the record)")
    parser.add_argument("--out", help="output file, .npz")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="override a parameter; one number, x,y,z per axis, or JSON "
                             "(repeatable; --list shows the keys)")
    parser.add_argument("--list", action="store_true",
                        help="print the preset's parameters (after --set) and exit")


def _progress(started: float):
    """Progress on a terminal (one rewritten line), or log lines when stderr is not one."""
    last = [0.0]

    def report(done: int, total: int) -> None:
        stream = sys.stderr
        now = time.monotonic()
        if now - last[0] < 1.0 and done < total:
            return
        last[0] = now
        msg = f"simulated {done / total:6.1%} ({done}/{total} samples, {now - started:.0f} s)"
        if stream.isatty():
            stream.write("\r" + msg + ("\n" if done >= total else ""))
            stream.flush()
        else:
            log.info(msg)

    return report


def run(args: argparse.Namespace) -> int:
    overrides = dict(parse_override(text) for text in args.overrides)
    cfg = make_config(args.preset, **overrides)
    if args.list:
        for key, value in cfg.to_dict().items():
            sys.stdout.write(f"{key} = {value!r}\n")
        sys.stdout.write(f"# real ODR {cfg.rate_hz:.6f} Hz, LSB {cfg.lsb_mps2:.6e} m/s²\n")
        return 0
    if not args.out:
        raise DataError("say where to write the record: --out FILE.npz")
    if not (math.isfinite(args.hours) and args.hours > 0):
        raise DataError(f"--hours must be a positive number, got {args.hours}")
    check_seed(args.seed)
    check_output_file(args.out, what=f"--out {args.out}", suffixes=(".npz",))
    size = npz_size(cfg, args.hours)
    free = free_bytes(args.out)
    if size.peak_bytes > free:
        raise OutputError(
            f"--out {args.out}: {args.hours:g} h is {size.n_samples} samples, "
            f"{_gb(size.final_bytes)} (up to {_gb(size.peak_bytes)} while writing), but only "
            f"{_gb(free)} are free there; ask for fewer --hours or write to a bigger disk")
    seed = draw_seed() if args.seed is None else args.seed
    log.info("writing %s: %d samples, %s (%s free), seed %d%s", args.out, size.n_samples,
             _gb(size.final_bytes), _gb(free), seed,
             "" if args.seed is not None else " (drawn; stored in the record)")
    started = time.monotonic()
    with stop_signals_unwind():  # SIGTERM/SIGHUP remove the temporary files as Ctrl-C does
        n = write_npz(args.out, cfg, args.hours, seed, progress=_progress(started))
    took = time.monotonic() - started
    sys.stdout.write(
        f"{args.out}: {n} samples × 3 axes ({args.hours:g} h at {cfg.rate_hz:.6f} Hz, preset "
        f"{cfg.preset}, seed {seed}), {_gb(size.final_bytes)}, accel in m/s², DS18B20 "
        f"plate/ambient in °C; {took:.1f} s\n")
    return 0


def _gb(n: int) -> str:
    """Bytes in the unit that reads best (SI prefixes, as df -H shows them)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} B"
