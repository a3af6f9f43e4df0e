"""How often explain's coupling-change line (core/explain/coupling_change.py) appears, and what
it does to the claims, on the weekend benchmark's records (remount27).

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/remount27_count.py --source rows \
        --rows null --cases 10

Sources: ``rows`` (``bench_explain_weekend.rows``, seeds ``seed0 + 1000·j + i``, j the row's
place among those selected: the benchmark's own ``run``), ``events`` (``rows_events``, seeds
``seed0 + 500 + 1000·j + i``, the benchmark's ``score_events``), ``paths``
(``rows_paths``, ``seed0 + 7000 + 1000·j + i``), ``outside`` (``outside_rows``, j the place
in the whole list) and ``stepcoupled``: a steady one-lag coupling at 3× its stated minimum on
x beside one bias step at 3× its stated minimum at 30, 50 or 70 % of a 4 h record (seeds
``29000 + i``). Per axis: the claims other than lines, whether the line appears, and the
steps the change took (not claimed); y and z are null axes in every row (the generator
couples x only), x too in a null row.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks import bench_explain_weekend as bw

LINES = ("sinusoid", "periodic")


def stepcoupled() -> list[tuple[str, object, tuple[str, ...]]]:
    from avard.core.explain.causes import min_detectable_step
    from avard.core.explain.thermal_fit import min_detectable_tempco

    from tests.support.weekend import Weekend

    rec = 4 * 3600.0
    w = 2 * math.pi / bw.PERIOD
    A = bw._plate_swing() / math.hypot(1.0, w * 60.0)
    c = 3 * min_detectable_tempco(bw.N, bw.B, bw.K, rec, A, bw.PERIOD, 0.0)
    st = 3 * min_detectable_step(bw.N, bw.B, bw.K, rec)
    base = Weekend(hours=4.0, rate_hz=bw.RATE, N=bw.N, B=bw.B, K=bw.K,
                   coefficient=(c, 0.0, 0.0))
    return [(f"coupling {cc:.3g} + step {st:.3g} at {f:.0%}",
             replace(base, coefficient=(cc, 0.0, 0.0), steps=[(f * rec, st)]),
             ("temperature", "bias_step"))
            for cc in (c, 2e-3) for f in (0.3, 0.5, 0.7)]


def selected(source: str, only: list[str] | None, seed0: int, cases: int):
    def pick(names: list[str]) -> list[int]:
        return [i for i, n in enumerate(names) if only is None
                or any(n.startswith(p) for p in only)]

    out = []
    if source == "rows":
        rs = bw.rows()
        for j, i in enumerate(pick([r.name for r in rs])):
            r = rs[i]
            want = ("temperature",) if r.coefficient else ()
            out += [(r.name, r.weekend, want, seed0 + 1000 * j + k) for k in range(cases)]
    elif source == "events":
        rs = bw.rows_events()
        for j, i in enumerate(pick([r.name for r in rs])):
            r = rs[i]
            want = tuple(c for c, _ in r.expect) + r.also
            out += [(r.name, r.weekend, want, seed0 + 500 + 1000 * j + k)
                    for k in range(cases)]
    elif source == "paths":
        rs = bw.rows_paths()
        for j, i in enumerate(pick([r.name for r in rs])):
            r = rs[i]
            out += [(r.name, r.weekend, ("temperature", "warmup"), seed0 + 7000 + 1000 * j + k)
                    for k in range(cases)]
    elif source == "outside":
        rs = bw.outside_rows()
        for i in pick([r.name for r in rs]):
            r = rs[i]
            out += [(r.name, r.weekend, ("temperature",), seed0 + 1000 * i + k)
                    for k in range(cases)]
    elif source == "stepcoupled":
        for name, w, want in stepcoupled():
            if only is None or any(name.startswith(p) for p in only):
                out += [(name, w, want, 29000 + k) for k in range(cases)]
    return out


def main(argv: list[str]) -> int:
    from avard.core.explain.coupling_change import change_line

    ap = argparse.ArgumentParser()
    ap.add_argument("--source", default="rows")
    ap.add_argument("--rows")
    ap.add_argument("--cases", type=int, default=10)
    ap.add_argument("--seed0", type=int, default=23000)
    a = ap.parse_args(argv)
    only = a.rows.split(",") if a.rows else None
    table: dict[str, dict[str, int]] = {}
    for name, w, want, seed in selected(a.source, only, a.seed0, a.cases):
        ex, cpu = bw.explain_weekend(w, seed)
        t = table.setdefault(name, {"records": 0, "axes": 0, "false": 0, "line_x": 0,
                                    "line_yz": 0, "steps_taken": 0, "x_step": 0,
                                    "x_right": 0, "cpu": 0})
        t["records"] += 1
        t["cpu"] += cpu
        for ax, ch in ex.channels.items():
            t["axes"] += 1
            mine = want if ax == "x" else ()
            other = [f for f in ch.claimed if f.cause not in LINES and f.cause not in mine]
            t["false"] += bool(other)
            line = change_line(ch.findings)
            t["line_x" if ax == "x" else "line_yz"] += line is not None
            taken = [f for f in ch.findings if not f.claimed and f.model_dependent
                     and f.cause in ("bias_step", "excursion")]
            t["steps_taken"] += len(taken)
            if ax == "x":
                t["x_step"] += any(f.cause == "bias_step" for f in ch.claimed)
                t["x_right"] += bool(want) and set(want) <= {f.cause for f in ch.claimed}
            if line is not None:
                print(f"  {name} seed {seed} {ax}: {line}; claims "
                      f"{[g.cause for g in ch.claimed]}", flush=True)
            if other:
                print(f"  {name} seed {seed} {ax}: claimed {[g.cause for g in other]}",
                      flush=True)
    print("| row | records | axes | axes claiming outside the row's causes | line on x | "
          "line on y, z | steps not claimed at a change | x: a step claimed | "
          "x: the row's causes all claimed | CPU-s/record |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, t in table.items():
        print(f"| {name} | {t['records']} | {t['axes']} | {t['false']} | {t['line_x']} | "
              f"{t['line_yz']} | {t['steps_taken']} | {t['x_step']} | {t['x_right']} | "
              f"{t['cpu'] / t['records']:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
