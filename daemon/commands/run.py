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
import logging
from typing import Any

from avard.core.errors import ConfigError, HardwareError
from avard.daemon import blas_threads  # noqa: F401  (first: before anything imports numpy)
from avard.daemon.config import load_config
from avard.daemon.sdnotify import Notifier
from avard.daemon.service import Service

NAME = "run"
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
    if args.speed is not None and args.speed < 0:
        raise ConfigError(f"--speed {args.speed}: must be ≥ 0 (0 = as fast as possible)")
    if args.duration is not None and args.duration <= 0:
        raise ConfigError(f"--duration {args.duration}: must be a positive number of seconds")


def build(args: argparse.Namespace, cfg: dict[str, dict[str, Any]],
          notifier: Any = None, **service_kw: Any) -> Service:
    """The service for these arguments: simulated rig or real hardware."""
    if args.simulate:
        from avard.core.presets import PRESETS
        from avard.daemon.simulation import simulated_service

        if args.simulate not in PRESETS:
            raise ConfigError(f"--simulate {args.simulate!r}: unknown preset; choose one of "
                              f"{', '.join(sorted(PRESETS))}")
        speed = 1.0 if args.speed is None else (args.speed or None)
        svc, _sims, _emu = simulated_service(
            cfg, args.simulate, seed=args.seed, speed=speed, notifier=notifier,
            sensor_info={"device": "ADXL355 (emulated)", "preset": args.simulate},
            **service_kw)
        return svc
    from avard.daemon.adxl355 import Adxl355
    from avard.daemon.pacing import watermark_settings
    from avard.daemon.timebase import SystemClock
    from avard.daemon.transport import open_bus

    s = cfg["sensor"]
    bus = open_bus(s["bus"], bus=s["spi_bus"] if s["bus"] == "spi" else s["i2c_bus"],
                   device=s["spi_device"], address=s["i2c_address"],
                   speed_hz=s["spi_speed_hz"])
    dev = Adxl355(bus, temp_intercept_lsb=float(s["temp_intercept_lsb"]))
    info = dev.probe()
    dev.reset()
    interrupt = None
    if s["int1_gpio"]:
        from avard.daemon.interrupt import GpiodPin

        interrupt = GpiodPin(s["int1_gpio"])
    dev.configure(range_g=int(s["range_g"]), odr_hz=float(s["odr_hz"]),
                  **watermark_settings(interrupt is not None))
    dev.start()
    bank = _ds18b20_bank(cfg)
    return Service(cfg, dev, SystemClock(), temperature_bank=bank, notifier=notifier,
                   interrupt=interrupt,
                   sensor_info={"device": info.name, "partid": info.partid,
                                "revid": info.revid, "bus": s["bus"]}, **service_kw)


def _ds18b20_bank(cfg: dict[str, dict[str, Any]]) -> Any:
    """The DS18B20 reader threads for the configured (or every present) sensor."""
    t = cfg["temperature"]
    if not t["ds18b20"]:
        return None
    from avard.daemon import ds18b20

    present = ds18b20.discover()
    wanted = [ds18b20.normalise_id(i) for i in t["ids"]]
    missing = sorted(set(wanted) - set(present))
    if missing and t["required"]:
        raise HardwareError(f"DS18B20 {', '.join(missing)} not found on the 1-Wire bus; check "
                            "the wiring and dtoverlay=w1-gpio, or set temperature.required = "
                            "false")
    if missing:
        log.warning("DS18B20 %s not found now; reading them anyway (they may appear)",
                    ", ".join(missing))
    ids = wanted or present
    if not ids:
        return None
    return ds18b20.Ds18b20Bank([f"28-{i}" for i in ids], interval_s=float(t["interval_s"]))


def run(args: argparse.Namespace) -> int:
    _check_args(args)
    overrides = {"recording.data_dir": args.data_dir}
    cfg = load_config(args.config, **overrides)
    notifier = Notifier()
    svc = build(args, cfg, notifier=notifier)
    svc.install_signals()
    return svc.run(args.duration)
