"""Per-parameter check of an event row's 68 % intervals (trans23g, docs/log/explain.md).

    python docs/scripts/compound_intervals.py run "compound 24" 23500 23540 OUT.jsonl
    python docs/scripts/compound_intervals.py table "compound 24" OUT.jsonl [...]

``run`` makes each record of the row (``benchmarks/bench_explain_weekend.py``'s
``rows_events``, the benchmark's seeds when given its first seed), explains it as the
benchmark does and appends x's claims (parameters, intervals) and the benchmark's own score
(``_match``) as one JSON line. ``table`` matches each true effect to a claim as ``_match``
does and prints, per parameter, how often its interval holds the truth, the scatter of the
estimates about the truth, the median half-width and the mean error: an interval too narrow
for its scatter and one off centre read differently here, where the benchmark's one
fraction mixes them. Run from the repository's root, one process at a time.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _row(name: str):  # type: ignore[no-untyped-def]
    from benchmarks.bench_explain_weekend import rows_events

    return next(e for e in rows_events() if e.name.startswith(name))


def run(name: str, first: int, stop: int, out: str) -> None:
    from avard.core.explain.engine import explain_file
    from avard.core.explain.options import ExplainOptions
    from avard.core.io.source import open_record

    from benchmarks.bench_explain_weekend import _match
    from tests.support.weekend import save

    r = _row(name)
    with tempfile.TemporaryDirectory() as d, open(out, "a") as f:
        for seed in range(first, stop):
            path = save(seed, r.weekend, Path(d) / "w.npz")
            t0 = time.process_time()
            ex = explain_file(open_record(path), ExplainOptions(heldout=False))
            ch = ex.channels["x"]
            right, par, inside, total = _match(ch, r.expect, r.weekend.hours * 3600)
            f.write(json.dumps({
                "seed": seed, "right": right, "par": par, "inside": inside, "total": total,
                "claimed": [{"cause": c.cause, "params": c.params, "intervals": c.intervals}
                            for c in ch.claimed],
                "cpu": time.process_time() - t0}) + "\n")
            print(seed, right, par, inside, total, flush=True)


def table(name: str, files: list[str]) -> None:
    r = _row(name)
    recs = [json.loads(line) for fn in files for line in open(fn)]
    stats: dict[str, list[tuple[float, float, float]]] = {}
    for rec in recs:
        used: set[int] = set()
        for j, (cause, p) in enumerate(r.expect):
            cands = [(i, c) for i, c in enumerate(rec["claimed"])
                     if c["cause"] == cause and i not in used]
            if not cands:
                continue
            key0 = next(iter(p))
            i, c = min(cands, key=lambda ic: abs(ic[1]["params"].get(key0, 1e99) - p[key0]))
            used.add(i)
            for k, v in p.items():
                if k not in c["intervals"]:
                    continue
                lo, hi = c["intervals"][k]
                est = c["params"][k]
                stats.setdefault(f"{cause}{j}.{k}", []).append(
                    (float(lo <= v <= hi), est - v, 0.5 * (hi - lo)))
    print(f"{'parameter':28s} {'n':>3s} {'held':>5s} {'sd(err)':>10s} {'median hw':>10s} "
          f"{'ratio':>6s} {'mean err':>10s}")
    held = n = 0
    for k, v in stats.items():
        a = np.array(v)
        held += int(a[:, 0].sum())
        n += len(a)
        sd = float(a[:, 1].std(ddof=1)) if len(a) > 1 else float("nan")
        hw = float(np.median(a[:, 2]))
        print(f"{k:28s} {len(a):3d} {int(a[:, 0].sum()):5d} {sd:10.3g} {hw:10.3g} "
              f"{sd / hw if hw else float('nan'):6.2f} {float(a[:, 1].mean()):10.3g}")
    print(f"held {held}/{n}; right {sum(x['right'] for x in recs)}, params "
          f"{sum(x['par'] for x in recs)} of {len(recs)}")


if __name__ == "__main__":
    if sys.argv[1] == "run":
        run(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5])
    else:
        table(sys.argv[2], sys.argv[3:])
