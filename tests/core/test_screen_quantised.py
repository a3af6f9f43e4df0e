"""The input screen on records whose noise is below one LSB of their grid (issue 23, found by
an adversary): the robust scale of a discrete distribution (the median distance of a sample
from its neighbours' mean) is 0 or a fraction of a step there, and ±1 LSB samples were cut
as "isolated shocks" (noise of 0.3–0.35 LSB), or nothing was judged at all (0.2 LSB: a real
shock stayed in). The scale is now never below what the grid's quantisation (q/√12) and the
distances' own spread support (``screen.grid_scale``)."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan import kernels
from avard.core.io.screen import screen_accel
from avard.core.io.screen.accel import GRID_SHARE, grid_scale, grid_step

LSB = 3.9e-6 * 9.80665  # the ADXL355's step at ±2 g


@pytest.fixture(params=[True, False], ids=["compiled", "numpy"])
def path(request, monkeypatch):
    if request.param and kernels.compiled() is None:
        pytest.skip("no compiled kernels here")
    if not request.param:
        monkeypatch.setattr(kernels, "compiled", lambda: None)
    return request.param


@pytest.mark.parametrize("sigma", [0.2, 0.3, 0.32, 0.35, 0.5, 0.7, 1.0])
def test_sub_lsb_noise_is_never_cut_and_a_real_shock_still_is(path, sigma):
    """Noise of σ LSB (a fifth of a step to one step) rounded to the grid, at offsets that
    put the mean on a step and between steps: no sample is cut on any of the blocks (main
    cut 5–20 samples a block at 0.3–0.35 LSB); a shock of 40 LSB on one axis is cut at every
    level, 0.2 LSB included (main judged nothing there: the scale was 0)."""
    cut = 0
    for seed in range(4):
        for off in (0.0, 0.1, 0.25):
            rng = np.random.default_rng(1000 * seed + int(100 * sigma))
            a = np.round(rng.normal(off, sigma, (1 << 16, 3))) * LSB
            a += np.array([0.0, 0.0, round(9.81 / LSB) * LSB])  # the z axis at 1 g, on grid
            cut += int(screen_accel(a).sum())
            a[40_000, 1] += 40 * LSB
            bad = screen_accel(a)
            assert bad[40_000], (sigma, seed, off)
            assert set(np.flatnonzero(bad)) == set(range(39_998, 40_003))
    assert cut == 0


def test_the_grid_floor_is_the_quantisation_and_stays_off_a_fine_record():
    """The floor is q/√12 of the distance's share where the distances take few values, and
    0 where the record is finer than its noise (the median's scale stands, as before)."""
    rng = np.random.default_rng(3)
    a = np.round(rng.normal(0.0, 0.05, 1 << 14)) * LSB
    a[::50] += LSB  # steps of one LSB: the grid is seen
    assert grid_step(a) == pytest.approx(LSB, rel=1e-9)
    dist = np.zeros(len(a))
    assert grid_scale(a, dist, 0.0) == pytest.approx(GRID_SHARE * LSB, rel=1e-9)
    fine = rng.normal(0.0, 1e-3, 1 << 14)
    assert grid_scale(fine, np.abs(fine), 1e-3) == 0.0
    # a dead axis with one jump shows no grid: no floor made of that jump
    dead = np.zeros(1 << 14)
    dead[100] = 40 * LSB
    assert grid_step(dead) == 0.0


@pytest.mark.parametrize("noise, share, burst, shock", [
    (1.5, 0.2, 30, 40), (1.5, 0.3, 30, 80), (1.0, 0.3, 20, 40), (0.4, 0.3, 10, 20)])
def test_bursts_of_vibration_do_not_hide_a_shock(path, noise, share, burst, shock):
    """Review of the grid floor: the distances' trimmed RMS, taken wherever the grid step
    was over a quarter of the median's scale, took a block's bursts of vibration (20–30 %
    of it at ±10–30 LSB) for its noise, and a 20–80 LSB shock in a quiet stretch was no
    longer cut. The median stands where it is above the quantisation, and the RMS, used
    only below it, is capped at a few times the quantisation."""
    rng = np.random.default_rng(3)
    n = 1 << 16
    x = noise * rng.standard_normal((n, 3))
    length = int(share * n)
    x[10_000:10_000 + length] += burst * np.sin(2 * np.pi * 20 / 125 * np.arange(length))[:, None]
    x[40_000, 0] += shock
    bad = screen_accel(np.round(x) * LSB)
    assert bad[40_000]
