"""One-lag truth logged on a DS18B20's 9/10/11/12-bit step (0.5, 0.25, 0.125, 0.0625 K):
explain's verdict, mechanism and coefficient against the truth, per step (grid27).

Records: ``tests/support/hidden.make_record(seed, hours=2, logged=("ambient",))`` with a
3e-3 m/s²/K coupling through a 300 s lag, the log rounded to q (the generator's step set to q).
Run from the repository: ``PYTHONPATH=. OMP_NUM_THREADS=1 nice .venv/bin/python
docs/scripts/grid27_coarse_step_rows.py [SEEDS] [HOURS] [FIRST_SEED] [STEPS]``, STEPS a
comma-separated list of steps (K), default ``0.5,0.25,0.125,0.0625`` (``0.1125``: a °F log
taken as °C, from 0). Each record's line on stderr ends with a digest of its whole
explanation (``--json``), so two runs can be compared to the bit (coarse28)."""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
from pathlib import Path

from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

import tests.support.hidden as hidden
from tests.support.hidden import Truth, make_record, save

TRUTH_C, LAG_S = 3e-3, 300.0


def row(q: float, seed: int, hours: float, tmp: Path) -> dict:
    old = hidden.DS18B20_STEP_C
    hidden.DS18B20_STEP_C = q
    try:
        rec, _ = make_record(seed, hours=hours, logged=("ambient",),
                             truth=Truth(coefficient=(TRUTH_C, 0, 0), lag_s=LAG_S))
    finally:
        hidden.DS18B20_STEP_C = old
    path = save(rec, tmp / f"q{q}_{seed}.npz")
    ex = explain_file(open_record(path), ExplainOptions(channels=("x",)))
    x = ex.channels["x"]
    th = x.thermal
    out = {"explained": bool(x.verdict and x.verdict.explained), "mech": None, "c": None,
           "in": False, "chi2": x.extended.chi2_dof,
           # (the record's temporary directory left out: it differs from run to run)
           "digest": hashlib.sha256(json.dumps(ex.to_dict(), sort_keys=True, default=repr)
                                    .replace(str(tmp), "").encode()).hexdigest()[:16]}
    if th is not None:
        d = th.to_dict()
        lo, hi = d.get("coefficient_interval") or (float("nan"), float("nan"))
        out.update(mech=th.mechanism, c=th.coefficient, lag=th.lag_s,
                   inside=bool(lo <= TRUTH_C <= hi))
        out["in"] = out.pop("inside")
    return out


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 6
    hours = float(sys.argv[2]) if len(sys.argv) > 2 else 2.0
    first = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    steps = ([float(v) for v in sys.argv[4].split(",")] if len(sys.argv) > 4
             else [0.5, 0.25, 0.125, 0.0625])
    print(f"{'step K':>7} {'explained':>10} {'one lag':>8} {'c in 68 %':>10} "
          f"{'median c/truth':>15} {'median chi2/dof':>16}")
    with tempfile.TemporaryDirectory() as d:
        for q in steps:
            rows = [row(q, first + s, hours, Path(d)) for s in range(seeds)]
            n = len(rows)
            cs = sorted(r["c"] / TRUTH_C for r in rows if r["c"] is not None)
            ch = sorted(r["chi2"] for r in rows)
            print(f"{q:>7g} {sum(r['explained'] for r in rows):>6}/{n:<3} "
                  f"{sum(r['mech'] == 'one_lag' for r in rows):>5}/{n:<2} "
                  f"{sum(r['in'] for r in rows):>7}/{n:<2} "
                  f"{cs[len(cs) // 2] if cs else float('nan'):>15.4f} "
                  f"{ch[len(ch) // 2]:>16.3g}", flush=True)
            for s, r in enumerate(rows):
                print(f"    seed {first + s}: {r}", file=sys.stderr)


if __name__ == "__main__":
    main()
