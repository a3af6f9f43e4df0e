"""analyze's rate ramp R and random walk K on the adversary's drift records (issue 24,
docs/log/analysis.md "R and K on the adversary's drift records (drift24)"). Records from
tests/support/adversary_gen.py, written apart from avard: white + flicker + a walk
K = 1.5e-6 m/s²·√s on x, 4 h, with (factor 3) or without (factor 0) a linear drift; the
noise of one seed is the same with and without the drift."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.deviations import allan_variance
from avard.core.analysis.drift import mean_difference
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.io.source import open_record

from tests.support.adversary_gen import make_record


def _x(tmp_path, seed: int, factor: float):
    p = tmp_path / f"drift_{seed}_{factor:g}.npz"
    truth = make_record("drift", seed, p, None, factor)
    ch = analyze(open_record(p), AnalyzeOptions(channels=("x",))).channels["x"]
    return ch, truth


def test_the_mean_allan_difference_from_block_means_equals_the_samples_one():
    """D(τ), the mean of the overlapping differences of τ-averages, from block means (the
    record read as piecewise constant) against the samples' own at every τ a block or more."""
    rng = np.random.default_rng(5)
    y = np.cumsum(rng.normal(size=8192)) * 0.01 + 0.002 * np.arange(8192)
    b = 32
    yb = y.reshape(-1, b).mean(axis=1)
    for m in (32, 128, 640, 2048):
        c = np.concatenate([[0.0], np.cumsum(y)])
        avg = (c[m:] - c[:-m]) / m
        d = float(np.mean(avg[m:] - avg[:-m]))
        got = float(mean_difference(yb, float(b), np.array([float(m)]))[0])
        assert got == pytest.approx(d, rel=2e-3, abs=1e-3 * abs(m * 0.002))
    # and the AVAR of the record less a line is the AVAR less R̂τ·D − R̂²τ²/2, exactly with
    # the samples' own D (the algebra resolve_drift uses), within 1 % with the block form
    # from a block on (far inside the estimates' own scatter: a few dozen averages there)
    r = 0.002
    res = allan_variance(y, 1.0)
    tau, m = np.asarray(res.tau, dtype=float), np.asarray(res.m, dtype=int)
    det = np.asarray(allan_variance(y - r * np.arange(len(y)), 1.0).var)
    c = np.concatenate([[0.0], np.cumsum(y)])
    exact = np.array([np.mean((c[2 * k:] - 2 * c[k:-k] + c[: -2 * k]) / k) for k in m])
    want = np.asarray(res.var) - (r * tau * exact - r * r * tau**2 / 2)
    assert np.allclose(det, want, rtol=1e-9)
    approx = np.asarray(res.var) - (r * tau * mean_difference(yb, float(b), tau)
                                    - r * r * tau**2 / 2)
    sel = (m >= b) & np.isfinite(approx)  # (NaN where 2τ ≥ T: no difference fits)
    assert sel.sum() >= 6
    assert np.allclose(det[sel], approx[sel], rtol=1e-2)


@pytest.mark.parametrize("seed", [305])
def test_no_ramp_is_claimed_where_the_time_domain_finds_no_drift(tmp_path, seed):
    """Without a drift, a walk's realisation that curves like τ² at the longest τ made the
    AVAR fit claim R (seed 305: R 3.2e-8 [2.6e-8, 3.8e-8] m/s³ present, K absent) where the
    block means found no drift. R is now absent, with an upper limit, and the rise is K's."""
    ch, _ = _x(tmp_path, seed, 0.0)
    r = ch.fit.terms["rate_ramp"]
    assert not r.present and r.value is None
    assert r.upper is not None and r.upper > 0
    assert ch.to_dict()["drift"]["rate_ramp_from"] is None


@pytest.mark.parametrize("seed", [300, 302])
def test_k_beside_a_resolved_ramp_is_the_k_of_the_same_noise_without_it(tmp_path, seed):
    """The same noise with and without a 3×-minimum ramp: the ramp is resolved from the time
    domain and holds the truth, and K beside it is the K the record gives without the ramp
    (the AVAR less the fitted line). Before, the ramp × walk cross term was left in the AVAR:
    seed 300 gave K 2.03e-6 [1.79e-6, 2.24e-6] beside the ramp, 1.46e-6 without it, and
    seed 302 2.32e-6 against 1.51e-6; the generator's K is 1.5e-6."""
    ch0, _ = _x(tmp_path, seed, 0.0)
    ch3, truth = _x(tmp_path, seed, 3.0)
    r = ch3.fit.terms["rate_ramp"]
    assert r.present and "rate_ramp" in ch3.fit.resolved_apart
    assert r.lo is not None and r.hi is not None
    assert r.lo <= truth["axes"]["x"]["rate_mps3"] <= r.hi
    k0, k3 = ch0.fit.terms["rate_random_walk"], ch3.fit.terms["rate_random_walk"]
    assert k0.present and k3.present and k0.value and k3.value
    assert abs(k3.value / k0.value - 1.0) < 0.1, (k0, k3)
    assert k3.lo is not None and k3.hi is not None
    assert k3.lo <= 1.5e-6 <= k3.hi


@pytest.mark.parametrize("seed", [332, 333])
def test_k_beside_a_resolved_ramp_where_the_refit_finds_none_is_the_walks_own(tmp_path, seed):
    """Where the AVAR refit beside the ramp finds no K, the time domain's K stands. Its
    ordinary profile beside the fitted slope lost the walk's linear part to the slope (seed
    332: 1.18e-6 [0.76e-6, 1.49e-6], 333: 1.07e-6 [0.42e-6, 1.45e-6], the generator's
    1.5e-6 above both); K's restricted likelihood, B profiled under the AVAR fit's B,
    gives the walk's own, its range either side of it its own."""
    ch3, _ = _x(tmp_path, seed, 3.0)
    assert "rate_ramp" in ch3.fit.resolved_apart
    k3 = ch3.fit.terms["rate_random_walk"]
    assert k3.present and k3.value is not None and k3.lo is not None and k3.hi is not None
    assert 0 < k3.lo < k3.value < k3.hi
    assert k3.lo <= 1.5e-6 <= k3.hi
