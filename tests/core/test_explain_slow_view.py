"""explain's slow view (``engine.SlowView``): the temperature block means by ``bincount`` of
the few readings equal the masked mean over every value they replaced, bit for bit."""

from __future__ import annotations

import numpy as np
from avard.core.explain.engine import SlowView
from avard.core.explain.engine.slow import _reading_means, slow_block_means


def _masked_means(t: np.ndarray, b: int) -> np.ndarray:
    """The general formula: the finite values of each block summed (zeros elsewhere) over
    their count."""
    nb = len(t) // b
    blk = t[:nb * b].reshape(nb, b, t.shape[1])
    ok = np.isfinite(blk)
    cnt = ok.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, np.where(ok, blk, 0.0).sum(axis=1) / cnt, np.nan)


def test_reading_means_equal_the_masked_mean_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    for b, every in ((64, 94), (128, 94), (256, 3), (16, 1)):
        t = np.full((20_000, 3), np.nan)
        for j in range(3):  # DS18B20 readings, rounded, a different phase per channel
            t[j::every, j] = np.round((21 + rng.normal(0, 0.3, len(t[j::every]))) / 0.0625
                                      ) * 0.0625
        t[100:3000, 1] = np.nan  # a dropout: blocks without a reading
        t[7, 0], t[9, 2] = np.inf, -np.inf  # never a reading
        got, _when = _reading_means(t[:len(t) // b * b], b)
        np.testing.assert_array_equal(got, _masked_means(t, b))
        assert np.isnan(got[3000 // b - 1, 1])


def test_slow_view_of_blocks_that_leave_a_carry() -> None:
    """Blocks of any length (a carry between them) give the means of the whole record, and
    a block the reader reuses afterwards does not change the carry."""
    rng = np.random.default_rng(6)
    a = rng.normal(0, 1e-3, (10_000, 3))
    t = np.full((10_000, 1), np.nan)
    t[::94, 0] = 21.0 + rng.normal(0, 0.1, len(t[::94]))
    view = SlowView(64, 3, 1)
    buf_a, buf_t = np.empty((1000, 3)), np.empty((1000, 1))
    for i in range(0, 10_000, 1000):
        buf_a[:], buf_t[:] = a[i:i + 1000], t[i:i + 1000]
        view.update(buf_a, buf_t)  # the same buffers every time, as a reader may reuse them
    y, temp = view.finish()
    nb = 10_000 // 64
    np.testing.assert_allclose(y, a[:nb * 64].reshape(nb, 64, 3).mean(axis=1), rtol=1e-12)
    assert temp is not None and np.all(np.isfinite(temp))


def test_temperature_means_sit_at_the_acceleration_block_centres() -> None:
    """A DS18B20 read every 8 rows of a 10 Hz record holds its readings at rows 0 and 8 of
    each 16-row block, 3.5 rows (0.35 s) before the block's centre, where the acceleration's
    block mean sits. Each block's temperature is the readings' value at that centre: a
    linear ramp read so comes out at the centre's time exactly (the readings' mean taken
    as the block's own value was the ramp 0.35 s early, a +0.35 s bias on every lag)."""
    rate, b, every, n = 10.0, 16, 8, 16 * 400
    t_s = np.arange(n) / rate
    temp = np.full((n, 2), np.nan)
    temp[::every, 0] = 20.0 + 0.01 * t_s[::every]  # 0.01 K/s
    temp[3::every, 1] = 20.0 + 0.01 * t_s[3::every]  # another phase: rows 3 and 11
    view = SlowView(b, 1, 2)
    view.update(np.zeros((n, 1)), temp)
    _y, got = view.finish()
    assert got is not None
    centre = (np.arange(n // b) * b + 0.5 * (b - 1)) / rate
    inner = slice(1, -1)  # the ends are held at the first and last readings
    np.testing.assert_allclose(got[inner, 0], 20.0 + 0.01 * centre[inner], atol=1e-9)
    np.testing.assert_allclose(got[inner, 1], 20.0 + 0.01 * centre[inner], atol=1e-9)
    _m, when = _reading_means(temp, b)
    np.testing.assert_allclose(when[:, 0], (4.0 - 7.5) / b)
    np.testing.assert_allclose(when[:, 1], (7.0 - 7.5) / b)


def test_block_means_equal_numpys_mean_bit_for_bit() -> None:
    """The slow view's block means (whole row slices added in order) equal numpy's mean over
    the blocks to the bit: one to six channels, short and long blocks, signed zeros, NaN,
    values of very different size, and no whole block at all."""
    rng = np.random.default_rng(17)
    for c in (1, 2, 3, 6):
        for b, nb in ((1, 50), (2, 40), (7, 30), (128, 512), (128, 100), (1024, 64), (3, 0)):
            a = (rng.standard_normal((nb * b, c)) * 10.0 ** rng.uniform(-12, 3, (nb * b, 1))
                 + 9.80665)
            if nb:
                a[rng.integers(0, nb * b, 5)] = -0.0
                a[rng.integers(0, nb * b), 0] = np.nan
                a[:b] = -0.0  # a block of negative zeros: numpy's mean gives +0.0
            for x in (a, np.asfortranarray(a)):  # rows in order, and columns in order
                want = x.reshape(nb, b, c).mean(axis=1)
                got = slow_block_means(x, b)
                assert got.shape == want.shape and got.tobytes() == want.tobytes(), (c, b, nb)
