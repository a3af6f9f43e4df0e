"""The bounds beside a drift the time domain found short of its level (issue 24;
``signal_edf.floor_bounds``, ``NoiseFit.drift_slope``): the ramp's uncertainty from the
slope's 68 % interval and the noise part's from its χ², in quadrature about the estimate,
instead of a χ² about the estimate, which over-covered those records at the longest τ
(the verdict is made of the slope whose error dominates the estimate there)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from avard.core.allan.deviations import allan_variance
from avard.core.allan.edf import chi2_interval
from avard.core.analysis.signal_edf import noise_part_edf, unresolved_noise_edf

from benchmarks.bench_coverage import mix_for
from tests.core.test_drift import N_12H, _analyze
from tests.core.test_noise_id_rate import support
from tests.support.coverage_gen import record


@pytest.mark.parametrize("seed", [2453, 2407])
def test_a_floor_records_bounds_take_the_ramps_uncertainty_from_the_slope(seed: int) -> None:
    """12 h of the coverage generator's drift mix, the drift test short of its level but the
    slope's 68 % interval clear of zero (seeds 2453 and 2407: z 2.1 and below): the fit
    carries the slope and its interval; where the ramp at the interval's top holds under
    0.1 % of the estimate the bounds are the printed EDF's χ² ones, exactly; at the longest
    τ, where the ramp holds most of the AVAR, they are the quadrature of the slope's and the
    noise part's uncertainty, and the top lies below the χ²'s, which reached far above the
    low estimate these records have there (the over-coverage); never narrower than the
    record's support, and wider at a wider level."""
    y, _clean = record(mix_for("drift", N_12H, 1.0), N_12H, np.random.default_rng(seed))
    ch = _analyze(y, 1.0)
    a, fit = ch.allan, ch.fit
    assert fit.drift_floor > 0 and not fit.resolved_apart
    slope, s_lo, s_hi = fit.drift_slope
    assert s_lo * s_hi > 0 and min(abs(s_lo), abs(s_hi)) == pytest.approx(fit.drift_floor)
    assert min(abs(s_lo), abs(s_hi)) < abs(slope) < max(abs(s_lo), abs(s_hi))
    lo_c, hi_c = chi2_interval(a.var, a.edf, a.ci)
    ramp_top = max(abs(s_lo), abs(s_hi)) ** 2 * a.tau**2 / 2
    small = ramp_top < 1e-3 * a.var
    assert small[0] and not small[-1]
    np.testing.assert_array_equal(a.lo[small], lo_c[small])
    np.testing.assert_array_equal(a.hi[small], hi_c[small])
    # the longest τ: the quadrature about the estimate
    k = len(a.tau) - 1
    g = a.tau[k] ** 2 / 2
    ramp = slope**2 * g
    noise = max(a.var[k] - ramp, 0.01 * a.var[k])  # (the ramp at R̂ may pass the estimate)
    est = replace(a, edf=allan_variance(y, 1.0).edf[:len(a.tau)])  # (the estimator's EDF)
    nu = noise_part_edf(est, unresolved_noise_edf(fit, est))[k]
    n_lo, n_hi = chi2_interval(np.array([noise]), np.array([nu]), a.ci)
    r_lo, r_hi = sorted((abs(s_lo), abs(s_hi)))
    want_lo = a.var[k] - np.hypot(ramp - r_lo**2 * g, noise - n_lo[0])
    want_hi = a.var[k] + np.hypot(r_hi**2 * g - ramp, n_hi[0] - noise)
    s_lo_r, s_hi_r = chi2_interval(np.ones(len(a.tau)), support(a), a.ci)
    widen = np.sqrt(s_hi_r[k] / s_lo_r[k] / (want_hi / want_lo))
    if widen > 1:  # (narrower than the support: widened about the geometric mean)
        want_lo, want_hi = want_lo / widen, want_hi * widen
    assert a.lo[k] == pytest.approx(want_lo, rel=1e-3)
    assert a.hi[k] == pytest.approx(want_hi, rel=1e-3)
    assert a.hi[k] < 0.95 * hi_c[k]
    # never narrower than the record's support
    assert np.all(a.hi / a.lo >= s_hi_r / s_lo_r * (1 - 1e-9))
    # a wider level, a wider interval
    from avard.core.analysis.signal_edf import floor_bounds

    lo95, hi95 = floor_bounds(replace(a, ci=0.95), fit.drift_slope, nu * np.ones(len(a.tau)))
    assert lo95[k] < a.lo[k] and hi95[k] > a.hi[k]


def test_no_floor_no_change() -> None:
    """Where the slope's interval holds zero (seed 2473, z 0.75) the fit carries no slope
    and the bounds are the printed EDF's χ² ones at every τ."""
    y, _clean = record(mix_for("drift", N_12H, 1.0), N_12H, np.random.default_rng(2473))
    ch = _analyze(y, 1.0)
    assert ch.fit.drift_floor == 0 and ch.fit.drift_slope == ()
    lo_c, hi_c = chi2_interval(ch.allan.var, ch.allan.edf, ch.allan.ci)
    np.testing.assert_array_equal(ch.allan.lo, lo_c)
    np.testing.assert_array_equal(ch.allan.hi, hi_c)
