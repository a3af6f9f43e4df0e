"""`avard explain` over the large hidden-effect set: detection rate and false-claim rate.

    python -m benchmarks explain [--per-kind 12] [--n 262144] [--seed0 7000]

Every case is drawn by ``avard.core.effects.make_case`` (one of the eight causes or none,
parameters from a seeded random choice) and only the record is handed to ``explain``. A case
is *detected* when the hidden cause is named with its parameters within the issue's
tolerances (``effects.TOLERANCE``); a *false claim* is any claimed cause that was not hidden
(or a second claim of it). The reference measured in the same run is what the five-term fit
alone can say: it flags a record when its misfit exceeds 3 sigma somewhere, but cannot name a
cause; its "false flags" are flags on null records. Times are process CPU seconds per case,
with the AVAR measurement of the same record (one pass of the estimator) as the unit.
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

from avard.core import effects, explain


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks explain")
    ap.add_argument("--per-kind", type=int, default=12, help="cases per cause and null")
    ap.add_argument("--n", type=int, default=1 << 18, help="samples per record (50 Hz)")
    ap.add_argument("--seed0", type=int, default=7000)
    args = ap.parse_args(argv)

    rows: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    failures: list[str] = []
    t_meas = 0.0
    for j, kind in enumerate(effects.CASE_KINDS):
        for i in range(args.per_kind):
            seed = args.seed0 + 1000 * j + i
            rec, truth = effects.make_case(seed, kind, n=args.n)
            y = rec.accel[:, 0]
            t0 = time.process_time()
            meas = explain.measure(y, rec.rate_hz)
            base = explain.fit_terms(meas)
            flagged = bool(explain.misfit_ranges(meas, base.avar(meas.tau)))
            t1 = time.process_time()
            ch = explain.explain(rec).channels["x"]
            t2 = time.process_time()
            t_meas += t1 - t0
            ok, why = effects.check_case(truth, ch.findings)
            claimed = [f["cause"] for f in ch.findings]
            false = [c for c in claimed if c != truth.cause] + \
                ([truth.cause] * (claimed.count(truth.cause) - 1) if truth.cause else [])
            r = rows[kind]
            r["cases"] += 1
            r["detected"] += ok
            r["false"] += bool(false)
            r["flagged"] += flagged
            r["cpu"] += t2 - t1
            if not ok:
                failures.append(f"seed {seed} {kind}: {why}")

    total_cases = int(sum(r["cases"] for r in rows.values()))
    eff = [k for k in rows if k != "none"]
    det = sum(rows[k]["detected"] for k in eff) / sum(rows[k]["cases"] for k in eff)
    fcl = sum(r["false"] for r in rows.values()) / total_cases
    flag = sum(rows[k]["flagged"] for k in eff) / sum(rows[k]["cases"] for k in eff)
    null_flag = rows["none"]["flagged"] / max(rows["none"]["cases"], 1)
    unit = t_meas / total_cases

    print(f"explain on {total_cases} hidden-effect cases, {args.n} samples at 50 Hz each "
          f"({args.n / 50 / 3600:.2f} h), seeds from {args.seed0}")
    print()
    print(f"{'kind':14s} {'cases':>5s} {'detected':>9s} {'false claims':>13s} "
          f"{'5-term flags':>13s} {'CPU s/case':>11s} {'x AVAR':>7s}")
    for k in effects.CASE_KINDS:
        r = rows[k]
        n = r["cases"]
        label = "no findings" if k == "none" else "detected"
        det_s = f"{r['detected'] / n:8.0%}" if n else "-"
        print(f"{k:14s} {n:5.0f} {det_s:>9s} {r['false'] / n:13.0%} {r['flagged'] / n:13.0%} "
              f"{r['cpu'] / n:11.2f} {r['cpu'] / n / unit:7.1f}   ({label})")
    print()
    print(f"detection rate (right cause, parameters within tolerance, nothing else): {det:.1%}")
    print(f"false-claim rate (any cause claimed that was not hidden, all cases):     {fcl:.1%}")
    print(f"null records with no findings: {rows['none']['detected'] / rows['none']['cases']:.0%}")
    print(f"reference, five-term fit alone: flags {flag:.0%} of effect records (names no cause),"
          f" flags {null_flag:.0%} of null records")
    print(f"ratio detection(explain) / flag(5-term): {det / flag if flag else float('nan'):.2f}")
    print(f"CPU per case {sum(r['cpu'] for r in rows.values()) / total_cases:.2f} s = "
          f"{sum(r['cpu'] for r in rows.values()) / total_cases / unit:.1f}x one AVAR "
          f"measurement + 5-term fit ({unit:.2f} s)")
    if failures:
        print("\nmissed or wrong:")
        for f in failures:
            print("  " + f)
    return 0
