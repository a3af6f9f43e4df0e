"""The simulator's numpy filters (core/sim/linear_filter.py) against scipy.signal, which the
simulated rig no longer loads: same outputs to ~1e-12, state carried across blocks."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from avard.core.sim.linear_filter import (
    SCAN_BLOCK,
    ModalFilter,
    butterworth_lowpass_zpk,
    first_order_scan,
)
from avard.core.sim.noise_gen import white_plus_ar1_filter
from avard.core.sim.simulate import adxl355_lowpass_sos
from scipy import signal

LENGTHS = [1, 2, 7, SCAN_BLOCK, 2 * SCAN_BLOCK + 1, 5 * SCAN_BLOCK + 17, 50_000]


@pytest.mark.parametrize("m", LENGTHS)
@pytest.mark.parametrize("lam", [0.0, -0.7, 0.5, 0.999, 1.0])
def test_first_order_scan_is_the_recurrence(m: int, lam: float) -> None:
    u = np.random.default_rng(m).standard_normal((2, m))
    prev = np.array([0.3, -2.0])
    ref, _ = signal.lfilter([1.0], [1.0, -lam], u, axis=-1, zi=(lam * prev)[:, None])
    got = first_order_scan(u, lam, prev)
    assert np.max(np.abs(got - ref)) <= 1e-12 * max(1.0, np.max(np.abs(ref)))


def test_first_order_scan_broadcasts_one_pole_per_row() -> None:
    u = np.random.default_rng(0).standard_normal((3, 2, 1000))
    lam = np.array([0.1, 0.9, 1.0])[:, None]
    got = first_order_scan(u, lam, np.zeros((3, 2)))
    for p in range(3):
        ref = signal.lfilter([1.0], [1.0, -lam[p, 0]], u[p], axis=-1)
        assert np.allclose(got[p], ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))


def test_butterworth_design_is_scipys() -> None:
    for order, wn in [(2, 0.5), (3, 0.2), (4, 0.7)]:
        z, p, k = butterworth_lowpass_zpk(order, wn)
        zs, ps, ks = signal.butter(order, wn, output="zpk")
        # the same set of poles (each one's nearest scipy pole, both ways)
        dist = np.abs(p[:, None] - ps[None, :])
        assert dist.min(axis=1).max() < 1e-14 and dist.min(axis=0).max() < 1e-14
        assert np.allclose(z, zs, atol=1e-14) and k == pytest.approx(ks, rel=1e-14)
    assert np.allclose(adxl355_lowpass_sos(), signal.butter(2, 0.5, output="sos"),
                       rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="corner"):
        butterworth_lowpass_zpk(2, 1.0)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_butterworth_of_any_order_filters_as_lfilter(order: int) -> None:
    """The modal filter of an odd order's design too: its real pole is exactly real (with
    the 1e-16 of imaginary part e^{jπ} left it, the filter took it for half of a conjugate
    pair and counted it twice)."""
    z, p, k = butterworth_lowpass_zpk(order, 0.3)
    assert np.count_nonzero(p.imag == 0) == order % 2
    x = np.random.default_rng(order).standard_normal((1, 500))
    got = ModalFilter.from_zpk(z, p, k).run(x)[0]
    ref = signal.lfilter(*signal.butter(order, 0.3), x[0])
    assert np.allclose(got, ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))


@pytest.mark.parametrize("m", LENGTHS)
def test_chip_lowpass_streams_equal_to_sosfilt(m: int) -> None:
    """The ADXL355 Butterworth in modal form, split in uneven blocks, started in the steady
    state of the first sample (sosfilt_zi), equals one sosfilt call."""
    x = np.random.default_rng(m).standard_normal((3, m)) + np.array([[0.1], [-0.2], [9.81]])
    sos = adxl355_lowpass_sos()
    ref, _ = signal.sosfilt(sos, x, axis=-1,
                            zi=signal.sosfilt_zi(sos)[:, None, :] * x[:, 0][None, :, None])
    f = ModalFilter.from_zpk(*butterworth_lowpass_zpk(2, 0.5), channels=3)
    f.steady(x[:, 0])
    cuts = sorted({0, m // 3, m // 3 + 1, m})
    got = np.concatenate([f.run(x[:, a:b]) for a, b in itertools.pairwise(cuts)],
                         axis=1)
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_arma_noise_filter_equals_zpk2sos_cascade() -> None:
    """The simulator's white + Gauss–Markov ARMA filter (real poles, complex or real zeros)
    in modal form against scipy's zpk2sos + sosfilt, state carried across calls."""
    phis = [math.exp(-1 / t) for t in (1.0, 3.2, 10.0, 31.6)]
    g, zeros, poles = white_plus_ar1_filter(1.0, phis, [0.3, 0.2, 0.15, 0.1])
    sos = signal.zpk2sos(zeros, poles, g)
    w = np.random.default_rng(5).standard_normal(20_000)
    ref = signal.sosfilt(sos, w)
    f = ModalFilter.from_zpk(zeros, poles, g)
    got = np.concatenate([f.run(w[None, :777])[0], f.run(w[None, 777:])[0]])
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_first_order_lag_equals_lfilter() -> None:
    b0, b1, a = 0.2, 0.05, 0.75
    u = np.random.default_rng(2).standard_normal(3000)
    ref, _ = signal.lfilter([b0, b1], [1.0, -a], u, zi=[0.4])
    f = ModalFilter.first_order(b0, b1, a)
    f.state[:] = 0.4
    got = np.concatenate([f.run(u[None, :1000])[0], f.run(u[None, 1000:])[0]])
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_repeated_poles_are_refused() -> None:
    with pytest.raises(ValueError, match="repeated"):
        ModalFilter.from_zpk([], [0.5, 0.5], 1.0)
