"""Peak memory and CPU of each long-τ statistic (``avard analyze --stat NAME``) on a long
record, each in a fresh process.

    python -m benchmarks longtau [--hours 60] [--stats mdev,totdev,...]

The record is ``bench_analyze``'s (default 60 h at 100 Hz, 21.6 M samples × 3 axes, float64
m/s², a 518 MB .npz). Each worker runs ``analysis.statistics.compute_statistics`` for one
statistic on the three axes (the pass over the file that averages it, then the statistic with
EDF, α and bounds; "dynamic" is the dynamic ADEV with its default window), and reports its CPU
seconds and its peak RSS (VmHWM: the whole process, interpreter and numpy included). The
statistics must each stay within 300 MB (issue 24). The analysis itself (``benchmarks
analyze``) is not part of these figures: it runs before them and is unchanged.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .bench_allan import RATE_HZ, _peak_rss_mb
from .bench_analyze import make_npz

LIMIT_MB = 300.0


def worker(path: str, stat: str, n: int) -> dict:
    from avard.core.analysis.statistics import StatisticsRequest, compute_statistics
    from avard.core.io.source import open_record

    req = StatisticsRequest(names=() if stat == "dynamic" else (stat,),
                            dynamic=stat == "dynamic")
    t0 = time.process_time()
    rep = compute_statistics(open_record(path), req, rate_hz=RATE_HZ, names=["x", "y", "z"],
                             n_samples=n)
    cpu = time.process_time() - t0
    ch = rep.channels["x"]
    taus = len(ch.dynamic.tau) if ch.dynamic is not None else len(ch.results[stat].tau)
    tau_max = float(ch.dynamic.tau[-1]) if ch.dynamic is not None else \
        float(ch.results[stat].tau[-1])
    return {"cpu_s": cpu, "peak_rss_mb": _peak_rss_mb(), "taus": taus, "tau_max_s": tau_max,
            "averaging": dict(rep.averaging)}


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--worker":
        print(json.dumps(worker(argv[1], argv[2], int(argv[3]))))
        return 0
    from avard.core.allan.longtau import STATISTICS

    ap = argparse.ArgumentParser(prog="python -m benchmarks longtau", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=60.0)
    ap.add_argument("--stats", default=",".join([s for s in STATISTICS if s != "oadev"]
                                                + ["dynamic"]))
    args = ap.parse_args(argv)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    worst = 0.0
    with tempfile.TemporaryDirectory(prefix="avard-bench-") as tmp:
        path, n = make_npz(Path(tmp), args.hours)
        print(f"record: {args.hours:g} h at {RATE_HZ:g} Hz = {n:,} samples × 3 axes, "
              f"{path.stat().st_size / 1e6:.0f} MB .npz")
        print(f"{'statistic':<9} | {'CPU s':>7} | {'peak RSS MB':>11} | τ points | τ max (s) "
              "| averaging")
        for stat in args.stats.split(","):
            cmd = [sys.executable, "-m", "benchmarks.bench_longtau", "--worker", str(path),
                   stat, str(n)]
            out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env,
                                 cwd=Path(__file__).resolve().parents[1])
            r = json.loads(out.stdout.strip().splitlines()[-1])
            worst = max(worst, r["peak_rss_mb"])
            print(f"{stat:<9} | {r['cpu_s']:7.2f} | {r['peak_rss_mb']:11.0f} | "
                  f"{r['taus']:>8} | {r['tau_max_s']:9.4g} | {r['averaging']}", flush=True)
    print(f"\nlargest peak RSS {worst:.0f} MB (limit {LIMIT_MB:.0f} MB): "
          + ("within" if worst <= LIMIT_MB else "OVER"))
    return 0 if worst <= LIMIT_MB else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
