"""The coupling-change line on adversary_gen3 records (change28): read JSONLs of
``docs/scripts/adversary_gen3_run.py run`` and count, per kind and length, the axes where
the change is said ("changed"), where the hedged line is said instead ("hedged": the
one-lag parts differ but one fixed path of three lags fitted on either part predicts the
other), and on ``remount`` axes its time, the parts' coefficients against the truth and
whether their ±1 se intervals hold it. A run made before change28 has no hedged line: its
line is "changed" wherever the scan fired (statistic ≥ threshold).

    .venv/bin/python docs/scripts/adversary_gen3_change28.py /tmp/change28/after_remount.jsonl
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict

CAUSE = "coupling_change"
KEYS = ["records", "axes", "coupled axes", "changed (coupled)", "hedged (coupled)",
        "changed (uncoupled z)", "hedged (uncoupled z)", "time within 2 % of the record",
        "before within 20 %", "after within 20 %", "before in its ±1 se",
        "after in its ±1 se", "step or excursion claimed (axes)"]


def _said(f: dict | None) -> tuple[bool, bool]:
    """(changed, hedged) of a coupling_change finding, before and after change28."""
    if f is None:
        return False, False
    p = f["params"]
    if "changed" in p:
        return bool(p["changed"]), bool(p.get("hedged"))
    return f["statistic"] >= f["threshold"], False


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
                coupled = tr.get("cause") is not None
                t["axes"] += 1
                t["coupled axes"] += coupled
                f = next((f for f in a["findings"] if f["cause"] == CAUSE), None)
                changed, hedged = _said(f)
                tag = "coupled" if coupled else "uncoupled z"
                t[f"changed ({tag})"] += changed
                t[f"hedged ({tag})"] += hedged
                t["step or excursion claimed (axes)"] += any(
                    g["claimed"] and g["cause"] in ("bias_step", "excursion")
                    for g in a["findings"])
                if tr.get("cause") != "remount" or not (changed or hedged) or f is None:
                    continue
                p, iv = f["params"], f["intervals"]
                t["time within 2 % of the record"] += abs(p["time_s"] - tr["change_s"]) <= (
                    0.02 * rec_s)
                for side in ("before", "after"):
                    want, got = tr[f"coefficient_{side}"], p[f"coefficient_{side}"]
                    t[f"{side} within 20 %"] += abs(got - want) <= 0.2 * abs(want)
                    lo, hi = iv[f"coefficient_{side}"]
                    t[f"{side} in its ±1 se"] += lo <= want <= hi
    print("| kind | hours | " + " | ".join(KEYS) + " |")
    print("|---|---|" + "---|" * len(KEYS))
    for (kind, h), t in sorted(rows.items()):
        print(f"| {kind} | {h:g} | " + " | ".join(str(t[k]) for k in KEYS) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
