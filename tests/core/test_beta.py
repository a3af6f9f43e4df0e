"""core/allan/beta.py (incomplete beta, its inverse, F quantiles) and chi2.chi2_sf, without
scipy, against scipy.special and against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.allan.beta import (
    betainc,
    betainc_pair,
    betaincinv,
    f_isf,
    f_isf_array,
    f_ppf,
    t_two_sided,
)
from avard.core.allan.chi2 import chi2_sf
from avard.core.analysis.spectrum import line_threshold
from scipy.special import betainc as sc_betainc
from scipy.special import betaincc, betainccinv, chdtrc, fdtri
from scipy.special import betaincinv as sc_betaincinv

DFN = [1.0, 2.0, 7.0, 50.0, 500.0, 5000.0]
DFD = [2.0, 10.0, 1e3, 1e5, 3e5]
P = np.geomspace(1e-9, 0.9, 31)


@pytest.mark.parametrize("dfn", DFN)
@pytest.mark.parametrize("dfd", DFD)
def test_f_lower_quantile_equals_scipy_fdtri(dfn: float, dfd: float) -> None:
    got = np.array([f_ppf(float(p), dfn, dfd) for p in P])
    np.testing.assert_allclose(got, fdtri(dfn, dfd, P), rtol=1e-9)


@pytest.mark.parametrize("dfn", DFN)
@pytest.mark.parametrize("dfd", DFD)
def test_f_upper_quantile_equals_scipy(dfn: float, dfd: float) -> None:
    """f with Pr(F > f) = q. scipy's fdtri(…, 1 − q) rounds 1 − q (a relative 1e-7 of q at
    q = 1e-9), so the reference is built from scipy's inverse incomplete beta on the tail
    itself (A&S 26.6.2): x = ν₁f/(ν₁f + ν₂) with 1 − I_x(ν₁/2, ν₂/2) = q, or y = 1 − x with
    I_y(ν₂/2, ν₁/2) = q, whichever of x and y is the smaller (it carries f's precision)."""
    q = P
    x = betainccinv(dfn / 2, dfd / 2, q)
    y = sc_betaincinv(dfd / 2, dfn / 2, q)
    ref = np.where(x <= 0.5, dfd / dfn * x / (1.0 - x), dfd / dfn * (1.0 - y) / y)
    got = np.array([f_isf(float(v), dfn, dfd) for v in q])
    np.testing.assert_allclose(got, ref, rtol=1e-9)


def test_f_quantiles_in_closed_form() -> None:
    """F(2, 2): Pr(F > f) = 1/(1 + f), so f = 1/q − 1; F(1, 1) is the square of a Cauchy
    variable: Pr(F > f) = 1 − (2/π)·atan(√f). References independent of scipy."""
    for q in (1e-12, 1e-6, 0.01, 0.3, 0.5, 0.7, 0.99):
        assert f_isf(q, 2.0, 2.0) == pytest.approx(1.0 / q - 1.0, rel=1e-12)
        assert f_isf(q, 1.0, 1.0) == pytest.approx(1.0 / math.tan(math.pi * q / 2) ** 2,
                                                   rel=1e-9)
        assert f_ppf(q, 2.0, 2.0) == pytest.approx(q / (1.0 - q), rel=1e-12)


@pytest.mark.parametrize("a", [0.05, 0.5, 1.0, 3.7, 40.0, 2500.0, 1.5e5])
@pytest.mark.parametrize("b", [0.05, 0.5, 1.0, 3.7, 40.0, 2500.0, 1.5e5])
def test_incomplete_beta_equals_scipy(a: float, b: float) -> None:
    """Both tails to relative 1e-10 (each where it is ≥ 1e-300), either side of the
    fraction's switch at x = (a + 1)/(a + b + 2), and x spread around the mean a/(a + b)."""
    mean = a / (a + b)
    xs = np.unique(np.clip(np.concatenate([
        np.geomspace(1e-12, 1 - 1e-12, 25),
        mean * np.array([0.5, 0.9, 0.99, 1.0, 1.01, 1.1, 1.5]),
        [(a + 1) / (a + b + 2)]]), 1e-12, 1 - 1e-12))
    for x in xs:
        p, q = betainc_pair(a, b, float(x))
        ref_p, ref_q = sc_betainc(a, b, x), betaincc(a, b, x)
        if ref_p >= 1e-300:
            assert p == pytest.approx(ref_p, rel=1e-10), (a, b, x)
        if ref_q >= 1e-300:
            assert q == pytest.approx(ref_q, rel=1e-10), (a, b, x)
        assert betainc(a, b, float(x)) == p


def test_incomplete_beta_in_closed_form() -> None:
    """I_x(a, 1) = xᵃ and I_x(1, b) = 1 − (1 − x)ᵇ (DLMF 8.17.1 integrated), I_x(a, b) =
    1 − I_{1−x}(b, a) (8.17.4)."""
    for x in (2.0**-30, 1 / 64, 0.25, 0.5, 0.75, 1 - 2.0**-20):   # 1 − x exact
        for s in (0.2, 1.0, 7.5, 300.0):
            assert betainc(s, 1.0, x) == pytest.approx(x**s, rel=1e-12)
            assert betainc_pair(1.0, s, x)[1] == pytest.approx((1.0 - x) ** s, rel=1e-12)
            p, q = betainc_pair(s, 3.0, x)
            assert betainc_pair(3.0, s, 1.0 - x) == pytest.approx((q, p), rel=1e-9)


@pytest.mark.parametrize("a", [0.1, 0.5, 1.0, 4.0, 60.0, 1e3])
@pytest.mark.parametrize("b", [0.1, 0.5, 1.0, 4.0, 60.0, 1e3])
def test_inverse_incomplete_beta_equals_scipy(a: float, b: float) -> None:
    ps = np.concatenate([np.geomspace(1e-20, 0.5, 15), [0.7, 0.9, 0.999]])
    got = np.array([betaincinv(a, b, float(p)) for p in ps])
    ref = sc_betaincinv(a, b, ps)
    ok = ref > 1e-300                  # below, the answer underflows in both
    np.testing.assert_allclose(got[ok], ref[ok], rtol=1e-9)
    # and it inverts: I at the quantile gives p back (where x ≤ ½: nearer 1, the double x
    # itself no longer carries 1 − x to the precision asked)
    low = ok & (got <= 0.5)
    back = np.array([betainc(a, b, float(x)) for x in got[low]])
    np.testing.assert_allclose(back, ps[low], rtol=1e-8)


def test_edges_and_bad_input() -> None:
    assert f_isf(0.0, 3.0, 4.0) == math.inf
    assert f_isf(1.0, 3.0, 4.0) == 0.0
    assert f_ppf(0.0, 3.0, 4.0) == 0.0
    assert f_ppf(1.0, 3.0, 4.0) == math.inf
    assert betainc_pair(2.0, 3.0, 0.0) == (0.0, 1.0)
    assert betainc_pair(2.0, 3.0, 1.0) == (1.0, 0.0)
    assert betaincinv(2.0, 3.0, 0.0) == 0.0
    assert betaincinv(2.0, 3.0, 1.0) == 1.0
    # p → 0 and → 1: finite, ordered, and a tail beyond the doubles is 0, not an error
    tiny = [f_isf(q, 7.0, 10.0) for q in (1e-300, 1e-100, 1e-20)]
    assert all(math.isfinite(v) for v in tiny) and tiny[0] > tiny[1] > tiny[2]
    assert 0.0 < f_isf(1.0 - 1e-16, 7.0, 10.0) < f_isf(1.0 - 1e-9, 7.0, 10.0)
    assert betainc_pair(1e5, 1e5, 0.1) == (0.0, 1.0)
    assert betaincinv(0.05, 1e6, 1e-300) == 0.0          # x ≈ 1e-6000 underflows
    for bad in (lambda: f_isf(-0.1, 2.0, 2.0), lambda: f_ppf(1.5, 2.0, 2.0),
                lambda: f_isf(0.1, 0.0, 2.0), lambda: f_isf(0.1, 2.0, math.inf),
                lambda: betainc(1.0, 1.0, 1.5), lambda: betaincinv(-1.0, 1.0, 0.5)):
        with pytest.raises(ValueError):
            bad()


def test_chi2_upper_tail_equals_scipy_chdtrc() -> None:
    """Pr(χ²_k > x) to relative 1e-10 wherever it is > 1e-300: all three methods of
    gammainc_pq (series, fraction, quadrature for k ≥ 100), far into both tails."""
    for k in (0.3, 1.0, 2.0, 3.0, 7.0, 30.0, 99.0, 100.0, 101.0, 1e3, 1e4):
        x = np.concatenate([k * np.geomspace(1e-3, 0.999, 30),
                            k + math.sqrt(2 * k) * np.linspace(0.0, 60.0, 61),
                            k * np.geomspace(1.001, 50.0, 30)])
        ref = chdtrc(k, x)
        got = chi2_sf(x, k)
        live = ref > 1e-300
        np.testing.assert_allclose(got[live], ref[live], rtol=1e-10, err_msg=f"k = {k}")
    assert float(chi2_sf(0.0, 5.0)) == 1.0
    assert chi2_sf(np.array([1.0, 2.0]), 3.0).shape == (2,)


def test_line_threshold_is_the_f_upper_quantile() -> None:
    """The line finder's threshold (report.line_threshold) as it was with scipy's fdtri,
    to that function's rounding of 1 − q; one value per background width."""
    n_bins, n_seg = 8193, 3296
    n_bg = np.r_[np.arange(8, 62, 2), np.full(50, 60.0)]
    nu = 1.8 * n_seg
    nu_bg = n_bg * nu * 2.0 / math.pi
    thr = line_threshold(n_bins, n_seg, n_bg)
    np.testing.assert_allclose(thr, fdtri(nu, nu_bg, 1.0 - 0.01 / n_bins), rtol=1e-8)
    assert thr.shape == n_bg.shape
    np.testing.assert_array_equal(f_isf_array(0.01 / n_bins, nu, nu_bg), thr)
    assert float(line_threshold(n_bins, 40, 60.0)) == pytest.approx(
        float(fdtri(72.0, 60 * 72.0 * 2 / math.pi, 1.0 - 0.01 / n_bins)), rel=1e-8)


def test_student_t_two_sided_quantile_in_closed_form_and_against_scipy() -> None:
    from scipy.stats import t as student_t

    # one dof (Cauchy): Pr(|T| > t) = 1 − (2/π)·atan t; two dof: 1 − t/√(2 + t²)
    for q in (0.5, 0.05, 1e-3, 1e-6):
        assert t_two_sided(q, 1) == pytest.approx(math.tan(0.5 * math.pi * (1 - q)), rel=1e-9)
        t2 = t_two_sided(q, 2)
        assert 1 - t2 / math.sqrt(2 + t2 * t2) == pytest.approx(q, rel=1e-9)
    # the published table value t₉ at two-sided 1e-3 is 4.781
    assert t_two_sided(1e-3, 9) == pytest.approx(4.781, abs=5e-4)
    for q, dof in ((0.32, 9), (1e-6, 9), (0.01, 30)):
        assert t_two_sided(q, dof) == pytest.approx(float(student_t.isf(q / 2, dof)), rel=1e-9)
