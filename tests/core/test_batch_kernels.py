"""The batch estimator's compiled path (one float64 channel, fully overlapping Allan and
Hadamard: ``deviations._compiled_sums``) against its numpy path (``grid_sums``), and the
deferred R(n) against R(n) summed at every τ of B1's range."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan import kernels
from avard.core.allan.deviations import allan_variance, rn_sums_for


@pytest.mark.parametrize("kind", ["oavar", "ohvar"])
def test_compiled_batch_sums_equal_numpys(kind: str) -> None:
    if kernels.compiled() is None:
        pytest.skip("the compiled kernels are not built here")
    rng = np.random.default_rng(2)
    y = rng.standard_normal(50_000) + np.cumsum(rng.standard_normal(50_000)) * 1e-2
    taus = [1, 2, 3, 7, 100, 1000, 12_000, 16_000]
    fast = allan_variance(y, 1.0, taus, kind=kind, gaps=[20_000])
    try:
        kernels.use_compiled(False)
        slow = allan_variance(y, 1.0, taus, kind=kind, gaps=[20_000])
    finally:
        kernels.use_compiled(True)
    np.testing.assert_array_equal(fast.n, slow.n)
    np.testing.assert_allclose(fast.var, slow.var, rtol=1e-12)
    np.testing.assert_array_equal(fast.alpha, slow.alpha)
    np.testing.assert_allclose(fast.edf, slow.edf, rtol=1e-12)


def test_deferred_rn_gives_the_alpha_of_rn_everywhere() -> None:
    """White PM (the phase white: B1 says PM in its range) and white FM records: the α of every
    τ of B1's range equals the one computed with R(n) summed at all of them."""
    from avard.core.allan.deviations import (
        DifferenceSums,
        finish_result,
        grid_sums,
        segment_phase,
    )
    from avard.core.allan.noise_id import Lag1Ladder

    rng = np.random.default_rng(6)
    for y in (np.diff(rng.standard_normal(6_001)), rng.standard_normal(6_000)):
        ms = np.array([250, 300, 400, 500, 700, 1000, 1400], dtype=np.int64)
        # the power-law rule (phase data's): the default reads rate data, where no PM type is
        # possible on float samples and R(n) is never read
        got = allan_variance(y, 1.0, ms.astype(float), kind="oavar", noise_id="powerlaw")
        assert np.any(got.alpha >= 1)  # B1 says PM somewhere: R(n) is read
        # the former way: R(n) at every τ of B1's range
        p = segment_phase(y[:, None], False)
        sums = [DifferenceSums.zeros(1) for _ in ms]
        ladders = [Lag1Ladder(1, dmax=2, cross=False) for _ in ms]
        rn = rn_sums_for("oavar", ms, [y.size], 1)
        assert all(r is not None for r in rn)
        for k, m in enumerate(ms.tolist()):
            grid_sums(p, m, 0, sums[k], 2)
            ladders[k].push((np.diff(p[::m], axis=0) + m * y[0]).astype(np.float64))
            ladders[k].gap()
            rn[k].push((p[2 * m:] - 2 * p[m:-m] + p[:-2 * m]).T.astype(np.float64))
            rn[k].gap()
        want = finish_result("oavar", 1.0, ms, np.ones_like(ms), sums, ladders, one_d=True,
                             rn=rn, noise_id="powerlaw")
        np.testing.assert_array_equal(got.alpha, want.alpha)
