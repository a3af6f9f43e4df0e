"""The null study of the Gauss–Markov claim threshold (docs/log/explain.md, "Stated detection
power (Gauss–Markov)"): records without a Gauss–Markov process from tests/support/hidden.py
(the generator written apart from the simulator; 4 h at 10 Hz, N = 1.6e-4 m/s/√s, B = 2e-5
m/s², K = 2e-6 m/s²·√s, nothing hidden) through ``explain_file``; prints the quantiles of
the scan's z per axis, the axes with z ≥ 3 and the Gauss–Markov claims, beside
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
    noise_whitener,
    scan_arc_length,
    scan_directions,
    scan_false_claim_bound,
)
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tests.support.hidden import make_record, save

N_W, B_I, K_R, HOURS, RATE = 1.6e-4, 2e-5, 2e-6, 4.0, 10.0


def z_cumulants(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                rate_hz: float, steps: int = 40) -> tuple[NDArray, NDArray]:
    """(variance, skewness) of z(T) over the scanned T under the fit's own noise model. z is
    a quadratic form in the Gaussian data, xᵀBx with B = Σ w_k A_k (w = L⁻ᵀU, the weights
    z puts on the AVAR estimates): κ_r = 2^(r−1)(r−1)!·tr((BΣ)^r), in Whittle form κ2 =
    (2/M)∫S²g² dν, κ3 = (8/M²)∫S³g³ dν over (−½, ½), g = Σ w_k|H_k|². κ2 = 1 checks the
    integration against the covariance the fit uses."""
    m, n, comps, theta, L = noise_whitener(n_white, b_inst, k_rrw, record_s, rate_hz)
    W = np.linalg.solve(L.T, scan_directions(n_white, b_inst, k_rrw, record_s, rate_hz, steps))
    mmax = float(m.max())
    nu = np.concatenate([np.linspace(1e-12, 8.0 / mmax, 513)[1:],
                         np.linspace(8.0 / mmax, 0.5, int(12 * mmax))[1:]])
    dnu = np.gradient(nu)
    S = sum(t * c.psd(rate_hz)(nu) for t, c in zip(theta, comps, strict=True))
    H = np.array([2.0 * np.sin(np.pi * nu * k) ** 4 / (k**2 * np.sin(np.pi * nu) ** 2)
                  for k in m])
    g = W.T @ H
    k2 = (2.0 / n) * 2.0 * np.sum((S * g) ** 2 * dnu, axis=1)
    k3 = (8.0 / n**2) * 2.0 * np.sum((S * g) ** 3 * dnu, axis=1)
    return k2, k3 / k2**1.5


def main(records: int, seed0: int) -> None:
    k2, skew = z_cumulants(N_W, B_I, K_R, HOURS * 3600, RATE)
    print(f"z under the fit's model over the scanned T: variance {k2.min():.3f}…{k2.max():.3f},"
          f" skewness {skew.min():.3f}…{skew.max():.3f}")
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
                if gm.statistic >= 3.0:
                    high.append(f"seed {seed0 + i} {name}: z {gm.statistic:.2f}, T "
                                f"{gm.params.get('time_constant_s', float('nan')):.4g} s, "
                                f"claimed {gm.claimed}")
            print(f"record {i + 1}/{records}", file=sys.stderr, flush=True)
    if not zs:
        return
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
