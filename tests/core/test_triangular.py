"""core/model/triangular.py: the blocked forward substitution equals scipy's triangular solve
(LAPACK) to rounding, on the factors explain whitens with (the noise covariance of block
means with white, flicker and random-walk noise) and on sizes around the block size."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.explain.causes import _noise_cov
from avard.core.model.triangular import BLOCK, LowerSolver, solve_lower
from scipy.linalg import solve_triangular


def _reference(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Forward substitution in extended precision: the answer both are compared with."""
    Ll = L.astype(np.longdouble)
    X = np.zeros(B.shape, dtype=np.longdouble)
    for i in range(len(L)):
        X[i] = (B[i] - Ll[i, :i] @ X[:i]) / Ll[i, i]
    return X.astype(float)


@pytest.mark.parametrize("n", [1, 7, BLOCK - 1, BLOCK, BLOCK + 1, 3 * BLOCK + 5, 514])
@pytest.mark.parametrize("noise", [(1.6e-4, 2e-5, 2e-6), (1.6e-4, 0.0, 2e-5),
                                   (1e-4, 1e-5, 0.0)])
def test_equals_scipy_on_noise_factors(n: int, noise: tuple[float, float, float]) -> None:
    dt = 43200.0 / n
    t = (np.arange(n) + 0.5) * dt
    L = np.linalg.cholesky(_noise_cov(t, dt, *noise))
    rng = np.random.default_rng(n)
    solver = LowerSolver(L)
    for B in (L @ rng.standard_normal(n), rng.standard_normal((n, 3)),
              np.column_stack([np.ones(n), t])):
        got = solver.solve(B)
        assert got.shape == B.shape
        ref = solve_triangular(L, B, lower=True)
        exact = _reference(L, B)
        scale = np.max(np.abs(exact), axis=0)
        # as close to the exact answer as LAPACK's, within a few units of rounding
        err = np.max(np.abs(got - exact) / scale)
        err_lapack = np.max(np.abs(ref - exact) / scale)
        assert err <= max(4 * err_lapack, 1e-13), (err, err_lapack)
        assert np.allclose(got, ref, rtol=1e-11, atol=1e-12 * np.max(scale))


def test_one_solve_and_bad_shapes() -> None:
    rng = np.random.default_rng(1)
    L = np.tril(rng.standard_normal((70, 70))) + 10 * np.eye(70)
    b = rng.standard_normal(70)
    assert np.allclose(L @ solve_lower(L, b), b, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="square"):
        LowerSolver(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="70 rows"):
        LowerSolver(L).solve(np.zeros(69))
