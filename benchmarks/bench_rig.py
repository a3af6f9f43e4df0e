"""CPU of the service per second with several sensors against one, at real time (issue 28).

``python -m benchmarks rig [--seconds S] [--sensors 3] [--odr 125]``

Three runs in this process, one after the other, each at ``--speed 1`` (real time) for
``--seconds`` of clock, recording into a temporary directory and publishing on loopback (no
subscriber), at ``--odr``:

- ``service``: today's one-sensor service (daemon/compose.py simulated_service, preset
  quiet-lab: the simulator's DS18B20s too);
- ``rig of 1``: the RigService over one emulated ADXL355 (daemon/hw/simulation.emulated_rig);
- ``rig of N``: the RigService over N emulated ADXL355s on one bed, one reader thread (a
  simulated rig's virtual clock is stepped by its reader), with the live separation of the
  first three (daemon/service/rig_separation.py; its thread's CPU is printed apart: the
  computation at stop is once per run, so a short run overstates it per second).

Measured: CPU seconds of the process (all threads, ``time.process_time``) per second of clock,
and per run the overruns, estimated losses and unaccounted losses summed over the sensors
(each must be 0). The check of issue 28: rig of N ≤ N × the one-sensor figure, 0 overruns.
Wall-clock pacing depends on the machine's load: report the ratios, and say the load.
"""

from __future__ import annotations

import argparse
import logging
import os
import tempfile
import time
from typing import Any

from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config, validate_config
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import build_lanes, describe_rig
from avard.daemon.service.rig_service import RigService

_SENSORS = [{"name": "left", "spi_device": 0}, {"name": "right", "spi_device": 1},
            {"name": "far", "spi_bus": 1}, {"name": "i2c", "bus": "i2c", "i2c_address": 0x53},
            {"name": "i2c2", "bus": "i2c", "i2c_address": 0x1D}]


def _common(odr: float, data_dir: str) -> dict[str, Any]:
    return {"recording": {"data_dir": data_dir},
            "publish": {"endpoint": "tcp://127.0.0.1:0", "request_endpoint": "tcp://127.0.0.1:0",
                        "hwm": 1_000_000},
            "service": {"status_log_interval_s": 3600.0}, "temperature": {"ds18b20": False}}


def _measure(svc: Any, seconds: float) -> tuple[float, float]:
    c0, w0 = time.process_time(), time.monotonic()
    svc.run(seconds)
    return time.process_time() - c0, time.monotonic() - w0


def _losses(lanes: list[Any]) -> tuple[int, int, int]:
    acqs = [lane.acq for lane in lanes]
    return (sum(a.overruns for a in acqs), sum(a.lost_estimate for a in acqs),
            sum(a.unaccounted for a in acqs))


def run_one(odr: float, seconds: float) -> tuple[float, tuple[int, int, int]]:
    with tempfile.TemporaryDirectory() as d:
        raw = _common(odr, d)
        cfg = load_config(None, **{"sensor.odr_hz": odr, "recording.data_dir": d,
                                   "publish.endpoint": raw["publish"]["endpoint"],
                                   "publish.request_endpoint": raw["publish"]["request_endpoint"],
                                   "publish.hwm": 1_000_000,
                                   "service.status_log_interval_s": 3600.0})
        svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, speed=1.0)
        cpu, _wall = _measure(svc, seconds)
        return cpu / seconds, _losses([svc])


def run_rig(odr: float, seconds: float, n: int) -> tuple[float, tuple[int, int, int]]:
    with tempfile.TemporaryDirectory() as d:
        raw = _common(odr, d)
        raw["sensor"] = [{**s, "odr_hz": odr} for s in _SENSORS[:n]]
        if n == 1:
            raw["sensor"] = [{**_SENSORS[0], "odr_hz": odr}]
        config = Config.from_dict(validate_config(raw))
        svc = RigService(config, build_lanes(describe_rig(config, simulate="quiet-lab", seed=1,
                                                          speed=1.0)))
        cpu, _wall = _measure(svc, seconds)
        if svc.separation is not None:
            # the live separation's thread (rig_separation.py), within the figure above
            sep = svc.separation.cpu_s
            print(f"  rig of {n}: live separation thread {sep['feed'] / seconds:.4f} CPU-s/s "
                  f"aligning and feeding the pairs, {sep['separation']:.2f} CPU-s computing "
                  f"{svc.separation.stage.computed} separations (the last at stop)")
        return cpu / seconds, _losses(list(svc.lanes))


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks rig", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=30.0, help="clock seconds per run")
    p.add_argument("--sensors", type=int, default=3, choices=range(2, len(_SENSORS) + 1))
    p.add_argument("--odr", type=float, default=125.0)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    print(f"rig benchmark: {args.seconds:g} s each at {args.odr:g} Hz, real time; load "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    one, l1 = run_one(args.odr, args.seconds)
    rig1, lr1 = run_rig(args.odr, args.seconds, 1)
    rign, lrn = run_rig(args.odr, args.seconds, args.sensors)
    rows = [("service (1 sensor)", one, l1), ("rig of 1", rig1, lr1),
            (f"rig of {args.sensors}", rign, lrn)]
    print(f"{'run':<20}{'CPU-s/s':>10}{'overruns':>10}{'lost':>8}{'unacc.':>8}")
    for name, cpu, (ov, lost, un) in rows:
        print(f"{name:<20}{cpu:>10.4f}{ov:>10d}{lost:>8d}{un:>8d}")
    print(f"rig of {args.sensors} / service (1 sensor): {rign / one:.2f} "
          f"(asked ≤ {args.sensors}); / rig of 1: {rign / rig1:.2f}")
    ok = rign <= args.sensors * one and lrn[0] == 0
    print("check:", "met" if ok else "NOT met")
    return 0
