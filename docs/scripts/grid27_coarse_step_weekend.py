"""The weekend generator (``tests/support/weekend.py``) with its log read on 0.25, 0.125 and
0.0625 K: a one-lag coupling of 3e-3 m/s²/K on x, the plate logged, 4 h, seeds 31–36
(grid27). Run from the repository: ``PYTHONPATH=. OMP_NUM_THREADS=1 nice .venv/bin/python
docs/scripts/grid27_coarse_step_weekend.py``."""

from __future__ import annotations

import tempfile
from pathlib import Path

from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

import tests.support.weekend as wk

C = 3e-3


def main() -> None:
    base = wk.Weekend(hours=4.0, coefficient=(C, 0.0, 0.0), logged=("plate",))
    print(f"{'step':>6} explained one_lag  c_in68  c/truth")
    with tempfile.TemporaryDirectory() as d:
        for q in (0.25, 0.125, 0.0625):
            wk.STEP_C = q
            rows = []
            for seed in range(31, 37):
                p = wk.save(seed, base, Path(d) / f"w{seed}.npz")
                x = explain_file(open_record(p), ExplainOptions(channels=("x",))).channels["x"]
                th = x.thermal
                lo, hi = th.to_dict()["coefficient_interval"] if th else (0.0, 0.0)
                rows.append((bool(x.verdict and x.verdict.explained),
                             th.mechanism if th else None, lo <= C <= hi,
                             th.coefficient / C if th else 0.0))
            ratios = " ".join(f"{r[3]:.3f}" for r in rows)
            print(f"{q:6g} {sum(r[0] for r in rows)}/6 "
                  f"{sum(r[1] == 'one_lag' for r in rows)}/6 "
                  f"{sum(r[2] for r in rows)}/6  {ratios}", flush=True)


if __name__ == "__main__":
    main()
