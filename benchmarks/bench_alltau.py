"""ADEV + OADEV + HDEV + OHDEV at Stable32's all-τ AFs on the Cs 5071A record, avard against
allantools, in one run.

    python -m benchmarks alltau [--repeat 3]

The record (556 990 phase points, 1 s) and Stable32's all-τ AF lists (306 + 314 + 306 + 314 =
1240 τ) come from allantools' source archive (tests/support/allantools_sdist.py fetches and
checks it). avard: ``allan_variance`` for each deviation, with its EDF, χ² bounds and the noise
identification (α) at every τ; allantools: ``adev``, ``oadev``, ``hdev``, ``ohdev`` (the
deviations only) at the same τ, from the same rate samples. Times are process CPU seconds
(the machine may be loaded: read the ratio, both measured in this run); the best of
``--repeat`` runs of each.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

KINDS = {"adev": "avar", "oadev": "oavar", "hdev": "phvar", "ohdev": "ohvar"}


def load() -> tuple[np.ndarray, dict[str, list[int]]]:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.core.stable32 import read_rows
    from tests.support.allantools_sdist import reference_tests

    folder = reference_tests() / "Cs5071A"
    phase = np.loadtxt(folder / "5071A_phase.txt.gz", comments="#", dtype=np.float64)
    afs = {name: [r.af for r in read_rows(folder / f"{name}_all.txt")] for name in KINDS}
    return np.diff(phase), afs


def run_avard(y: np.ndarray, afs: dict[str, list[int]]) -> float:
    from avard.core.allan.deviations import allan_variance

    t0 = time.process_time()
    for name, kind in KINDS.items():
        ms = np.asarray(afs[name], dtype=float)
        kw = {"stride": int(ms.max())} if kind == "phvar" else {}
        res = allan_variance(y, 1.0, ms, kind=kind, **kw)
        assert np.all(np.isfinite(res.lo)) and np.all(np.isfinite(res.alpha))
    return time.process_time() - t0


def run_allantools(y: np.ndarray, afs: dict[str, list[int]]) -> float:
    import allantools

    t0 = time.process_time()
    for name in KINDS:
        getattr(allantools, name)(y, rate=1.0, data_type="freq",
                                  taus=np.asarray(afs[name], dtype=float))
    return time.process_time() - t0


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks alltau", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="runs of each; the best is kept")
    args = ap.parse_args(argv)
    y, afs = load()
    n_tau = sum(len(v) for v in afs.values())
    a = min(run_avard(y, afs) for _ in range(args.repeat))
    b = min(run_allantools(y, afs) for _ in range(args.repeat))
    print(f"Cs 5071A: {y.size + 1} phase points, {n_tau} τ (ADEV+OADEV+HDEV+OHDEV at "
          "Stable32's all-τ AFs)")
    print(f"avard (with EDF, bounds, α): {a:.2f} CPU-s")
    print(f"allantools (deviations only): {b:.2f} CPU-s")
    print(f"ratio avard / allantools: {a / b:.2f}")
    return 0
