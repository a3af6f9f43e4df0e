"""Greenhall–Riley EDF with a stride, and chi-squared intervals."""

from __future__ import annotations

import math

import allantools.ci as atci
import numpy as np
import pytest
from avard.core.allan.deviations import allan_variance, oavar
from avard.core.allan.edf import chi2_interval, edf_greenhall
from avard.core.errors import DataError


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("alpha", [2, 1, 0, -1, -2])
def test_matches_allantools_for_full_and_no_overlap(alpha: int, d: int) -> None:
    """Independent implementation of the same paper: identical for stride 1 and stride m."""
    for m in (1, 2, 8, 64, 512):
        for n_phase in (1001, 100001):
            if n_phase < 1 + d * m:
                continue
            for overlapping in (True, False):
                try:
                    ref = atci.edf_greenhall(alpha, d, m, n_phase, overlapping=overlapping)
                except NotImplementedError:  # allantools lacks GR's small-K white-PM case
                    continue
                got = edf_greenhall(alpha, d, m, 1 if overlapping else m, n_phase)
                assert got == pytest.approx(ref, rel=1e-9), (m, n_phase, overlapping)


@pytest.mark.parametrize("alpha", [0, -1, -2])
def test_stride_m_over_8_keeps_98_percent_of_full_overlap(alpha: int) -> None:
    """The streaming cascade's claim (../shared/notes/allan.md), for white, flicker and
    random-walk rate noise, and the non-overlapping estimator's loss for white noise."""
    for m in (64, 1024, 8192):
        full = edf_greenhall(alpha, 2, m, 1, 200_000)
        part = edf_greenhall(alpha, 2, m, m // 8, 200_000)
        assert part >= 0.98 * full
    white_non = edf_greenhall(0, 2, 1024, 1024, 200_000) / edf_greenhall(0, 2, 1024, 1, 200_000)
    assert 0.40 < white_non < 0.50


def test_edf_grows_with_data_and_shrinks_with_stride() -> None:
    for alpha in (1, 0, -1, -2):
        edfs = [edf_greenhall(alpha, 2, 16, 1, n) for n in (200, 2000, 20000)]
        assert edfs[0] < edfs[1] < edfs[2]
        by_stride = [edf_greenhall(alpha, 2, 16, s, 20000) for s in (1, 4, 16)]
        assert by_stride[0] >= by_stride[1] >= by_stride[2]


def test_too_short_is_nan_and_bad_arguments_raise() -> None:
    assert np.isnan(edf_greenhall(0, 2, 100, 1, 150))
    with pytest.raises(DataError, match="alpha"):
        edf_greenhall(-3, 2, 4, 1, 1000)  # AVAR does not converge for alpha <= -3
    with pytest.raises(DataError, match="difference order"):
        edf_greenhall(0, 4, 4, 1, 1000)
    with pytest.raises(DataError, match="stride"):
        edf_greenhall(0, 2, 4, 0, 1000)
    with pytest.raises(DataError, match="confidence"):
        chi2_interval(1.0, 10.0, ci=1.5)


def test_chi2_interval_values() -> None:
    lo, hi = chi2_interval(np.array([2.0, 2.0]), np.array([10.0, np.nan]), ci=0.9)
    # χ²_10(0.95) = 18.307, χ²_10(0.05) = 3.9403 (standard tables)
    assert lo[0] == pytest.approx(2.0 * 10 / 18.307, rel=1e-4)
    assert hi[0] == pytest.approx(2.0 * 10 / 3.9403, rel=1e-4)
    assert np.isnan(lo[1]) and np.isnan(hi[1])


def _coverage(trials: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    sigma, m = 0.5, 8
    truth = sigma**2 / m  # white rate noise: AVAR(τ) = σ²·τ0/τ
    hits = 0
    for _ in range(trials):
        res = oavar(rng.normal(0.0, sigma, 2000), 1.0, [m])
        hits += bool(res.lo[0] <= truth <= res.hi[0])
    return hits / trials


def test_68_percent_interval_covers_the_truth_about_68_percent() -> None:
    # 300 trials: standard error of the coverage ≈ 0.027
    assert 0.58 < _coverage(300, seed=1) < 0.78


@pytest.mark.slow
def test_68_percent_interval_coverage_precise() -> None:
    assert 0.65 < _coverage(4000, seed=2) < 0.715


def _empirical_edf(alpha: int, stride: int, trials: int, seed: int) -> tuple[float, float]:
    """(empirical EDF = 2·mean²/var of the estimates over trials, GR's prediction)."""
    from tests.core.test_allan_noise_id import power_law

    rng = np.random.default_rng(seed)
    m, n = 32, 4096
    est = []
    for _ in range(trials):
        y = power_law(alpha, n, rng)
        est.append(allan_variance(y, 1.0, [m], kind="pavar", stride=stride, alpha=alpha).var[0])
    est = np.array(est)
    predicted = edf_greenhall(alpha, 2, m, stride, n + 1)
    return 2 * est.mean() ** 2 / est.var(ddof=1), predicted


@pytest.mark.parametrize(("alpha", "stride"), [(0, 1), (0, 4), (0, 32), (-2, 4)])
def test_gr_edf_with_stride_predicts_the_scatter_of_estimates(alpha: int, stride: int) -> None:
    """Monte Carlo check of the stride generalisation: the spread of 300 independent
    estimates matches 2σ⁴/EDF (the relative standard error of the check is about 10 %)."""
    empirical, predicted = _empirical_edf(alpha, stride, 300, seed=stride - alpha)
    assert empirical == pytest.approx(predicted, rel=0.3)


@pytest.mark.slow
@pytest.mark.parametrize(("alpha", "stride"), [(0, 1), (0, 4), (0, 32), (-1, 4), (-2, 4)])
def test_gr_edf_with_stride_precise(alpha: int, stride: int) -> None:
    empirical, predicted = _empirical_edf(alpha, stride, 4000, seed=100 + stride - alpha)
    assert empirical == pytest.approx(predicted, rel=0.1)


def _oavar_rows(y: np.ndarray, m: int) -> np.ndarray:
    """Each row's fully overlapping AVAR at m (SP 1065 eq. 12 on rate data), written out."""
    c = np.concatenate([np.zeros((len(y), 1)), np.cumsum(y, axis=1)], axis=1)
    d = c[:, 2 * m:] - 2 * c[:, m:-m] + c[:, :-2 * m]
    return np.asarray(np.mean(d * d, axis=1) / (2.0 * m * m))


def _white_fm_direct(m: int, n_phase: int) -> float:
    """The OADEV's EDF on white rate samples from the differences' covariance written out:
    d_k = Σ y over (k+m, k+2m] − Σ y over (k, k+m], so R(l) = 2m − 3l up to m, l − 2m up to
    2m, 0 beyond; EDF = M R(0)² / Σ_|l|<M (M − |l|)/M·R(l)²."""
    big_m = n_phase - 1 - 2 * m + 1
    lag = np.arange(0, min(big_m, 2 * m + 1))
    r = np.where(lag <= m, 2 * m - 3 * lag, lag - 2 * m).astype(float)
    c = np.where(lag == 0, 1.0, 2.0 * (1.0 - lag / big_m))
    return float(big_m * r[0] ** 2 / np.sum(c * r * r))


@pytest.mark.parametrize("m", [1, 2, 8, 33, 34, 64])
def test_rate_data_white_fm_edf_is_the_differences_own(m: int) -> None:
    """Rate samples' phase is their exact running sum: with ``rate_data`` GR's white-FM EDF
    is the one the differences' covariance gives directly, at every m (GR's one-sample
    phase averaging, F = m, the default kept for Stable32's rows, is off by up to 17 % at
    m ≤ 33 and equal beyond)."""
    n_phase = 20001
    direct = _white_fm_direct(m, n_phase)
    rate = edf_greenhall(0, 2, m, 1, n_phase, rate_data=True)
    phase = edf_greenhall(0, 2, m, 1, n_phase)
    if m * 3 <= 100:  # GR's basic sum, exact
        assert rate == pytest.approx(direct, rel=1e-9)
        assert abs(phase / direct - 1.0) > 0.02  # (the default is GR's F = m, not this)
    else:  # GR's asymptotic form (continuous time, F = ∞ either way)
        assert rate == phase
        assert rate == pytest.approx(direct, rel=3e-3)


def test_rate_data_edf_predicts_white_noises_scatter_at_m_1() -> None:
    """White rate noise at m = 1: the OADEV estimates scatter with the rate-data EDF 2M/3,
    not GR's F = m value (17 % above it): 1500 records of 3000 samples."""
    rng = np.random.default_rng(8)
    n = 3000
    est = _oavar_rows(rng.normal(size=(1500, n)), 1)
    seen = 2.0 * 1.0 / np.mean((est - 1.0) ** 2)  # the truth: AVAR = s² = 1 at m = 1
    exact = edf_greenhall(0, 2, 1, 1, n + 1, rate_data=True)
    assert seen == pytest.approx(exact, rel=0.1), (seen, exact)
    assert abs(seen / edf_greenhall(0, 2, 1, 1, n + 1) - 1.0) > 0.1


def test_mixture_edf_of_one_type_is_its_own_and_never_below_the_bound() -> None:
    """One type alone (or every level on one type): that type's EDF; two types: at least
    the Cauchy–Schwarz bound (ρ ≤ 1), and on types correlated over different spans more."""
    from avard.core.allan.edf import edf_mixture, edf_mixture_bound

    for m, n_phase in ((4, 4097), (64, 4097), (512, 36001), (4096, 36001)):
        nus = [edf_greenhall(a, 2, m, 1, n_phase, rate_data=True) for a in (0, -1, -2)]
        for k in range(3):
            lv = [0.0, 0.0, 0.0]
            lv[k] = 3.0
            assert edf_mixture((0, -1, -2), lv, 2, m, 1, n_phase, rate_data=True) == \
                pytest.approx(nus[k], rel=1e-12)
        lv = [1.0, 2.0, 0.5]
        mix = edf_mixture((0, -1, -2), lv, 2, m, 1, n_phase, rate_data=True)
        bound = float(edf_mixture_bound(np.array(lv)[:, None], np.array(nus)[:, None])[0])
        assert mix >= bound * (1 - 1e-12)
    assert math.isnan(edf_mixture((0, -2), [0.0, 0.0], 2, 8, 1, 4097))
    assert math.isnan(edf_mixture((0, -2), [1.0, 1.0], 2, 4096, 1, 4097))  # nothing fits


def test_mixture_edf_predicts_the_scatter_of_white_plus_random_walk() -> None:
    """White + random-walk rate noise of equal AVAR at m = 2: the OADEV estimates scatter
    with the mixture's own EDF (Monte Carlo, 1000 records, ±6 %), which is above both types'
    own and 28 % above the Cauchy–Schwarz bound it replaced (their differences are
    correlated over different spans: white FM's within 2m, the walk's far beyond)."""
    from avard.core.allan.edf import edf_mixture, edf_mixture_bound

    rng = np.random.default_rng(21)
    n, m = 4096, 2
    s2, q2 = 1.0, 6.0 / (2 * m * m + 1)  # white s²/m = walk q²(2m²+1)/(6m) at m
    truth = 2.0 * s2 / m
    y = rng.normal(size=(1000, n)) + np.cumsum(rng.normal(scale=np.sqrt(q2), size=(1000, n)),
                                               axis=1)
    est = _oavar_rows(y, m)
    seen = 2.0 * truth**2 / np.mean((est - truth) ** 2)
    lv = [s2 / m, s2 / m]
    mix = edf_mixture((0, -2), lv, 2, m, 1, n + 1, rate_data=True)
    nus = [edf_greenhall(a, 2, m, 1, n + 1, rate_data=True) for a in (0, -2)]
    bound = float(edf_mixture_bound(np.array(lv)[:, None], np.array(nus)[:, None])[0])
    assert mix > max(nus) and mix > 1.2 * bound
    assert seen == pytest.approx(mix, rel=0.15), (seen, mix, bound, nus)
    assert seen > 1.1 * bound, (seen, bound)


@pytest.mark.slow
def test_mixture_edf_predicts_the_independent_generators_scatter() -> None:
    """The coverage generator's plain mix (tests/support/coverage_gen.py, written apart:
    white + Fourier-series flicker + random walk) on 12 h at 1 Hz, 400 records: at
    512–2048 s, where the walk holds 14–40 % of the AVAR and the lag-1 ACF reads nearly a
    walk, the OADEV estimates scatter with the mixture's EDF (``edf_mixture`` at the
    generator's levels, ±15 %), above the walk's own EDF by more than that."""
    from avard.core.allan.edf import edf_mixture

    from benchmarks.bench_coverage import mix_for
    from tests.support.coverage_gen import flicker_avar, noise_avar, record

    n, ms = 43200, (512, 1024, 2048)
    mix = mix_for("plain", n, 1.0)
    rng = np.random.default_rng(40)
    est = np.array([[_oavar_rows(record(mix, n, rng)[0][None, :], m)[0] for m in ms]
                    for _ in range(400)])
    truth = noise_avar(mix, n, np.array(ms, dtype=float))
    seen = 2.0 * truth**2 / np.mean((est - truth) ** 2, axis=0)
    for k, m in enumerate(ms):
        lv = [mix.s2 / m, float(flicker_avar(n, mix.h, np.array([m]))[0]),
              mix.q2 * (2 * m * m + 1) / (6 * m)]
        mixture = edf_mixture((0, -1, -2), lv, 2, m, 1, n + 1, rate_data=True)
        walk = edf_greenhall(-2, 2, m, 1, n + 1, rate_data=True)
        assert seen[k] == pytest.approx(mixture, rel=0.15), (m, seen[k], mixture)
        assert mixture > 1.2 * walk
