"""``fit.model_chi2``: the χ² of a fixed, already fitted model on other Allan variance data,
with ``fit_noise``'s modelled covariance (the held-out gain of ``avard explain`` rests on it).
Data from the generator written apart from the simulator (tests/core/independent_noise.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from avard.core.allan.streaming import StreamingAllan
from avard.core.model.fit import fit_noise, model_chi2

from tests.core.independent_noise import rate_random_walk, white

RATE = 10.0
N, K = 1.6e-4, 2e-6


def _avar(y):
    sa = StreamingAllan(1, RATE)
    sa.update(np.asarray(y, dtype=float)[:, None])
    return sa.result()


def _record(seed, hours=2.0):
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * RATE)
    return white(n, RATE, N, rng) + rate_random_walk(n, RATE, K, rng)


def test_on_its_own_data_it_is_the_fits_own_chi2():
    """Same data, same τ range, no prediction term: exactly the fit's generalised χ²
    (chi2_dof·dof), also with a fixed component (the LSB rounding) in the model."""
    res = _avar(_record(1))
    for fit in (fit_noise(res), fit_noise(res, rounding_lsb=1e-4)):
        got = model_chi2(fit, res, (fit.tau_min_s, fit.tau_max_s))
        assert got.n_points == fit.n_points
        assert got.tau_s[0] == pytest.approx(fit.tau_min_s)
        assert got.chi2 == pytest.approx(fit.chi2_dof * fit.dof, rel=1e-9)
        # the prediction's own uncertainty only ever adds to the covariance
        pred = model_chi2(fit, res, (fit.tau_min_s, fit.tau_max_s), predictive=True)
        assert pred.chi2 <= got.chi2 * (1 + 1e-9)


def test_a_model_of_the_sensor_predicts_another_record_and_a_wrong_one_does_not():
    """Fitted on one record, the model predicts independent records of the same noise with
    χ² near their n; the same model with every θ ×4 (ADEV ×2) misses them by far."""
    fit = fit_noise(_avar(_record(2)))
    ratios, wrong = [], []
    bad = replace(fit, theta=4.0 * fit.theta, theta_cov=16.0 * fit.theta_cov)
    for seed in range(3, 9):
        res = _avar(_record(seed))
        got = model_chi2(fit, res, predictive=True)
        assert got.n_points >= 10
        ratios.append(got.chi2 / got.n_points)
        wrong.append(model_chi2(bad, res, predictive=True).chi2 / got.n_points)
    assert 0.3 < float(np.mean(ratios)) < 2.0
    assert min(wrong) > 5 * max(ratios)


def test_no_usable_tau_gives_nan_and_zero():
    res = _avar(_record(10, hours=0.5))
    fit = fit_noise(res)
    got = model_chi2(fit, res, (1e6, 2e6))
    assert got.n_points == 0 and math.isnan(got.chi2)
