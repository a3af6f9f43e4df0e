"""The uncertainty of what `avard explain` removes, as the covariance ``engine.
removal_covariance`` gives ``fit_noise(added_cov=…)``: its delta-method Jacobian equals the
analytic derivative of the compensated AVAR (that ``fit_noise`` widens intervals by such a
covariance is tests/core/test_fit.py::test_added_covariance_enters_the_fit)."""

from __future__ import annotations

import numpy as np
from avard.core.explain.engine.removal import removal_covariance, removed_avar
from avard.core.explain.thermal_fit import allan2, compensated_avar, lag_filter


def test_removal_covariance_is_the_delta_method_of_the_compensated_avar() -> None:
    """For the thermal coefficient the compensated AVAR is quadratic,
    AVAR_y − 2c·Cov_A(y, u) + c²·AVAR_u, so moving c by ± s gives J = 2s(c·AVAR_u − Cov_A):
    the covariance is J Jᵀ at the estimator's own τ (where no interpolation enters)."""
    rng = np.random.default_rng(4)
    rate, n = 1.0, 1 << 14
    t = np.arange(n) / rate
    temp = 0.5 * np.sin(2 * np.pi * t / 1800.0) + 0.01 * rng.standard_normal(n)
    u = lag_filter(temp, 300.0, rate)
    u -= u.mean()
    c, s = 2e-3, 3e-4
    y = c * u + 1e-4 * rng.standard_normal(n) + np.cumsum(1e-6 * rng.standard_normal(n))
    res = allan2(y, c * u, rate)
    tau = np.asarray(res.tau, dtype=float)
    var = np.asarray(res.cov[:, 0, 0], dtype=float)
    ok = np.isfinite(var) & (var > 0)
    tau, var = tau[ok], var[ok]
    cov = removal_covariance(var, tau, y, c * u, rate, [(s * u, -s * u)])
    both = allan2(y, u, rate)
    vu = np.asarray(both.cov[:, 1, 1], float)[ok]
    cyu = np.asarray(both.cov[:, 0, 1], float)[ok]
    j = 2 * s * (c * vu - cyu)
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), np.abs(j), rtol=1e-6)
    np.testing.assert_allclose(cov, np.outer(j, j), rtol=1e-6, atol=1e-12 * np.abs(j).max()**2)
    # nothing removed with an uncertainty: nothing added
    assert not removal_covariance(var, tau, y, c * u, rate, []).any()


def test_removed_avar_is_the_compensated_avar_of_the_full_allan_result_to_the_bit() -> None:
    """Explain removes each signal through the Allan covariance alone
    (``StreamingAllan.covariance``); it gives ``compensated_avar`` of ``allan2``'s full result
    to the bit: at the estimator's τ, between them (interpolated) and below them, for a
    coupling, a step and nothing removed."""
    rng = np.random.default_rng(9)
    rate, n = 2.0, 20_000
    t = np.arange(n) / rate
    u = lag_filter(0.5 * np.sin(2 * np.pi * t / 1800.0), 300.0, rate)
    y = 2e-3 * u + 1e-4 * rng.standard_normal(n) + np.cumsum(1e-6 * rng.standard_normal(n))
    ref = allan2(y, u, rate)
    tau = np.concatenate([[0.1], np.asarray(ref.tau, float)[:-1] * 1.3])
    var = 1e-8 / tau + 1e-10
    for d in (2e-3 * u, np.where(t > 3000.0, 5e-4, 0.0), np.zeros(n)):
        want = compensated_avar(var, tau, allan2(y, d, rate), 1.0)
        assert removed_avar(var, tau, y, d, rate).tobytes() == want.tobytes()
