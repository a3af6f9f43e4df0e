"""Closed-form AVAR of the noise terms (IEEE 952 Annex C) and the estimator-covariance model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.errors import FitError
from avard.core.model import terms as M
from scipy import signal
from scipy.integrate import quad


def _oavar(y: np.ndarray, ms: np.ndarray) -> np.ndarray:
    """Plain overlapping AVAR (NIST SP 1065 eq. 12) of rate data, τ0 = 1, for the checks."""
    x = np.concatenate([[0.0], np.cumsum(y)])
    return np.array([np.mean((x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]) ** 2) / (2.0 * m * m)
                     for m in ms])


def _spectral_avar(psd, m: int) -> float:
    """σ²(m) = ∫ S(ν)|H_m(ν)|² dν over (−½, ½) by adaptive quadrature (independent of the
    kernel code under test)."""
    def f(nu: float) -> float:
        return psd(np.array([nu]))[0] * 2 * math.sin(math.pi * nu * m) ** 4 / (
            m**2 * math.sin(math.pi * nu) ** 2)
    pts = [k / m for k in range(1, min(m, 50)) if k / m < 0.5]
    return 2 * quad(f, 1e-12, 0.5, limit=2000, points=pts or None)[0]


@pytest.mark.parametrize(("term", "value", "slope"), [
    ("quantization", 2e-4, -1.0), ("velocity_random_walk", 3e-4, -0.5),
    ("bias_instability", 5e-5, 0.0), ("rate_random_walk", 7e-6, 0.5), ("rate_ramp", 1e-7, 1.0),
])
def test_term_adev_slopes_and_values(term: str, value: float, slope: float) -> None:
    tau = np.array([1.0, 10.0, 100.0])
    adev = np.sqrt(M.term_avar(term, tau, value))
    assert np.allclose(np.diff(np.log10(adev)), slope)
    expect = {"quantization": math.sqrt(3) * value, "velocity_random_walk": value,
              "bias_instability": M.BI_FACTOR * value, "rate_random_walk": value / math.sqrt(3),
              "rate_ramp": value / math.sqrt(2)}[term]
    assert adev[0] == pytest.approx(expect, rel=1e-12)


def test_bias_instability_floor_factor() -> None:
    assert M.BI_FACTOR == pytest.approx(0.6643, abs=1e-4)


def test_term_psds_give_the_closed_forms() -> None:
    """The PSD used for the covariance model must reproduce each term's AVAR."""
    fs = 50.0
    for term, value in [("velocity_random_walk", 2e-4), ("rate_random_walk", 3e-5),
                        ("quantization", 1e-4)]:
        psd = M.term_psd(term, fs)
        for m in (64, 256):
            want = M.term_avar(term, np.array([m / fs]), value)[0]
            got = value**2 * _spectral_avar(psd, m)
            # discrete RRW carries the known K²τ0²/(6τ) extra (allan.md); Q its aliasing
            assert got == pytest.approx(want, rel=2e-3 if term != "quantization" else 2e-2)
    psd = M.term_psd("bias_instability", fs)
    got = _spectral_avar(psd, 512) * 1e-8
    assert got == pytest.approx(M.BI_FACTOR**2 * 1e-8, rel=5e-3)
    assert M.term_psd("rate_ramp", fs) is None


def test_sinusoid_peak() -> None:
    f0, amp = 2.0, 3e-4
    tau = np.geomspace(0.05, 1.0, 20001)
    adev = np.sqrt(M.sinusoid_avar(tau, amp, f0))
    k = int(np.argmax(adev))
    assert adev[k] / amp == pytest.approx(0.7246, abs=2e-4)
    assert tau[k] * f0 == pytest.approx(0.371, abs=2e-3)


def test_sinusoid_matches_simulated_sine() -> None:
    fs, f0, amp = 100.0, 0.7, 1e-3
    t = np.arange(400_000) / fs
    ms = np.array([10, 40, 53, 200])
    est = _oavar(amp * np.sin(2 * np.pi * f0 * t + 0.3), ms)
    assert np.allclose(est, M.sinusoid_avar(ms / fs, amp, f0), rtol=0.02, atol=1e-12)


def test_gauss_markov_peak_and_limits() -> None:
    sigma, T = 2e-4, 5.0
    tau = np.geomspace(0.5, 50, 40001)
    adev = np.sqrt(M.gauss_markov_avar(tau, sigma, T))
    k = int(np.argmax(adev))
    assert adev[k] / sigma == pytest.approx(0.6174, abs=2e-4)
    assert tau[k] / T == pytest.approx(1.893, abs=3e-3)
    small = np.array([1e-6, 1e-4, 1e-3]) * T
    assert np.allclose(M.gauss_markov_avar(small, sigma, T), 2 * sigma**2 * small / (3 * T),
                       rtol=1e-3)
    big = np.array([1e4, 1e5]) * T
    assert np.allclose(M.gauss_markov_avar(big, sigma, T), 2 * sigma**2 * T / big, rtol=1e-3)
    # continuous across the series/closed-form switch
    x = np.array([0.0099999, 0.0100001]) * T
    v = M.gauss_markov_avar(x, sigma, T)
    assert v[1] / v[0] == pytest.approx(x[1] / x[0], rel=1e-5)


def test_gauss_markov_matches_simulated_ar1() -> None:
    rng = np.random.default_rng(4)
    fs, sigma, T = 10.0, 1.0, 3.0
    phi = math.exp(-1 / (fs * T))
    n = 400_000
    y = signal.lfilter([sigma * math.sqrt(1 - phi**2)], [1, -phi], rng.standard_normal(n))
    ms = np.array([8, 32, 128, 512])
    est = _oavar(y, ms)
    want = M.gauss_markov_avar(ms / fs, sigma, T)
    assert np.allclose(est, want, rtol=0.08)


def test_lowpass_white_bends_short_tau_and_tends_to_white() -> None:
    fs, N = 125.0, 2e-4
    m = np.array([1, 2, 4, 8, 64, 1024])
    v = M.lowpass_white_avar(m / fs, N, fs, fs / 4)
    white = N**2 / (m / fs)
    assert np.all(v[:3] < white[:3] * 0.97)  # the filter removes variance at a few samples
    assert v[-1] == pytest.approx(white[-1], rel=2e-3)
    # the same filter on simulated white noise (what core/sim/simulate.py does)
    rng = np.random.default_rng(1)
    b, a = signal.butter(2, 0.5)
    y = signal.lfilter(b, a, N * math.sqrt(fs) * rng.standard_normal(600_000))
    est = _oavar(y, m[:4])
    assert np.allclose(est, v[:4], rtol=0.02)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_filter_model_is_scipys_butterworth(order: int) -> None:
    """The chip-filter model without scipy (the simulator's numpy Butterworth, its impulse
    response by the modal filter, |G|² from zeros and poles) against scipy.signal's butter,
    lfilter and freqz: the autocovariance behind ``lowpass_white_avar`` and the gain behind
    the flicker model and the AVAR covariance, at corners from ODR/100 to 0.45·ODR."""
    for fs, fc in [(125.0, 31.25), (125.0, 5.0), (100.0, 1.0), (100.0, 45.0)]:
        b, a = signal.butter(order, fc / (fs / 2))
        n = 64
        while True:  # the truncation rule of the model: decayed to 1e-12
            imp = np.zeros(n)
            imp[0] = 1.0
            h = signal.lfilter(b, a, imp)
            if np.max(np.abs(h[-8:])) < 1e-12 * np.max(np.abs(h)):
                break
            n *= 2
        h = h / h.sum()
        ref = np.correlate(h, h, mode="full")[len(h) - 1:]
        got = M._lowpass_autocov_wn.__wrapped__(fc / (fs / 2), order)
        assert len(got) == len(ref)
        assert np.max(np.abs(got - ref)) < 1e-9 * ref[0]
        nu = np.linspace(0.0, 0.5, 257)
        _, g = signal.freqz(b, a, worN=2 * np.pi * nu)
        np.testing.assert_allclose(M.lowpass_gain2(nu, fs, fc, order), np.abs(g) ** 2,
                                   rtol=0, atol=1e-9)


def test_model_avar_adds_components() -> None:
    tau = np.array([0.1, 1.0, 10.0])
    terms = {"velocity_random_walk": 1e-4, "bias_instability": 2e-5, "rate_ramp": None}
    extra = [{"cause": "sinusoid", "params": {"amplitude": 1e-4, "frequency_hz": 0.3}},
             {"cause": "gauss_markov", "params": {"sigma": 1e-4, "time_constant_s": 2.0}}]
    got = M.model_avar(tau, terms, extra)
    want = (M.term_avar("velocity_random_walk", tau, 1e-4)
            + M.term_avar("bias_instability", tau, 2e-5)
            + M.sinusoid_avar(tau, 1e-4, 0.3) + M.gauss_markov_avar(tau, 1e-4, 2.0))
    assert np.allclose(got, want, rtol=1e-14)


def test_bad_inputs_are_named() -> None:
    with pytest.raises(FitError, match="unknown noise term"):
        M.term_avar("pink", np.array([1.0]), 1.0)
    with pytest.raises(FitError, match="tau"):
        M.term_avar("rate_ramp", np.array([0.0, 1.0]), 1.0)
    with pytest.raises(FitError, match="Nyquist"):
        M.lowpass_white_avar(np.array([1.0]), 1.0, 100.0, 80.0)
    with pytest.raises(FitError, match="component"):
        M.component_avar("hum", np.array([1.0]), {})


def test_covariance_kernels_match_monte_carlo() -> None:
    """Variance and neighbour correlation of overlapping AVAR estimates of white noise and of
    a random walk, against a Monte Carlo of the estimator itself."""
    rng = np.random.default_rng(7)
    n, reps = 4096, 600
    ms = np.array([1, 2, 4, 8, 16, 32])
    for name, make in [("velocity_random_walk", lambda: rng.standard_normal(n)),
                       ("rate_random_walk", lambda: np.cumsum(rng.standard_normal(n)))]:
        est = np.array([_oavar(make(), ms) for _ in range(reps)])
        G = M.avar_covariance_kernels(ms, [M.term_psd(name, 1.0)])[:, :, 0, 0]
        cnt = (n - 2 * ms + 1).astype(float)
        cov = 2 * G / np.maximum.outer(cnt, cnt)  # θ = 1: per-sample variance 1 / K² = 1
        sd_ratio = est.std(axis=0) / np.sqrt(np.diag(cov))
        assert np.all(np.abs(sd_ratio - 1) < 0.12), (name, sd_ratio)
        emp = np.corrcoef(est.T)
        pred = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
        assert np.all(np.abs(np.diag(emp, 1) - np.diag(pred, 1)) < 0.08), (name, emp, pred)


def test_filter_terms_are_computed_once_per_corner_not_per_fitted_rate() -> None:
    """A running service's fitted rate moves by ppm between snapshots: the low-pass terms must
    come from the cache (keyed by the normalised corner), not be integrated again each time
    (issue 26 item 9: one `snapshot` request raised the fit thread's CPU ~6x for the run)."""
    tau = np.array([1, 2, 3, 5, 8, 16, 64, 1000]) / 125.0
    first = M.lowpass_flicker_avar(tau, 2e-5, 125.0, 31.25)
    white = M.lowpass_white_avar(tau, 1e-4, 125.0, 31.25)
    flicker0 = M._flicker_ratio_one.cache_info().misses
    white0 = M._lowpass_autocov_wn.cache_info().misses
    for k in range(1, 6):
        rate = 125.0 * (1 + 2.7e-6 * k)
        # the service's corner is the fitted rate / 4
        again = M.lowpass_flicker_avar(tau * 125.0 / rate, 2e-5, rate, rate / 4)
        np.testing.assert_allclose(again, first, rtol=1e-12)
        w = M.lowpass_white_avar(tau * 125.0 / rate, 1e-4, rate, rate / 4)
        np.testing.assert_allclose(w, white * rate / 125.0, rtol=1e-12)
    assert M._flicker_ratio_one.cache_info().misses == flicker0
    assert M._lowpass_autocov_wn.cache_info().misses == white0
    # a corner that really differs is computed anew, and differs
    other = M.lowpass_flicker_avar(tau, 2e-5, 125.0, 20.0)
    assert M._flicker_ratio_one.cache_info().misses > flicker0
    assert not np.allclose(other, first, rtol=1e-3, atol=0)


def test_lowpass_white_avar_cached_equals_the_direct_sum_to_the_bit() -> None:
    """The filtered white AVAR is cached per averaging factors and corner (a fit per
    Gauss–Markov T builds the same column and kernels again): every call, first or repeated,
    equals the direct sum over the autocovariance bit for bit, and a caller
    cannot change what the next one reads."""
    rate, corner = 124.9, 31.225
    r = M._lowpass_autocov_wn(M._filter_key(rate, corner), 2)
    for m in (np.array([1, 2, 3, 4, 8, 16, 1024, 70000]), np.array([5]), 2 ** np.arange(20)):
        tau = m / rate
        direct = 3e-4**2 * rate * M._avar_from_autocov(m, r)
        for _ in range(2):  # a miss, then a hit
            got = M.lowpass_white_avar(tau, 3e-4, rate, corner)
            assert got.tobytes() == direct.tobytes()
            got *= 2.0  # the caller's own array
    with pytest.raises(ValueError):  # the cached curve itself is read-only
        M._lowpass_white_unit(np.array([1, 2], dtype=np.int64).tobytes(),
                              M._filter_key(rate, corner), 2)[0] = 0.0


def test_covariance_kernels_cached_equal_the_direct_quadrature():
    """The kernels, cached per pair of component PSDs (a Gauss–Markov T scan recomputes only
    its own component's share), equal the direct sum over every pair's quadrature, for any
    order of calls."""
    import numpy as np
    from avard.core.model import terms as mdl

    m = np.array([1, 2, 4, 8, 16, 32, 64, 128])
    rate = 10.0

    def direct(psds):
        K, A = len(m), len(psds)
        G = np.zeros((K, K, A, A))
        for k in range(K):
            for j in range(k, K):
                nu, w = mdl._pair_quadrature(int(m[k]), int(m[j]))
                s = [p(nu) if p is not None else np.zeros_like(nu) for p in psds]
                for a in range(A):
                    for b in range(A):
                        G[k, j, a, b] = G[j, k, a, b] = 2.0 * np.sum(w * s[a] * s[b])
        return G

    base = [mdl.term_psd(t, rate) for t in ("velocity_random_walk", "bias_instability",
                                            "rate_random_walk", "rate_ramp")]
    for T in (3.0, 30.0, 3.0):
        psds = [*base, mdl.gauss_markov_psd(rate, T), mdl.lowpass_white_psd(rate, 2.5)]
        got = mdl.avar_covariance_kernels(m, psds)
        assert np.allclose(got, direct(psds), rtol=1e-12, atol=0)
