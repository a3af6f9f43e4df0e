"""Check a service configuration file without starting anything.

Reads the TOML file exactly as ``avard run`` does and reports every unknown key, wrong type
and out-of-range value with the key's name, the value and what is allowed, then what ``avard
run`` needs from this machine (the data directory writable, CURVE key files and their modes,
the authorised-keys directory): the same two checks as ``avard run``, so a config that passes
here starts. Exit 0 when the file is valid, 2 when it is not.
"""

from __future__ import annotations

import argparse
import sys

from avard.daemon.config import check_runtime, effective_poll_hz, load_config
from avard.daemon.config_types import Config
from avard.daemon.service.acquisition import REALTIME_HELD_HZ

NAME = "check-config"
HELP = "check a config file (unknown keys, types, ranges) without starting"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", help="TOML configuration file (see config/avard.toml)")
    parser.add_argument("--show", action="store_true",
                        help="print the effective configuration (defaults filled in)")


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    check_runtime(cfg)
    config = Config.from_dict(cfg)
    out = sys.stdout
    out.write(f"{args.config}: valid\n")
    out.write(f"  ADXL355 at {config.sensor.odr_hz:g} Hz ODR, ±{config.sensor.range_g} g, "
              f"drained at {effective_poll_hz(cfg):g} Hz\n")
    if config.sensor.odr_hz > REALTIME_HELD_HZ:
        fifo_ms = 32e3 / config.sensor.odr_hz
        out.write(f"  note: at {config.sensor.odr_hz:g} Hz the FIFO holds {fifo_ms:.3g} ms: "
                  f"beside a CPU-bound process on a 2-core machine only "
                  f"{REALTIME_HELD_HZ:g} Hz was measured free of FIFO overruns (no SCHED_FIFO "
                  "under the unit); each overrun is a recorded gap of counted size "
                  "(docs/service.md, python -m benchmarks realtime)\n")
    if config.recording.enabled:
        out.write(f"  recording into {config.recording.data_dir}\n")
    if config.publish.enabled:
        out.write(f"  publishing on {config.publish.endpoint}, requests on "
                  f"{config.publish.request_endpoint}\n")
    if args.show:
        for sec, table in cfg.items():
            out.write(f"[{sec}]\n")
            for key, value in table.items():
                out.write(f"{key} = {value!r}\n")
    return 0
