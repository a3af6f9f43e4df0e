"""The thermal coefficient's 68 % interval from its two standard errors
(``thermal_fit.coefficient_se``): the delete-a-group jackknife's and the regressor's analytic
one. Both estimate one deviation, each with its own scatter; the interval is their average,
not their larger (which is above the deviation by construction, and over-covered on the
adversary's generator: docs/log/2026-11-28-coef26.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.explain.thermal_fit import JACKKNIFE_GROUPS, coefficient_se


def test_the_coefficient_se_lies_between_its_two_estimates_and_is_theirs_where_they_agree():
    for a, b in [(1.0, 1.0), (2e-5, 3e-5), (3e-5, 2e-5), (1e-6, 4e-6), (5.0, 0.5)]:
        s = coefficient_se(a, b)
        assert s == pytest.approx(coefficient_se(b, a))
        if a == b:
            assert s == pytest.approx(a)
        else:
            # strictly inside: the larger of two estimates is an upper bound of the two, not
            # an estimate of the deviation
            assert min(a, b) < s < max(a, b)
    # an estimate that could not be made leaves no interval
    assert math.isinf(coefficient_se(math.inf, 1.0))
    assert math.isinf(coefficient_se(1.0, math.inf))


def test_from_two_scattered_estimates_of_the_deviation_it_holds_a_normal_error_68_percent():
    """Errors of deviation 1 and, per draw, the two estimates as they scatter: the jackknife's
    variance a χ² of G − 1 degrees of freedom over G − 1, the analytic one's of 20 (a model's
    few slow octaves). ± the rule's se holds the error as a t of their pooled degrees of
    freedom does (about 67 %); ± the larger of the two held it on about 72 %. Seeded: the
    count is one number, its binomial standard error 0.33 points."""
    rng = np.random.default_rng(20261128)
    n = 20000
    e = rng.standard_normal(n)
    g1 = JACKKNIFE_GROUPS - 1
    s_jk = np.sqrt(rng.chisquare(g1, n) / g1)
    s_a = np.sqrt(rng.chisquare(20, n) / 20)
    se = np.array([coefficient_se(a, b) for a, b in zip(s_jk, s_a, strict=True)])
    held = float(np.mean(np.abs(e) <= se))
    assert 0.655 <= held <= 0.695, held
