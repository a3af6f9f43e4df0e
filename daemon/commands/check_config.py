"""Check a service configuration file without starting anything.

Reads the TOML file exactly as ``avard run`` does and reports every unknown key, wrong type
and out-of-range value with the key's name, the value and what is allowed, then what ``avard
run`` needs from this machine (the data directory writable, CURVE key files and their modes,
the authorised-keys directory): the same two checks as ``avard run``, so a config that passes
here starts. Exit 0 when the file is valid, 2 when it is not.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Mapping
from typing import Any

from avard.daemon.config import check_runtime, effective_poll_hz, load_config
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import SensorSpec, wiring
from avard.daemon.service.acquisition import REALTIME_HELD_HZ

NAME = "check-config"
HELP = "check a config file (unknown keys, types, ranges) without starting"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", help="TOML configuration file (see config/avard.toml)")
    parser.add_argument("--data-dir", metavar="DIR",
                        help="override recording.data_dir, as `avard run --data-dir` does")
    parser.add_argument("--show", action="store_true",
                        help="print the effective configuration (defaults filled in)")


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, **{"recording.data_dir": args.data_dir})
    check_runtime(cfg)
    config = Config.from_dict(cfg)
    summary = [f"{args.config}: valid"]
    rig = config.rig_sensors
    if len(rig) > 1:
        summary.append(f"  {len(rig)} sensors, each recorded in DATA_DIR/NAME:")
    for s in rig:     # every sensor's rate, drain and real-time note, not only the first's
        poll_hz = effective_poll_hz({"sensor": {"odr_hz": s.odr_hz, "poll_hz": s.poll_hz}})
        where = f"{s.name}: {wiring(SensorSpec.from_config(s).bus)}, " if len(rig) > 1 else ""
        summary.append(f"  {'  ' if len(rig) > 1 else ''}{where}ADXL355 at {s.odr_hz:g} Hz "
                       f"ODR, ±{s.range_g} g, drained at {poll_hz:g} Hz"
                       + (f", sync {s.sync}" if len(rig) > 1 else ""))
    fastest = max(s.odr_hz for s in rig)
    if fastest > REALTIME_HELD_HZ:
        fifo_ms = 32e3 / fastest
        names = [s.name for s in rig if s.odr_hz > REALTIME_HELD_HZ]
        which = f" ({', '.join(names)})" if len(rig) > 1 else ""
        summary.append(
            f"  note: at {fastest:g} Hz{which} the FIFO holds {fifo_ms:.3g} ms: "
            f"beside a CPU-bound process on a 2-core machine only {REALTIME_HELD_HZ:g} Hz was "
            "measured free of FIFO overruns (no SCHED_FIFO under the unit); each overrun is a "
            "recorded gap of counted size (docs/service.md, python -m benchmarks realtime)")
    if config.recording.enabled:
        summary.append(f"  recording into {config.recording.data_dir}")
    if config.publish.enabled:
        summary.append(f"  publishing on {config.publish.endpoint}, requests on "
                       f"{config.publish.request_endpoint}")
    out = sys.stdout
    # with --show the whole output is TOML (the summary as comments): it can be saved and run
    out.write("".join(("# " if args.show else "") + ln + "\n" for ln in summary))
    if args.show:
        out.write(to_toml(cfg))
    return 0


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        if isinstance(value, float) and not math.isfinite(value):
            return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a TOML basic string is JSON's escaping
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML for {type(value).__name__}")


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def to_toml(cfg: Mapping[str, Any]) -> str:
    """The effective configuration as TOML that ``avard run --config`` reads back."""
    lines: list[str] = []
    several = cfg.get("sensors")
    for sec, table in cfg.items():
        if sec == "sensors":
            continue
        for entry in (several if sec == "sensor" and several else [table]):
            lines.append(f"[[{sec}]]" if sec == "sensor" and several else f"[{_toml_key(sec)}]")
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" if v is not None
                      else f"# {k}: not set (TOML has no empty value)" for k, v in entry.items()]
            lines.append("")
    return "\n".join(lines)
