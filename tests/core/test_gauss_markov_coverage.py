"""The Gauss–Markov cause's 68 % intervals are checked, not assumed (issue 11, item 3).

Records from tests/support/hidden.py (written apart from the simulator: its GM process is an
AR(1) recursion, the fit's model the continuous-time closed form), at the benchmark's case:
4 h at 10 Hz, N = 1.6e-4 m/s/√s, B = 2e-5 m/s², K = 2e-6 m/s²·√s, a Gauss–Markov process on
every axis at 3× its stated minimum (σ and T to 10 %), with T = 10 s and T = 30 s. Each
record goes through ``explain_file`` as a user's file would. Over 40 records (120 axes) per
T, the share of 68 % intervals of σ and of T that hold the truth must be 68.3 % within two
binomial standard deviations (±8.5 % at 120 axes), and the cause claimed on every axis.

Measured (2026-11-24): see docs/log/explain.md, "Stated detection power (Gauss–Markov)".
"""

from __future__ import annotations

import math

import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.gauss_markov import min_detectable_gauss_markov
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save

N_W, B_I, K_R = 1.6e-4, 2e-5, 2e-6
HOURS, RATE = 4.0, 10.0
RECORDS = 40
LEVEL = 0.683


def _sigma_at_3x(T: float) -> float:
    args = (N_W, B_I, K_R, T, HOURS * 3600, RATE)
    return 3 * max(min_detectable_gauss_markov(*args), min_detectable_gauss_markov(*args, rel=0.1))


@pytest.mark.slow
@pytest.mark.parametrize(("T", "seed0"), [(10.0, 70000), (30.0, 71000)])
def test_gauss_markov_intervals_hold_the_truth_68_percent(tmp_path, T, seed0):
    sigma = _sigma_at_3x(T)
    hits = {"sigma": 0, "time_constant_s": 0}
    truth = {"sigma": sigma, "time_constant_s": T}
    axes = 0
    for i in range(RECORDS):
        rec, _ = make_record(seed0 + i, hours=HOURS, rate_hz=RATE, N=N_W, B=B_I, K=K_R,
                             truth=Truth(gauss_markov=(sigma, T)))
        path = save(rec, tmp_path / f"gm{seed0 + i}.npz")
        ex = explain_file(open_record(str(path)), ExplainOptions(heldout=False))
        path.unlink()
        for ch in ex.channels.values():
            gm = {f.cause: f for f in ch.claimed}.get("gauss_markov")
            assert gm is not None, (seed0 + i, ch.name, [f.evidence for f in ch.findings])
            axes += 1
            for k, v in truth.items():
                lo, hi = gm.intervals[k]
                hits[k] += lo <= v <= hi
    band = 2.0 * math.sqrt(LEVEL * (1 - LEVEL) / axes)
    share = {k: v / axes for k, v in hits.items()}
    print(f"T {T:g} s, σ {sigma:.3g} m/s², {axes} axes: 68 % intervals holding the truth "
          f"σ {share['sigma']:.1%}, T {share['time_constant_s']:.1%} (binomial σ "
          f"{band / 2:.1%})")
    for k, v in share.items():
        assert abs(v - LEVEL) <= band, (k, share)
