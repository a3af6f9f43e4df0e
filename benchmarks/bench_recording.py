"""`avard analyze` of a service recording against the same samples as an .npz (issue #25).

Writes an H-hour recording laid out as the service lays it out: one hour written by the
service itself (``avard run --simulate quiet-lab --speed 0``: the emulated ADXL355 at 125 Hz,
its temperature channels, Allan snapshots, checkpoints, header copies, hourly segments) is
the template of every hour, written again through the recorder's segment writer
(daemon/service/recorder.py) with the sample index, times and sequence numbers moved on and
fresh counts (white noise and a random walk at the template's levels), so writing 60 h takes
minutes, not the ~40 min of running the service for 60 simulated hours (``--service`` does
that). The recording is kept under the temp directory between runs (``--fresh`` writes it
again). Copies its samples (streamed, never held whole) into an uncompressed .npz carrying
the same rate, LSB and ADXL355 ODR (so both fits model the same filter corner), and runs
`avard analyze FILE --json` on each in a fresh process with one BLAS thread. Prints the CPU
seconds and the peak RSS (VmHWM) of both and their ratios: the recording is streamed, so its
peak must stay within 10 % of the .npz's and its time within 1.3×. The two analyses must
give the same N.

    python -m benchmarks recording              # 60 h
    python -m benchmarks recording --hours 2    # shorter; run two lengths to see the scaling
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
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


def worker(path: str, workers: str = "1") -> dict:
    """`avard analyze PATH --json --workers W` in this process: its CPU seconds (with any
    worker processes it forked), peak RSS and N per axis."""
    import contextlib
    import io
    import resource

    from avard.daemon import cli

    def cpu() -> float:
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + kids.ru_utime + kids.ru_stime

    out = io.StringIO()
    t0 = cpu()
    with contextlib.redirect_stdout(out):
        rc = cli.main(["analyze", path, "--json", "--workers", workers])
    used = cpu() - t0
    d = json.loads(out.getvalue())
    n = {k: c["terms"]["velocity_random_walk"]["value"] for k, c in d["channels"].items()}
    return {"rc": rc, "cpu_s": used, "peak_rss_mb": _peak_rss_mb(), "n_samples": d["n_samples"],
            "N": n}


def _run_worker(path: Path, workers: str) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "benchmarks.bench_recording", "--worker", str(path), workers]
    done = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env,
                          cwd=Path(__file__).resolve().parents[1])
    return json.loads(done.stdout.strip().splitlines()[-1])


def _median(results: list[dict]) -> dict:
    """The run of median CPU seconds, with the median peak RSS of all runs."""
    by_cpu = sorted(results, key=lambda r: r["cpu_s"])
    mid = dict(by_cpu[len(by_cpu) // 2])
    mid["peak_rss_mb"] = float(np.median([r["peak_rss_mb"] for r in results]))
    mid["all_cpu_s"] = [round(r["cpu_s"], 2) for r in results]
    return mid


def write_recording(tmp: Path, hours: float, seed: int = 1, name: str = "rec") -> Path:
    """The service's own recording of ``hours`` simulated hours."""
    cfg = tmp / "avard.toml"
    cfg.write_text(CONFIG)
    data = tmp / name
    subprocess.run([sys.executable, "-m", "avard.daemon.cli", "run", "--config", str(cfg),
                    "--simulate", "quiet-lab", "--data-dir", str(data), "--speed", "0",
                    "--duration", str(hours * 3600.0), "--seed", str(seed)],
                   check=True, capture_output=True)
    return data


def write_from_template(tmp: Path, hours: float, seed: int = 1) -> Path:
    """``hours`` of recording whose every hour is the service's first hour (written by
    :func:`write_recording`) with the index, times and sequence numbers moved on and fresh
    counts, written through the recorder's segment writer (hourly segments)."""
    from avard.core.io.recording import RecordingReader
    from avard.daemon.service.recorder import Recorder

    template = write_recording(tmp, min(hours, 1.0), seed, name="template")
    records = list(RecordingReader(template))
    raws = [r for r in records if r["kind"] == "raw"]
    first = records[0]
    span = int(raws[-1]["i0"]) + int(raws[-1]["n"]) - int(raws[0]["i0"])
    rate = float(first["rate_hz"])
    counts = np.concatenate([np.asarray(r["counts"], dtype=np.float64) for r in raws])
    level = counts.mean(axis=0)
    white = np.diff(counts, axis=0).std(axis=0) / np.sqrt(2.0)
    rng = np.random.default_rng(seed)
    walk = np.zeros(3)
    run = str(first["run"])
    clock = [0.0]
    header = [first]

    def moved(rec: dict, h: int) -> dict:
        out = dict(rec)
        shift = h * span
        for key in ("i0", "i_end", "n_samples"):
            if key in out and out[key] is not None:
                out[key] = int(out[key]) + shift
        for key in ("t_mono", "t_real"):
            if key in out:
                out[key] = float(out[key]) + shift / rate
        return out

    data = tmp / "rec"
    rec = Recorder(data, run, lambda: header[0],
                   segment_s=3600.0, header_every_s=0.0, fsync_interval_s=1e9,
                   clock=lambda: clock[0], wall=lambda: 0.0,
                   realtime=lambda: float(first["t_real"]) + clock[0])
    t0 = float(first["t_mono"])
    for h in range(int(np.ceil(hours))):
        for r in records:
            if r["kind"] == "header" and r is first:
                continue                       # the recorder writes one at each rotation
            out = moved(r, h)
            if r["kind"] == "raw":
                n = int(r["n"])
                if int(out["i0"]) >= hours * 3600.0 * rate:
                    break
                steps = rng.normal(0.0, 0.02, (n, 3)).cumsum(axis=0) + walk
                walk = steps[-1]
                out["counts"] = np.rint(level + steps + rng.normal(0.0, 1.0, (n, 3)) * white
                                        ).astype(np.int32)
            elif r["kind"] == "header":
                header[0] = out
            clock[0] = float(out["t_mono"]) - t0
            rec.write(out)
    rec.close()
    shutil.rmtree(template)
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
    part = out.with_suffix(".part")          # renamed when whole: a kept .npz is complete
    with zipfile.ZipFile(part, "w", compression=zipfile.ZIP_STORED) as zf:
        zf.write(npy, "accel.npy")
        for key, v in small.items():
            tmp = out.with_suffix(f".{key}.npy")
            np.save(tmp, v)
            zf.write(tmp, f"{key}.npy")
            tmp.unlink()
    npy.unlink()
    os.replace(part, out)
    return out


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--worker":
        print(json.dumps(worker(*argv[1:3])))
        return 0
    ap = argparse.ArgumentParser(prog="python -m benchmarks recording", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=60.0, help="recording length (default 60)")
    ap.add_argument("--keep", metavar="DIR", help="write into DIR and keep the files; a "
                    "recording already there (DIR/rec, DIR/same.npz) is measured again "
                    "(default: a directory under the temp directory named by hours, seed "
                    "and how it was written)")
    ap.add_argument("--fresh", action="store_true", help="write the recording again even if "
                    "one is kept")
    ap.add_argument("--service", action="store_true", help="write all of it with the service "
                    "(`avard run --simulate quiet-lab --speed 0`, ~40 s an hour on an idle "
                    "machine) instead of from its first hour")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3, help="analyses of each, alternated; the "
                    "medians are compared (default 3)")
    ap.add_argument("--workers", default="1", help="analyze's --workers for both (default 1:"
                    " what a Raspberry Pi with under 2 GB runs; the CPU seconds count the "
                    "worker processes too, the peak RSS is the main process's)")
    args = ap.parse_args(argv)
    how = "service" if args.service else "template"
    tmp = (Path(args.keep) if args.keep else Path(tempfile.gettempdir())
           / "avard-bench-recording" / f"{args.hours:g}h-seed{args.seed}-{how}")
    if args.fresh and tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    again = (tmp / "rec").is_dir() and (tmp / "same.npz").is_file()
    if not again:
        for old in ("rec", "template"):
            shutil.rmtree(tmp / old, ignore_errors=True)
        if args.service:
            rec = write_recording(tmp, args.hours, args.seed)
        else:
            rec = write_from_template(tmp, args.hours, args.seed)
        t_write = time.perf_counter() - t0
        to_npz(rec, tmp / "same.npz")
    rec, npz = tmp / "rec", tmp / "same.npz"
    size_rec = sum(f.stat().st_size for f in rec.glob("*.avr"))
    # alternated, the median of each: on a loaded machine one run of either can take half
    # as long again, and whichever runs first reads its file with a colder page cache
    runs: list[tuple[dict, dict]] = [(_run_worker(rec, args.workers),
                                      _run_worker(npz, args.workers))
                                     for _ in range(args.repeat)]
    ours, ref = (_median([r[k] for r in runs]) for k in (0, 1))
    written = ("by `avard run --simulate quiet-lab --speed 0`" if args.service else
               "from the service's first hour through the recorder's segment writer")
    said = (f"(kept in {tmp}: --fresh writes it again)" if again
            else f"written {written} in {t_write:.0f} s wall, kept in {tmp}")
    print(f"recording: {ours['n_samples'] / 125 / 3600:.3g} h {said}; "
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
    print(f"CPU s of each run, in order: recording {ours['all_cpu_s']}, .npz "
          f"{ref['all_cpu_s']} (medians above)")
    print(f"CPU seconds of each analyzing process (`--workers {args.workers}`, one BLAS "
          "thread); the machine may be loaded: compare the ratio, not the seconds.")
    return 0 if same and ours["rc"] == 0 and ref["rc"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
