"""Streaming Allan core against allantools on a synthetic ADXL355 + DS18B20 record.

    python -m benchmarks allan [--hours 60] [--fifo-sets 2000000] [--realtime-samples 200000]

The record (default 60 h at 100 Hz: 21.6 M sets) has three axes of raw 20-bit counts (white
noise ~45 LSB rms, a slow bias random walk, 1 g = 256000 LSB on z) and one temperature channel
in DS18B20 raw units (1/16 °C). It is written once to a temporary .npy file, and every
measurement runs in a fresh subprocess so that peak RSS (``ru_maxrss``) is its own:

* allantools ``oadev(y, rate=100, data_type="freq", taus="octave")`` per axis (in m/s²);
* ``StreamingAllan`` (4 channels, full 4×4 Allan covariance) reading the file in blocks of
  65536 sets: throughput, peak RSS, state size (msgpack bytes), snapshot time;
* ``StreamingAllan`` fed FIFO-sized blocks of 32 sets (one ADXL355 FIFO drain);
* allantools ``oadev_realtime`` (octave averaging factors) sample by sample on a prefix;
* the service's use (``--service``): a 5-channel accumulator warmed with 10 h at 125 Hz, then
  fed 10 minutes in 0.1 s batches with a snapshot every 10 s (the service's default
  ``snapshot_interval_s``): CPU seconds per second of data, against the service's whole
  budget at 125 Hz (0.02 CPU-s/s, issue 13).

Ratios are against allantools measured in the same run. Times are process CPU seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import msgpack
import numpy as np

RATE_HZ = 100.0
LSB_MS2 = 9.80665 / 256000.0  # ADXL355 ±2 g: 256000 LSB/g (3.9 µg/LSB)
BLOCK = 1 << 16


def make_record(path: Path, hours: float, seed: int = 1) -> int:
    """Write an (N, 4) int32 record: x, y, z counts and temperature in 1/16 °C."""
    n = round(hours * 3600 * RATE_HZ)
    out = np.lib.format.open_memmap(path, mode="w+", dtype=np.int32, shape=(n, 4))
    rng = np.random.default_rng(seed)
    bias = np.zeros(3)
    temp = 22.0
    for start in range(0, n, 1 << 20):
        k = min(1 << 20, n - start)
        walk = bias + np.cumsum(rng.normal(0.0, 0.02, (k, 3)), axis=0)
        bias = walk[-1]
        axes = rng.normal(0.0, 45.0, (k, 3)) + walk + np.array([0.0, 0.0, 256000.0])
        t = start + np.arange(k)
        temp_c = temp + 0.5 * np.sin(2 * np.pi * t / (RATE_HZ * 3600 * 6)) + \
            rng.normal(0.0, 0.02, k)
        out[start : start + k, :3] = np.rint(axes).astype(np.int32)
        out[start : start + k, 3] = np.rint(temp_c * 16).astype(np.int32)
    out.flush()
    del out
    return n


def read_blocks(path: str, rows: int):
    """Yield (≤ rows, 4) int32 blocks read with plain file reads.

    Not np.memmap: pages of a mapped file count in the reader's resident set, which would
    charge the whole 345 MB file to whichever process touched it.
    """
    with open(path, "rb") as f:
        major, _ = np.lib.format.read_magic(f)
        read_header = (np.lib.format.read_array_header_1_0 if major == 1
                       else np.lib.format.read_array_header_2_0)
        shape, _, _ = read_header(f)
        left = shape[0]
        while left > 0:
            k = min(rows, left)
            yield np.fromfile(f, dtype=np.int32, count=k * shape[1]).reshape(k, shape[1])
            left -= k


def _peak_rss_mb() -> float:
    """Peak resident set of this process image, MB.

    VmHWM, not ru_maxrss: Linux carries ru_maxrss over exec from the forked parent, so a child
    of a big parent would report the parent's peak.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def worker_allantools(path: str, axis: int) -> dict:
    import allantools

    y = np.concatenate([blk[:, axis].astype(np.float64) for blk in read_blocks(path, BLOCK)])
    y *= LSB_MS2
    t0 = time.process_time()
    allantools.oadev(y, rate=RATE_HZ, data_type="freq", taus="octave")
    return {"cpu_s": time.process_time() - t0, "peak_rss_mb": _peak_rss_mb()}


def worker_stream(path: str) -> dict:
    from avard.core.allan.streaming import StreamingAllan

    acc = StreamingAllan(4, RATE_HZ, names=["x", "y", "z", "temp"])
    t0 = time.process_time()
    for blk in read_blocks(path, BLOCK):
        acc.update(blk)
    cpu = time.process_time() - t0
    t1 = time.process_time()
    snaps = 20
    for _ in range(snaps):
        acc.snapshot()
    snap_s = (time.process_time() - t1) / snaps
    state = msgpack.packb(acc.state())
    return {"cpu_s": cpu, "peak_rss_mb": _peak_rss_mb(), "state_bytes": len(state),
            "snapshot_s": snap_s, "n": int(acc.n_samples),
            "taus": int(acc.snapshot().tau.size)}


def worker_fifo(path: str, n_sets: int) -> dict:
    from avard.core.allan.streaming import StreamingAllan

    block = next(read_blocks(path, n_sets))
    n_sets = block.shape[0]
    acc = StreamingAllan(4, RATE_HZ)
    t0 = time.process_time()
    for start in range(0, n_sets, 32):
        acc.update(block[start : start + 32])
    acc.snapshot()  # includes folding in the last pending sets
    return {"cpu_s": time.process_time() - t0, "sets": n_sets}


def worker_realtime(path: str, n: int) -> dict:
    from allantools.realtime import oadev_realtime
    from avard.core.allan.streaming import StreamingAllan

    y = next(read_blocks(path, n))[:, 0].astype(np.float64) * LSB_MS2
    n = y.size
    afs = [2**k for k in range(int(np.log2(n // 2)) + 1)]
    rt = oadev_realtime(afs=afs, tau0=1.0 / RATE_HZ)
    t0 = time.process_time()
    for v in y:
        rt.add_frequency(float(v))
    cpu = time.process_time() - t0
    acc = StreamingAllan(1, RATE_HZ, overlap=1 << 30)  # fully overlapping: same estimator
    acc.update(y)
    ours = acc.result().dev
    k = min(3, ours.size - 1)
    return {"cpu_s": cpu, "samples": n, "their_over_ours_adev": float(rt.dev[k] / ours[k]),
            "tau_s": afs[k] / RATE_HZ, "peak_rss_mb": _peak_rss_mb()}


def worker_service(path: str) -> dict:
    from avard.core.allan.streaming import StreamingAllan

    rng = np.random.default_rng(3)
    rate = 125.0
    acc = StreamingAllan(5, rate)
    warm = int(10 * 3600 * rate)
    for start in range(0, warm, BLOCK):
        acc.update(rng.normal(0.0, 45.0, (min(BLOCK, warm - start), 5)).round().astype(np.int64))
    batches = [rng.normal(0.0, 45.0, (12, 5)).round().astype(np.int64) for _ in range(100)]
    seconds = 600
    t0 = time.process_time()
    for s in range(seconds):
        for b in range(10):  # 0.1 s batches (12-13 sets at 125 Hz)
            acc.update(batches[(10 * s + b) % 100])
        if s % 10 == 9:
            acc.snapshot()
    return {"cpu_per_s": (time.process_time() - t0) / seconds}


WORKERS = {"allantools": worker_allantools, "stream": worker_stream, "fifo": worker_fifo,
           "realtime": worker_realtime, "service": worker_service}


def _run(kind: str, *args: object) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "benchmarks.bench_allan", "--worker", kind, *map(str, args)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env,
                         cwd=Path(__file__).resolve().parents[1])
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--worker":
        kind, *rest = argv[1:]
        fn = WORKERS[kind]
        print(json.dumps(fn(rest[0], *[int(r) for r in rest[1:]])))
        return 0
    ap = argparse.ArgumentParser(prog="python -m benchmarks allan", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=60.0, help="record length (default 60 h)")
    ap.add_argument("--fifo-sets", type=int, default=2_000_000,
                    help="sets fed in 32-set blocks (default 2,000,000)")
    ap.add_argument("--realtime-samples", type=int, default=200_000,
                    help="prefix for allantools oadev_realtime (default 200,000)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="avard-bench-") as tmp:
        path = Path(tmp) / "record.npy"
        n = make_record(path, args.hours)
        print(f"record: {args.hours:g} h at {RATE_HZ:g} Hz = {n:,} sets × (3 axes + 1 temp), "
              f"{path.stat().st_size / 1e6:.0f} MB int32")
        at = [_run("allantools", path, axis) for axis in range(3)]
        st = _run("stream", path)
        fifo = _run("fifo", path, args.fifo_sets)
        rt = _run("realtime", path, args.realtime_samples)
        svc = _run("service", path)
    at_cpu = sum(r["cpu_s"] for r in at)
    at_rss = max(r["peak_rss_mb"] for r in at)
    fifo_rate = fifo["sets"] / fifo["cpu_s"]
    rt_rate = rt["samples"] / rt["cpu_s"]
    rows = [
        ("allantools oadev, 3 axes one by one: CPU s", f"{at_cpu:.2f}", "reference", "1.00"),
        ("StreamingAllan 4 ch + 4×4 cov, 65536-set blocks: CPU s", f"{st['cpu_s']:.2f}",
         f"{at_cpu:.2f}", f"{at_cpu / st['cpu_s']:.2f}× faster (target ≥ 3)"),
        ("  throughput, sets/s (4 channels each)", f"{n / st['cpu_s']:,.0f}",
         f"{3 * n / at_cpu:,.0f} axis-samples/s", ""),
        ("peak RSS streaming the file: MB", f"{st['peak_rss_mb']:.0f}",
         f"{at_rss:.0f} (allantools, one axis)",
         f"{st['peak_rss_mb'] / at_rss:.3f} (target ≤ 0.2)"),
        ("accumulator state (msgpack): KiB", f"{st['state_bytes'] / 1024:.1f}", "64 (limit)",
         f"{st['state_bytes'] / 65536:.2f}"),
        ("snapshot (EDF + CI for all τ, 4 ch): ms", f"{st['snapshot_s'] * 1e3:.1f}", "", ""),
        (f"StreamingAllan 32-set blocks ({fifo['sets']:,} sets): sets/s", f"{fifo_rate:,.0f}",
         "100,000 (target)", f"{fifo_rate / 1e5:.1f}"),
        (f"allantools oadev_realtime ({rt['samples']:,} samples, 1 axis): samples/s",
         f"{rt_rate:,.0f}", f"{fifo_rate:,.0f} (ours, 4 ch)", f"{fifo_rate / rt_rate:.0f}× "
         "faster"),
        ("service use: 125 Hz, 5 ch, 0.1 s batches, snapshot / 10 s: CPU-s per s",
         f"{svc['cpu_per_s']:.5f}", "0.02 (the service's whole budget)",
         f"{svc['cpu_per_s'] / 0.02:.3f}"),
        (f"  oadev_realtime / our ADEV at τ = {rt['tau_s']:g} s",
         f"{rt['their_over_ours_adev']:.4g}", f"1/τ0 = {RATE_HZ:g}",
         "(its phase is not scaled by τ0)"),
    ]
    w = [max(len(r[i]) for r in rows) for i in range(4)]
    head = ("measurement", "avard", "reference", "ratio")
    w = [max(wi, len(h)) for wi, h in zip(w, head, strict=True)]
    print(" | ".join(h.ljust(wi) for h, wi in zip(head, w, strict=True)))
    print("-|-".join("-" * wi for wi in w))
    for r in rows:
        print(" | ".join(c.ljust(wi) for c, wi in zip(r, w, strict=True)))
    print(f"\nτ values: {st['taus']}; allantools per-axis CPU s: "
          + ", ".join(f"{r['cpu_s']:.2f}" for r in at) + "; CPU seconds, OPENBLAS_NUM_THREADS=1")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
