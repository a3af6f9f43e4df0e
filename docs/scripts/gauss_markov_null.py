"""The null study of the Gauss–Markov claim threshold (docs/explain.md, "Stated detection
power (Gauss–Markov)"): records without a Gauss–Markov process from tests/support/hidden.py
(the generator written apart from the simulator; 4 h at 10 Hz, N = 1.6e-4 m/s/√s, B = 2e-5
m/s², K = 2e-6 m/s²·√s, nothing hidden) through ``explain_file``; prints the quantiles of
the scan's z per axis, the axes above the threshold and the Gauss–Markov claims, beside
Davies' bound (``gauss_markov.scan_false_claim_bound``) for the same scan.

    python docs/scripts/gauss_markov_null.py [records] [first seed]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from avard.core.explain.engine import explain_file
from avard.core.explain.gauss_markov import (
    Z_GAUSS_MARKOV,
    scan_arc_length,
    scan_false_claim_bound,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tests.support.hidden import make_record, save

N_W, B_I, K_R, HOURS, RATE = 1.6e-4, 2e-5, 2e-6, 4.0, 10.0


def main(records: int, seed0: int) -> None:
    zs: list[float] = []
    high: list[str] = []
    claims = 0
    with tempfile.TemporaryDirectory() as d:
        for i in range(records):
            rec, _ = make_record(seed0 + i, hours=HOURS, rate_hz=RATE, N=N_W, B=B_I, K=K_R)
            ex = explain_file(str(save(rec, Path(d) / "r.npz")), heldout=False)
            for name, ch in ex.channels.items():
                gm = next(f for f in ch.findings if f.cause == "gauss_markov")
                zs.append(gm.statistic)
                claims += gm.claimed
                if gm.statistic >= Z_GAUSS_MARKOV:
                    high.append(f"seed {seed0 + i} {name}: z {gm.statistic:.2f}, T "
                                f"{gm.params.get('time_constant_s', float('nan')):.4g} s, "
                                f"claimed {gm.claimed}")
            print(f"record {i + 1}/{records}", file=sys.stderr, flush=True)
    z = np.asarray(zs)
    v = scan_arc_length(N_W, B_I, K_R, HOURS * 3600, RATE)
    print(f"{len(z)} null axes ({records} records, seeds {seed0}…{seed0 + records - 1}); "
          f"z = 0 (no component present at any T) on {int(np.sum(z == 0))}")
    for q in (0.5, 0.9, 0.95, 0.99, 1.0):
        print(f"  z quantile {q:.2f}: {np.quantile(z, q):.2f}")
    for u in (2.5, 3.0, Z_GAUSS_MARKOV):
        print(f"  share z ≥ {u:g}: {np.mean(z >= u):.3f} (Davies' bound, V = {v:.2f}: "
              f"{scan_false_claim_bound(u, v):.4f})")
    print(f"  Gauss–Markov claims: {claims} of {len(z)}")
    for h in high:
        print("  " + h)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 50,
         int(sys.argv[2]) if len(sys.argv) > 2 else 80000)
