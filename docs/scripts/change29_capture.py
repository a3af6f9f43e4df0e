"""Capture ``coupling_change.find_change``'s inputs on adversary_gen3 records (change29), so
the parts' refit can be studied without re-running explain.

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/change29_capture.py \
        --kinds remount --hours 4,12 --seeds 101-110 --out /tmp/c29/cap

One pickle per record (``KIND_SEED_H.pkl``): the truth and, per axis, the arguments
find_change was called with (y, temps, thermal, trans, rate_b, screen) and its outcome.
"""

from __future__ import annotations

import argparse
import pickle
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from avard.core.explain import coupling_change as cc
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

from tests.support import adversary_gen3 as gen


def _seeds(s: str) -> list[int]:
    out: list[int] = []
    for part in s.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--kinds", default="remount")
    ap.add_argument("--hours", default="4,12")
    ap.add_argument("--seeds", default="101-110")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    orig = cc.find_change
    calls: list[tuple] = []

    def spy(*args, **kw):
        r = orig(*args, **kw)
        calls.append((args, kw, r))
        return r

    cc.find_change = spy
    with tempfile.TemporaryDirectory() as tmp:
        for seed in _seeds(a.seeds):
            for h in [float(x) for x in a.hours.split(",")]:
                for kind in a.kinds.split(","):
                    dest = out / f"{kind}_{seed}_{h:g}.pkl"
                    if dest.exists():
                        continue
                    p = Path(tmp) / "r.npz"
                    truth = gen.make_record(kind, seed, h, p)
                    truth.pop("_signals", None)
                    calls.clear()
                    explain_file(open_record(str(p)), ExplainOptions())
                    with open(dest, "wb") as fo:
                        pickle.dump({"truth": truth, "calls": list(calls)}, fo)
                    print(dest, len(calls), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
