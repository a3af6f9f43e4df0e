"""The coverage of ``avard separate``'s intervals and the bias of its fit, on ≥ 100 records
from a generator written apart from core/sim (tests/support/colocated.py): 2 and 3 sensors,
common input 0.1–10× the sensors' white level, different N/B/K per sensor (slow: minutes)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_separate import FAR_RATIOS, MIN_AVERAGES, coverage_run


@pytest.mark.slow
def test_self_noise_intervals_hold_the_truth_at_their_level_and_n_is_unbiased() -> None:
    cov = coverage_run(records=120, seed=2026)
    rate = cov.rate()
    counted = cov.averages >= MIN_AVERAGES
    assert counted.sum() >= 10
    for k in np.flatnonzero(counted):
        assert 0.60 <= rate[k] <= 0.76, (cov.tau[k], rate[k])
    assert cov.n_fitted >= 100
    assert cov.n_within >= 0.90 * cov.n_fitted


@pytest.mark.slow
def test_far_below_the_bed_the_limits_hold_the_truth_and_are_not_trivially_wide() -> None:
    """The sensors' own noise 0.1× down to 0.01× the common input: with two sensors many
    self-noise results are upper limits at the sensitivity floor. Every τ with ≥ 5 averages
    (m ≥ 2, below)
    holds the truth at least at the nominal 68 %, within two binomial standard errors of the
    intervals counted there, and at ≥ 68 % pooled over those τ; and at ≤ 90 % (an upper
    limit far above the truth everywhere would hold it always, and say nothing). At m = 1
    the project's Greenhall EDF for white FM is 0.78 N where the exact one is 2N/3, which
    narrows every interval there (docs/separate.md); that τ is reported, not held."""
    cov = coverage_run(records=120, seed=2026, ratios=FAR_RATIOS, fit=False)
    counted = (cov.averages >= MIN_AVERAGES) & (cov.tau > cov.tau[0])
    assert counted.sum() >= 10
    for s in (2, 3):
        rate, n = cov.rate(s), cov.total[s]
        floor = 0.68 - 2 * np.sqrt(0.68 * 0.32 / n)
        for k in np.flatnonzero(counted):
            assert floor[k] <= rate[k] <= 0.90, (s, cov.tau[k], rate[k], floor[k])
        pooled = cov.held[s][counted].sum() / n[counted].sum()
        assert pooled >= 0.68, (s, pooled)
        assert cov.was_limit[s][:, counted].mean() > (0.2 if s == 2 else 0.0)
