"""Why a re-mount's parts missed their ±1 se (change29): one adversary_gen3 re-mount record
explained whole, with the generator changed one thing at a time, and each part's coupling
against the truth.

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/change29_sensor_lag.py 107 12 base

Variants: base, nolag (the plate sensor's own 15 s lag taken out), noround (no 0.0625 K
rounding), nolag_noround.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from avard.core.explain import coupling_change as cc
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

from tests.support import adversary_gen3 as gen


def main(seed: int, hours: float, variant: str) -> int:
    lag1 = gen.lag1
    if "nolag" in variant:
        gen.lag1 = lambda x, dt, tau: x.copy() if tau == 15.0 else lag1(x, dt, tau)
    if "noround" in variant:
        gen.DS_STEP = 1e-6
    res = []
    orig = cc.find_change

    def spy(*a, **k):
        r = orig(*a, **k)
        res.append(r)
        return r

    cc.find_change = spy
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "r.npz"
        truth = gen.make_record("remount", seed, hours, p)
        explain_file(open_record(str(p)), ExplainOptions())
    for ax, r in zip("xy", res, strict=False):
        t = truth["axes"][ax]
        for side, part in (("before", r.before), ("after", r.after)):
            w = t[f"coefficient_{side}"]
            print(f"{variant} {ax} {side} rel {(part.c - w) / w:+.4f} "
                  f"z {(part.c - w) / part.se:+.2f} lag {part.lag_s:.0f} true {t['lag_s']:.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]))
