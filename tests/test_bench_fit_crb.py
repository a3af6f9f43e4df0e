"""The Cramér–Rao bound for K printed by benchmarks/bench_fit.py (row "K CRB").

The bound rests on the autocovariances of the first differences of τd-block means for white,
flicker and random-walk rate noise; γ(0)/2 is the Allan variance at τd, so each must reproduce
the IEEE closed forms. The bound itself must shrink with the record like T^(−1/2) and must not
depend on τd at the chosen block length.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.bench_fit import (
    CRB_TAU_D,
    CRB_TERMS,
    REGIMES,
    diff_autocov,
    diff_spectrum,
    k_crb,
)

AVAR_PER_THETA = {
    "velocity_random_walk": lambda tau: 1.0 / tau,
    "bias_instability": lambda tau: 2.0 * math.log(2.0) / math.pi,
    "rate_random_walk": lambda tau: tau / 3.0,
}


@pytest.mark.parametrize("term", CRB_TERMS)
@pytest.mark.parametrize("tau_d", [0.0625, 1.0, 37.0])
def test_half_lag0_autocov_is_the_allan_variance(term: str, tau_d: float) -> None:
    g0 = diff_autocov(term, tau_d, [0])[0]
    assert g0 / 2.0 == pytest.approx(AVAR_PER_THETA[term](tau_d), rel=1e-12)


def test_short_lags_white_and_random_walk_are_exact() -> None:
    tau = 2.0
    np.testing.assert_allclose(diff_autocov("velocity_random_walk", tau, [0, 1, 2, 7]),
                               [2.0 / tau, -1.0 / tau, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(diff_autocov("rate_random_walk", tau, [0, 1, 2, 7]),
                               [2.0 * tau / 3.0, tau / 6.0, 0.0, 0.0], atol=1e-15)


def test_flicker_tail_joins_the_exact_lags_and_spectrum_sums_them() -> None:
    # exact 4th difference of j² ln j against the asymptotic −(2/j² + 2/j⁴)/(2π) at the seam
    j = np.arange(60, 64)
    exact = diff_autocov("bias_instability", 1.0, j)
    np.testing.assert_allclose(exact, (-2.0 / j**2 - 2.0 / j**4) / (2.0 * np.pi), rtol=1e-5)
    # the closed-form spectrum equals the (long) direct cosine sum of the autocovariances
    w = np.array([0.05, 0.7, 2.0, math.pi])
    lags = np.arange(1, 200_000)
    g = diff_autocov("bias_instability", 1.0, lags)
    direct = diff_autocov("bias_instability", 1.0, [0])[0] + 2.0 * np.cos(np.outer(w, lags)) @ g
    np.testing.assert_allclose(diff_spectrum("bias_instability", 1.0, w), direct, rtol=1e-4)
    # flicker's 1/f through the differencing: S(ω) → |ω| at low frequency
    assert diff_spectrum("bias_instability", 1.0, np.array([1e-5]))[0] == pytest.approx(1e-5,
                                                                                      rel=1e-3)


def test_k_bound_falls_like_inverse_root_of_record_length() -> None:
    truth = REGIMES["floor"]
    short, long_ = k_crb(truth, 1.5, tau_d=0.25), k_crb(truth, 6.0, tau_d=0.25)
    assert 0.0 < long_ < short
    assert long_ / short == pytest.approx(0.5, abs=0.05)  # 4× the record: ≈ ½ the error


def test_k_bound_is_settled_at_the_chosen_block_length() -> None:
    truth = REGIMES["datasheet"]
    coarse, fine = k_crb(truth, 1.5, tau_d=CRB_TAU_D), k_crb(truth, 1.5, tau_d=CRB_TAU_D / 4)
    assert fine <= coarse
    assert coarse / fine - 1.0 < 0.01
