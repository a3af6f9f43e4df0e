"""fit._settled, the noise fit's iteration stop: the same answer as
np.allclose(new, old, rtol=1e-5, atol=0) (its fast comparison for finite values, allclose
itself otherwise), at the boundary, at zero and with infinities and NaN."""

from __future__ import annotations

import numpy as np
from avard.core.model.fit.problem import _settled


def test_equals_allclose() -> None:
    rng = np.random.default_rng(0)
    cases = []
    for _ in range(2000):
        old = rng.standard_normal(6) * 10.0 ** rng.uniform(-30, 5, 6)
        old[rng.uniform(size=6) < 0.2] = 0.0
        new = old * (1 + rng.choice([0.0, 1e-6, 1e-5, -1e-5, 2e-5, 1e-3], size=6))
        cases.append((new, old))
    old = np.array([1.0, 0.0, 3.0])
    cases += [(old + np.array([1e-5, 0.0, 0.0]), old),  # exactly at the boundary
              (np.array([1e-300, 0.0, 3.0]), old),  # a zero that moved
              (np.array([np.inf, 0.0, 3.0]), np.array([np.inf, 0.0, 3.0])),
              (np.array([np.nan, 0.0, 3.0]), old), (old, np.array([np.nan, 0.0, 3.0]))]
    for new, old in cases:
        assert _settled(new, old) == np.allclose(new, old, rtol=1e-5, atol=0)


def test_the_fits_inner_steps_equal_numpys_general_forms_to_the_bit() -> None:
    """The iteration's inner steps skip numpy's wrappers (norm, outer, diag_indices): the
    column norms, the whitener and the floored covariance equal the general forms bit for
    bit on random well- and badly-scaled problems."""
    from avard.core.model.fit import problem as F
    from avard.core.model.nnls import nnls

    rng = np.random.default_rng(21)
    for _ in range(200):
        k, a = int(rng.integers(3, 25)), int(rng.integers(1, 7))
        X = rng.standard_normal((k, a)) * 10.0 ** rng.uniform(-8, 8, a)
        y = rng.standard_normal(k)
        B = rng.standard_normal((k, k))
        C = B @ B.T + np.diag(rng.uniform(0.1, 2.0, k))
        d = np.sqrt(np.diag(C))
        w, V = np.linalg.eigh(C / np.outer(d, d))
        keep = w > 1e-10 * w.max()
        T = (V[:, keep] / np.sqrt(w[keep])).T / d
        assert F._whitener(C).tobytes() == T.tobytes()
        A = T @ X
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        sol, r = nnls(A / scale, T @ y, maxiter=50 * a + 100)
        got = F._gls_nnls(X, y, T)
        assert got[0].tobytes() == (sol / scale).tobytes() and got[1] == float(r**2)
        floor = rng.uniform(0.0, 2.0, k) * np.diag(C)
        want = C.copy()
        dd = np.diag(want).copy()
        want[np.diag_indices_from(want)] = dd + np.maximum(floor - dd, 0.0)
        got_c = C.copy()
        got_c.flat[:: len(got_c) + 1] = dd + np.maximum(floor - dd, 0.0)
        assert got_c.tobytes() == want.tobytes()
