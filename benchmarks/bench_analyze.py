"""`avard analyze` (fully overlapping ADEV + fit + spectrum) against allantools ``oadev``.

    python -m benchmarks analyze [--hours 60] [--workers N]

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

Both workers import their modules from bytecode compiled once, in an untimed warm-up run on a
short record, as installed packages do (pip compiles it at install). ``--bytecode
environment`` leaves that to the environment instead: with PYTHONDONTWRITEBYTECODE=1 and no
bytecode beside the sources (an editable install that never wrote any), every module analyze
imports while it runs is compiled inside its timed call, at every run (allantools, installed,
has its bytecode either way).

With ``--workers N`` it also runs ``analyze(path, workers=N)`` (the exact parallel analysis,
``core/analysis/parallel.py``) beside ``analyze(path)`` in the same run, ``--repeat`` times
alternated, and prints each run's wall time and the CPU seconds of the parent and of every
worker process, the CPU on the longest path against one worker's (what the wall ratio is
on an idle machine), the peak memory of the whole process tree (the sum of the processes'
proportional set sizes, sampled every 10 ms in runs of their own: the sampler's CPU would
otherwise fall on the workers' cores), with the largest ADEV difference and whether α, EDF
and the terms' presence agree.
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


def _tree_rss_mb() -> float:
    """Memory of this process and its children (MB): the sum of their proportional set sizes
    (/proc/PID/smaps_rollup Pss), so pages a forked worker shares with its parent count once,
    not once per process as a sum of resident sets would."""
    me = os.getpid()
    total = 0
    for pid in [me, *_children(me)]:
        try:
            with open(f"/proc/{pid}/smaps_rollup") as f:
                for line in f:
                    if line.startswith("Pss:"):
                        total += int(line.split()[1])
        except OSError:
            pass
    return total / 1024


def _children(pid: int) -> list[int]:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(p) for p in f.read().split()]
    except OSError:
        return []


def _log_task(kind: str) -> None:
    """One line per task a worker process ends (its pid and CPU seconds since its fork) in
    the file ``AVARD_BENCH_TASKLOG`` names: the per-worker CPU of a parallel run."""
    path = os.environ.get("AVARD_BENCH_TASKLOG")
    if path:
        with open(path, "a") as f:
            f.write(f"{kind} {os.getpid()} {time.process_time():.6f}\n")


def _logged_chunk(p: int, i: int) -> Any:
    try:
        return _INNER["chunk"](p, i)
    finally:
        _log_task("chunk")


def _logged_fit(job: Any) -> Any:
    try:
        return _INNER["fit"](job)
    finally:
        _log_task("fit")


_INNER: dict[str, Any] = {}


def _sample_tree(peak: list[float], stop: Any) -> None:
    while not stop.wait(0.01):
        peak[0] = max(peak[0], _tree_rss_mb())


def worker_parallel(path: str, workers: str, mode: str = "time") -> dict:
    """``analyze(path, workers=N)`` (N = 1 for the reference).

    ``mode="time"``: its wall time and the CPU seconds of the process and of each worker
    process (the chunks' and the fits'), nothing else running in the process. ``mode=
    "memory"``: the peak of the process tree's memory, sampled every 10 ms by a thread.
    The two are separate runs because the sampler is not free: reading /proc/PID/smaps_rollup
    of the tree costs milliseconds of CPU per sample, which on a 2-core machine the
    workers of a parallel run pay and a one-worker run (one core left idle) does not."""
    import tempfile
    import threading

    from avard.core.analysis import engine, parallel
    from avard.core.analysis.options import AnalyzeOptions
    from avard.core.io.source import open_record

    log = tempfile.NamedTemporaryFile(prefix="avard-bench-tasks-", delete=False)
    log.close()
    os.environ["AVARD_BENCH_TASKLOG"] = log.name
    phase: dict[str, float] = {}
    if mode == "time":
        # forked workers run these (the pools take the functions by module and name)
        _INNER["chunk"], _INNER["fit"] = parallel._chunk_part, engine._fit_one
        parallel._chunk_part = _logged_chunk  # type: ignore[assignment]
        engine._fit_one = _logged_fit  # type: ignore[assignment]
        passes = parallel.run_passes

        def timed_passes(*args: Any, **kwargs: Any) -> Any:
            # the parent's CPU while its chunk workers run (it finishes and fits the passes
            # whose chunks are in meanwhile); the pass handed on last comes after the last
            # chunk, so its share is the parent's serial end
            handed = kwargs.get("on_pass")
            if handed is not None:
                def timed_pass(*a: Any) -> None:
                    t0 = time.process_time()
                    try:
                        handed(*a)
                    finally:
                        phase["last"] = time.process_time() - t0

                kwargs["on_pass"] = timed_pass
            phase["start"] = time.process_time()
            try:
                return passes(*args, **kwargs)
            finally:
                phase["end"] = time.process_time()

        parallel.run_passes = timed_passes  # type: ignore[assignment]
    peak = [0.0]
    stop = threading.Event()
    t = threading.Thread(target=_sample_tree, args=(peak, stop), daemon=True)
    if mode == "memory":
        t.start()
    c0 = time.process_time()
    t0 = time.monotonic()
    an = engine.analyze(open_record(path), AnalyzeOptions(workers=int(workers)))
    wall = time.monotonic() - t0
    parent = time.process_time() - c0
    if mode == "memory":
        stop.set()
        t.join()
    # the chunk workers exit while the parent finishes the last pass: their CPU counts once
    # they are reaped
    import multiprocessing

    for child in multiprocessing.active_children():
        child.join()
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    per: dict[str, dict[int, float]] = {"chunk": {}, "fit": {}}
    with open(log.name) as f:
        for line in f:
            kind, pid, cpu = line.split()
            if int(pid) != os.getpid():  # the parent's own fits are in its CPU
                per[kind][int(pid)] = max(per[kind].get(int(pid), 0.0), float(cpu))
    os.unlink(log.name)
    during = phase.get("end", 0.0) - phase.get("start", 0.0) - phase.get("last", 0.0)
    out: dict[str, Any] = {"wall_s": wall, "peak_tree_mb": peak[0], "parent_cpu_s": parent,
                           "parent_during_chunks_cpu_s": during,
                           "cpu_s": parent + kids.ru_utime + kids.ru_stime,
                           "chunk_workers_cpu_s": sorted(per["chunk"].values()),
                           "fit_workers_cpu_s": sorted(per["fit"].values()),
                           "channels": {}}
    for name, ch in an.channels.items():
        out["channels"][name] = {
            "adev": [float(v) for v in ch.allan.dev], "alpha": [int(v) for v in ch.allan.alpha],
            "edf": [float(v) for v in ch.allan.edf],
            "present": [bool(e.present) for e in ch.fit.terms.values()]}
    return out


WORKERS = {"analyze": worker_analyze, "allantools": worker_allantools,
           "parallel": worker_parallel}


#: Where the workers keep their modules' bytecode (``--bytecode cached``), or None.
_PYCACHE: str | None = None


def _run(kind: str, path: Path, *extra: str) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if _PYCACHE is not None:
        # as an installed package runs (pip compiles its bytecode at install): modules are
        # compiled once, not at every import of every run
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = _PYCACHE
    cmd = [sys.executable, "-m", "benchmarks.bench_analyze", "--worker", kind, str(path),
           *extra]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env,
                         cwd=Path(__file__).resolve().parents[1])
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--worker":
        print(json.dumps(WORKERS[argv[1]](*argv[2:])))
        return 0
    ap = argparse.ArgumentParser(prog="python -m benchmarks analyze", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=60.0, help="record length (default 60 h)")
    ap.add_argument("--workers", type=int, default=None, metavar="N",
                    help="also analyze(path, workers=N) against one worker, in the same run")
    ap.add_argument("--repeat", type=int, default=3, metavar="K",
                    help="with --workers: timed runs of each, alternated (default 3)")
    ap.add_argument("--bytecode", choices=("cached", "environment"), default="cached",
                    help="cached (default): the workers' modules compiled once, in a warm-up "
                         "run, as an installed avard and allantools run; environment: as "
                         "this environment says (PYTHONDONTWRITEBYTECODE=1 compiles every "
                         "module analyze imports inside its timed call, at every run)")
    args = ap.parse_args(argv)
    global _PYCACHE
    with tempfile.TemporaryDirectory(prefix="avard-bench-") as tmp:
        path, n = make_npz(Path(tmp), args.hours)
        print(f"record: {args.hours:g} h at {RATE_HZ:g} Hz = {n:,} samples × 3 axes, "
              f"{path.stat().st_size / 1e6:.0f} MB .npz (float64 m/s²)")
        if args.bytecode == "cached":
            _PYCACHE = str(Path(tmp) / "pycache")
            (Path(tmp) / "warm").mkdir()
            warm, _n = make_npz(Path(tmp) / "warm", 0.25)
            for kind, extra in (("allantools", ()), ("analyze", ()),
                                *((("parallel", ("1",)), ("parallel", (str(args.workers),)))
                                  if args.workers else ())):
                _run(kind, warm, *extra)  # untimed: the imports' bytecode compiled once
        ref = _run("allantools", path)
        ours = _run("analyze", path)
        if args.workers:
            load = os.getloadavg()[0]
            runs: list[tuple[dict, dict]] = []
            for _ in range(max(1, args.repeat)):  # alternated: a load change hits both
                runs.append((_run("parallel", path, "1"),
                             _run("parallel", path, str(args.workers))))
            mem = (_run("parallel", path, "1", "memory"),
                   _run("parallel", path, str(args.workers), "memory"))
            load = max(load, os.getloadavg()[0])
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
    env_bc = os.environ.get("PYTHONDONTWRITEBYTECODE", "")
    bytecode = ("compiled once in a warm-up run, as installed packages run" if _PYCACHE
                else f"as the environment says (PYTHONDONTWRITEBYTECODE={env_bc!r})")
    print(f"\nBytecode: {bytecode}. Load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores after the runs.")
    print("\nCPU seconds, one BLAS thread in both processes; peak RSS is VmHWM of each. "
          "avard's OADEV loop: " + ("compiled (core/allan/_kernels.c)" if ours["compiled"]
                                    else "numpy (the compiled loop is not built)") + ".")
    print("\nwhere avard's CPU time goes                              | CPU s | share")
    for what, sec in ours["split"].items():
        print(f"{what:<56} | {sec:5.2f} | {sec / ours['cpu_s']:.0%}")
    if args.workers:
        _print_parallel(runs, mem, args.workers, load)
    return 0


def _critical_cpu(run: dict, workers: int) -> float:
    """What the run's wall time would be on an idle machine with a core per worker whose
    cores do not slow each other, from its CPU seconds: the parent's serial part (before
    and after its chunk workers run), plus the chunk phase, which lasts at least as long as
    the busiest chunk worker and as the CPU of all chunk workers and of the parent meanwhile
    shared among the cores, plus the busiest fit worker's (a fit pool runs while the parent
    waits)."""
    chunks = run["chunk_workers_cpu_s"]
    during = run.get("parent_during_chunks_cpu_s", 0.0)
    phase = max(max(chunks, default=0.0), (sum(chunks) + during) / max(1, workers))
    return (run["parent_cpu_s"] - during + (phase if chunks else during)
            + max(run["fit_workers_cpu_s"], default=0.0))


def _print_parallel(runs: list[tuple[dict, dict]], mem: tuple[dict, dict], workers: int,
                    load: float) -> None:
    one, par = runs[-1]
    rel = max(float(np.max(np.abs(np.array(p["adev"]) / np.array(o["adev"]) - 1.0)))
              for o, p in zip(one["channels"].values(), par["channels"].values(),
                              strict=True))
    same = all(o[k] == p[k] for o, p in zip(one["channels"].values(),
                                             par["channels"].values(), strict=True)
               for k in ("alpha", "present"))
    edf = max(float(np.max(np.abs(np.array(p["edf"]) / np.array(o["edf"]) - 1.0)))
              for o, p in zip(one["channels"].values(), par["channels"].values(),
                              strict=True))
    med = float(np.median([p["wall_s"] / o["wall_s"] for o, p in runs]))
    best = min(p["wall_s"] for _o, p in runs) / min(o["wall_s"] for o, _p in runs)
    crit = [_critical_cpu(p, workers) / o["parent_cpu_s"] for o, p in runs]
    loaded = ": the machine was loaded, wall times are not an idle one's" if load > 0.5 else ""
    print(f"\nanalyze on {workers} workers against 1 (same record, same run; "
          f"{os.cpu_count()} cores here, load average up to {load:.1f}{loaded})")
    for k, (o, p) in enumerate(runs):
        print(f"  run {k + 1}: wall s {o['wall_s']:.2f} → {p['wall_s']:.2f} (ratio "
              f"{p['wall_s'] / o['wall_s']:.2f}); CPU s: one worker {o['parent_cpu_s']:.2f}; "
              f"{workers} workers: parent {p['parent_cpu_s']:.2f} (of which "
              f"{p['parent_during_chunks_cpu_s']:.2f} while chunks ran), chunk workers "
              f"{' + '.join(f'{c:.2f}' for c in p['chunk_workers_cpu_s'])}, fit workers "
              f"{' + '.join(f'{c:.2f}' for c in p['fit_workers_cpu_s']) or '-'}")
    print(f"  wall ratio: median {med:.2f}, fastest against fastest {best:.2f} "
          "(target ≤ 0.6 on 2 cores)")
    print(f"  CPU on the longest path (the parent's serial part, the chunk phase: its busiest "
          f"worker or all CPU then over {workers} cores, the busiest fit worker) against one "
          f"worker's CPU: {min(crit):.2f}–{max(crit):.2f} (the wall ratio of an idle machine "
          "whose cores do not slow each other)")
    print(f"  CPU s, all processes: {one['cpu_s']:.2f} → {par['cpu_s']:.2f}")
    print(f"  peak memory of the process tree (separate runs, sampled every 10 ms), MB: "
          f"{mem[0]['peak_tree_mb']:.0f} → {mem[1]['peak_tree_mb']:.0f}  ratio "
          f"{mem[1]['peak_tree_mb'] / mem[0]['peak_tree_mb']:.2f} (target ≤ 1.5)")
    print(f"  largest |ADEV ratio − 1|: {rel:.1e} (target ≤ 1e-12); EDF {edf:.1e}; "
          f"α and term presence {'equal' if same else 'DIFFER'}")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
