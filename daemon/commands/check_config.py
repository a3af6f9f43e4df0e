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
from avard.daemon.config_types import Config, SensorConfig
from avard.daemon.hw.pacing import (
    FILL_TARGET_PROCESS,
    HELD_HZ_PROCESS_FIFO,
    drain_period_s,
    reader_in_process,
)
from avard.daemon.hw.rig import SensorSpec, wiring

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
    several = len(rig) > 1
    if several:
        summary.append(f"  {len(rig)} sensors, each recorded in DATA_DIR/NAME:")
    for s in rig:     # every sensor's rate, drain and real-time note, not only the first's
        poll_hz = effective_poll_hz({"sensor": {"odr_hz": s.odr_hz, "poll_hz": s.poll_hz}})
        # a rig's bus is drained by a reader process unless one of its sensors waits on INT1
        int1 = any(o.int1_gpio for o in rig
                   if (o.bus, o.bus_number) == (s.bus, s.bus_number)) if several \
            else bool(s.int1_gpio)
        in_process = reader_in_process(int1)
        if in_process:
            hz = 1.0 / drain_period_s(s.odr_hz, s.poll_hz, FILL_TARGET_PROCESS)
            drains = (f"drained at {hz:g} Hz by {'its bus' if several else 'a'} reader "
                      "process on the hardware (SCHED_FIFO needs the drop-in "
                      "systemd/realtime.conf)")
        else:
            drains = (f"drained at {poll_hz:g} Hz"
                      + (" by its bus's reader thread (INT1 on the bus)" if several else ""))
        where = f"{s.name}: {wiring(SensorSpec.from_config(s).bus)}, " if several else ""
        indent = "  " if several else ""
        summary.append(f"  {indent}{where}ADXL355 at {s.odr_hz:g} Hz ODR, ±{s.range_g} g, "
                       f"{drains}" + (f", sync {s.sync}" if several else ""))
        note = realtime_note(s, rig=several and not in_process)
        if note:
            summary.append(f"  {indent}note: {note}")
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


#: The rate a reader thread (the service's own, sharing the GIL) held free of FIFO overruns
#: beside a CPU-bound process on a 2-core machine (2026-11-27, docs/service.md).
HELD_HZ_THREAD = 125.0


def realtime_note(sensor: SensorConfig, *, rig: bool = False) -> str:
    """What was measured at this ODR on the real clock beside a CPU-bound process (pacing.py's
    HELD_HZ_PROCESS_FIFO, docs/service.md), when it is not "no overrun"; "" when it is.
    ``rig``: the sensor is one of several, drained by its bus's reader thread (a sensor of
    its bus waits on INT1)."""
    odr = sensor.odr_hz
    after = ("; each overrun is a recorded gap of counted size (docs/service.md, python -m "
             "benchmarks realtime)")
    if rig:
        if odr <= HELD_HZ_THREAD:
            return ""
        return (f"at {odr:g} Hz ({sensor.name}) the FIFO holds {32e3 / odr:.3g} ms: the "
                "sensors of a bus with INT1 are "
                "drained by a reader thread, which shares the GIL with the service's "
                f"other threads and held only {HELD_HZ_THREAD:g} Hz free of FIFO overruns "
                "beside a CPU-bound process (the reader process, which held "
                f"{HELD_HZ_PROCESS_FIFO:g} Hz for one sensor, drains a bus without INT1)"
                + after)
    if sensor.int1_gpio:
        return ("with INT1 the FIFO is drained by the service's thread, which shares the GIL "
                "and was not measured free of FIFO overruns beside a CPU-bound process; "
                f"without int1_gpio a reader process at SCHED_FIFO held up to "
                f"{HELD_HZ_PROCESS_FIFO:g} Hz" + after)
    if odr <= HELD_HZ_PROCESS_FIFO:
        return ""
    return (f"at {odr:g} Hz the FIFO holds {32e3 / odr:.3g} ms: beside a CPU-bound process on "
            f"a 2-core machine only {HELD_HZ_PROCESS_FIFO:g} Hz was measured free of FIFO "
            "overruns (the reader process at SCHED_FIFO, systemd/realtime.conf): the "
            "machine's own stalls outlast the FIFO" + after)


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
