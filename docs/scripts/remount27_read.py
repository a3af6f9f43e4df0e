"""The coupling-change line (core/explain/coupling_change.py) on adversary_gen3 records
(remount27): read a JSONL of ``docs/scripts/adversary_gen3_run.py run`` and count, per kind
and length, the axes where the line appears, and on ``remount`` axes (x, y) its time and the
coefficients before and after against the truth and the steps claimed at the change.

    .venv/bin/python docs/scripts/remount27_read.py /tmp/rm27/remount.jsonl
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict

CAUSE = "coupling_change"


def main(argv: list[str]) -> int:
    rows: dict[tuple[str, float], dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for path in argv:
        for ln in open(path, encoding="utf-8"):
            r = json.loads(ln)
            if "axes" not in r:
                continue
            t = rows[(r["kind"], r["hours"])]
            t["records"] += 1
            rec_s = r["hours"] * 3600
            for ax, a in r["axes"].items():
                tr = r["truth"]["axes"][ax]
                coupled = tr.get("cause") == "remount"
                t["axes"] += 1
                t["coupled axes"] += coupled
                f = next((f for f in a["findings"] if f["cause"] == CAUSE), None)
                said = f is not None and f["statistic"] >= f["threshold"]
                t["line (axes)"] += said
                steps = [g for g in a["findings"] if g["claimed"]
                         and g["cause"] in ("bias_step", "excursion")]
                t["step or excursion claimed (axes)"] += bool(steps)
                if not coupled:
                    continue
                ts = tr["change_s"]
                t["step claimed within 5 % of the change"] += any(
                    abs(g["params"].get("time_s", g["params"].get("start_s", -1e9)) - ts)
                    <= 0.05 * rec_s
                    or abs(g["params"].get("end_s", -1e9) - ts) <= 0.05 * rec_s
                    for g in steps)
                if not said:
                    continue
                p = f["params"]
                t["time within 2 % of the record"] += abs(p["time_s"] - ts) <= 0.02 * rec_s
                t["before within 20 %"] += (abs(p["coefficient_before"]
                                               - tr["coefficient_before"])
                                           <= 0.2 * abs(tr["coefficient_before"]))
                t["after within 20 %"] += (abs(p["coefficient_after"] - tr["coefficient_after"])
                                          <= 0.2 * abs(tr["coefficient_after"]))
                iv = f["intervals"]
                t["before in its ±1 se"] += (iv["coefficient_before"][0]
                                             <= tr["coefficient_before"]
                                             <= iv["coefficient_before"][1])
                t["after in its ±1 se"] += (iv["coefficient_after"][0]
                                            <= tr["coefficient_after"]
                                            <= iv["coefficient_after"][1])
    keys = ["records", "axes", "coupled axes", "line (axes)", "time within 2 % of the record",
            "before within 20 %", "after within 20 %", "before in its ±1 se",
            "after in its ±1 se", "step or excursion claimed (axes)",
            "step claimed within 5 % of the change"]
    print("| kind | hours | " + " | ".join(keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for (kind, h), t in sorted(rows.items()):
        print(f"| {kind} | {h:g} | " + " | ".join(str(t[k]) for k in keys) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
