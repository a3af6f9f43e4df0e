"""Reading damaged segments: time against size, crafted worst case vs. a clean segment.

``python -m benchmarks resync [--max-mb 16]``

For each size (64 kB doubling up to ``--max-mb``) it times ``scan_frames`` over three
segments of that size:

- clean: real-sized frames (1.2 kB raw blocks), nothing to resynchronise (the reference);
- flipped: the same with one flipped bit every 64 kB (a resync per 64 kB);
- crafted: every 4-byte-aligned offset claims a frame that runs to the end of the file and
  none is valid (issue #16, item 7: quadratic before, > 7 min at 4 MB);
- dense: valid 13-byte frames each followed by a junk byte, a resync every 14 bytes (issue
  #26, item 10: a fixed 16 384-candidate window per resync cost ~140 CPU-s per MB).

Timings on a shared machine are noisy: read the ratios against the clean reference measured
in the same run, and the per-MB column (time / size), which stays flat when the work is linear.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from avard.core.io.recording import frame, scan_frames


def _clean(size: int, rng: np.random.Generator) -> bytes:
    one = frame(rng.bytes(1200))
    return (one * (size // len(one) + 1))[:size]


def _flipped(clean: bytes) -> bytes:
    buf = bytearray(clean)
    for at in range(1000, len(buf), 65536):
        buf[at] ^= 0x10
    return bytes(buf)


def _crafted(size: int) -> bytes:
    claims = size - np.arange(0, size, 4, dtype=np.int64) - 8
    return np.clip(claims, 0, None).astype("<u4").tobytes()


def _dense(size: int, rng: np.random.Generator) -> bytes:
    one = b"".join(frame(rng.bytes(5)) + b"\x01" for _ in range(1024))
    return (one * (size // len(one) + 1))[:size]


def _time(data: bytes) -> tuple[float, int]:
    """CPU seconds of this process (not wall time: the machine is shared) and frames read."""
    t0 = time.process_time()
    problems: list = []
    n = sum(1 for _ in scan_frames(data, problems=problems))
    return time.process_time() - t0, n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks resync", description=__doc__)
    ap.add_argument("--max-mb", type=float, default=16.0, help="largest segment, MB")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(1)
    print("segment reading CPU time (s) by size; ratios against the clean segment of that size")
    print(f"{'size MB':>8} {'clean s':>8} {'flipped s':>9} {'crafted s':>9} {'dense s':>8} "
          f"{'flip/clean':>10} {'craft/clean':>11} {'crafted s/MB':>12} {'dense s/MB':>10}")
    size = 1 << 16
    while size <= args.max_mb * 2**20:
        clean = _clean(size, rng)
        t_clean, _ = _time(clean)
        t_flip, _ = _time(_flipped(clean))
        t_craft, n = _time(_crafted(size))
        assert n == 0
        t_dense, _ = _time(_dense(size, rng))
        mb = size / 2**20
        print(f"{mb:8.3f} {t_clean:8.3f} {t_flip:9.3f} {t_craft:9.3f} {t_dense:8.3f} "
              f"{t_flip / max(t_clean, 1e-6):10.1f} {t_craft / max(t_clean, 1e-6):11.1f} "
              f"{t_craft / mb:12.3f} {t_dense / mb:10.3f}")
        size *= 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
