"""The coverage of ``avard separate``'s intervals and the bias of its fit, on ≥ 100 records
from a generator written apart from core/sim (tests/support/colocated.py): 2 and 3 sensors,
common input 0.1–10× the sensors' white level, different N/B/K per sensor (slow: minutes)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_separate import MIN_AVERAGES, coverage_run


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
