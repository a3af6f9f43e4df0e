"""The service's reader on the real clock: overruns per minute, and every loss checked against
a sample-encoded counter.

``python -m benchmarks realtime [--seconds 60] [--rates 125,4000] [--hog N]
[--reader thread|process] [--rt PRIORITY] [--gil-load N]``

The emulated ADXL355 produces sets on CLOCK_MONOTONIC (the emulator's clock at ``speed=1``: it
does not wait for the reader, so a reader that is late overruns the FIFO exactly as the part
does), fed by the emulator's counter source: set k carries k in its data. The reader is the
service's own (``Acquisition``: pacing from the fitted rate, the driver's drain, the time base,
the loss accounting) pushing into a ring stand-in that checks, for every block, the index the
reader gave against the counter. ``--hog N`` runs N CPU-bound processes (``yes >/dev/null``)
beside it, as the issue's acceptance run does. ``--reader process`` runs the drain loop in
the reader process (daemon/hw/drain_process.py: the emulator lives there, as the chip would be
read there), ``--rt`` asks SCHED_FIFO for the drain loop, ``--gil-load N`` keeps N Python
threads busy in the service's process (its Allan, recorder and publisher threads). Reported
per rate:

- sets the emulator produced, received, and lost by the counter (the truth);
- overruns (gap records from the driver), per minute, and the sets their gaps claim;
- ``unaccounted`` gaps: losses the chip did not report that the reader found from time;
- the largest difference between the index given to a set and its counter (the index must
  stay with the true count: a gap of the wrong size shows here), and the reader's CPU;
- per drain: the interval from the drain before (how late the reader came: the FIFO lasts 32
  sets) and the drain's own duration, percentiles p50/p99/p99.9/max.

Timing on a loaded machine is pessimistic: the figures are what this machine gave at the
time, with the load stated (``os.getloadavg`` before the run).
"""

from __future__ import annotations

import argparse
import logging
import os
import resource
import subprocess
import threading
import time
from typing import Any, ClassVar

import numpy as np
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.drain_process import ReaderProcess, ReaderSpec
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.pacing import drain_period_s
from avard.daemon.hw.thread_priority import raise_thread_priority
from avard.daemon.hw.timebase import SystemClock, TimeBase
from avard.daemon.hw.transport import SpiBus
from avard.daemon.service.acquisition import Acquisition, BusReader

WRAP = 1 << 19   # the counter source's modulus


class CheckingRing:
    """Stands in for the ring: checks each pushed block's indices against its counter."""

    capacity = 1 << 30
    consumers: ClassVar[list[Any]] = []

    def __init__(self) -> None:
        self.received = 0
        self.first: tuple[int, int] | None = None     # (index, counter) of the first set
        self.max_offset = 0            # largest |index drift| against the counter, sets
        self.true_lost = 0             # sets missing by the counter
        self.last_counter: int | None = None
        self.gaps: list[dict] = []
        self.disorder = 0              # counter not increasing by one inside a block

    def push(self, counts: np.ndarray, index: np.ndarray, t_mono: np.ndarray) -> None:
        c = counts[:, 0].astype(np.int64)
        if self.first is None:
            self.first = (int(index[0]), int(c[0]))
            # set k carries k from the start of measurement: the sets before the first
            # received are lost too (a late first drain)
            self.true_lost += int(c[0])
        elif self.last_counter is not None:
            self.true_lost += int((c[0] - self.last_counter - 1) % WRAP)
        self.disorder += int(np.count_nonzero(np.diff(c) % WRAP != 1))
        self.last_counter = int(c[-1])
        # the true number of this block's first set: every set before it received or lost
        off = int(index[0]) - (self.received + self.true_lost)
        self.max_offset = max(self.max_offset, abs(off))
        self.received += len(c)

    def mark(self, rec: dict) -> None:
        if rec["kind"] == "gap":
            self.gaps.append(rec)


def realtime_rig(odr_hz: float) -> tuple[Adxl355, EmulatedAdxl355, VirtualClock]:
    """The driver over the counter-fed emulator on the real clock, configured, not started
    (also bench_driver's real-time run)."""
    clock = VirtualClock(speed=1.0)
    emu = EmulatedAdxl355(counter_source(), clock)
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=2, odr_hz=odr_hz)
    return dev, emu, clock


class DrainLog:
    """Wraps a source's ``drain``: each drain's interval from the one before (its
    ``since_last_s``: the chip's view of how late the reader came) and its duration (``t_mono``
    to ``t_mono_end``: the bus transfers and decoding, pre-emptions included), seconds."""

    def __init__(self, drain: Any) -> None:
        self._drain = drain
        self.intervals: list[float] = []
        self.durations: list[float] = []

    def __call__(self, max_sets: int | None = None) -> Any:
        d = self._drain(max_sets)
        if d.since_last_s is not None:
            self.intervals.append(d.since_last_s)
        self.durations.append(d.t_mono_end - d.t_mono)
        return d

    @staticmethod
    def percentiles_ms(values: list[float]) -> tuple[float, ...]:
        if not values:
            return (float("nan"),) * 4
        return tuple(float(v) * 1e3 for v in np.percentile(values, [50, 99, 99.9, 100]))


def gil_load(stop: threading.Event) -> None:
    """Stands for the service's other threads (Allan, recorder, publisher): Python and numpy
    work that takes the GIL back as soon as it can."""
    a = np.random.default_rng(0).random(20_000)
    while not stop.is_set():
        x = 0
        for i in range(2_000):
            x += i * i
        np.cumsum(a)


def run_realtime(odr_hz: float, seconds: float, poll_hz: float = 4.0, *, reader: str = "thread",
                 rt_priority: int = 0, gil_threads: int = 0) -> dict[str, Any]:
    ring = CheckingRing()
    proc: ReaderProcess | None = None
    emu: EmulatedAdxl355 | None = None
    source: Any
    if reader == "process":
        spec = ReaderSpec("avard.daemon.hw.drain_process:open_emulated", {"odr_hz": odr_hz},
                          poll_hz=poll_hz, rt_priority=rt_priority)
        proc = ReaderProcess(spec).start()
        source, clock = proc, SystemClock()
    else:
        dev, emu, clock = realtime_rig(odr_hz)
        dev.start()
        source = dev
    drains = DrainLog(source.drain)
    source.drain = drains
    acq = Acquisition(source, ring, TimeBase(odr_hz), clock, poll_hz=poll_hz)  # type: ignore[arg-type]
    bus = BusReader([acq])
    cpu: dict[str, float] = {}
    stop = threading.Event()
    loaders = [threading.Thread(target=gil_load, args=(stop,), daemon=True)
               for _ in range(gil_threads)]

    def timed_run() -> None:
        if reader == "thread" and rt_priority:
            raise_thread_priority(rt_priority)
        t0 = time.thread_time()
        bus._run()
        cpu["reader"] = time.thread_time() - t0

    c0 = _children_cpu()
    for t in loaders:
        t.start()
    thread = threading.Thread(target=timed_run, name="avard-reader", daemon=True)
    thread.start()
    time.sleep(seconds)
    bus.stop()
    thread.join(5.0)
    stop.set()
    if proc is not None:
        proc.close()
    child_cpu = _children_cpu() - c0
    claimed = sum(int(g["n"]) for g in ring.gaps)
    minutes = seconds / 60.0
    produced = ring.received + ring.true_lost
    return {
        "odr": odr_hz, "seconds": seconds, "reader": reader, "rt": rt_priority,
        "gil": gil_threads, "produced": emu.produced_total if emu is not None else produced,
        "received": ring.received, "true_lost": ring.true_lost,
        "overruns": acq.overruns, "per_min": acq.overruns / minutes, "claimed": claimed,
        "unaccounted": acq.unaccounted, "max_offset": ring.max_offset,
        "disorder": ring.disorder,
        "reader_cpu_per_s": (cpu.get("reader", float("nan")) + child_cpu) / seconds,
        "interval_ms": DrainLog.percentiles_ms(drains.intervals),
        "drain_ms": DrainLog.percentiles_ms(drains.durations),
        "drain_period_s": (acq.period if proc is None
                           else drain_period_s(odr_hz, poll_hz, proc.spec.fill)),
        "error": repr(acq.error) if acq.error else "",
    }


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks realtime", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=60.0, help="real seconds per rate")
    p.add_argument("--rates", default="125,4000", help="ODRs in Hz, comma separated")
    p.add_argument("--hog", type=int, default=0, help="CPU-bound `yes` processes beside it")
    p.add_argument("--poll-hz", type=float, default=4.0, help="[sensor] poll_hz (the least "
                   "drain rate; a reader thread drains every half FIFO anyway, the reader "
                   "process every quarter)")
    p.add_argument("--reader", choices=("thread", "process"), default="thread",
                   help="the drain loop in the reader thread, or in its own process "
                   "(hw/drain_process.py) feeding the reader thread through a pipe")
    p.add_argument("--rt", type=int, default=0, metavar="PRIORITY",
                   help="SCHED_FIFO priority of the drain loop (0: normal scheduling)")
    p.add_argument("--gil-load", type=int, default=0, metavar="N",
                   help="N threads of Python/numpy work in the service's process, standing "
                   "for its Allan, recorder and publisher threads")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    load = os.getloadavg()
    hogs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(args.hog)]
    rows = []
    try:
        for odr in (float(r) for r in args.rates.split(",")):
            rows.append(run_realtime(odr, args.seconds, args.poll_hz, reader=args.reader,
                                     rt_priority=args.rt, gil_threads=args.gil_load))
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    load_after = os.getloadavg()
    sched = f"SCHED_FIFO {args.rt}" if args.rt else "normal scheduling"
    print(f"the service's reader on the real clock, {args.seconds:g} s per rate, drain loop in "
          f"its {args.reader}, {sched}, {args.gil_load} GIL-load thread(s), {args.hog} `yes` "
          f"hog(s) beside it, {os.cpu_count()} CPUs, load average before {load[0]:.2f} "
          f"{load[1]:.2f} {load[2]:.2f}, after {load_after[0]:.2f}")
    hdr = (f"{'ODR Hz':>7} {'produced':>9} {'received':>9} {'lost (counter)':>14} "
           f"{'claimed by gaps':>15} {'overruns':>8} {'/min':>6} {'unacc.':>6} "
           f"{'max |index-true|':>16} {'reader CPU-s/s':>14}")
    print(hdr)
    print("-" * len(hdr))
    bad = False
    for r in rows:
        print(f"{r['odr']:7g} {r['produced']:9d} {r['received']:9d} {r['true_lost']:14d} "
              f"{r['claimed']:15d} {r['overruns']:8d} {r['per_min']:6.1f} "
              f"{r['unaccounted']:6d} {r['max_offset']:16d} {r['reader_cpu_per_s']:14.4f}"
              + (f"  ERROR {r['error']}" if r["error"] else ""))
        bad |= bool(r["disorder"] or r["error"])
    print("lost (counter) = sets missing from the counter sequence (the truth); claimed = sum "
          "of the reader's gap records; max |index-true| = largest drift of the index from "
          "the counter, sets (each gap is an estimate from time: a few sets); reader CPU "
          "includes the reader process's")
    print(f"\n{'ODR Hz':>7} {'FIFO ms':>8} {'drain period ms':>15}   drain-to-drain interval ms "
          "p50 / p99 / p99.9 / max   drain duration ms p50 / p99 / p99.9 / max")
    for r in rows:
        iv = " / ".join(f"{v:.2f}" for v in r["interval_ms"])
        du = " / ".join(f"{v:.3f}" for v in r["drain_ms"])
        print(f"{r['odr']:7g} {32e3 / r['odr']:8.2f} {r['drain_period_s'] * 1e3:15.2f}   "
              f"{iv:>46}   {du:>36}")
    return 1 if bad else 0
