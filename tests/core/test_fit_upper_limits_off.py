"""fit_noise(upper_limits=False, long_tau_notes=False): the absent terms' upper limits and the
long-τ notes are not computed, and every other number of the fit is the same bit for bit
(the Gauss–Markov scan's profile fits read −2 ln L and the component alone)."""

from __future__ import annotations

import numpy as np
from avard.core.allan.deviations import allan_variance
from avard.core.model.fit import fit_noise
from avard.core.model.fit.results import NOT_RESOLVED


def test_only_the_upper_limits_go() -> None:
    rng = np.random.default_rng(4)
    rate = 10.0
    y = 1e-4 * np.sqrt(rate) * rng.standard_normal(1 << 16)  # white: B, K, Q, ramp absent
    res = allan_variance(y, rate)
    for z in (2.33, 0.0):
        full = fit_noise(res, z_present=z)
        lean = fit_noise(res, z_present=z, upper_limits=False)
        absent = [n for n, t in full.terms.items() if not t.present]
        assert absent and any(full.terms[n].upper is not None for n in absent)
        for name, t in full.terms.items():
            u = lean.terms[name]
            assert u.upper is None or t.present
            assert (u.value, u.lo, u.hi, u.present, u.z) == (t.value, t.lo, t.hi, t.present,
                                                             t.z)
        assert lean.chi2_dof == full.chi2_dof and lean.log_det_cov == full.log_det_cov
        assert np.array_equal(lean.theta, full.theta)
        assert np.array_equal(lean.theta_cov, full.theta_cov)


def test_without_long_tau_notes_only_the_notes_go() -> None:
    """fit_noise(long_tau_notes=False): a rate ramp that only the long end of the fit shows
    keeps its value and interval, without its "not yet resolved" note (the Gauss–Markov
    scan's profile fits read the numbers alone)."""
    rate = 10.0
    rng = np.random.default_rng(2)  # white + random walk read as a ramp at the long end
    y = (1e-4 * np.sqrt(rate) * rng.standard_normal(1 << 15)
         + np.cumsum(rng.standard_normal(1 << 15)) * 1e-6 / np.sqrt(rate))
    res = allan_variance(y, rate)
    full = fit_noise(res)
    assert full.terms["rate_ramp"].note == NOT_RESOLVED
    lean = fit_noise(res, long_tau_notes=False)
    for name, t in full.terms.items():
        u = lean.terms[name]
        assert (u.value, u.lo, u.hi, u.present, u.z, u.upper) == (t.value, t.lo, t.hi,
                                                                   t.present, t.z, t.upper)
        assert u.note == (None if t.note == NOT_RESOLVED else t.note)
    assert lean.chi2_dof == full.chi2_dof and lean.log_det_cov == full.log_det_cov
    assert np.array_equal(lean.theta, full.theta)
    assert np.array_equal(lean.theta_cov, full.theta_cov)
