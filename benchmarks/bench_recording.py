"""`avard analyze` of a service recording against the same samples as an .npz (issue #25).

Writes a recording with the service itself (``avard run --simulate quiet-lab --speed 0
--duration H h``: the emulated ADXL355 at 125 Hz, its temperature channels, hourly segments),
copies its samples (streamed, never held whole) into an uncompressed .npz carrying the same
rate, LSB and ADXL355 ODR (so both fits model the same filter corner), and runs `avard analyze
FILE --json` on each in a fresh process with one BLAS thread. Prints the CPU seconds and the
peak RSS (VmHWM) of both and their ratios: the recording is streamed, so its peak must stay
within 10 % of the .npz's and its time within 1.3×. The two analyses must give the same N.

    python -m benchmarks recording              # 60 h (writing it takes ~100× less than 60 h)
    python -m benchmarks recording --hours 2    # shorter; run two lengths to see the scaling
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

CONFIG = """
[recording]
segment_s = 3600.0
fsync_interval_s = 60.0
[publish]
enabled = false
"""


def _peak_rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def worker(path: str) -> dict:
    """`avard analyze PATH --json` in this process: its CPU seconds, peak RSS and N per axis."""
    import contextlib
    import io

    from avard.daemon import cli

    out = io.StringIO()
    t0 = time.process_time()
    with contextlib.redirect_stdout(out):
        rc = cli.main(["analyze", path, "--json"])
    cpu = time.process_time() - t0
    d = json.loads(out.getvalue())
    n = {k: c["terms"]["velocity_random_walk"]["value"] for k, c in d["channels"].items()}
    return {"rc": rc, "cpu_s": cpu, "peak_rss_mb": _peak_rss_mb(), "n_samples": d["n_samples"],
            "N": n}


def _run_worker(path: Path) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "benchmarks.bench_recording", "--worker", str(path)]
    done = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env,
                          cwd=Path(__file__).resolve().parents[1])
    return json.loads(done.stdout.strip().splitlines()[-1])


def write_recording(tmp: Path, hours: float, seed: int = 1) -> Path:
    cfg = tmp / "avard.toml"
    cfg.write_text(CONFIG)
    data = tmp / "rec"
    subprocess.run([sys.executable, "-m", "avard.daemon.cli", "run", "--config", str(cfg),
                    "--simulate", "quiet-lab", "--data-dir", str(data), "--speed", "0",
                    "--duration", str(hours * 3600.0), "--seed", str(seed)],
                   check=True, capture_output=True)
    return data


def to_npz(rec: Path, out: Path) -> Path:
    """The recording's samples as an uncompressed .npz, written block by block."""
    from avard.core.io.source import open_record

    src = open_record(rec)
    info = src.info
    assert info.n_samples is not None
    npy = out.with_suffix(".accel.npy")
    accel = np.lib.format.open_memmap(npy, mode="w+", dtype=np.float64,
                                      shape=(info.n_samples, 3))
    at = 0
    for a, _t, _end in src.blocks(1 << 16, temperature=False):
        accel[at:at + len(a)] = a
        at += len(a)
    accel.flush()
    del accel
    small = {"rate_hz": np.float64(info.rate_hz), "odr_nominal_hz": np.float64(125.0),
             "lsb_mps2": np.float64(info.lsb_mps2 or 0.0)}
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_STORED) as zf:
        zf.write(npy, "accel.npy")
        for key, v in small.items():
            tmp = out.with_suffix(f".{key}.npy")
            np.save(tmp, v)
            zf.write(tmp, f"{key}.npy")
            tmp.unlink()
    npy.unlink()
    return out


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--worker":
        print(json.dumps(worker(argv[1])))
        return 0
    ap = argparse.ArgumentParser(prog="python -m benchmarks recording", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=60.0, help="recording length (default 60)")
    ap.add_argument("--keep", metavar="DIR", help="write into DIR and keep the files; a "
                    "recording already there (DIR/rec, DIR/same.npz) is measured again")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="avard-bench-") as tmpd:
        tmp = Path(args.keep) if args.keep else Path(tmpd)
        tmp.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        again = (tmp / "rec").is_dir() and (tmp / "same.npz").is_file()
        rec = tmp / "rec" if again else write_recording(tmp, args.hours)
        t_write = time.perf_counter() - t0
        npz = tmp / "same.npz" if again else to_npz(rec, tmp / "same.npz")
        size_rec = sum(f.stat().st_size for f in rec.glob("*.avr"))
        ours = _run_worker(rec)
        ref = _run_worker(npz)
    how = ("(kept from an earlier run)" if again
           else f"written by `avard run --simulate quiet-lab --speed 0` in {t_write:.0f} s wall")
    print(f"recording: {ours['n_samples'] / 125 / 3600:.3g} h {how}; "
          f"{ours['n_samples']:,} samples × 3 axes, "
          f"{size_rec / 1e6:.0f} MB of segments; the .npz {npz.name}: the same samples")
    rows = [("CPU s of `avard analyze --json`", ours["cpu_s"], ref["cpu_s"], 1.3),
            ("peak RSS (VmHWM), MB", ours["peak_rss_mb"], ref["peak_rss_mb"], 1.10)]
    print(f"{'measurement':<34} | {'recording':>9} | {'.npz':>9} | ratio | target")
    for what, a, b, target in rows:
        print(f"{what:<34} | {a:9.2f} | {b:9.2f} | {a / b:5.2f} | ≤ {target:.2f}")
    same = all(ours["N"][k] == ref["N"][k] for k in ref["N"])
    print("N per axis equal on both paths: " + ("yes" if same else f"NO {ours['N']} "
                                                 f"{ref['N']}"))
    print("CPU seconds of each analyzing process (one BLAS thread); the machine may be "
          "loaded: compare the ratio, not the seconds.")
    return 0 if same and ours["rc"] == 0 and ref["rc"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
