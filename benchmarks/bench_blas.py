"""avard's computations with OpenBLAS's default thread pool against one BLAS thread
(``avard.core.blas.one_blas_thread``, what the Python API does), measured in one run.

    python -m benchmarks blas                # 3 channels × 2^21 samples
    python -m benchmarks blas --log2n 19     # shorter

It re-runs itself in a child with OPENBLAS_NUM_THREADS / OMP_NUM_THREADS unset, so that numpy
starts its default pool (one thread per core) whatever the calling shell says. The pool is
reached by calling the entry points' undecorated functions (``__wrapped__``).

Table 1: wall time, CPU time of the whole process and of the BLAS worker threads, per
computation, and the ratio one thread / pool. Table 2: what the guard costs per call against
a one-second block of the service (125 samples × 3). Table 3: one-thread sums of products of
two vectors (np.dot, einsum, multiply-and-reduce) against np.dot with the pool, for the
lengths avard's kernels use (the lag-1 products of noise_id.row_products).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

_CHILD = "AVARD_BENCH_BLAS_CHILD"


def _worker_seconds() -> float:
    """CPU seconds of every thread of this process but the main one (the BLAS workers)."""
    main_tid = threading.get_native_id()
    ticks = 0
    for tid in os.listdir("/proc/self/task"):
        if int(tid) == main_tid:
            continue
        try:
            with open(f"/proc/self/task/{tid}/stat") as fh:
                f = fh.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        ticks += int(f[11]) + int(f[12])
    return ticks / os.sysconf("SC_CLK_TCK")


def _measure(fn: Callable[[], object]) -> tuple[float, float, float]:
    time.sleep(0.3)  # let the workers of the previous run stop spinning
    w0, c0, t0 = _worker_seconds(), time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0, _worker_seconds() - w0


def _computations(log2n: int) -> dict[str, tuple[Callable[[], object], Callable[[], object]]]:
    from avard.core.allan.deviations import allan_variance
    from avard.core.allan.overlapping import OverlappingAllan
    from avard.core.allan.streaming import StreamingAllan

    y = np.random.default_rng(0).normal(size=(1 << log2n, 3))
    block = 1 << 16

    def streamed(s: Any, pool: bool) -> object:
        """Feed ``y`` to accumulator ``s``; ``pool``: without the one-thread hold."""
        cls = type(s)
        upd = cls.update.__wrapped__ if pool else cls.update
        res = cls.result.__wrapped__ if pool else cls.result
        for i in range(0, len(y), block):
            upd(s, y[i:i + block])
        return res(s)

    def cascade(pool: bool) -> object:
        return streamed(StreamingAllan(3, 100.0), pool)

    def oadev(pool: bool) -> object:
        return streamed(OverlappingAllan(3, 100.0, 2 ** np.arange(log2n - 2)), pool)

    def batch(pool: bool) -> object:
        f = allan_variance.__wrapped__ if pool else allan_variance  # type: ignore[attr-defined]
        return f(y, 100.0, "octave", kind="oavar")

    return {name: (lambda g=g: g(True), lambda g=g: g(False))
            for name, g in (("StreamingAllan (cascade)", cascade),
                            ("OverlappingAllan (OADEV)", oadev),
                            ("allan_variance oavar (batch)", batch))}


def _child(log2n: int) -> None:
    from avard.core.allan.streaming import StreamingAllan
    from avard.core.blas import active_backends, one_blas_thread, single_blas_thread

    libs = ", ".join(f"{os.path.basename(b.path)} ({'per thread' if b.local else 'global'})"
                     for b in active_backends()) or "none found"
    print(f"{os.cpu_count()} CPUs; OpenBLAS: {libs}; 3 channels × 2^{log2n} samples\n")
    print("| computation | pool: wall s | CPU s | workers' CPU s | one thread: wall s | CPU s |"
          " workers' CPU s | wall ratio one/pool | CPU ratio one/pool |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, (pool, one) in _computations(log2n).items():
        p = _measure(pool)
        o = _measure(one)
        print(f"| {name} | {p[0]:.2f} | {p[1]:.2f} | {p[2]:.2f} | {o[0]:.2f} | {o[1]:.2f} | "
              f"{o[2]:.2f} | {o[0] / p[0]:.2f} | {o[1] / max(p[1], 1e-9):.2f} |")

    def noop() -> None:
        return None

    held = one_blas_thread(noop)
    reps = 20000
    t0 = time.perf_counter()
    for _ in range(reps):
        noop()
    t1 = time.perf_counter()
    for _ in range(reps):
        held()
    guard = ((time.perf_counter() - t1) - (t1 - t0)) / reps
    s = StreamingAllan(3, 125.0)
    blk = np.random.default_rng(1).normal(size=(125, 3))
    for _ in range(50):
        s.update(blk)
    t0 = time.perf_counter()
    for _ in range(500):
        s.update(blk)
    upd = (time.perf_counter() - t0) / 500
    print("\n| per call | µs | ratio to the update |\n|---|---|---|")
    print(f"| one_blas_thread on a call (hold, give back) | {guard * 1e6:.1f} | "
          f"{guard / upd:.3f} |")
    print(f"| StreamingAllan.update, 125 × 3 samples (with guard) | {upd * 1e6:.1f} | 1 |")

    print("\n| n | np.dot, pool µs | np.dot, one thread µs | einsum 'i,i->' | "
          "np.add.reduce(x*y) | ratios to np.dot one thread: pool / einsum / reduce |")
    print("|---|---|---|---|---|---|")
    rng = np.random.default_rng(2)
    for n in (8192, 1 << 16, 1 << 20):
        x, z = rng.normal(size=n), rng.normal(size=n)
        k = max(20, (1 << 24) // n)

        def per_call(f: Callable[[], object], k: int = k) -> float:
            t = time.perf_counter()
            for _ in range(k):
                f()
            return (time.perf_counter() - t) / k * 1e6

        time.sleep(0.3)
        dot_pool = per_call(lambda x=x, z=z: np.dot(x, z))
        with single_blas_thread():
            dot_one = per_call(lambda x=x, z=z: np.dot(x, z))
            ein = per_call(lambda x=x, z=z: np.einsum("i,i->", x, z))
            red = per_call(lambda x=x, z=z: np.add.reduce(x * z))
        print(f"| {n} | {dot_pool:.1f} | {dot_one:.1f} | {ein:.1f} | {red:.1f} | "
              f"{dot_pool / dot_one:.2f} / {ein / dot_one:.2f} / {red / dot_one:.2f} |")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks blas", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--log2n", type=int, default=21, help="samples per channel, log2")
    args = ap.parse_args(argv)
    if os.environ.get(_CHILD):
        _child(args.log2n)
        return 0
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    env[_CHILD] = "1"
    return subprocess.call([sys.executable, "-m", "benchmarks", "blas", *argv], env=env)
