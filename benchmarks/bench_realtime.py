"""The service's reader on the real clock: overruns per minute, and every loss checked against
a sample-encoded counter.

``python -m benchmarks realtime [--seconds 60] [--rates 125,4000] [--hog N]``

The emulated ADXL355 produces sets on CLOCK_MONOTONIC (the emulator's clock at ``speed=1``: it
does not wait for the reader, so a reader that is late overruns the FIFO exactly as the part
does), fed by the emulator's counter source: set k carries k in its data. The reader is the
service's own (``Acquisition``: pacing from the fitted rate, the driver's drain, the time base,
the loss accounting) pushing into a ring stand-in that checks, for every block, the index the
reader gave against the counter. ``--hog N`` runs N CPU-bound processes (``yes >/dev/null``)
beside it, as the issue's acceptance run does. Reported per rate:

- sets the emulator produced, received, and lost by the counter (the truth);
- overruns (gap records from the driver), per minute, and the sets their gaps claim;
- ``unaccounted`` gaps: losses the chip did not report that the reader found from time;
- the largest difference between the index given to a set and its counter (the index must
  stay with the true count: a gap of the wrong size shows here), and the reader's CPU.

Timing on a loaded machine is pessimistic: the figures are what this machine gave at the
time, with the load stated (``os.getloadavg`` before the run).
"""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import threading
import time
from typing import Any, ClassVar

import numpy as np
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.timebase import TimeBase
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
        if self.last_counter is not None:
            self.true_lost += int((c[0] - self.last_counter - 1) % WRAP)
        self.disorder += int(np.count_nonzero(np.diff(c) % WRAP != 1))
        self.last_counter = int(c[-1])
        # true number of set k since the first: counter difference (unwrapped by the total)
        true = self.first[1] + self.received + self.true_lost   # counter of c[0], unwrapped
        off = int(index[0]) - (true - self.first[1] + self.first[0])
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


def run_realtime(odr_hz: float, seconds: float, poll_hz: float = 4.0) -> dict[str, Any]:
    dev, emu, clock = realtime_rig(odr_hz)
    ring = CheckingRing()
    dev.start()
    acq = Acquisition(dev, ring, TimeBase(odr_hz), clock, poll_hz=poll_hz)  # type: ignore[arg-type]
    reader = BusReader([acq])
    cpu: dict[str, float] = {}

    def timed_run() -> None:
        t0 = time.thread_time()
        reader._run()
        cpu["reader"] = time.thread_time() - t0

    thread = threading.Thread(target=timed_run, name="avard-reader", daemon=True)
    thread.start()
    time.sleep(seconds)
    reader.stop()
    thread.join(5.0)
    claimed = sum(int(g["n"]) for g in ring.gaps)
    minutes = seconds / 60.0
    return {
        "odr": odr_hz, "seconds": seconds, "produced": emu.produced_total,
        "received": ring.received, "true_lost": ring.true_lost, "emu_lost": emu.lost,
        "overruns": acq.overruns, "per_min": acq.overruns / minutes, "claimed": claimed,
        "unaccounted": acq.unaccounted, "max_offset": ring.max_offset,
        "disorder": ring.disorder, "reader_cpu_per_s": cpu.get("reader", float("nan")) / seconds,
        "drain_period_s": acq.period, "error": repr(acq.error) if acq.error else "",
    }


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks realtime", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=60.0, help="real seconds per rate")
    p.add_argument("--rates", default="125,4000", help="ODRs in Hz, comma separated")
    p.add_argument("--hog", type=int, default=0, help="CPU-bound `yes` processes beside it")
    p.add_argument("--poll-hz", type=float, default=4.0, help="[sensor] poll_hz (the least "
                   "drain rate; the reader drains every half FIFO anyway)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    load = os.getloadavg()
    hogs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(args.hog)]
    rows = []
    try:
        for odr in (float(r) for r in args.rates.split(",")):
            rows.append(run_realtime(odr, args.seconds, args.poll_hz))
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    print(f"the service's reader on the real clock, {args.seconds:g} s per rate, "
          f"{args.hog} `yes` hog(s) beside it, {os.cpu_count()} CPUs, load average before "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
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
          "the counter, sets (each gap is an estimate from time: a few sets)")
    return 1 if bad else 0
