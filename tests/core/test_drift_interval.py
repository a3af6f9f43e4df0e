"""The drift test's 68 % slope interval (issue 24, drift25): where the profile likelihood
rises by the Bartlett factor β the test's z is calibrated with (z = ±√(Λ/β)), not by 1.
At Δ ≤ 1 it held the true slope in 53–59 % of the independent generator's driftless 1 h and
12 h records (adv25), and "drift: a ramp of at least …" showed on about 45 % of them."""

from __future__ import annotations

import math

import numpy as np
from avard.core.allan.deviations import allan_variance
from avard.core.analysis import drift as dr
from avard.core.model.fit import fit_noise

from tests.support import coverage_gen2 as gen


def test_the_slope_interval_ends_where_the_profile_has_risen_by_beta() -> None:
    """A driftless 12 h record of the independent generator (white + flicker, corner 300 s,
    + walk, corner 10 000 s) whose walk holds a few of the block means' directions (β about
    1.4): the slope's profile −2 ln L (K profiled, computed here apart from the test) stands
    β above its minimum at both ends of the interval, so the interval is √β times as wide
    as the Δ = 1 one."""
    n, rate = 43_200, 1.0
    lv = gen.levels(n, 300.0, 10_000.0, rate)
    y, _clean = gen.record(lv, n, np.random.default_rng([7, 12]))
    fit = fit_noise(allan_variance(y, rate))
    b = dr.drift_block(n)
    yb = y[: n // b * b].reshape(-1, b).mean(axis=1)
    block_s = b / rate
    lik = dr.channel_drift(fit, yb, block_s)
    assert lik is not None and lik.bartlett > 1.2
    t = (np.arange(len(yb)) + 0.5) * block_s
    n_w = float(fit.terms["velocity_random_walk"].value or 0.0)
    b_i = float(fit.terms["bias_instability"].value or 0.0)
    top = dr.K_SPAN * max(dr._k_upper(fit), n_w / (len(t) * block_s))
    ks = np.concatenate([[0.0], np.geomspace(top * 10.0**-dr.K_DECADES, top, dr.K_POINTS)])
    prof = dr._Profile(yb, t, block_s, n_w, b_i)
    w0 = prof.white(np.ones((len(t), 1)))
    wt = prof.white(t - t.mean())
    grid = lik.slope + (lik.slope_hi - lik.slope_lo) * np.linspace(-0.05, 0.05, 41)
    least = float(np.min(prof.slope_profile(ks, w0, wt, grid)))
    ends = prof.slope_profile(ks, w0, wt, np.array([lik.slope_lo, lik.slope_hi])) - least
    np.testing.assert_allclose(ends, lik.bartlett, rtol=0.03)
    # the Δ = 1 interval lies inside, by about √β
    one = prof.slope_profile(ks, w0, wt, lik.slope + (lik.slope_hi - lik.slope) /
                             math.sqrt(lik.bartlett) * np.array([1.0])) - least
    assert 0.9 < float(one[0]) < 1.1
