"""avard's NNLS (Lawson–Hanson in numpy) against scipy.optimize.nnls, the reference it replaces
in the noise fit: the same solution on random, rank-deficient and badly scaled problems, and
the Kuhn–Tucker conditions that define the solution."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.errors import FitError
from avard.core.model.nnls import nnls
from scipy.optimize import nnls as scipy_nnls


def _kkt(a: np.ndarray, b: np.ndarray, x: np.ndarray) -> None:
    """x ≥ 0, the gradient Aᵀ(b − Ax) ≤ 0 where x = 0 and = 0 where x > 0 (to rounding)."""
    g = a.T @ (b - a @ x)
    scale = np.abs(a).sum() * np.abs(b).sum() + 1e-300
    assert np.all(x >= 0)
    assert np.all(g[x == 0] <= 1e-10 * scale)
    np.testing.assert_allclose(g[x > 0], 0.0, atol=1e-10 * scale)


@pytest.mark.parametrize("seed", range(40))
def test_equals_scipy_on_random_problems(seed: int) -> None:
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(3, 30)), int(rng.integers(1, 12))
    a = rng.standard_normal((m, n)) * 10.0 ** rng.uniform(-3, 3, n)  # columns over decades
    b = rng.standard_normal(m)
    x, r = nnls(a, b)
    ref, rref = scipy_nnls(a, b)
    assert r == pytest.approx(rref, rel=1e-9, abs=1e-12)
    if m >= n:  # unique solution: the same x
        np.testing.assert_allclose(x, ref, rtol=1e-7, atol=1e-10 * np.abs(ref).max(initial=1))
    _kkt(a, b, x)


def test_noise_fit_like_problem() -> None:
    """Five AVAR terms over 20 octaves, the kind of basis the fit scales to unit columns."""
    tau = 2.0 ** np.arange(20) / 100.0
    basis = np.stack([3 / tau**2, 1 / tau, np.full_like(tau, 2 * np.log(2) / np.pi),
                      tau / 3, tau**2 / 2], axis=1)
    truth = np.array([0.0, 2.5e-8, 4e-10, 4e-12, 0.0])
    rng = np.random.default_rng(3)
    y = basis @ truth * (1 + 0.05 * rng.standard_normal(tau.size))
    a = basis / y[:, None]
    b = np.ones_like(y)
    scale = np.linalg.norm(a, axis=0)
    x, r = nnls(a / scale, b)
    ref, rref = scipy_nnls(a / scale, b)
    np.testing.assert_allclose(x, ref, rtol=1e-8, atol=1e-12)
    assert r == pytest.approx(rref, rel=1e-9)


def test_all_negative_and_degenerate() -> None:
    a = np.eye(3)
    x, r = nnls(a, np.array([-1.0, -2.0, -3.0]))
    assert np.all(x == 0) and r == pytest.approx(np.sqrt(14))
    a = np.array([[1.0, 1.0], [1.0, 1.0]])  # identical columns: any split is a solution
    x, r = nnls(a, np.array([2.0, 2.0]))
    assert r == pytest.approx(0.0, abs=1e-12) and x.sum() == pytest.approx(2.0)
    with pytest.raises(FitError, match="matrix"):
        nnls(np.ones(3), np.ones(3))
    x, r = nnls(np.zeros((3, 0)), np.array([3.0, 4.0, 0.0]))  # no unknowns: b is the residual
    assert x.shape == (0,) and r == pytest.approx(5.0)


def _array_nnls(a: np.ndarray, b: np.ndarray, maxiter: int | None = None
                ) -> tuple[np.ndarray, float]:
    """Lawson–Hanson written on numpy arrays (the form ``nnls`` had before its bookkeeping
    moved to Python floats): the reference it must equal to the bit."""
    m, n = a.shape
    limit = 3 * n if maxiter is None else int(maxiter)
    x = np.zeros(n)
    passive = np.zeros(n, dtype=bool)
    tol = 10.0 * np.finfo(float).eps * max(m, n) * max(1.0, float(np.abs(a).sum(axis=0).max()))
    w = a.T @ b
    stuck = np.zeros(n, dtype=bool)
    steps = 0
    while not (passive | stuck).all():
        free = np.where(~(passive | stuck), w, -np.inf)
        j = int(np.argmax(free))
        if free[j] <= tol:
            break
        passive[j] = True
        first = True
        while True:
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(a[:, passive], b, rcond=None)[0]
            if np.all(z[passive] > 0):
                break
            if first and z[j] <= 0:
                passive[j] = False
                stuck[j] = True
                z = x
                break
            first = False
            steps += 1
            if steps > limit:
                raise FitError("no convergence")
            neg = passive & (z <= 0)
            step = np.min(x[neg] / (x[neg] - z[neg]))
            x = x + step * (z - x)
            passive &= x > tol
            x[~passive] = 0.0
        x = z
        w = a.T @ (b - a @ x)
    return x, float(np.linalg.norm(a @ x - b))


@pytest.mark.parametrize("seed", range(0, 600, 3))
def test_equals_the_array_form_to_the_bit(seed: int) -> None:
    """The same x and residual, bit for bit, as the array form, on random problems over
    decades, with a repeated column (a tie) and with the noise fit's shapes (unit columns)."""
    rng = np.random.default_rng(seed)
    for _ in range(3):
        m, n = int(rng.integers(3, 30)), int(rng.integers(1, 12))
        a = rng.standard_normal((m, n)) * 10.0 ** rng.uniform(-3, 3, n)
        if n > 1 and rng.uniform() < 0.3:
            a[:, 0] = a[:, -1]
        b = rng.standard_normal(m)
        for aa in (a, a / np.linalg.norm(a, axis=0)):
            x, r = nnls(aa, b)
            ref, rref = _array_nnls(aa, b)
            assert np.array_equal(x, ref) and r == rref


def test_the_subproblems_solve_is_numpys_lstsq_to_the_bit() -> None:
    """The subproblems call numpy's own least-squares gufunc without ``lstsq``'s wrapper: the
    same solution bit for bit on tall, square, wide, rank-deficient and badly scaled
    problems, with its own rcond or a given one, and a non-finite problem still raises
    numpy's LinAlgError."""
    from avard.core.model.nnls import _lstsq

    rng = np.random.default_rng(12)
    for _ in range(400):
        m, n = int(rng.integers(1, 30)), int(rng.integers(1, 12))
        a = rng.standard_normal((m, n)) * 10.0 ** rng.uniform(-6, 6, n)
        if n > 1 and rng.random() < 0.2:
            a[:, -1] = a[:, 0]  # rank-deficient
        b = rng.standard_normal(m)
        want = np.linalg.lstsq(a, b, rcond=None)[0]
        assert np.array(_lstsq(a, b)).tobytes() == want.tobytes()
        # and with a given rcond (thermal_paths' pooled fit: 1e-10)
        for rc in (1e-10, 1e-3):
            want = np.linalg.lstsq(a, b, rcond=rc)[0]
            assert np.array(_lstsq(a, b, rcond=rc)).tobytes() == want.tobytes()
    bad = np.array([[1.0, np.nan], [0.0, 1.0], [2.0, 1.0]])
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.lstsq(bad, np.ones(3), rcond=None)
    with pytest.raises(np.linalg.LinAlgError):
        _lstsq(bad, np.ones(3))
