"""The thermal-path rows with a quadratic or a dT/dt truth, the log read on a coarse step
(coarse29): the path candidates' temperature behind the readings on a 9–11-bit DS18B20.

Records: the benchmark's "path: quadratic" and "path: dT/dt" rows
(``benchmarks.bench_explain_weekend.rows_paths``: ``tests/support/weekend.py``, 4 h, the
plate logged, the linear coupling and the extra term each at 3× their stated minima), with the
room's HVAC swing ``HVAC`` K (default 2.0, the rows' 0.5 scaled so that a 0.25 or 0.5 K step
sees a cycle of several levels; each term's size scaled with it, the coupling and r by
0.5/HVAC and the quadratic by its square, so that its signal stays the row's: 3× its
stated minimum) and the
log rounded to q (the generator's ``STEP_C`` set to q). Seeds ``FIRST_SEED`` on, the row's
scoring (``score_path_record``: right = the row's mechanism chosen alone; params = within 20 %;
in 68 % = the parameters inside their intervals).

Run from the repository: ``PYTHONPATH=. OMP_NUM_THREADS=1 nice .venv/bin/python
docs/scripts/coarse29_path_rows.py [SEEDS] [FIRST_SEED] [STEPS] [HVAC] [ROWS]``; STEPS a
comma-separated list (K), default ``0.25,0.5``; ROWS ``quadratic,dT/dt`` by default. Each
record's line goes to stderr."""

from __future__ import annotations

import sys
from dataclasses import replace

import tests.support.weekend as wk
from benchmarks.bench_explain_weekend import _path_param_ok, explain_weekend, rows_paths

#: each row's extra term (the parameter named in its truth)
EXTRA = {"quadratic": "quadratic", "rate": "rate_coupling"}


def score(r, seed: int) -> dict:
    """The row's scoring (``score_path_record``'s rules) with the extra term's ratio to its
    truth kept."""
    ex, _ = explain_weekend(r.weekend, seed, heldout=True)
    x = ex.channels["x"]
    th = [f for f in x.claimed if f.cause == "temperature"]
    out = {"seed": seed, "chosen": str(th[0].mechanism) if th else "",
           "alternatives": list(th[0].alternatives) if th else [], "params": False,
           "inside": 0, "total": 0, "ratio": float("nan"), "c_ratio": float("nan"),
           "unexplained": bool(x.verdict is not None and not x.verdict.explained),
           "false": sum(bool([f for f in ex.channels[a].claimed
                              if f.cause not in ("sinusoid", "periodic")]) for a in "yz")}
    if out["chosen"] == r.mechanism:
        p, iv = th[0].params, th[0].intervals
        out["params"] = all(k in p and _path_param_ok(k, p[k], v) for k, v in r.truth.items())
        for k, v in r.truth.items():
            if k in iv and not k.startswith("lag"):
                out["total"] += 1
                out["inside"] += int(iv[k][0] <= v <= iv[k][1])
        key = EXTRA[r.mechanism]
        out["ratio"] = p.get(key, float("nan")) / r.truth[key]
        out["c_ratio"] = p.get("coefficient", float("nan")) / r.truth["coefficient"]
    return out


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    first = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    steps = ([float(v) for v in sys.argv[3].split(",")] if len(sys.argv) > 3
             else [0.25, 0.5])
    hvac = float(sys.argv[4]) if len(sys.argv) > 4 else 2.0
    names = (sys.argv[5].split(",") if len(sys.argv) > 5 else ["quadratic", "dT/dt"])
    rows = [r for r in rows_paths() if r.name in {f"path: {n}" for n in names}]
    print(f"{'row':16s} {'step K':>6s} {'right':>6s} {'named':>6s} {'params':>7s} "
          f"{'in 68 %':>8s} {'x unexpl.':>9s} {'false (y,z)':>11s} {'extra/truth':>11s}  chosen")
    for r in rows:
        # the sizes scaled with the swing (c and r as it, the quadratic as its square): each
        # term's signal stays the row's, at 3× its stated minimum
        k = 0.5 / hvac
        scale = {"coefficient": k, "quadratic": k * k, "rate_coupling": k}
        truth = {key: v * scale[key] for key, v in r.truth.items()}
        w = r.weekend
        r = replace(r, truth=truth, weekend=replace(
            w, hvac_c=hvac, coefficient=(truth["coefficient"], 0.0, 0.0),
            quadratic=w.quadratic * k * k, rate_coupling=w.rate_coupling * k))
        for q in steps:
            old = wk.STEP_C
            wk.STEP_C = q
            try:
                got = []
                for s in range(seeds):
                    got.append(score(r, first + s))
                    print(f"    {r.name} q {q:g} {got[-1]}", file=sys.stderr, flush=True)
            finally:
                wk.STEP_C = old
            n = len(got)
            chosen = ", ".join(sorted({g["chosen"] or "none" for g in got}))
            ratios = sorted(g["ratio"] for g in got if g["ratio"] == g["ratio"])
            med = ratios[len(ratios) // 2] if ratios else float("nan")
            alone = sum(g['chosen'] == r.mechanism and not g['alternatives'] for g in got)
            print(f"{r.name[6:]:16s} {q:6g} {alone:>3}/{n:<2} "
                  f"{sum(r.mechanism in (g['chosen'], *g['alternatives']) for g in got):>3}/{n:<2} "
                  f"{sum(g['params'] for g in got):>4}/{n:<2} "
                  f"{sum(g['inside'] for g in got):>4}/{sum(g['total'] for g in got):<3} "
                  f"{sum(g['unexplained'] for g in got):>9} "
                  f"{sum(g['false'] for g in got):>7}/{2 * n:<3} {med:>11.3f}  {chosen}",
                  flush=True)


if __name__ == "__main__":
    main()
