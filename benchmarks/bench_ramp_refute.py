"""Ramp claims, live and offline (issue 24): does analyze refute what the live fit refutes?

Two rows:

* **quiet-lab (no ramp)**: seeds × 41 and 55 min × 3 axes. Counted: the live snapshot fit
  (cascade, one snapshot a minute) claiming a rate ramp resolved, or any term analyze of
  the same samples does not claim; ``avard analyze`` with its
  default OADEV (to N/4) claiming it, with the TOTVAR test out to T/2
  (core/analysis/long_tau_check.py) and without it; analyze's claims the live fit does not
  make.
* **true ramp**: ``--ramp`` m/s³ on ``--hours`` of ``adxl355-datasheet`` noise, seeds × 3
  axes: analyze's claims with the test and without it (the test must not cost power).

    python -m benchmarks ramp_refute                       # 12 seeds; ramp 5e-8 over 12 h, 5 seeds
    python -m benchmarks ramp_refute --seeds 4 --ramp-seeds 2 --hours 1
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def _claimed(term) -> bool:
    return bool(term.present and term.note is None)


def _analyze(y: np.ndarray, rate: float, path: Path, check: bool):
    from avard.core.analysis import long_tau_check as ltc
    from avard.core.analysis.engine import analyze
    from avard.core.analysis.options import AnalyzeOptions
    from avard.core.io.source import open_record

    np.savez(path, accel=y, rate_hz=rate, axes=np.array(["x", "y", "z"]))
    original = ltc.check_ramp
    if not check:
        ltc.check_ramp = lambda fit, *a, **k: fit  # type: ignore[assignment]
    try:
        return analyze(open_record(path), AnalyzeOptions(filter_corner_hz=rate / 4,
                                                         find_sinusoids=False))
    finally:
        ltc.check_ramp = original


def quiet_lab_row(seeds: int, tmp: Path) -> dict[str, int]:
    from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
    from avard.core.model.fit import fit_noise
    from avard.core.sim.presets import make_config
    from avard.core.sim.simulate import SensorSimulator
    from avard.daemon.service.snapshots import fit_snapshot

    out = {"fits": 0, "live": 0, "analyze": 0, "analyze_without_test": 0, "analyze_not_live": 0,
           "live_any_term_analyze_not": 0, "cpu_live_fit_ms": 0, "cpu_bare_fit_ms": 0}
    cfg = make_config("quiet-lab")
    rate = cfg.rate_hz
    for seed in range(seeds):
        full = SensorSimulator(cfg, seed=seed).next(int(55 * 60 * rate)).counts * cfg.lsb_mps2
        for minutes in (41, 55):
            y = full[:int(minutes * 60 * rate)].astype(np.float64)
            sa = StreamingAllan(3, rate, names=["x", "y", "z"])
            step = int(60 * rate)
            for i in range(0, y.shape[0], step):
                sa.update(y[i:i + step])
            snap = AllanSnapshot.from_dict(sa.snapshot().to_dict())

            def bare(snap: AllanSnapshot = snap) -> None:
                for c in range(3):  # the bare fit of the same channels: the guard's cost
                    fit_noise(snap.channel(c), ci=snap.ci, filter_corner_hz=snap.rate_hz / 4)

            bare()  # once untimed: the filter terms of this corner are computed and kept
            t0 = time.process_time()
            live = fit_snapshot(snap)
            t1 = time.process_time()
            bare()
            out["cpu_live_fit_ms"] += round(1000 * (t1 - t0))
            out["cpu_bare_fit_ms"] += round(1000 * (time.process_time() - t1))
            on = _analyze(y, rate, tmp / "q.npz", True)
            off = _analyze(y, rate, tmp / "q.npz", False)
            for axis, fit in live.items():
                lv = _claimed(fit.terms["rate_ramp"])
                an = _claimed(on.channels[axis].fit.terms["rate_ramp"])
                out["fits"] += 1
                out["live"] += lv
                out["analyze"] += an
                out["analyze_without_test"] += _claimed(off.channels[axis].fit.terms["rate_ramp"])
                out["analyze_not_live"] += an and not lv
                # any term (N, B, K, R, Q) the live fit claims and analyze of the same
                # samples does not (issue 24: one fit, live and offline)
                claims = {t for t, e in fit.terms.items() if _claimed(e)}
                out["live_any_term_analyze_not"] += bool(claims - {
                    t for t, e in on.channels[axis].fit.terms.items() if _claimed(e)})
    return out


def ramp_row(seeds: int, ramp: float, hours: float, tmp: Path) -> dict[str, int]:
    from avard.core.sim.presets import make_config
    from avard.core.sim.simulate import SensorSimulator

    cfg = make_config("adxl355-datasheet", rate_ramp=(ramp, ramp, ramp))
    rate = cfg.rate_hz
    out = {"axes": 0, "analyze": 0, "analyze_without_test": 0}
    for seed in range(1, seeds + 1):
        y = SensorSimulator(cfg, seed=seed).next(int(hours * 3600 * rate)).counts * cfg.lsb_mps2
        on = _analyze(y, rate, tmp / "r.npz", True)
        off = _analyze(y, rate, tmp / "r.npz", False)
        for axis in ("x", "y", "z"):
            out["axes"] += 1
            out["analyze"] += _claimed(on.channels[axis].fit.terms["rate_ramp"])
            out["analyze_without_test"] += _claimed(off.channels[axis].fit.terms["rate_ramp"])
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks ramp_refute")
    ap.add_argument("--seeds", type=int, default=12, help="quiet-lab seeds (0 … n−1)")
    ap.add_argument("--ramp", type=float, default=5e-8, help="true ramp, m/s³")
    ap.add_argument("--hours", type=float, default=12.0, help="true-ramp record length, h")
    ap.add_argument("--ramp-seeds", type=int, default=5, help="true-ramp seeds (1 … n)")
    args = ap.parse_args(argv)
    t0 = time.process_time()
    with tempfile.TemporaryDirectory() as d:
        q = quiet_lab_row(args.seeds, Path(d))
        print(f"quiet-lab, {args.seeds} seeds × 41/55 min × 3 axes: {q}")
        print(f"the live snapshot fit (decimation guard and signal_edf) costs "
              f"{q['cpu_live_fit_ms'] / max(q['cpu_bare_fit_ms'], 1):.2f}× the bare fit_noise of "
              "the same snapshots (process time, same run)")
        r = ramp_row(args.ramp_seeds, args.ramp, args.hours, Path(d))
        print(f"true ramp {args.ramp:g} m/s³ over {args.hours:g} h, {args.ramp_seeds} seeds × 3 "
              f"axes: {r}")
    print(f"CPU {time.process_time() - t0:.1f} s (process time; the machine may be loaded)")
    return 0
