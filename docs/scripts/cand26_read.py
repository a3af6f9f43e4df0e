"""One line per record of an ``adversary_run`` output (cand26): x's chosen mechanism, what is
named beside it, and each extension's held-out −2 ln L against one lag (matched) and z.

    python docs/scripts/cand26_read.py OUT.jsonl [...]
"""

from __future__ import annotations

import json
import sys

SHORT = {"one_lag": "1lag", "two_path": "2p", "quadratic": "quad", "rate": "rate",
         "hysteresis": "hyst"}


def line(r: dict) -> str:
    t = r["truth"]
    kw = t.get("kw", {})
    head = f"{r['kind']} {r['seed']} ×{kw.get('factor', 3):g}"
    if r["rc"] != 0:
        return head + " ERROR"
    x = r["axes"]["x"]
    th = x["thermal"] or {}
    claims = [f for f in x["findings"] if f["claimed"]]
    tc = [f for f in claims if f["cause"] == "temperature"]
    p = th.get("path") or {}
    mech = tc[0].get("mechanism") if tc else "—"
    m = p.get("heldout_matched_minus_one_lag", {})
    ms = " ".join(f"{SHORT[k]} {v:+.1f}" for k, v in m.items() if k != "one_lag")
    beside = ",".join(p.get("mechanism_alternatives", []) + p.get("mechanism_fits_as_well", []))
    others = ",".join(f["cause"] for f in claims if f["cause"] != "temperature")
    c = t["axes"]["x"].get("coefficient_mps2_per_k", 0.0)
    return (f"{head} c{'+' if c > 0 else '-'} → {mech}"
            + (f" [{beside}]" if beside else "") + (f" +{others}" if others else "")
            + f" | passed {th.get('passed')} z {th.get('z', float('nan')):.1f}"
            + f" | matched {ms} | zext {p.get('z_extra')}")


if __name__ == "__main__":
    for fn in sys.argv[1:]:
        for ln in open(fn):
            print(line(json.loads(ln)))
