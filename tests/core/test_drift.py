"""The time-domain drift test analyze and explain share (core/analysis/drift.py, issues 23
and 24): calibrated on records with no drift, and its adversaries (a pure random walk, a
drift beside a walk of similar size, a drift across a gap, a step that looks like a drift).
Records from tests/support/coverage_gen.py, the generator written apart from avard."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from avard.core.allan.deviations import allan_variance
from avard.core.analysis import drift as dr
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.io.source import RecordFormat, RecordInfo, StreamSource
from avard.core.model.fit import fit_noise
from avard.core.model.terms import TERMS

from benchmarks.bench_coverage import mix_for
from tests.support.coverage_gen import Mix, record

N_12H = 43200  # 12 h at 1 Hz


def _lik(y: np.ndarray, rate: float = 1.0) -> dr.DriftLikelihood:
    b = dr.drift_block(len(y))
    yb = y[: len(y) // b * b].reshape(-1, b).mean(axis=1)
    lik = dr.channel_drift(fit_noise(allan_variance(y, rate)), yb, b / rate)
    assert lik is not None
    return lik


def test_no_drift_gives_z_of_unit_spread_and_no_claim_past_the_level():
    """12 h of white + flicker + random walk whose walk meets the flicker floor at a
    fifteenth of the record: the AVAR fit finds no K on most of them, and a slope tested
    against the noise it does find spread 2.4× too wide (13 % past the 0.1 % level). With
    K profiled past the fit's upper K, z is N(0, 1)."""
    mix = mix_for("plain", N_12H, 1.0)
    rng = np.random.default_rng(2401)
    z = np.array([_lik(record(mix, N_12H, rng)[0]).z for _ in range(30)])
    assert 0.7 <= z.std() <= 1.35, z
    assert abs(z.mean()) < 0.6, z
    assert np.max(np.abs(z)) < dr.two_sided_z(1e-3), z


def test_a_pure_random_walk_is_not_a_drift():
    """A strong walk (the record's wander is all walk) and white noise: no drift."""
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(10):
        y = rng.normal(size=N_12H) + np.cumsum(rng.normal(scale=0.02, size=N_12H))
        lik = _lik(y)
        hits += lik.passes(dr.two_sided_z(dr.LEVEL))
        assert not lik.at_edge, lik
    assert hits == 0


def test_a_drift_beside_a_walk_of_similar_size_is_found_and_its_interval_holds_it():
    """The drift moves the rate by as much over the record as the walk's standard
    deviation over the record (the AVAR cannot tell them apart); the slope's profile
    interval holds it in about 68 % of records."""
    rng = np.random.default_rng(11)
    q = 0.01
    slope = 6.0 * q / math.sqrt(N_12H)  # ≈ 5.5 σ of the walk's own OLS slope
    held = found = 0
    for _ in range(12):
        y = rng.normal(size=N_12H) + np.cumsum(rng.normal(scale=q, size=N_12H))
        lik = _lik(y + slope * np.arange(N_12H))
        found += lik.passes(dr.two_sided_z(dr.LEVEL))
        held += lik.slope_lo <= slope <= lik.slope_hi
    assert found >= 9
    assert 5 <= held <= 12


@pytest.mark.parametrize("size", [0.3, 3.0, 10.0])
def test_a_step_that_looks_like_a_drift_is_not_one(size):
    """A level step has a least-squares slope too (at 10, 40 times the record's white σ
    over a block); the walk K profiled in the likelihood takes it (a walk makes steps), and
    the slope against it stays below the level. (One line per half, the second guard,
    would refute it if it passed.)"""
    mix = mix_for("plain", N_12H, 1.0)
    for at in (0.3, 0.5):
        y, _ = record(mix, N_12H, np.random.default_rng(6))
        y = y + np.where(np.arange(N_12H) >= int(N_12H * at), size, 0.0)
        lik = _lik(y)
        assert not lik.passes(dr.two_sided_z(dr.LEVEL)), (at, lik)
        assert lik.k_walk > 0.5 * math.sqrt(mix.q2)


def test_block_means_keep_the_longest_stretch_between_gaps():
    bm = dr.BlockMeans(2, 4)
    bm.update(np.ones((10, 2)))  # two blocks and a rest of 2
    bm.gap()
    bm.update(np.arange(26.0).reshape(13, 2))  # three blocks
    assert bm.longest().shape == (3, 2)
    np.testing.assert_allclose(bm.longest()[0], [3.0, 4.0])
    bm.gap()
    bm.update(np.zeros((4, 2)))
    assert bm.longest().shape == (3, 2)
    # any cut of the stream into pieces gives the one-shot means
    y = np.random.default_rng(0).normal(size=(10007, 2))
    for size in (1, 7, 1000, 20000):
        bm, i = dr.BlockMeans(2, size), 0
        for step in (3, 500, 17, 4096, 1, 2000):
            bm.update(y[i:i + step])
            i += step
        bm.update(y[i:])
        n = len(y) // size * size
        np.testing.assert_allclose(bm.longest(), y[:n].reshape(-1, size, 2).mean(axis=1),
                                   rtol=1e-12)


def _analyze(y: np.ndarray, rate: float, gap_at: int | None = None):
    info = RecordInfo(source="drift", format=RecordFormat.STREAM, rate_hz=rate,
                      names=("x",), n_samples=len(y))
    cut = [0, len(y)] if gap_at is None else [0, gap_at, len(y)]
    blocks = [(y[a:b, None], None, b != len(y)) for a, b in itertools.pairwise(cut)]
    return analyze(StreamSource(info, blocks), AnalyzeOptions()).channels["x"]


@pytest.mark.parametrize("gap_at", [None, 9000])
def test_analyze_resolves_a_found_drift_as_a_ramp_with_k_refitted_without_it(gap_at):
    """12 h, a drift 12 σ of its slope beside the benchmark's walk: the AVAR fit alone
    reads it as "ramp or random walk"; analyze claims the ramp from the time domain, its
    interval holds the truth within two half-widths, and the walk refitted without it is
    below what the drift made of it and holds the generator's (the time domain's K range
    beside the drift where the AVAR refit finds none). Across a gap the longest stretch is
    tested."""
    mix = mix_for("plain", N_12H, 1.0)
    rng = np.random.default_rng(3)
    y, _ = record(mix, N_12H, rng)
    slope = 4 * mix_for("drift", N_12H, 1.0).drift
    y = y + slope * np.arange(N_12H)
    ch = _analyze(y, 1.0, gap_at)
    r = ch.fit.terms["rate_ramp"]
    assert r.present and r.note is None
    assert ch.to_dict()["drift"]["rate_ramp_from"] == "time_domain"   # said in the JSON
    from avard.core.analysis.formats import format_table
    from avard.core.analysis.results import Analysis

    text = format_table(Analysis("drift", 1.0, len(y), {"x": ch}))     # and in the table
    assert "R from the time domain" in text
    assert r.lo is not None and r.hi is not None and r.value is not None
    half = 0.5 * (r.hi - r.lo)
    assert r.lo - half <= slope <= r.hi + half, (r, slope)
    no_ramp = fit_noise(ch.allan, terms=[t for t in TERMS if t != "rate_ramp"])
    k0 = no_ramp.terms["rate_random_walk"].value
    k = ch.fit.terms["rate_random_walk"]
    assert k0 is not None and k.value is not None and k.value < 0.75 * k0
    assert k.lo is not None and k.hi is not None and k.lo < k.value < k.hi
    # (whether a 68 % interval holds the generator's walk is a share of records, not one
    # record's: test_k_beside_a_resolved_ramp_holds_the_walk_as_often_as_it_claims)


@pytest.mark.slow
def test_k_beside_a_resolved_ramp_holds_the_walk_as_often_as_it_claims():
    """The records of the test above, 24 seeds: where the ramp is resolved, K's 68 %
    interval beside it holds the generator's walk in a share within a 68.3 % interval's
    binomial 99 % range, and K is not biased (its median within 15 % of the walk's)."""
    held, ratio = [], []
    for seed in range(24):
        mix = mix_for("plain", N_12H, 1.0)
        y, _ = record(mix, N_12H, np.random.default_rng(seed))
        ch = _analyze(y + 4 * mix_for("drift", N_12H, 1.0).drift * np.arange(N_12H), 1.0)
        if "rate_ramp" not in ch.fit.resolved_apart:
            continue
        k, truth = ch.fit.terms["rate_random_walk"], math.sqrt(mix.q2)
        assert k.value is not None and k.lo is not None and k.hi is not None
        held.append(k.lo <= truth <= k.hi)
        ratio.append(k.value / truth)
    n, p = len(held), 0.683
    assert n >= 20
    spread = 2.58 * math.sqrt(n * p * (1 - p))
    assert n * p - spread <= sum(held) <= n * p + spread, (sum(held), n)
    assert 0.85 <= float(np.median(ratio)) <= 1.15, ratio


def test_analyze_claims_no_drift_on_a_record_without_one():
    mix = Mix(s2=1.0, h=0.02, q2=1e-5)
    y, _ = record(mix, N_12H, np.random.default_rng(9))
    ch = _analyze(y, 1.0)
    assert not ch.fit.terms["rate_ramp"].present or ch.fit.terms["rate_ramp"].note is not None


def test_a_parallel_analysis_keeps_the_block_means_in_its_chunks_and_finds_the_same_drift(
        tmp_path, monkeypatch):
    """A parallel pass's chunks keep the block sums of the rows they own (``BlockSums``),
    so no channel is read again for the drift test (that read would be the parallel
    analysis's serial end): the same ramp and walk as one pass's."""
    from avard.core.analysis import engine
    from avard.core.io.source import open_record

    mix = mix_for("plain", N_12H, 1.0)
    y, _ = record(mix, N_12H, np.random.default_rng(3))
    y = y + 4 * mix_for("drift", N_12H, 1.0).drift * np.arange(N_12H)
    path = tmp_path / "d.npz"
    np.savez(path, accel=y[:, None], rate_hz=1.0, axes=np.array(["x"]))
    one = analyze(open_record(path), AnalyzeOptions()).channels["x"].fit

    def no_reread(*_a, **_k):
        raise AssertionError("the parallel analysis built block means of its own")

    monkeypatch.setattr(engine, "BlockMeans", no_reread)
    par = analyze(open_record(path), AnalyzeOptions(workers=2)).channels["x"].fit
    assert one.resolved_apart == par.resolved_apart == ("rate_ramp",)
    for term in ("rate_ramp", "rate_random_walk"):
        a, b = one.terms[term], par.terms[term]
        assert a.value is not None and b.value == pytest.approx(a.value, rel=1e-9)


@pytest.mark.parametrize("cols", [1, 2, 4])
def test_the_k_profile_at_every_k_at_once_equals_one_fit_per_k(cols):
    """``_Profile.k_profile`` solves every K's normal equations at once; each −2 ln L must
    equal the per-K least-squares fit (``_Profile.fit``), the general path it replaces."""
    rng = np.random.default_rng(cols)
    n, bs = 200, 600.0
    t = (np.arange(n) + 0.5) * bs
    y = rng.normal(0, 1e-5, n) + np.cumsum(rng.normal(0, 3e-7, n))
    prof = dr._Profile(y, t, bs, 2e-4, 1e-5)
    x = np.column_stack([np.ones(n), t - t.mean(), (t > t[n // 3]).astype(float),
                         np.sin(t / 3e4)][:cols])
    wx = prof.white(x)
    ks = np.concatenate([[0.0], np.geomspace(1e-10, 1e-5, 40)])
    j, nll = prof.k_profile(ks, wx)
    each = np.array([prof.fit(float(k), wx)[0] for k in ks])
    np.testing.assert_allclose(nll, each, rtol=1e-10, atol=1e-8)
    assert j == int(np.argmin(each))


@pytest.mark.parametrize("seed", range(6))
def test_block_sums_of_chunks_add_up_to_one_passs_block_means(seed):
    """A parallel pass's chunks each keep the block sums of the rows they own
    (``BlockSums``), fed from the record's start in pieces of any size, with gaps; added
    up they give what ``BlockMeans`` over the whole record gives: the same blocks of the
    same (longest) stretch, equal to rounding where a cut splits a block, and the means
    taken directly from the rows."""
    rng = np.random.default_rng(seed)
    n, c = int(rng.integers(3000, 9000)), int(rng.integers(1, 4))
    y = rng.normal(0, 1, (n, c)) + 5.0
    gaps = sorted(int(g) for g in rng.integers(1, n - 1, int(rng.integers(0, 3))))
    edges = sorted({0, n, *gaps, *(int(p) for p in rng.integers(1, n - 1, 12))})
    b = int(rng.integers(7, 90))

    def feed(acc):
        for lo, hi in itertools.pairwise(edges):
            acc.update(y[lo:hi])
            if hi in gaps:
                acc.gap()
        return acc

    one = feed(dr.BlockMeans(c, b)).longest()
    cuts = sorted({0, n, *(int(p) for p in rng.integers(1, n - 1, int(rng.integers(1, 4))))})
    parts = [feed(dr.BlockSums(c, b, lo, None if hi == n else hi)).part()
             for lo, hi in itertools.pairwise(cuts)]
    total = parts[0]
    for p in parts[1:]:
        total = total + p
    got = total.longest()
    assert got.shape == one.shape and len(one) > 0
    np.testing.assert_allclose(got, one, rtol=1e-13, atol=0)
    # and both are the longest stretch's block means (the first of equal ones), directly
    starts, ends = [0, *gaps], [*gaps, n]
    whole = [(e - s) // b for s, e in zip(starts, ends, strict=True)]
    s0, k = starts[whole.index(max(whole))], max(whole)
    np.testing.assert_allclose(one, y[s0:s0 + k * b].reshape(-1, b, c).mean(axis=1),
                               rtol=1e-12)


@pytest.mark.parametrize(("seed", "floored"), [(2453, True), (2473, False)])
def test_a_drift_short_of_the_level_is_no_claim_but_its_floor_holds_part_of_the_avar(
        seed, floored):
    """The benchmark's 12 h drift is about 2.6 standard errors of its slope against the walk
    (against a walk of known K, exactly √(20/3): no test at the 1 % level finds it in more
    than about half the records). Where the test falls short of its level (seed 2453, z
    2.1) no ramp is claimed: the terms are the AVAR fit's, the walk the fit read. But the
    slope's 68 % interval is clear of zero, so the fit carries its near end
    (``drift_floor``): that much of the AVAR does not scatter, and the printed EDF at the
    longest τ rises above the noise's, within the record's support, never below the
    estimator's. Where the interval holds zero (seed 2473, z 0.75) nothing is carried and the
    printed EDF is the noise's. (Seeds 2401 and 2406 were these two cases until the fit found
    the random walk their AVAR misfit without, χ²/dof 4.9 on 2401; with it in the model the
    floor is a small share of the longest τ's AVAR there (EDF 3.48 with and without it), and
    2406 now carries a floor.)"""
    from avard.core.analysis.signal_edf import with_signal_edf

    from tests.core.test_noise_id_rate import support

    mix = mix_for("drift", N_12H, 1.0)
    y, _ = record(mix, N_12H, np.random.default_rng(seed))
    lik = _lik(y)
    assert not lik.passes(dr.two_sided_z(dr.LEVEL))
    ch = _analyze(y, 1.0)
    assert not ch.fit.resolved_apart
    assert not ch.fit.terms["rate_ramp"].present or ch.fit.terms["rate_ramp"].note
    assert (ch.fit.drift_floor > 0) is floored
    said = ch.to_dict()["drift"]                               # and in the JSON
    assert said["rate_ramp_from"] != "time_domain"
    assert said["floor"] == ch.fit.drift_floor and said["unit"] == "m/s^3"
    if floored:
        lo, hi = sorted((abs(lik.slope_lo), abs(lik.slope_hi)))
        assert ch.fit.drift_floor == pytest.approx(lo, rel=0.05) and lo < abs(lik.slope) < hi
    est = allan_variance(y, 1.0).edf[:len(ch.allan.tau)]
    noise = with_signal_edf(replace(ch.allan, edf=est), replace(ch.fit, drift_floor=0.0))
    ok = np.isfinite(ch.allan.edf)
    assert np.all(ch.allan.edf[ok] >= est[ok] * (1 - 1e-12))
    assert np.all(ch.allan.edf[ok] <= support(ch.allan)[ok] * (1 + 1e-12))
    if floored:
        assert ch.allan.edf[-1] > 1.1 * noise.edf[-1]
        np.testing.assert_allclose(ch.allan.edf[:6], noise.edf[:6], rtol=1e-9)
    else:
        np.testing.assert_array_equal(ch.allan.edf, noise.edf)


def test_the_floor_is_the_intervals_near_end_and_nothing_where_the_test_cannot_speak():
    base = dict(z=1.8, slope=2.0, k_walk=1.0, k_drift=0.5, k_drift_hi=0.8, k_top=10.0,
                halves_gain=0.0, blocks=256, record_s=1.0)
    assert dr.DriftLikelihood(slope_lo=1.0, slope_hi=3.0, **base).floor == 1.0
    assert dr.DriftLikelihood(slope_lo=-3.0, slope_hi=-1.5,
                              **{**base, "slope": -2.0}).floor == 1.5
    assert dr.DriftLikelihood(slope_lo=-0.1, slope_hi=3.0, **base).floor == 0.0
    step = {**base, "halves_gain": 20.0}
    assert dr.DriftLikelihood(slope_lo=1.0, slope_hi=3.0, **step).floor == 0.0
    edge = {**base, "k_walk": 10.0}
    assert dr.DriftLikelihood(slope_lo=1.0, slope_hi=3.0, **edge).floor == 0.0


def test_the_block_means_covariance_is_the_exact_average_of_the_point_covariance():
    """``block_noise_cov`` (the one covariance of the drift test, the slow search and
    explain's transients) against brute force: the point covariance of each process on a
    fine grid, averaged over every pair of blocks (A Σ Aᵀ). The walk's diagonal is
    K²(t − b/6), not K²t, and each flicker member is block-averaged: the point form the
    drift test used before differed by K²b/6 on the diagonal and in the flicker's variance."""
    from avard.core.sim.noise_gen import flicker_ladder

    blocks, per, block_s = 10, 160, 10.0
    s = (np.arange(blocks * per) + 0.5) * (block_s / per)  # fine points, midpoints of cells
    avg = np.kron(np.eye(blocks), np.full((1, per), 1.0 / per))  # the block-mean operator
    t = (np.arange(blocks) + 0.5) * block_s
    k = 0.3
    walk = avg @ (k * k * np.minimum.outer(s, s)) @ avg.T
    got = dr.block_noise_cov(t, block_s, 0.0, 0.0, k)
    assert np.allclose(got, walk, rtol=1e-4, atol=0.0)  # (the grid's midpoint rule)
    assert not np.allclose(np.diag(got), k * k * t, rtol=1e-3)  # the point form's diagonal
    b_inst = 2e-3
    lag = np.abs(np.subtract.outer(s, s))
    flick = np.zeros((len(s), len(s)))
    for T, sd in flicker_ladder([b_inst], block_s / dr.FLICKER_BELOW,
                                10 * float(t[-1] + block_s), 2.0):
        flick += float(np.asarray(sd)[0]) ** 2 * np.exp(-lag / T)
    assert np.allclose(dr.block_noise_cov(t, block_s, 0.0, b_inst, 0.0), avg @ flick @ avg.T,
                       rtol=1e-3, atol=0.0)


def _model_means(blocks: int, block_s: float, n_w: float, b_i: float, k: float,
                 rng: np.random.Generator) -> np.ndarray:
    t = (np.arange(blocks) + 0.5) * block_s
    chol = np.linalg.cholesky(dr.block_noise_cov(t, block_s, n_w, b_i, k))
    return chol @ rng.normal(size=blocks)


def test_the_bartlett_factor_divides_the_likelihood_ratio_by_the_tables_value():
    """z² · β is the raw likelihood ratio of the slope (K profiled), and β is the table's at
    the walk's directions at the offset-only K: never below 1, above it where the walk
    holds a few directions."""
    from benchmarks.bench_drift_null import _truth

    n_w, b_i, k, block_s, blocks = _truth(12)
    yb = _model_means(blocks, block_s, n_w, b_i, k, np.random.default_rng(5))
    t = (np.arange(blocks) + 0.5) * block_s
    lik = dr.drift_likelihood(yb, t, block_s, n_w, b_i, 2 * k)
    prof = dr._Profile(yb, t, block_s, n_w, b_i)
    top = dr.K_SPAN * max(2 * k, n_w / (blocks * block_s))
    ks = np.concatenate([[0.0], np.geomspace(top * 10.0**-dr.K_DECADES, top, dr.K_POINTS)])
    w0 = prof.white(np.ones((blocks, 1)))
    i, h0 = prof.best(ks, w0)
    _j, h1 = prof.best(ks, np.column_stack([w0, prof.white(t - t.mean())]))
    assert lik.walk_dof == pytest.approx(dr.walk_directions(prof.lam, float(ks[i])))
    assert lik.bartlett == pytest.approx(dr.bartlett(lik.walk_dof))
    assert lik.z**2 * lik.bartlett == pytest.approx(h0 - h1, rel=1e-9, abs=1e-12)
    assert all(dr.bartlett(v) >= 1.0 for v in (0.0, 0.5, 3.0, 10.0, 1e4))
    assert dr.bartlett(4.6) > 1.3  # a few walk directions: the ratio's tail is t-like
    assert dr.bartlett(0.0) == 1.0  # no walk: χ²(1) (the ratio is below it there)


def test_ks_restricted_profile_beside_a_slope_is_unbiased_and_its_range_holds_k():
    """On block means drawn from the model itself (white, flicker and a walk at known N, B,
    K, plus a slope; 4 h in 256 blocks, the adversary's drift class), K's ordinary profile
    beside the fitted slope comes out low (the slope takes the walk's own linear part);
    its restricted likelihood (``walk_beside_slope``'s) does not, and its Δ(−2 ln L) ≤ 1
    range holds the true K as often as a 68 % interval should (60–76 % of 200 draws)."""
    rng = np.random.default_rng(5)
    nb, bs = 256, 14400 / 256
    n_w, b_i, k = 1.6e-4, 2e-5, 1.5e-6
    t = (np.arange(nb) + 0.5) * bs
    chol = np.linalg.cholesky(dr.block_noise_cov(t, bs, n_w, b_i, k))
    top = dr.K_SPAN * k
    ks = np.concatenate([[0.0], np.geomspace(top * 1e-4, top, dr.K_POINTS)])
    prof = dr._Profile(np.zeros(nb), t, bs, n_w, b_i)
    w1 = np.column_stack([prof.white(np.ones(nb)), prof.white(t - t.mean())])
    held, ln_reml, ln_ml = 0, [], []
    for _ in range(200):
        prof.wy = prof.white(chol @ rng.standard_normal(nb) + 2e-7 * t)
        j, _nll = prof.k_profile(ks, w1)
        best, lo, hi = dr._reml_range(ks, prof.k_profile_reml(ks, w1))
        held += lo <= k <= hi
        ln_reml.append(math.log(best / k))
        ln_ml.append(math.log(max(float(ks[j]), 1e-3 * k) / k))
    assert 0.60 <= held / 200 <= 0.76, held
    assert abs(np.mean(ln_reml)) < 0.1, np.mean(ln_reml)
    assert np.mean(ln_ml) < np.mean(ln_reml) - 0.08, (np.mean(ln_ml), np.mean(ln_reml))


@pytest.mark.slow
def test_the_level_holds_on_means_drawn_from_the_noise_where_the_walk_holds_few_directions():
    """Block means drawn from the covariance itself at the 12 h geometry, the walk at the
    benchmark's level (it holds about five directions, where the likelihood ratio's 1 % point
    is 1.4 times χ²(1)'s): read as χ²(1) the test passes about 3 % of them; with the Bartlett
    factor it stays within a 1 % test's binomial range."""
    from benchmarks.bench_drift_null import _binomial_99, _truth

    n_w, b_i, k, block_s, blocks = _truth(12)
    t = (np.arange(blocks) + 0.5) * block_s
    chol = np.linalg.cholesky(dr.block_noise_cov(t, block_s, n_w, b_i, k))
    rng = np.random.default_rng(2026)
    thr, draws = dr.two_sided_z(dr.LEVEL), 300
    corrected = raw = 0
    for _ in range(draws):
        lik = dr.drift_likelihood(chol @ rng.normal(size=blocks), t, block_s, n_w, b_i, 2 * k)
        corrected += abs(lik.z) >= thr
        raw += abs(lik.z) * math.sqrt(lik.bartlett) >= thr
    assert corrected <= _binomial_99(draws, dr.LEVEL)[1], (corrected, raw)
    assert raw >= corrected


@pytest.mark.slow
def test_the_false_rate_on_plain_12h_records_is_within_a_1_percent_tests_range():
    """200 plain 12 h records of the generator written apart (white + flicker + random walk,
    the walk meeting the flicker floor at a fifteenth of the record: the few-directions case
    the Bartlett factor is for). With the block means' covariance and no factor 4.4 % of 800
    such records passed (docs/log/analysis.md); the test must stay within a 1 % test's
    binomial 99 % range."""
    from benchmarks.bench_drift_null import _binomial_99

    mix = mix_for("plain", N_12H, 1.0)
    rng = np.random.default_rng(2412)
    thr, n = dr.two_sided_z(dr.LEVEL), 200
    passed = sum(_lik(record(mix, N_12H, rng)[0]).passes(thr) for _ in range(n))
    assert passed <= _binomial_99(n, dr.LEVEL)[1], passed


def test_the_model_slope_variance_is_the_gls_slopes_under_the_fitted_noise():
    """``model_slope_var``: the variance of the GLS slope of the block means (offset beside
    it) under the fit's N, B and K. White alone: N²/block over Σ(t − t̄)², in closed form;
    white, flicker and walk: the spread of the GLS slope over means drawn from that
    covariance; a larger walk, a larger variance. A fit without white N: NaN."""
    from avard.core.model.fit import Component, NoiseFit, TermEstimate  # noqa: F401

    blocks, block_s, n_w, b_i, k = 96, 40.0, 2e-3, 3e-4, 2e-6
    means = np.zeros(blocks)
    t = (np.arange(blocks) + 0.5) * block_s

    def fit_with(n: float, b: float, kk: float):
        y = np.random.default_rng(1).standard_normal(20000) * 1e-3
        fit = fit_noise(allan_variance(y, 1.0))
        terms = dict(fit.terms)
        for name, v in (("velocity_random_walk", n), ("bias_instability", b),
                        ("rate_random_walk", kk)):
            terms[name] = replace(terms[name], value=v or None, present=v > 0)
        j = next(i for i, c in enumerate(fit.components) if c.cause == "rate_random_walk")
        theta = np.array(fit.theta, dtype=float)
        theta[j] = kk * kk
        return replace(fit, terms=terms, theta=theta)

    white = dr.model_slope_var(fit_with(n_w, 0.0, 0.0), means, block_s)
    np.testing.assert_allclose(white, n_w**2 / block_s / np.sum((t - t.mean()) ** 2),
                               rtol=1e-9)
    full = dr.model_slope_var(fit_with(n_w, b_i, k), means, block_s)
    chol = np.linalg.cholesky(dr.block_noise_cov(t, block_s, n_w, b_i, k))
    rng = np.random.default_rng(11)
    ci = np.linalg.inv(dr.block_noise_cov(t, block_s, n_w, b_i, k))
    x = np.column_stack([np.ones(blocks), t - t.mean()])
    gls = np.linalg.solve(x.T @ ci @ x, x.T @ ci)[1]
    slopes = gls @ (chol @ rng.standard_normal((blocks, 4000)))
    assert abs(np.var(slopes) / full - 1.0) < 4 * math.sqrt(2 / 4000)
    assert full > dr.model_slope_var(fit_with(n_w, b_i, k / 4), means, block_s) > white
    assert math.isnan(dr.model_slope_var(fit_with(0.0, b_i, k), means, block_s))
