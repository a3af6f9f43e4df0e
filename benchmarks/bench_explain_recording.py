"""`avard explain` against `avard analyze` on a service recording (issue 23's resources check:
explain within 3× the CPU time and 2× the peak memory of analyze on the same record).

The recording is ``bench_recording``'s: one hour written by the service itself
(``avard run --simulate quiet-lab --speed 0``: the emulated ADXL355 at 125 Hz, its DS18B20
and chip temperature channels, Allan snapshots, checkpoints, hourly segments) repeated to
``--hours`` with the index and times moved on, kept under the temp directory between runs.
Each command runs in a fresh process (``bench_explain.resources``: CPU seconds with its
worker processes, peak RSS); the figures are ratios to analyze's, never a timed assertion.
``--npz-hours H`` measures the simulator's quiet-lab record of H hours as an .npz too, where
temperatures are NaN between readings, for comparison: a recording must cost explain what an
.npz of its length costs, since both hand the screen and the slow view the same readings.

    python -m benchmarks explain_recording                  # 24 h recording
    python -m benchmarks explain_recording --hours 6 --npz-hours 12
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _recording(hours: float, seed: int, keep: str | None) -> Path:
    from benchmarks.bench_recording import write_from_template

    tmp = (Path(keep) if keep else Path(tempfile.gettempdir()) / "avard-bench-recording"
           / f"{hours:g}h-seed{seed}-template")
    rec = tmp / "rec"
    if not rec.is_dir():
        tmp.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        write_from_template(tmp, hours, seed)
        print(f"wrote the {hours:g} h recording in {time.perf_counter() - t0:.0f} s")
    size = sum(f.stat().st_size for f in rec.glob("*.avr")) / 1e6
    print(f"recording: {rec} ({hours:g} h, {size:.0f} MB)")
    return rec


def main(argv: list[str]) -> int:
    from benchmarks.bench_explain import resources

    ap = argparse.ArgumentParser(prog="python -m benchmarks explain_recording",
                                 description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0, help="recording length (default 24)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--keep", metavar="DIR", help="write the recording into DIR (DIR/rec) and "
                    "keep it; one already there is measured again")
    ap.add_argument("--npz-hours", type=float, default=0.0, metavar="H",
                    help="also the simulator's quiet-lab record of H hours as an .npz")
    ap.add_argument("--repeat", type=int, default=1,
                    help="each command this many times, interleaved; least CPU time taken")
    args = ap.parse_args(argv)
    rec = _recording(args.hours, args.seed, args.keep)
    resources(str(rec), args.repeat)
    if args.npz_hours > 0:
        with tempfile.TemporaryDirectory() as d:
            path = str(Path(d) / "quiet-lab.npz")
            subprocess.run([sys.executable, "-m", "avard.daemon.cli", "simulate", "--preset",
                            "quiet-lab", "--hours", str(args.npz_hours), "--seed", "1",
                            "--out", path], check=True, stdout=subprocess.DEVNULL)
            print(f"\nquiet-lab, {args.npz_hours:g} h, seed 1, .npz")
            resources(path, args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
