"""A rig of several sensors against one, on the real clock (issue 28): overruns, FIFO
high-water marks, CPU per second and memory.

``python -m benchmarks rig [--seconds S] [--sensors 3] [--odr 125] [--clock real|virtual]
[--hog N] [--no-rt]``

Two runs in this process, one after the other, each for ``--seconds`` of clock, recording into
a temporary directory and publishing on loopback (no subscriber), at ``--odr``:

- ``rig of 1``: the RigService over one emulated ADXL355 (SPI0 CE0);
- ``rig of N``: the RigService over N emulated ADXL355s on one bed (SPI0 CE0, SPI0 CE1,
  I2C 0x53, SPI1, I2C 0x1D, the first N: their emulated transports), with the live
  separation of the first three (daemon/service/rig_separation.py).

``--clock real`` (the default): the emulated parts make their sets on CLOCK_MONOTONIC whether
read or not (daemon/hw/rig.py ``describe_rig(real_clock=True)``), so a reader that comes late
overruns a FIFO exactly as the part would. ``--reader process`` (the default, as the Pi's buses
are built): the parts are made and drained in one reader process (they share the bed);
``--reader thread``: each bus has its reader thread in the service (SCHED_FIFO unless
``--no-rt``).
``--clock virtual``: the reader steps a virtual clock paced at real time (one reader; no
overrun is possible), and a third run, today's one-sensor service (daemon/compose.py
simulated_service), comes first. ``--hog N`` runs N CPU-bound processes (``yes``) beside it.

Printed per sensor: overruns, estimated and unaccounted losses (each must be 0), the FIFO's
high-water mark (the most entries of 96 a drain found; 96 entries = 32 sets = 0.256 s at
125 Hz: the deadline), the longest interval between two drains and the margin left to the
deadline by it. Per run: CPU seconds of the process (all threads, ``time.process_time``) per
second of clock with the reader processes' while the run lasts (from /proc/PID/stat every
0.5 s: their start-up is not in it), per thread name (from /proc/self/task), and the
service's peak RSS sampled every 0.5 s.
The check of issue 28: rig of N ≤ N × rig of 1 in the same run, 0 overruns. Wall-clock pacing
depends on the machine's load: report the ratios, and say the load.
"""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import tempfile
import threading
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config, validate_config
from avard.daemon.config_types import Config
from avard.daemon.hw.pacing import FIFO_SETS
from avard.daemon.hw.registers import FIFO_LOCATIONS
from avard.daemon.hw.rig import build_lanes, describe_rig, wiring
from avard.daemon.service.rig_service import RigService

#: In this order: three sensors are SPI0's two chip selects (one reader drains both) and I2C;
#: four add SPI1, five I2C's second address.
_SENSORS = [{"name": "left", "spi_device": 0}, {"name": "right", "spi_device": 1},
            {"name": "i2c", "bus": "i2c", "i2c_address": 0x53}, {"name": "far", "spi_bus": 1},
            {"name": "i2c2", "bus": "i2c", "i2c_address": 0x1D}]
_PAGE = os.sysconf("SC_PAGE_SIZE")
_TICK = os.sysconf("SC_CLK_TCK")


@dataclass
class Lane:
    name: str
    wiring: str
    overruns: int
    lost: int
    unaccounted: int
    samples: int
    fifo_high_water: int
    max_interval_s: float


@dataclass
class Run:
    name: str
    seconds: float
    cpu_s: float
    rss_peak_mb: float
    lanes: list[Lane]
    threads: dict[str, float] = field(default_factory=dict)   # CPU-s by thread name
    note: str = ""

    @property
    def cpu_per_s(self) -> float:
        return self.cpu_s / self.seconds


class Sampler:
    """Peak RSS and each thread's CPU (utime + stime of /proc/self/task/TID/stat, by the
    Python thread's name), read every ``interval_s`` while a run lasts (a thread that ends
    keeps its last reading: its last interval is lost, the process time is not)."""

    def __init__(self, interval_s: float = 0.5, children: tuple[int, ...] = ()) -> None:
        self.interval_s = interval_s
        self.children = children        # reader processes' pids: their CPU while they run
        self.rss_peak = 0
        self._cpu: dict[int, tuple[str, float]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-sampler", daemon=True)

    def __enter__(self) -> Sampler:
        self._read()
        self._base = {tid: c for tid, (_n, c) in self._cpu.items()}
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self._read()

    def _read(self) -> None:
        with open("/proc/self/statm") as f:
            self.rss_peak = max(self.rss_peak, int(f.read().split()[1]) * _PAGE)
        names = {t.native_id: t.name for t in threading.enumerate()}
        paths = {tid: (name, f"/proc/self/task/{tid}/stat") for tid, name in names.items()}
        paths.update({-pid: ("reader process(es)", f"/proc/{pid}/stat")
                      for pid in self.children})
        for tid, (name, path) in paths.items():
            try:
                with open(path) as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except (OSError, TypeError):
                continue
            self._cpu[int(tid or 0)] = (name, (int(fields[11]) + int(fields[12])) / _TICK)

    def _run(self) -> None:
        while not self._stop.wait(self.interval_s):
            self._read()

    def by_name(self) -> dict[str, float]:
        out: dict[str, float] = defaultdict(float)
        for tid, (name, cpu) in self._cpu.items():
            if name != "bench-sampler":
                out[name] += cpu - self._base.get(tid, 0.0)
        return dict(out)


def _raw(odr: float, data_dir: str, n: int) -> dict[str, Any]:
    return {"recording": {"data_dir": data_dir},
            "publish": {"endpoint": "tcp://127.0.0.1:0", "request_endpoint": "tcp://127.0.0.1:0",
                        "hwm": 1_000_000},
            "service": {"status_log_interval_s": 3600.0}, "temperature": {"ds18b20": False},
            "sensor": [{**s, "odr_hz": odr} for s in _SENSORS[:n]]}


def _lane(lane: Any, where: str) -> Lane:
    a = lane.acq
    return Lane(lane.sensor_name, where, a.overruns, a.lost_estimate, a.unaccounted, a.samples,
                a.fifo_high_water, a.max_drain_interval_s)


def _timed(name: str, svc: Any, seconds: float, children: tuple[int, ...] = ()
           ) -> tuple[Run, Sampler]:
    with Sampler(children=children) as sampler:
        c0 = time.process_time()
        svc.run(seconds)
        cpu = time.process_time() - c0
    threads = sampler.by_name()
    # the reader processes' CPU while the run lasted (read every 0.5 s until they end at
    # stop; their start-up, before the run, is not in it)
    return Run(name, seconds, cpu + threads.get("reader process(es)", 0.0),
               sampler.rss_peak / 1e6, [], threads), sampler


def run_service(odr: float, seconds: float) -> Run:
    """Today's one-sensor service on the stepped clock paced at real time."""
    with tempfile.TemporaryDirectory() as d:
        cfg = load_config(None, **{"sensor.odr_hz": odr, "recording.data_dir": d,
                                   "publish.endpoint": "tcp://127.0.0.1:0",
                                   "publish.request_endpoint": "tcp://127.0.0.1:0",
                                   "publish.hwm": 1_000_000,
                                   "service.status_log_interval_s": 3600.0})
        svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, speed=1.0)
        run, _s = _timed("service (1 sensor)", svc, seconds)
        run.lanes = [_lane(svc, "SPI0 CE0")]
        return run


def run_rig(odr: float, seconds: float, n: int, *, real_clock: bool, rt: bool = True,
            reader: str = "process") -> Run:
    with tempfile.TemporaryDirectory() as d:
        config = Config.from_dict(validate_config(_raw(odr, d, n)))
        spec = describe_rig(config, simulate="quiet-lab", seed=1, speed=1.0,
                            real_clock=real_clock)
        built = build_lanes(spec, reader_process=reader == "process")
        svc = RigService(config, built, **({} if rt else {"reader_rt_priority": 0}))
        pids = {int(str(lane.info["reader"]).split()[-1]) for lane in built.lanes
                if "reader" in lane.info}
        run, _s = _timed(f"rig of {n}", svc, seconds, tuple(sorted(pids)))
        run.lanes = [_lane(lane, wiring(s.bus))
                     for lane, s in zip(svc.lanes, spec.sensors, strict=True)]
        granted = sum(r.realtime for r in svc.readers)
        procs = {lane.sensor_info.get("reader") for lane in svc.lanes} - {None}
        run.note = (f"{len(svc.readers)} reader thread(s), {granted} of them SCHED_FIFO"
                    + (f", draining {', '.join(sorted(map(str, procs)))}" if procs else ""))
        if svc.separation is not None:
            sep = svc.separation.cpu_s
            run.note += (f"; live separation: {sep['feed'] / seconds:.4f} CPU-s/s aligning "
                         f"and feeding the pairs, {sep['separation']:.2f} CPU-s computing "
                         f"{svc.separation.stage.computed} separations (the last at stop)")
        return run


def _print_run(run: Run, odr: float) -> None:
    deadline = FIFO_SETS / odr
    print(f"{run.name}: {run.cpu_per_s:.4f} CPU-s/s, peak RSS {run.rss_peak_mb:.1f} MB; "
          f"{run.note}")
    print(f"  {'sensor':<8}{'wiring':<32}{'samples':>9}{'overruns':>9}{'lost':>6}"
          f"{'unacc.':>7}{'FIFO max':>10}{'drain max':>11}{'margin':>9}")
    for ln in run.lanes:
        print(f"  {ln.name:<8}{ln.wiring:<32}{ln.samples:>9d}{ln.overruns:>9d}{ln.lost:>6d}"
              f"{ln.unaccounted:>7d}{ln.fifo_high_water:>5d}/{FIFO_LOCATIONS:<4d}"
              f"{ln.max_interval_s:>10.3f}s{deadline - ln.max_interval_s:>8.3f}s")
    threads = sorted(run.threads.items(), key=lambda kv: -kv[1])
    print("  CPU-s/s by thread: " + ", ".join(f"{n} {c / run.seconds:.4f}"
                                              for n, c in threads if c > 0))


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks rig", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=30.0, help="clock seconds per run")
    p.add_argument("--sensors", type=int, default=3, choices=range(2, len(_SENSORS) + 1))
    p.add_argument("--odr", type=float, default=125.0)
    p.add_argument("--clock", choices=("real", "virtual"), default="real")
    p.add_argument("--hog", type=int, default=0, help="CPU-bound processes beside the runs")
    p.add_argument("--reader", choices=("process", "thread"), default="process",
                   help="on the real clock: the parts drained by a reader process (as "
                        "daemon/hw/rig.py builds the Pi's buses) or by the service's threads")
    p.add_argument("--no-rt", action="store_true",
                   help="readers at normal priority (by default they ask for SCHED_FIFO)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    real = args.clock == "real"
    print(f"rig benchmark: {args.seconds:g} s each at {args.odr:g} Hz on the {args.clock} "
          f"clock, {args.hog} CPU hog(s); load {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
          f"cores; FIFO deadline {FIFO_SETS / args.odr:.3f} s ({FIFO_LOCATIONS} entries)")
    hogs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(args.hog)]
    try:
        runs = [] if real else [run_service(args.odr, args.seconds)]
        rt = not args.no_rt
        runs.append(run_rig(args.odr, args.seconds, 1, real_clock=real, rt=rt,
                            reader=args.reader))
        runs.append(run_rig(args.odr, args.seconds, args.sensors, real_clock=real, rt=rt,
                            reader=args.reader))
    finally:
        for h in hogs:
            h.terminate()
            h.wait()
    for run in runs:
        _print_run(run, args.odr)
    one, rig = runs[-2], runs[-1]
    ratio = rig.cpu_per_s / one.cpu_per_s
    overruns = sum(ln.overruns for ln in rig.lanes)
    losses = sum(ln.lost + ln.unaccounted for ln in rig.lanes)
    margin = FIFO_SETS / args.odr - max(ln.max_interval_s for ln in rig.lanes)
    def share(run: Run, readers: bool) -> float:
        r = run.threads.get("reader process(es)", 0.0)
        return (r if readers else run.cpu_s - r) / run.seconds

    if "reader process(es)" in rig.threads and share(one, True) > 0:
        print(f"  of which the service process {share(rig, False) / share(one, False):.2f}× "
              f"({share(rig, False):.4f} / {share(one, False):.4f} CPU-s/s), the reader "
              f"processes {share(rig, True) / share(one, True):.2f}× "
              f"({share(rig, True):.4f} / {share(one, True):.4f})")
    print(f"rig of {args.sensors} / rig of 1: {ratio:.2f} (asked ≤ {args.sensors}); "
          f"overruns {overruns}, losses {losses}; least margin to the FIFO deadline "
          f"{margin:.3f} s of {FIFO_SETS / args.odr:.3f}; load now {os.getloadavg()[0]:.1f}")
    ok = ratio <= args.sensors and overruns == 0 and losses == 0
    print("check:", "met" if ok else "NOT met")
    return 0
