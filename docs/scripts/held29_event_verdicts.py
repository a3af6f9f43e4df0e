"""held29: the verdict of axis x (and its held-out χ², n, gain) on the weekend benchmark's
event rows, record by record, which the benchmark's table does not print (it counts claims
and intervals): what the held-out handling of claimed events can move.

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/held29_event_verdicts.py ROW ...

ROW: a prefix of an event row's name ("compound 4 h", "warm-up", "drift"); seeds as the
benchmark's ``run_events`` gives them (seed0 23000 + 500 + 1000·j, j the row's place).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def main() -> None:
    from avard.core.explain.engine import explain_file
    from avard.core.explain.options import ExplainOptions
    from avard.core.io.source import open_record

    from benchmarks.bench_explain_weekend import rows_events
    from tests.support.weekend import save

    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=8)
    ap.add_argument("rows", nargs="+")
    a = ap.parse_args()
    allrows = rows_events()
    for j, r in enumerate(allrows):
        if not any(r.name.startswith(p) for p in a.rows):
            continue
        seed0 = 23000 + 500 + 1000 * j
        bad = 0
        print(f"{r.name}:")
        with tempfile.TemporaryDirectory() as d:
            for i in range(a.cases):
                path = save(seed0 + i, r.weekend, Path(d) / "w.npz")
                ex = explain_file(open_record(path), ExplainOptions()).to_dict()
                ch = ex["channels"]["x"]
                v = ch["verdict"]
                bad += not v["explained"]
                claimed = ",".join(f["cause"] for f in ch["findings"] if f["claimed"])
                print(f"  seed {seed0 + i}: {'fits' if v['explained'] else 'UNEXPLAINED'}"
                      f" held-out χ² {v['heldout_chi2']} n {v['heldout_n']} p {v['heldout_p']}"
                      f" gain {ex['holdout_gain']} claimed {claimed}", flush=True)
        print(f"  unexplained {bad}/{a.cases}")


if __name__ == "__main__":
    main()
