"""ADXL355 driver costs: FIFO decode, one full drain over the emulated SPI bus, real-time run.

``python -m benchmarks driver [--seconds 60] [--poll-ms 2] [--odr 4000]``

1. Decode throughput: the vectorised numpy decode against a naive per-entry Python decode
   (the reference) on the same bytes.
2. One full 32-set drain (1 + 288-byte burst) through SpiBus → FakeSpiDev → emulator, and the
   same through I2cBus; the reference is the time the FIFO takes to fill at 4 kHz (8 ms): the
   ratio is the fraction of one core a 4 kHz acquisition spends draining.
3. A real-time run at the given ODR (default 4 kHz) for ``--seconds`` with a reader thread that
   drains every ``--poll-ms``; it must see zero overruns. The reference is the number of sets
   the emulated chip produced. Every drain-to-drain interval is split into the reader's own
   CPU time (drain and bookkeeping) and the time it was not running (the requested sleep, then
   waiting for a CPU: the run-queue wait from /proc/thread-self/schedstat, or a hypervisor
   that did not run the virtual CPU), so a long interval shows whether the code or the
   scheduler made it; the wake-up lateness covers only the sleep, not a reader preempted
   mid-drain.
"""

from __future__ import annotations

import argparse
import logging
import os
import threading
import time
from collections.abc import Callable

import numpy as np
from avard.daemon.hw.adxl355 import Adxl355, decode_counts, decode_counts_naive, decode_fifo
from avard.daemon.hw.emulator import (
    EmulatedAdxl355,
    FakeSMBus,
    FakeSpiDev,
    VirtualClock,
    counter_source,
    encode_entries,
)
from avard.daemon.hw.thread_priority import raise_thread_priority
from avard.daemon.hw.transport import I2cBus, SpiBus


def _best(fn, repeat: int = 5, number: int = 1) -> float:
    """Best of ``repeat`` runs of ``number`` calls, seconds per call."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def bench_decode(n_sets: int = 32_000) -> list[tuple[str, float, float]]:
    rng = np.random.default_rng(0)
    counts = rng.integers(-(1 << 19), 1 << 19, size=(n_sets, 3))
    raw = encode_entries(counts)
    t_naive = _best(lambda: decode_counts_naive(raw), repeat=3)
    t_vec = _best(lambda: decode_counts(raw), repeat=7)
    assert decode_counts(raw).tolist() == decode_counts_naive(raw)
    t_fifo = _best(lambda: decode_fifo(raw), repeat=7)
    assert np.array_equal(decode_fifo(raw).counts, counts)
    n = 3 * n_sets
    return [("naive Python (reference)", n / t_naive, 1.0),
            ("numpy vectorised", n / t_vec, t_naive / t_vec),
            ("numpy, markers and empty bits checked", n / t_fifo, t_naive / t_fifo)]


def _rig(kind: str) -> tuple[Adxl355, VirtualClock]:
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock)
    bus = SpiBus(FakeSpiDev(emu)) if kind == "spi" else I2cBus(FakeSMBus(emu))
    dev = Adxl355(bus, clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=2, odr_hz=4000)
    dev.start()
    return dev, clock


def bench_full_drain(n: int = 2000) -> list[tuple[str, float, float]]:
    fifo_s = 32 / 4000.0
    rows = [("FIFO fill time at 4 kHz (reference)", fifo_s * 1e6, 1.0)]
    for kind in ("spi", "i2c"):
        dev, clock = _rig(kind)

        def one(dev: Adxl355 = dev, clock: VirtualClock = clock) -> None:
            clock.advance(32 / 4000.0)  # exactly 32 sets waiting
            d = dev.drain()
            assert d.n_sets == 32 and not d.overrun

        t = _best(one, repeat=5, number=n // 5)
        rows.append((f"one 32-set drain, {kind.upper()} bus over the emulator", t * 1e6,
                     t / fifo_s))
    return rows


def _run_queue_wait_reader() -> Callable[[], float] | None:
    """``() -> s`` the calling thread has spent runnable but waiting for a CPU (Linux
    schedstat), or None where the kernel does not provide it."""
    try:
        fd = os.open("/proc/thread-self/schedstat", os.O_RDONLY)
    except OSError:
        return None

    def wait_s() -> float:
        return int(os.pread(fd, 128, 0).split()[1]) * 1e-9

    return wait_s


def bench_realtime(seconds: float, poll_s: float, odr_hz: float,
                   rt_priority: int = 0) -> dict[str, float]:
    from benchmarks.bench_realtime import realtime_rig

    dev, emu, _clock = realtime_rig(odr_hz)
    stop = threading.Event()
    stats = {"sets": 0, "overruns": 0, "drains": 0, "max_gap_s": 0.0, "bad_sequence": 0,
             "silent_breaks": 0, "rt_refused": 0, "max_gap_cpu_s": 0.0, "max_gap_wait_s": -1.0,
             "max_loop_cpu_s": 0.0, "max_drain_s": 0.0, "max_drain_cpu_s": 0.0,
             "gaps_over_fifo": 0, "gaps_over_fifo_cpu": 0}
    lateness: list[float] = []  # how much later than asked the OS woke the reader, s
    fifo_s = 32 / odr_hz

    def reader() -> None:
        if rt_priority and not raise_thread_priority(rt_priority):
            stats["rt_refused"] = 1
        runq = _run_queue_wait_reader()
        last_t = None
        last_cpu = last_wait = 0.0
        expect = 0
        while not stop.is_set():
            # Read just before the drain stamps t_mono, so each drain-to-drain interval gets
            # the CPU time and run-queue wait spent inside it.
            cpu = time.thread_time()
            wait = runq() if runq is not None else -1.0
            w0 = time.perf_counter()
            d = dev.drain()
            drain_s = time.perf_counter() - w0
            if drain_s > stats["max_drain_s"]:
                stats["max_drain_s"] = drain_s
                stats["max_drain_cpu_s"] = time.thread_time() - cpu
            stats["drains"] += 1
            stats["overruns"] += int(d.overrun)
            if d.n_sets:
                if d.counts[0, 0] != expect % (1 << 19):
                    stats["bad_sequence"] += 1
                    # data jumped without the driver saying so: the one unforgivable error
                    stats["silent_breaks"] += int(not d.overrun)
                if np.any(np.diff(d.counts[:, 0]) != 1):
                    stats["silent_breaks"] += 1
                expect = int(d.counts[-1, 0]) + 1
            stats["sets"] += d.n_sets
            if last_t is not None:
                gap, gap_cpu = d.t_mono - last_t, cpu - last_cpu
                stats["max_loop_cpu_s"] = max(stats["max_loop_cpu_s"], gap_cpu)
                if gap > fifo_s:
                    stats["gaps_over_fifo"] += 1
                    stats["gaps_over_fifo_cpu"] += int(gap_cpu > fifo_s - poll_s)
                if gap > stats["max_gap_s"]:
                    stats["max_gap_s"], stats["max_gap_cpu_s"] = gap, gap_cpu
                    stats["max_gap_wait_s"] = wait - last_wait if runq is not None else -1.0
            last_t, last_cpu, last_wait = d.t_mono, cpu, wait
            t0 = time.monotonic()
            time.sleep(poll_s)
            lateness.append(time.monotonic() - t0 - poll_s)

    dev.start()
    th = threading.Thread(target=reader, name="bench-reader")
    th.start()
    time.sleep(seconds)
    stop.set()
    th.join()
    stats["produced"] = emu.produced
    stats["lost"] = emu.lost
    stats["fifo_s"] = 32 / odr_hz
    late = np.asarray(lateness)
    stats["late_p99_s"] = float(np.percentile(late, 99)) if late.size else 0.0
    stats["late_max_s"] = float(late.max()) if late.size else 0.0
    stats["late_over_fifo"] = int(np.sum(late + poll_s > stats["fifo_s"]))
    return stats


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks driver", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=60.0, help="real-time run length, s")
    p.add_argument("--poll-ms", type=float, default=2.0, help="reader sleep between drains, ms")
    p.add_argument("--odr", type=float, default=4000.0, help="ODR of the real-time run, Hz")
    p.add_argument("--rt-priority", type=int, default=0, metavar="N",
                   help="run the reader thread SCHED_FIFO at priority N (1-99; needs "
                   "CAP_SYS_NICE); 0: normal scheduling (default)")
    args = p.parse_args(argv)
    # Overruns are counted in the table; one warning line each would drown it.
    logging.getLogger("avard.daemon.hw.adxl355").setLevel(logging.ERROR)

    print("1. FIFO decode throughput (96 000 entries)")
    print(f"{'method':<40}{'entries/s':>14}{'× reference':>13}")
    for name, rate, ratio in bench_decode():
        print(f"{name:<40}{rate:>14.3e}{ratio:>13.1f}")

    print("\n2. One full FIFO drain (32 sets: status, 288-byte burst, status check)")
    print(f"{'case':<50}{'µs':>10}{'× reference':>13}")
    for name, us, ratio in bench_full_drain():
        print(f"{name:<50}{us:>10.1f}{ratio:>13.4f}")

    sched = f"SCHED_FIFO {args.rt_priority}" if args.rt_priority else "normal scheduling"
    print(f"\n3. Real time, {args.odr:g} Hz ODR, {args.seconds:g} s, reader polls every "
          f"{args.poll_ms:g} ms (FIFO lasts {32 / args.odr * 1e3:g} ms), {sched}")
    load0 = os.getloadavg()[0]
    s = bench_realtime(args.seconds, args.poll_ms / 1e3, args.odr, args.rt_priority)
    if s["rt_refused"]:
        print("(SCHED_FIFO was refused: needs CAP_SYS_NICE; the run used normal scheduling)")
    load1 = os.getloadavg()[0]
    print(f"{'quantity':<40}{'value':>14}")
    print(f"{'sets produced by the chip (reference)':<40}{s['produced']:>14d}")
    print(f"{'sets received by the reader':<40}{s['sets']:>14d}")
    print(f"{'received / produced':<40}{s['sets'] / max(s['produced'], 1):>14.5f}")
    print(f"{'drains':<40}{s['drains']:>14d}")
    print(f"{'overruns (gaps) reported':<40}{s['overruns']:>14d}")
    print(f"{'sets lost in the chip':<40}{s['lost']:>14d}")
    print(f"{'sequence breaks seen in the data':<40}{s['bad_sequence']:>14d}")
    print(f"{'data jumps the driver did not report':<40}{s['silent_breaks']:>14d}")
    print(f"{'longest time between drains, ms':<40}{s['max_gap_s'] * 1e3:>14.2f}")
    print(f"{'  of it the reader on a CPU, ms':<40}{s['max_gap_cpu_s'] * 1e3:>14.2f}")
    print(f"{'  of it the requested sleep, ms':<40}{args.poll_ms:>14.2f}")
    if s["max_gap_wait_s"] >= 0:
        rest = s["max_gap_s"] - s["max_gap_cpu_s"] - s["max_gap_wait_s"] - args.poll_ms / 1e3
        print(f"{'  of it runnable, waiting for a CPU, ms':<40}{s['max_gap_wait_s'] * 1e3:>14.2f}")
        # neither running nor queued: the virtual CPU itself was not run (steal), timer slack
        print(f"{'  of it the rest (steal, timer), ms':<40}{rest * 1e3:>14.2f}")
    else:
        print(f"{'  of it runnable, waiting for a CPU, ms':<40}{'n/a':>14}")
    drain = f"{s['max_drain_s'] * 1e3:.2f}/{s['max_drain_cpu_s'] * 1e3:.2f}"
    print(f"{'longest drain call, wall / CPU, ms':<40}{drain:>14}")
    print(f"{'most reader CPU in one interval, ms':<40}{s['max_loop_cpu_s'] * 1e3:>14.2f}")
    print(f"{'intervals longer than the FIFO lasts':<40}{s['gaps_over_fifo']:>14d}")
    print(f"{'  of them made long by reader CPU':<40}{s['gaps_over_fifo_cpu']:>14d}")
    print(f"{'host load average (1 min), start/end':<40}{f'{load0:.2f}/{load1:.2f}':>14}")
    late = f"{s['late_p99_s'] * 1e3:.2f}/{s['late_max_s'] * 1e3:.1f}"
    print(f"{'reader wake-up lateness p99 / max, ms':<40}{late:>14}")
    print(f"{'sleeps longer than the FIFO lasts':<40}{s['late_over_fifo']:>14d}")
    ok = s["overruns"] == 0 and s["lost"] == 0 and s["bad_sequence"] == 0
    cause = ("the reader thread was not scheduled in time; see the load average" if
             s["gaps_over_fifo_cpu"] == 0 else
             f"{s['gaps_over_fifo_cpu']} long interval(s) had more reader CPU time than the "
             "FIFO lasts: work in the reader's path (or a slowed CPU)")
    print("\nzero overruns: " + ("yes" if ok else f"NO ({cause})"))
    print("every data jump reported as a gap: " + ("yes" if s["silent_breaks"] == 0 else "NO"))
    return 0 if ok and s["silent_breaks"] == 0 else 1
