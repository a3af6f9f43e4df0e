"""Per record of an ``adversary_run`` output: the hidden term's size and its minima, and what x
claimed. Usage: .venv/bin/python docs/scripts/cand26b_read.py OUT.jsonl [OUT2.jsonl]
(with two outputs of one plan, before → after, record by record)."""

import json
import sys


def load(path: str) -> dict[int, dict]:
    return {r["seed"]: r for r in map(json.loads, open(path))}


def what(r: dict) -> str:
    th = [f for f in r["axes"]["x"]["findings"] if f["cause"] == "temperature" and f["claimed"]]
    if not th:
        return "no coupling"
    return th[0].get("mechanism", "?")


def size(r: dict) -> str:
    x = r["truth"]["axes"]["x"]
    c = x["coefficient_mps2_per_k"]
    if "h_mps2" in x:
        return f"c {c:+.2e} h {x['h_mps2']:.2e} (min {x['h_min']:.2e})"
    return f"c {c:+.2e} r {x['r_mps2_per_k_per_s']:.3g} (min {x['r_min']:.3g})"


runs = [load(p) for p in sys.argv[1:]]
for s in sorted(runs[-1]):
    cells = [f"{size(run[s])} {what(run[s])}" for run in runs if s in run]
    print(s, " → ".join(cells))
