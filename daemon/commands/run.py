"""Run the acquisition service (what systemd starts).

Drains the ADXL355 FIFO into a ring buffer, feeds the streaming Allan accumulators (3 axes in
m/s² and the temperature channels in °C, with their covariance), writes a crash-safe recording
and publishes everything over ZeroMQ. ``--simulate PRESET`` runs the same code over the
register-level emulator fed by the sensor simulator; ``--speed X`` runs that virtual clock at
most X times faster than real time (0: as fast as the CPU allows). SIGTERM stops cleanly,
SIGHUP reopens the recording files. Logs go to stderr.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
from pathlib import Path
from typing import Any

from avard.core.errors import ConfigError
from avard.daemon import blas_threads  # noqa: F401  (first: before anything imports numpy)
from avard.daemon.config import (
    check_positive_seconds,
    check_runtime,
    check_seed,
    load_config,
)
from avard.daemon.config_types import Config
from avard.daemon.service import dirlock
from avard.daemon.service.sdnotify import Notifier
from avard.daemon.service.supervisor import ServiceHooks, Supervised

NAME = "run"
#: INFO lines by default: a long-running command says what it does as it goes
NARRATES = True
HELP = "run the acquisition service (ADXL355 + DS18B20, Allan core, recording, ZeroMQ)"

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", metavar="FILE", help="TOML configuration (default: the "
                        "built-in defaults, see config/avard.toml)")
    parser.add_argument("--simulate", metavar="PRESET",
                        help="no hardware: emulated ADXL355 fed by the simulator "
                        "(quiet-lab, adxl355-datasheet, paper-table3)")
    parser.add_argument("--speed", type=float, default=None, metavar="X",
                        help="with --simulate: at most X times real time (default 1; 0 = as "
                        "fast as possible)")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="stop after S seconds of (simulated) time (default: run until "
                        "SIGTERM)")
    parser.add_argument("--data-dir", metavar="DIR", help="override recording.data_dir")
    parser.add_argument("--seed", type=int, default=None, help="simulator seed")


def _check_args(args: argparse.Namespace) -> None:
    if args.speed is not None and not args.simulate:
        raise ConfigError("--speed needs --simulate: real hardware runs in real time")
    if args.speed is not None and not (args.speed == 0 or 1e-3 <= args.speed <= 1e6):
        raise ConfigError(f"--speed {args.speed}: must be 0 (as fast as possible) or from "
                          "0.001 to 1e6 times real time")
    check_positive_seconds("--duration", args.duration)
    check_seed(args.seed)


def build(args: argparse.Namespace, config: Config, notifier: Any = None,
          hooks: ServiceHooks | None = None) -> Supervised:
    """The service for these arguments over the rig daemon/hw/rig.py describes (hardware, or
    the simulated rig for --simulate / $AVARD_BACKEND), composed in daemon/compose.py."""
    from avard.daemon.compose import compose_rig
    from avard.daemon.hw.rig import describe_rig

    speed = getattr(args, "speed", None)
    spec = describe_rig(config, simulate=getattr(args, "simulate", None),
                        seed=getattr(args, "seed", None),
                        speed=1.0 if speed is None else (speed or None))
    return compose_rig(config, spec, notifier=notifier, hooks=hooks)


def lock_dirs(config: Config) -> list[Path]:
    """The recording directories a service of ``config`` writes into: data_dir, and for a
    rig of several sensors each sensor's data_dir/NAME (rig_service.lane_config)."""
    root = config.recording.path
    sensors = config.rig_sensors
    return [root, *(root / s.name for s in sensors)] if len(sensors) > 1 else [root]


def run(args: argparse.Namespace) -> int:
    _check_args(args)
    overrides = {"recording.data_dir": args.data_dir}
    cfg = load_config(args.config, **overrides)
    config = Config.from_dict(cfg)
    if args.config is None:
        log.warning("no --config: using the built-in defaults (as in config/avard.toml); "
                    "recording into %s", config.recording.data_dir)
    check_runtime(cfg)          # the same checks as `avard check-config`
    with contextlib.ExitStack() as stack:
        if config.recording.enabled:
            # before the rig is opened: a second service on this directory (a manual run
            # beside the unit) stops here, before its start-up resets the first one's sensor.
            # A rig records each sensor in data_dir/NAME: those too, or a rig started beside
            # a one-sensor service on data_dir/NAME reset that service's sensor (build opens
            # and resets every sensor) before its lane was refused.
            for d in lock_dirs(config):
                stack.enter_context(dirlock.held(d))
        notifier = Notifier()
        svc = build(args, config, notifier=notifier)
        svc.install_signals()
        return svc.run(args.duration)
