"""core/allan/chi2.py (numpy-only χ² quantiles for the service) against scipy.special."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.chi2 import chi2_ppf, chi2_ppf_grid, chi2_ppf_stable32, gammainc_pq
from scipy.special import gammainc, gammaincc, gammaincinv

K = np.concatenate([np.geomspace(0.2, 1e9, 300), [1.0, 2.0, 3.0, 99.9, 100.0, 100.1]])


@pytest.mark.parametrize("p", [0.001, 0.025, 0.158655, 0.5, 0.841345, 0.975, 0.999])
def test_quantile_equals_scipy(p: float) -> None:
    ref = 2.0 * gammaincinv(K / 2.0, p)
    np.testing.assert_allclose(chi2_ppf(p, K), ref, rtol=1e-10)


def test_incomplete_gamma_equals_scipy_across_the_three_methods() -> None:
    """Series, continued fraction and quadrature: P and Q to 1e-13 absolute, and to 1e-10
    relative where they are ≥ 1e-3 (the quantiles asked for lie there)."""
    a = np.array([0.3, 2.0, 10.0, 49.0, 51.0, 1e3, 1e6])
    for f in (0.2, 0.9, 0.999, 1.0, 1.001, 1.1, 2.0):
        x = a * f
        p, q = gammainc_pq(a, x)
        ref_p, ref_q = gammainc(a, x), gammaincc(a, x)
        np.testing.assert_allclose(p, ref_p, rtol=0, atol=1e-13)
        np.testing.assert_allclose(q, ref_q, rtol=0, atol=1e-13)
        big = ref_p >= 1e-3
        np.testing.assert_allclose(p[big], ref_p[big], rtol=1e-10)
        big = ref_q >= 1e-3
        np.testing.assert_allclose(q[big], ref_q[big], rtol=1e-10)


def test_shape_and_bad_p() -> None:
    k = np.full((4, 3), 7.0)
    assert chi2_ppf(0.5, k).shape == (4, 3)
    assert chi2_ppf(0.5, np.zeros((0, 3))).shape == (0, 3)
    with pytest.raises(ValueError, match="strictly between"):
        chi2_ppf(1.0, k)


def test_the_service_path_imports_no_scipy() -> None:
    import subprocess
    import sys

    code = ("import sys; from avard.core.allan.streaming import StreamingAllan; import numpy as np;"
            "s = StreamingAllan(3, 125.0);"
            "s.update(np.random.default_rng(1).normal(size=(5000, 3)));"
            "s.snapshot(); print(sorted(m for m in sys.modules if m.startswith('scipy')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_stable32_quantiles_exact_to_100_dof_approximate_above() -> None:
    """Stable32's χ² quantiles: the exact ones up to 100 degrees of freedom, Wilson–Hilferty
    with A&S 26.2.22 (Stable32's coefficients) above: within 1e-3 relative there, closer
    as k grows, and never the exact value (the NBS14 bounds in test_allan hold it to
    Stable32's printed digits)."""
    for p in (0.1585, 0.8415, 0.025, 0.975):
        k = np.array([1.0, 10.0, 100.0])
        np.testing.assert_array_equal(chi2_ppf_stable32(p, k), chi2_ppf(p, k))
        big = np.array([101.0, 1e3, 1e5])
        rel = np.abs(chi2_ppf_stable32(p, big) / chi2_ppf(p, big) - 1.0)
        assert np.all(rel < 1e-3) and np.all(rel > 0) and rel[2] < rel[0], rel
    with pytest.raises(ValueError):
        chi2_ppf_stable32(1.0, 10.0)


def test_each_quantile_is_the_same_whatever_else_is_in_the_vector() -> None:
    """A converged entry stops changing, so χ²_k(p) does not depend on the other entries
    computed with it (the intervals remember quantiles by EDF: a snapshot must give the same
    bounds whichever EDF were computed together)."""
    k = np.concatenate([np.geomspace(0.3, 1e6, 120), [1.0, 99.9, 782.03]])
    for p in (0.025, 0.1585, 0.8415):
        vec = chi2_ppf(p, k)
        one = np.array([chi2_ppf(p, np.array([v]))[0] for v in k])
        np.testing.assert_array_equal(vec, one)


def test_the_grid_of_quantiles_equals_one_probability_at_a_time() -> None:
    """chi2_ppf_grid (the separation's intervals ask for 64 probabilities at once) is the
    fast path beside chi2_ppf: every row equal to chi2_ppf of its p over the same k, and
    every entry to chi2_ppf of one p and one k, across the start for a < 1, the series, the
    continued fraction and the quadrature (a ≥ 50), with k repeated and in any order."""
    k = np.concatenate([np.geomspace(0.3, 1e7, 40), [1.0, 2.0, 99.9, 100.0, 100.1, 782.03]])
    k = np.concatenate([k, k[::3]])           # repeated EDF (computed once) come back each
    ps = (np.arange(64) + 0.5) / 64
    grid = chi2_ppf_grid(ps, k)
    assert grid.shape == (64, k.size)
    for j, p in enumerate(ps):
        np.testing.assert_array_equal(grid[j], chi2_ppf(float(p), k))
    for j in (0, 5, 31, 63):
        one = np.array([chi2_ppf(float(ps[j]), np.array([v]))[0] for v in k])
        np.testing.assert_array_equal(grid[j], one)
    np.testing.assert_allclose(grid[[0, 63]], 2.0 * gammaincinv(k / 2.0, ps[[0, 63], None]),
                               rtol=1e-10)


def test_the_grid_shapes_and_bad_p() -> None:
    assert chi2_ppf_grid([0.1, 0.9], np.full((4, 3), 7.0)).shape == (2, 4, 3)
    assert chi2_ppf_grid([], np.ones(5)).shape == (0, 5)
    assert chi2_ppf_grid([0.5], np.zeros((0, 3))).shape == (1, 0, 3)
    with pytest.raises(ValueError, match="strictly between"):
        chi2_ppf_grid([0.5, 0.0], np.ones(3))


def test_a_stored_quantile_column_is_the_one_a_fresh_call_gives() -> None:
    """chi2_ppf_grid keeps the columns it computed (the live separation asks for the same
    probabilities on each axis, with mostly the same EDFs): a call served partly from them
    equals, bit for bit, the same call computed afresh, and the store stays bounded."""
    from avard.core.allan import chi2

    ps = [(j + 0.5) / 64 for j in range(64)]
    first = np.array([2.3e4, 1.1e4, 850.5, 41.1, 9.05, 2.79, 1.06])
    second = np.array([2.3e4, 1.1e4, 850.5, 19.7, 7.05, 2.79, 1.06, 0.4])   # mostly repeats
    chi2._COLUMNS.clear()
    chi2_ppf_grid(ps, first)
    assert len(chi2._COLUMNS) == first.size
    served = chi2_ppf_grid(ps, second)
    assert len(chi2._COLUMNS) == first.size + 3          # only the new EDFs were computed
    chi2._COLUMNS.clear()
    fresh = chi2_ppf_grid(ps, second)
    assert np.array_equal(served, fresh)
    served[0, 0] = -1.0                                   # a caller's array is its own
    assert chi2_ppf_grid(ps, second)[0, 0] == fresh[0, 0]
    for i in range(chi2._COLUMNS_MAX // 100 + 2):         # never more than the bound
        chi2_ppf_grid(ps, np.arange(100) + 1000.0 * (i + 1))
        assert len(chi2._COLUMNS) <= chi2._COLUMNS_MAX
