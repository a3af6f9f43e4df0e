"""``python -m benchmarks separation_live [--sensors 3] [--samples N] [--block B]``: what the
live separation costs the service (daemon/service/separation_stage.py).

CPU seconds (process time) to feed N aligned samples of 2 or 3 sensors in blocks of B (one
drain) to the SeparationStage (a CrossAllan per pair), against one sensor's own streaming
accumulator (StreamingAllan of x, y, z and a temperature, fed the same blocks) measured in the
same run; the CPU of one separation (the intervals of every τ, part and axis) against one
Allan snapshot; and the state's bytes per pair. Timings on a shared machine vary: read the
ratios.
"""

from __future__ import annotations

import argparse
import time

import msgpack
import numpy as np
from avard.core.allan.streaming import StreamingAllan
from avard.daemon.service.separation_stage import AlignedBlock, SeparationStage


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks separation_live")
    ap.add_argument("--sensors", type=int, default=3, choices=(2, 3))
    ap.add_argument("--samples", type=int, default=1 << 17)
    ap.add_argument("--block", type=int, default=32)
    ap.add_argument("--rate", type=float, default=125.0)
    args = ap.parse_args(argv)
    s, n, b = args.sensors, args.samples, args.block
    rng = np.random.default_rng(1)
    accel = rng.normal(size=(s, n, 3)) * 1e-4
    index = np.tile(np.arange(n, dtype=np.int64), (s, 1))
    names = tuple(f"s{i}" for i in range(s))

    one = StreamingAllan(4, args.rate)
    own = np.column_stack([accel[0], np.full(n, 21.0)])
    t = time.process_time()
    for a in range(0, n, b):
        one.update(own[a:a + b])
    ref = time.process_time() - t

    stage = SeparationStage(names, args.rate)
    t = time.process_time()
    for a in range(0, n, b):
        stage.feed(AlignedBlock(names, index[:, a:a + b], accel[:, a:a + b]))
    fed = time.process_time() - t

    t = time.process_time()
    sep = stage.separation()
    cost = time.process_time() - t
    t = time.process_time()
    one.snapshot()
    snap = time.process_time() - t
    assert sep is not None
    sizes = [len(msgpack.packb(acc.state())) for acc in stage.pairs.values()]
    run_s = n / args.rate
    print(f"{s} sensors, {n} samples ({run_s:.0f} s at {args.rate:g} Hz) in blocks of {b}; "
          "process time, machine shared:")
    print(f"  feed: SeparationStage {fed:.3f} s CPU, one sensor's StreamingAllan {ref:.3f} s "
          f"(ratio {fed / ref:.2f}); {1e3 * fed / run_s:.2f} ms of CPU per second of run")
    print(f"  one separation ({len(sep.axes)} axes, {len(sep.axes[0].tau)} τ): {cost:.3f} s "
          f"CPU, one Allan snapshot {snap:.4f} s (ratio {cost / max(snap, 1e-9):.0f})")
    print(f"  state per pair: {sizes[0]} bytes (msgpack)")
    return 0
