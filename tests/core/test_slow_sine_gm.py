"""The slow-sinusoid search with a Gauss–Markov process in its noise (sine30, adv29 D2): a
GM bump must not raise the floor that hides a slow sinusoid. Without the process in the
covariance its variance goes to the profiled walk, whose red spectrum hides the sinusoid
(and read as white, the process is taken for one)."""

from __future__ import annotations

import numpy as np
from avard.core.analysis.slow_sine import search_slow_sine

RATE, HOURS, N_SD = 1.0, 4.0, 1e-4  # white: N = 1e-4 m/s²/√Hz at 1 Hz
SIGMA, T_GM = 1.7e-4, 30.0
AMP, PERIOD = 1.5e-4, 5400.0
BLOCKS = 256


def _gm(n: int, rng: np.random.Generator) -> np.ndarray:
    a = np.exp(-1.0 / (RATE * T_GM))
    e = rng.standard_normal(n) * SIGMA * np.sqrt(1.0 - a * a)
    x = np.empty(n)
    x[0] = rng.standard_normal() * SIGMA
    for i in range(1, n):
        x[i] = a * x[i - 1] + e[i]
    return x


def _means(seed: int, amp: float) -> tuple[np.ndarray, float]:
    rng = np.random.default_rng(seed)
    n = int(HOURS * 3600 * RATE)
    t = np.arange(n) / RATE
    y = rng.standard_normal(n) * N_SD + _gm(n, rng)
    y += amp * np.sin(2 * np.pi * t / PERIOD + rng.uniform(0, 2 * np.pi))
    per = n // BLOCKS
    return y[:BLOCKS * per].reshape(BLOCKS, per).mean(axis=1), per / RATE


def _search(means: np.ndarray, block_s: float, gm: tuple[float, float] | None):
    record_s = len(means) * block_s
    return search_slow_sine(means, block_s, N_SD / np.sqrt(RATE), 0.0, 1e-9,
                            40.0 / record_s, gm=gm)


def test_a_slow_sinusoid_beside_a_gauss_markov_process_is_resolved_with_it_in_the_noise():
    for seed in (1, 2, 3):
        means, block_s = _means(seed, AMP)
        s = _search(means, block_s, (SIGMA, T_GM)).sine
        assert s is not None, seed
        assert abs(s.frequency_hz * PERIOD - 1.0) < 0.1, (seed, s.frequency_hz)
        assert 0.7 * AMP < s.amplitude < 1.4 * AMP, (seed, s.amplitude)
        assert s.amplitude_lo < s.amplitude < s.amplitude_hi


def test_a_gauss_markov_process_alone_is_no_slow_sinusoid_with_it_in_the_noise():
    # the search's level is 1 %: of 30 records at most two may pass (a binomial tail of
    # about 3.6 % at p = 0.01)
    found = [seed for seed in range(30)
             if _search(*_means(100 + seed, 0.0), (SIGMA, T_GM)).sine is not None]
    assert len(found) <= 2, found
