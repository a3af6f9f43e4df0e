"""`avard analyze` (fully overlapping ADEV + fit + spectrum) against allantools ``oadev``.

    python -m benchmarks analyze [--hours 60]

The record (default 60 h at 100 Hz: 21.6 M samples × 3 axes) is the synthetic ADXL355 record
of ``bench_allan`` (20-bit counts, white noise, a slow bias random walk, 1 g on z), scaled to
m/s² and written once as an uncompressed .npz, the form ``avard simulate`` writes. Each
measurement runs in a fresh subprocess with one BLAS thread, so peak RSS (VmHWM) is its own:

* avard: ``analyze(open_record(path))``, the whole `avard analyze` (the record streamed once into
  the fully overlapping ADEV at octave τ and the Welch spectrum, the noise fit per axis);
* allantools: the three axes loaded, then ``oadev(axis, rate, data_type="freq",
  taus="octave")`` on each; the same estimator at the same τ.

Ratios are against allantools measured in the same run; times are process CPU seconds:
avard's ``analyze`` call (reading the file, the OADEV, the spectrum, the line search and the
fit; no scipy is imported) against allantools' three ``oadev`` calls (its import and the loading of
the record outside); on a second row allantools' loading of the .npz counted too (both
then go from the file to the deviations); on a third, each whole worker process from its
start.
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
from typing import Any

import numpy as np

from .bench_allan import LSB_MS2, RATE_HZ, _peak_rss_mb, make_record, read_blocks


def make_npz(tmp: Path, hours: float) -> tuple[Path, int]:
    """The bench_allan record's three axes in m/s², as an uncompressed .npz, written in
    pieces (the record does not have to fit in memory twice)."""
    raw = tmp / "record.npy"
    n = make_record(raw, hours)
    member = tmp / "accel.npy"
    out = np.lib.format.open_memmap(member, mode="w+", dtype=np.float64, shape=(n, 3))
    i = 0
    for blk in read_blocks(str(raw), 1 << 20):
        out[i:i + len(blk)] = blk[:, :3] * LSB_MS2
        i += len(blk)
    out.flush()
    del out
    raw.unlink()
    path = tmp / "record.npz"
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED, allowZip64=True) as z:
        z.write(member, "accel.npy")
        rate = tmp / "rate_hz.npy"
        np.save(rate, np.float64(RATE_HZ))
        z.write(rate, "rate_hz.npy")
    member.unlink()
    return path, n


def _process_cpu_s() -> float:
    """CPU seconds of this whole process so far: interpreter start, imports, reading, work."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _timed(owner: Any, name: str, parts: dict[str, float], key: str) -> None:
    """Wrap ``owner.name`` so that its CPU time adds up in ``parts[key]`` (a few thousand
    calls: the wrapper's own cost is far below the figures' noise)."""
    inner = getattr(owner, name)

    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.process_time()
        try:
            return inner(*args, **kwargs)
        finally:
            parts[key] = parts.get(key, 0.0) + time.process_time() - t0

    setattr(owner, name, timed)


def worker_analyze(path: str) -> dict:
    from avard.core.allan.overlapping import OverlappingAllan
    from avard.core.analysis import engine as report
    from avard.core.io.source import open_record

    parts: dict[str, float] = {}
    _timed(report, "_one_pass", parts, "passes")
    for name in ("update", "result"):
        _timed(OverlappingAllan, name, parts, "oadev")
        _timed(report.WelchAccumulator, name, parts, "spectrum")
    t0 = time.process_time()
    # no scipy: NNLS, F quantile and χ² tail are avard's own
    an = report.analyze(open_record(path))
    cpu = time.process_time() - t0
    ch = an.channels["x"].allan
    split = {"OADEV (kernel, running sums, noise identification)": parts["oadev"],
             "Welch spectrum": parts["spectrum"],
             "reading the file (a pass per channel group, CRC on the 1st)":
                 parts["passes"] - parts["oadev"] - parts["spectrum"],
             "after the passes: line search, fit (no scipy)": cpu - parts["passes"]}
    from avard.core.allan import kernels

    return {"cpu_s": cpu, "process_cpu_s": _process_cpu_s(), "peak_rss_mb": _peak_rss_mb(),
            "compiled": kernels.compiled() is not None,
            "taus": len(ch.tau), "tau_max_s": float(ch.tau[-1]),
            "adev_x": [float(v) for v in ch.dev], "split": split}


def worker_allantools(path: str) -> dict:
    import allantools

    t_load = time.process_time()
    accel = np.load(path)["accel"]
    t0 = time.process_time()
    devs = [allantools.oadev(accel[:, a], rate=RATE_HZ, data_type="freq", taus="octave")[1]
            for a in range(3)]
    t1 = time.process_time()
    return {"cpu_s": t1 - t0, "load_cpu_s": t0 - t_load, "process_cpu_s": _process_cpu_s(),
            "peak_rss_mb": _peak_rss_mb(), "taus": len(devs[0]),
            "adev_x": [float(v) for v in devs[0]]}


WORKERS = {"analyze": worker_analyze, "allantools": worker_allantools}


def _run(kind: str, path: Path) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "benchmarks.bench_analyze", "--worker", kind, str(path)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env,
                         cwd=Path(__file__).resolve().parents[1])
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--worker":
        print(json.dumps(WORKERS[argv[1]](argv[2])))
        return 0
    ap = argparse.ArgumentParser(prog="python -m benchmarks analyze", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=60.0, help="record length (default 60 h)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="avard-bench-") as tmp:
        path, n = make_npz(Path(tmp), args.hours)
        print(f"record: {args.hours:g} h at {RATE_HZ:g} Hz = {n:,} samples × 3 axes, "
              f"{path.stat().st_size / 1e6:.0f} MB .npz (float64 m/s²)")
        ref = _run("allantools", path)
        ours = _run("analyze", path)
    k = min(len(ref["adev_x"]), len(ours["adev_x"]))
    agree = float(np.max(np.abs(np.array(ours["adev_x"][:k]) / np.array(ref["adev_x"][:k])
                                - 1.0)))
    rows = [
        ("allantools oadev, 3 axes (octave τ): CPU s", f"{ref['cpu_s']:.2f}", "reference",
         "1.00"),
        ("avard analyze (OADEV + spectrum + fit, 3 axes): CPU s", f"{ours['cpu_s']:.2f}",
         f"{ref['cpu_s']:.2f}", f"{ref['cpu_s'] / ours['cpu_s']:.2f}× faster (target ≥ 3)"),
        ("from the file (allantools: np.load + 3 oadev): CPU s", f"{ours['cpu_s']:.2f}",
         f"{ref['load_cpu_s'] + ref['cpu_s']:.2f}",
         f"{(ref['load_cpu_s'] + ref['cpu_s']) / ours['cpu_s']:.2f}× faster"),
        ("whole process (start, imports, reading, work): CPU s",
         f"{ours['process_cpu_s']:.2f}", f"{ref['process_cpu_s']:.2f}",
         f"{ref['process_cpu_s'] / ours['process_cpu_s']:.2f}× faster"),
        ("peak RSS: MB", f"{ours['peak_rss_mb']:.0f}", f"{ref['peak_rss_mb']:.0f}",
         f"{ours['peak_rss_mb'] / ref['peak_rss_mb']:.3f} (target ≤ 0.2)"),
        ("τ points (octave)", str(ours["taus"]), str(ref["taus"]),
         f"avard stops at τ = {ours['tau_max_s']:.0f} s"),
        ("largest |OADEV ratio − 1| on x, common τ", f"{agree:.1e}", "", ""),
    ]
    head = ("measurement", "avard", "reference", "ratio")
    w = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    print(" | ".join(h.ljust(wi) for h, wi in zip(head, w, strict=True)))
    print("-|-".join("-" * wi for wi in w))
    for r in rows:
        print(" | ".join(c.ljust(wi) for c, wi in zip(r, w, strict=True)))
    print("\nCPU seconds, one BLAS thread in both processes; peak RSS is VmHWM of each. "
          "avard's OADEV loop: " + ("compiled (core/allan/_kernels.c)" if ours["compiled"]
                                    else "numpy (the compiled loop is not built)") + ".")
    print("\nwhere avard's CPU time goes                              | CPU s | share")
    for what, sec in ours["split"].items():
        print(f"{what:<56} | {sec:5.2f} | {sec / ours['cpu_s']:.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
