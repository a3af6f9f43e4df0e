"""How fast the simulator streams a long record, against plain numpy in the same run.

    python -m benchmarks simulate [--hours 60] [--preset paper-table3] [--chunk 131072]

Rows: the simulator (every preset term, 3 axes, counts and temperatures per sample) and, as
the reference, numpy drawing the same number of standard normals in the same chunks (the
least any simulator of white noise has to do). Columns: seconds, samples/s, ratio to the
reference, and the peak RSS growth of the process while it ran (memory must not grow with
the duration). The issue's target: 60 h × 3 axes at 125 Hz in ≤ 20 s.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np
from avard.core.sim.presets import make_config
from avard.core.sim.simulate import SensorSimulator, n_samples


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # Linux: KiB


def _time_chunks(step, n_total: int, chunk: int) -> tuple[float, float]:
    """(wall seconds, CPU seconds of this process): on a shared machine the CPU time is what
    the code costs, the wall time what it took under the current load."""
    t0, c0 = time.perf_counter(), time.process_time()
    done = 0
    while done < n_total:
        k = min(chunk, n_total - done)
        step(k)
        done += k
    return time.perf_counter() - t0, time.process_time() - c0


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks simulate")
    ap.add_argument("--hours", type=float, default=60.0)
    ap.add_argument("--preset", default="paper-table3")
    ap.add_argument("--chunk", type=int, default=1 << 17)
    args = ap.parse_args(argv)
    cfg = make_config(args.preset)
    n = n_samples(cfg, args.hours)

    rss0 = _peak_rss_mb()
    rng = np.random.default_rng(0)
    t_ref = _time_chunks(lambda k: rng.standard_normal((k, 3)), n, args.chunk)
    rss_ref = _peak_rss_mb() - rss0

    sim = SensorSimulator(cfg, seed=0)
    rss1 = _peak_rss_mb()
    t_sim = _time_chunks(sim.next, n, args.chunk)
    rss_sim = _peak_rss_mb() - rss1

    load = os.getloadavg()[0]
    print(f"{args.hours:g} h × 3 axes at {cfg.rate_hz:g} Hz = {n} samples, preset "
          f"{args.preset}, chunk {args.chunk}; load average {load:.1f} on {os.cpu_count()} CPUs")
    print(f"{'generator':<34} {'wall s':>7} {'CPU s':>7} {'Msamples/s':>11} {'CPU ratio':>9} "
          f"{'+peak RSS MB':>13}")
    for name, (wall, cpu), rss in (("numpy standard_normal (reference)", t_ref, rss_ref),
                                   ("SensorSimulator.next", t_sim, rss_sim)):
        print(f"{name:<34} {wall:7.2f} {cpu:7.2f} {n / wall / 1e6:11.2f} "
              f"{cpu / t_ref[1]:9.2f} {rss:13.1f}")
    per60 = 60.0 / args.hours
    verdict = "meets" if t_sim[1] * per60 <= 20.0 else "misses"
    print(f"target ≤ 20 s per 60 h: {verdict} on CPU time ({t_sim[1] * per60:.1f} CPU s, "
          f"{t_sim[0] * per60:.1f} wall s per 60 h)")
    return 0
