"""Each cause detector on a signal where the answer is known, and on plain noise where it must
stay silent. White noise keeps these fast; the full pipeline is tested in test_explain*.py."""

from __future__ import annotations

import math

import allantools
import numpy as np
import pytest
from avard.core import causes as cz
from avard.core import model
from scipy import signal

FS = 50.0
N = 1 << 16


def white(seed: int, n: int = N, sd: float = 1e-3) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(n) * sd


def measured(y: np.ndarray):
    m = cz.tau_grid(len(y), FS)
    v = cz.oavar(y, FS, m)
    return m / FS, v, cz.avar_edf(v, m, len(y))


def test_oavar_matches_allantools_at_full_overlap():
    y = white(1)
    m = cz.tau_grid(len(y), FS)
    ours = cz.oavar(y, FS, m)
    ref = allantools.oadev(y, rate=FS, data_type="freq", taus=m / FS)[1] ** 2
    full = np.array([cz.stride_for(int(k)) == 1 for k in m])
    np.testing.assert_allclose(ours[full], ref[full], rtol=1e-10)
    # strided points estimate the same quantity; for white noise within their EDF scatter
    edf = cz.avar_edf(ours, m, len(y))
    assert np.all(np.abs(ours[~full] / ref[~full] - 1) < 4 * np.sqrt(2 / edf[~full]))


def test_tau_grid_strides_divide_m():
    m = cz.tau_grid(1 << 20, FS)
    assert m[0] == 1 and np.all(np.diff(m) > 0)
    for k in m:
        s = cz.stride_for(int(k))
        assert k % s == 0 and s <= max(1, k // 8)


def test_quantization_grid_and_relevance():
    y = white(2)
    lsb = 0.8e-3
    q = cz.detect_quantization(np.round(y / lsb) * lsb + 0.123, FS)
    assert q.passed and q.params["lsb"] == pytest.approx(lsb, rel=1e-6)
    fine = cz.detect_quantization(np.round(y / 1e-6) * 1e-6, FS)  # on a grid, but irrelevant
    assert not fine.passed and fine.statistic < 0.01
    assert not cz.detect_quantization(y, FS).passed


def test_sinusoid_frequency_and_amplitude():
    y = white(3)
    t = np.arange(N) / FS
    f0, amp = 0.8123, 4e-4
    tau, _v, edf = measured(y + amp * np.sin(2 * np.pi * f0 * t + 0.3))
    c = cz.detect_sinusoid(y + amp * np.sin(2 * np.pi * f0 * t + 0.3), FS, tau,
                           model.term_avar("velocity_random_walk", tau, 1e-3 / math.sqrt(FS)),
                           edf)
    assert c.passed
    assert c.params["frequency_hz"] == pytest.approx(f0, rel=2e-3)
    assert c.params["amplitude"] == pytest.approx(amp, rel=0.1)


def test_sinusoid_silent_on_noise():
    y = white(4)
    tau, v, edf = measured(y)
    c = cz.detect_sinusoid(y, FS, tau, v, edf)
    assert not c.passed and c.statistic < cz.SPECTRAL_RATIO


def test_step_time_and_size():
    y = white(5, sd=2e-3)
    t_s, size = 0.37 * N / FS, 1.5e-3
    y[int(t_s * FS):] += size
    c = cz.detect_bias_step(y, FS)
    assert c.passed
    assert abs(c.params["time_s"] - t_s) < 0.005 * N / FS
    assert c.params["size"] == pytest.approx(size, rel=0.2)
    assert not cz.detect_warmup(y, FS).passed


def test_warmup_time_constant():
    y = white(6, sd=2e-3)
    t = np.arange(N) / FS
    y += 4e-3 * np.exp(-t / 40.0)
    c = cz.detect_warmup(y, FS)
    assert c.passed and c.params["time_constant_s"] == pytest.approx(40.0, rel=0.2)
    assert not cz.detect_bias_step(y, FS).passed


def test_ramp_slope_and_silence_on_random_walk():
    t = np.arange(N) / FS
    y = white(7) + 2e-6 * t
    c = cz.detect_rate_ramp(y, FS)
    assert c.passed and c.params["slope"] == pytest.approx(2e-6, rel=0.1)
    rw = np.cumsum(white(8, sd=1e-5))  # random walk: wanders, but has no deterministic slope
    assert not cz.detect_rate_ramp(rw + white(9), FS).passed


def test_filter_bandwidth():
    fc = 6.0
    b, a = signal.butter(2, fc / (FS / 2))
    y = signal.lfilter(b, a, white(10))
    tau, v, edf = measured(y)
    c = cz.detect_filter(tau, v, edf, FS, np.zeros_like(tau))
    assert c.passed and c.params["bandwidth_hz"] == pytest.approx(fc, rel=0.1)
    tau, v, edf = measured(white(11))
    assert not cz.detect_filter(tau, v, edf, FS, np.zeros_like(tau)).passed


def test_temperature_coefficient_and_lag():
    rng = np.random.default_rng(12)
    n = N
    # a slow temperature wander (two-pole low-pass noise, ~200 s correlation)
    a = math.exp(-1 / (200 * FS))
    T = signal.lfilter([1.0], [1.0, -a], signal.lfilter([1.0], [1.0, -a],
                                                          rng.standard_normal(n)))
    T = 22 + 0.5 * T / T.std()
    lag, coef = 60.0, 2e-3
    k = int(lag * FS)
    y = white(13) + coef * np.concatenate((np.full(k, T[0]), T[:-k]))
    c = cz.detect_temperature(y, FS, T[:, None], ["plate"])
    assert c.passed and c.witness == "plate"
    assert c.params["coefficient"] == pytest.approx(coef, rel=0.2)
    assert c.params["lag_s"] == pytest.approx(lag, rel=0.3)
    # the same temperature without coupling is no witness
    assert not cz.detect_temperature(white(14), FS, T[:, None], ["plate"]).passed


def test_temperature_without_channels_is_not_claimed():
    c = cz.detect_temperature(white(15), FS, None, [])
    assert not c.passed and "no temperature" in c.evidence


def test_chi2_is_zero_for_a_perfect_model_and_grows_with_misfit():
    v = np.array([1.0, 2.0, 3.0])
    e = np.array([10.0, 10.0, 10.0])
    assert cz.chi2(v, v, e) == 0.0
    assert cz.chi2(v, 1.1 * v, e) < cz.chi2(v, 1.5 * v, e)
