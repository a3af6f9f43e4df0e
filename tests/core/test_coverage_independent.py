"""Coverage of the printed OADEV intervals on records from a generator written apart from
avard (tests/support/coverage_gen.py; issue 24): the slow set runs the benchmark's own
function (benchmarks/bench_coverage.py, its table in docs/analysis.md)."""

from __future__ import annotations

import pytest

from benchmarks.bench_coverage import BAND, coverage


@pytest.mark.slow
@pytest.mark.parametrize("hours", [1, 12, 60])
def test_intervals_cover_the_truth_on_noise(hours: int) -> None:
    """White + flicker + random walk, 200 records: at every τ with ≥ 5 averages the 68.3 %
    interval holds the closed-form AVAR in at least 60 % of the records, and in 60–76 % at
    all but two τ, none above 80 % (measured: 1 h and 12 h within 60–76 % at every τ; 60 h
    at 77.5 % and 76.5 % at 8 s and 4096 s, 14 of 16 inside; a share of 200 records has a
    standard error of 3.3 points, and neighbouring τ share their records)."""
    c = coverage(hours, "plain", 200, seed=1)
    detail = list(zip(c.tau, c.share, strict=True))
    assert all(c.share >= BAND[0]), detail
    assert len(c.outside()) <= 2 and all(c.share <= 0.80), detail


@pytest.mark.slow
@pytest.mark.parametrize("mix", ["sine", "drift"])
@pytest.mark.parametrize("hours", [1, 12, 60])
def test_intervals_are_never_too_narrow_with_a_signal(hours: int, mix: str) -> None:
    """With a slow sinusoid or a drift added: the interval holds the truth in at least 60 %
    of the records at every τ (measured 62.5–65 % at the lowest). Where the signal makes
    much of the AVAR they over-cover (measured up to 90 %): a deterministic part scatters
    less than the χ² of any noise type says, and the EDF may not exceed what an FM type
    gives (docs/analysis.md, "Coverage of the intervals")."""
    c = coverage(hours, mix, 200, seed=1)
    detail = list(zip(c.tau, c.share, c.signal, strict=True))
    assert all(c.share >= BAND[0]), detail
    assert all(c.share <= 0.92), detail
