"""The printed OADEV's EDF where the fit's deterministic terms hold part of the AVAR (issue 24,
core/analysis/signal_edf.py): the noise part's scatter (within the record's support) plus the
exact cross term of the terms the fit resolves (core/analysis/cross_term.py); the
non-central χ² moment match for the strided estimators; noise alone unchanged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from avard.core.allan.deviations import AllanResult, allan_variance
from avard.core.allan.edf import (
    chi2_interval,
    edf_greenhall,
    edf_mixture_bound,
    edf_with_signal,
)
from avard.core.allan.noise_id import SPREAD_LAG1
from avard.core.analysis.cross_term import cross_term_variance
from avard.core.analysis.engine import analyze
from avard.core.analysis.results import ChannelAnalysis
from avard.core.analysis.signal_edf import (
    noise_part_edf,
    parts_edf,
    signal_share,
    unresolved_noise_edf,
    with_signal_edf,
)
from avard.core.io.source import RecordFormat, RecordInfo, StreamSource
from avard.core.model.fit import fit_noise

from tests.core.test_noise_id_rate import support
from tests.support.coverage_gen import Mix, flicker, record

RATE = 10.0
N = 36000  # 1 h at 10 Hz


def _analyze(y: np.ndarray) -> ChannelAnalysis:
    info = RecordInfo(source="test", format=RecordFormat.STREAM, rate_hz=RATE, names=("x",),
                      n_samples=len(y))
    return analyze(StreamSource(info, iter([(y[:, None], None, False)]))).channels["x"]


def _record(drift: float, seed: int = 3, q2: float = 0.0) -> np.ndarray:
    return record(Mix(1.0, 0.02, q2, drift=drift), N, np.random.default_rng(seed))[0]


@pytest.mark.parametrize("nu", [1.5, 4.0, 30.0])
@pytest.mark.parametrize("f", [0.0, 0.3, 0.8])
def test_edf_is_the_noncentral_chi2_moment_match(nu: float, f: float) -> None:
    """ν/(1 − f²) is 2E²/Var of ν·V/E[V_n] ~ χ'²(ν, λ = ν f/(1 − f)), and a Monte Carlo of
    that non-central χ² scatters with it."""
    lam = nu * f / (1 - f)
    assert edf_with_signal(nu, f) == pytest.approx((nu + lam) ** 2 / (nu + 2 * lam), rel=1e-12)
    draws = np.random.default_rng(1).noncentral_chisquare(nu, lam, 400_000) if lam > 0 else \
        np.random.default_rng(1).chisquare(nu, 400_000)
    seen = 2 * draws.mean() ** 2 / draws.var()
    assert seen == pytest.approx(float(edf_with_signal(nu, f)), rel=0.02)


def test_the_mixture_bound_holds_on_simulated_estimates() -> None:
    """White + random walk of equal AVAR at the τ read: the EDF the OADEV estimates scatter
    with (Monte Carlo, 600 records) is at least the Cauchy–Schwarz bound from the two
    types' own Greenhall–Riley EDFs, which lies between them (so it is more than the least
    EDF of the two, what the estimator takes when it cannot tell them apart)."""
    rng = np.random.default_rng(2)
    n, m = 4096, 256
    s2, q2 = 1.0, 6.0 / (2 * m * m + 1)        # white s²/m = walk q²(2m²+1)/(6m) at m
    est = []
    for _ in range(600):
        y = rng.normal(scale=np.sqrt(s2), size=n) + np.cumsum(
            rng.normal(scale=np.sqrt(q2), size=n))
        est.append(allan_variance(y, 1.0, [float(m)], alpha=0).var[0])
    est_a = np.array(est)
    seen = 2 * est_a.mean() ** 2 / est_a.var()
    nus = np.array([[edf_greenhall(0, 2, m, 1, n + 1)], [edf_greenhall(-2, 2, m, 1, n + 1)]])
    levels = np.array([[s2 / m], [q2 * (2 * m * m + 1) / (6 * m)]])
    bound = float(edf_mixture_bound(levels, nus)[0])
    assert nus.min() < bound < nus.max()
    assert bound > 1.2 * nus.min()
    assert seen >= 0.85 * bound, (seen, bound, nus.ravel())  # 600 records: ±8 % on seen
    # one noise alone: its own EDF
    assert float(edf_mixture_bound(levels[:1], nus[:1])[0]) == pytest.approx(nus[0, 0])


def test_noise_alone_is_the_estimators_where_it_identified_one_type() -> None:
    """White noise alone: no deterministic share; where the estimator had enough averages to
    identify one type (≥ SPREAD_LAG1) the printed EDF and bounds are its own; with fewer,
    where it took the least EDF of the types it could not tell apart, the fit's white-only
    model may raise it, up to white FM's own EDF and no further."""
    y = np.random.default_rng(5).normal(size=N)
    ch = _analyze(y)
    assert not np.any(signal_share(ch.fit, ch.allan) > 0)
    r = allan_variance(y, RATE)
    k = len(ch.allan.tau)
    many = N / ch.allan.m >= SPREAD_LAG1
    np.testing.assert_allclose(ch.allan.edf[many], r.edf[:k][many], rtol=1e-12)
    np.testing.assert_allclose(ch.allan.hi[many], r.hi[:k][many], rtol=1e-12)
    few = ~many & np.isfinite(ch.allan.edf)
    white = np.array([edf_greenhall(0, 2, int(m), 1, N + 1) for m in ch.allan.m[few]])
    assert np.all(ch.allan.edf[few] >= r.edf[:k][few] * (1 - 1e-12))
    assert np.all(ch.allan.edf[few] <= white * (1 + 1e-12))
    assert np.any(ch.allan.edf[few] > r.edf[:k][few])  # raised where the estimator could not tell


@pytest.mark.parametrize("drift", [0.0, 1e-4, 3e-4])
def test_printed_edf_keeps_to_the_support(drift: float) -> None:
    """White + flicker + random walk with and without a ramp, through analyze: every printed
    EDF is at least the estimator's and at most what the record supports (unless the ramp
    was resolved apart from the AVAR, in the time domain), and so is the EDF given to the
    noise part."""
    for seed in (1, 2):
        y = _record(drift, seed, q2=1e-6)
        ch = _analyze(y)
        r = allan_variance(y, RATE)
        k = len(ch.allan.tau)
        ok = np.isfinite(ch.allan.edf)
        assert np.all(ch.allan.edf[ok] >= r.edf[:k][ok] * (1 - 1e-12))
        cap = support(ch.allan)
        noise = noise_part_edf(replace(ch.allan, edf=r.edf[:k]),
                               unresolved_noise_edf(ch.fit, ch.allan))
        noise_at_estimator = noise_part_edf(r)[:k]
        assert np.all(noise[ok] <= cap[ok] * (1 + 1e-12))
        assert np.all(noise_at_estimator[ok] <= cap[ok] * (1 + 1e-12))
        if not ch.fit.resolved_apart:
            # (a drift the time domain resolved may take the whole EDF past it: only a part
            # known apart from the AVAR may, analysis/drift.py)
            assert np.all(ch.allan.edf[ok] <= cap[ok] * (1 + 1e-12))
        if drift == 0.0:
            assert not np.any(signal_share(ch.fit, ch.allan) > 0)  # none on noise alone


def test_a_resolved_ramp_raises_the_edf_where_it_holds_the_avar() -> None:
    """A ramp the fit resolves (present, no note): where it holds most of the AVAR the EDF
    rises (an interval from the noise's EDF would be wider than the estimate's scatter) to
    the EDF of the noise part plus the ramp's exact cross term (``parts_edf``), never above
    the record's support (the AVAR fit cannot split the longest τ between a ramp and a
    random walk), never below the noise's; the bounds are the χ² bounds of the new EDF; at
    short τ, where the ramp holds nothing, nothing changes."""
    y = _record(3e-4)
    ch = _analyze(y)
    ramp = ch.fit.terms["rate_ramp"]
    assert ramp.present and ramp.note is None
    # analyze found it in the time domain (analysis/drift.py): the same fit, its ramp taken
    # as the AVAR fit's own, is held to the support
    assert ch.fit.resolved_apart == ("rate_ramp",)
    r = allan_variance(y, RATE)
    k = len(ch.allan.tau)
    base = r.edf[:k]
    est = replace(ch.allan, edf=base)
    share = signal_share(ch.fit, r)[:k]
    assert share[-1] > 0.5 and share[0] < 1e-6
    noise = noise_part_edf(est, unresolved_noise_edf(ch.fit, ch.allan))
    cap = support(ch.allan)
    assert np.all(noise <= cap * (1 + 1e-12))           # the noise part within the support
    for fit, capped in ((replace(ch.fit, resolved_apart=()), True), (ch.fit, False)):
        new = with_signal_edf(est, fit).edf
        assert new[-1] > 1.3 * noise[-1]                 # raised where the ramp dominates
        if capped:
            assert np.all(new <= cap * (1 + 1e-12))      # never above the support
        else:
            assert new[-1] > cap[-1]                     # known apart: past it
            np.testing.assert_allclose(new, ch.allan.edf, rtol=1e-12)
        assert np.all(new >= noise * (1 - 1e-12))        # never below the noise's
        np.testing.assert_allclose(new[:4], noise[:4], rtol=1e-12)
    lo, hi = chi2_interval(ch.allan.var, ch.allan.edf, ch.allan.ci)
    np.testing.assert_allclose(ch.allan.lo, lo, rtol=1e-12)
    np.testing.assert_allclose(ch.allan.hi, hi, rtol=1e-12)


@pytest.mark.parametrize("noise", ["white", "flicker", "walk"])
@pytest.mark.parametrize(("m", "cycles"), [(1, 0), (16, 0), (256, 0), (16, 6), (256, 6)])
def test_the_cross_term_is_the_simulated_one(noise: str, m: int, cycles: int) -> None:
    """The cross term of a ramp (cycles 0) or a sinusoid (6 cycles a record) with white,
    flicker (the independent generator's) and random-walk noise: its variance over 600
    records is ``cross_term_variance`` times the signal's own AVAR (±6 % Monte Carlo at
    2σ, and a margin for the flicker series' finite spectrum)."""
    n = 4096
    rng = np.random.default_rng([7, m, cycles])
    t = np.arange(n, dtype=float)
    signal = 1e-3 * t if cycles == 0 else np.sin(2 * np.pi * cycles * t / n + 0.7)

    def diffs(x: np.ndarray) -> np.ndarray:
        c = np.concatenate([[0.0], np.cumsum(x)])
        avg = (c[m:] - c[:-m]) / m
        return (avg[m:] - avg[:-m]) / np.sqrt(2.0)

    a = diffs(signal)
    psds = {"white": lambda nu: np.ones_like(nu),
            "flicker": lambda nu: 0.5 / np.abs(nu),  # the generator's h/f one-sided, h = 1
            "walk": lambda nu: 0.25 / np.sin(np.pi * nu) ** 2}
    cross = []
    for _ in range(600):
        if noise == "white":
            x = rng.normal(size=n)
        elif noise == "flicker":
            x = flicker(n, 1.0, rng)
        else:
            x = np.cumsum(rng.normal(size=n))
        cross.append(2.0 / len(a) * float(np.sum(a * diffs(x))))
    want = float(np.mean(a * a)) * cross_term_variance(psds[noise], m, len(a), cycles / n)
    assert np.var(cross) == pytest.approx(want, rel=0.15)


def test_a_ramp_the_fit_does_not_resolve_changes_nothing() -> None:
    """A ramp the fit keeps only as "not yet resolved" or reads as a random walk: no share
    is given to it (it is read as noise)."""
    found = 0
    for seed in range(3, 9):
        y = _record(1e-4, seed, q2=1e-6)
        # the AVAR fit alone (analyze also tests a drift in the time domain, which resolves
        # these: analysis/drift.py)
        allan = allan_variance(y, RATE)
        fit = fit_noise(allan)
        ramp = fit.terms["rate_ramp"]
        if ramp.present and ramp.note is None:
            continue
        if ramp.present or fit.terms["rate_random_walk"].present:
            found += 1
            assert not np.any(signal_share(fit, allan) > 0)
            np.testing.assert_array_equal(
                with_signal_edf(allan, fit).edf,
                with_signal_edf(allan, replace(fit, theta=np.where(
                    [c.label == "rate_ramp" for c in fit.components], 0.0, fit.theta))).edf)
    assert found >= 1  # the case occurred


def test_the_share_is_the_part_the_fit_is_sure_of() -> None:
    """The share uses the ramp at its lower 1σ bound over the larger of the measured and
    modelled AVAR: below the point value's share at every τ."""
    ch = _analyze(_record(3e-4))
    tau = ch.allan.tau
    point = ch.fit.component_avars(tau)["rate_ramp"] / np.fmax(ch.allan.var,
                                                              ch.fit.model_avar(tau))
    share = signal_share(ch.fit, ch.allan)
    assert np.all(share <= point * (1 + 1e-12)) and np.any(share < point)


def test_a_hadamard_result_is_left_alone() -> None:
    """The fit's basis is the AVAR: a Hadamard result is returned as it is."""
    y = _record(3e-4)
    ch = _analyze(y)
    h: AllanResult = allan_variance(y, RATE, kind="ohvar")
    assert with_signal_edf(h, ch.fit) is h


@pytest.mark.parametrize("cycles", [0, 6, 40])
@pytest.mark.parametrize("walk", [False, True])
def test_the_printed_rule_with_the_true_part_is_the_simulated_scatter(cycles: int,
                                                                      walk: bool) -> None:
    """White noise (and a random walk) with a ramp (cycles 0) or a sinusoid of random phase
    holding most of the AVAR at the τ read: the EDF ``parts_edf`` gives with the true
    deterministic part and the true spectrum is the EDF the OADEV estimates scatter with
    over 400 records (2·truth²/mean((σ̂² − truth)²); within 25 %, the Monte Carlo's spread
    of a variance of a few hundred heavy-tailed draws), and far above the non-central
    χ²'s ν/(1 − f²), which the support then capped. The sinusoid's own OADEV varies with
    its phase when the record holds a fraction of a cycle more (``phase_spread``): without
    that term the 6-cycle case's EDF was 3800 where the estimates scatter with 2400."""
    n, m = 4096, 64
    rng = np.random.default_rng([11, cycles, walk])
    t = np.arange(n, dtype=float)
    q2 = 1e-4 if walk else 0.0
    noise_avar = 1.0 / m + q2 * (2 * m * m + 1) / (6 * m)
    est, clean_avar = [], []

    def oavar(x: np.ndarray) -> float:  # the OADEV's estimate at m (SP 1065 eq. 11)
        c = np.concatenate([[0.0], np.cumsum(x)])
        avg = (c[m:] - c[:-m]) / m
        return float(np.mean((avg[m:] - avg[:-m]) ** 2) / 2)

    for _ in range(400):
        if cycles == 0:
            s = np.sqrt(2 * 3 * noise_avar) / m * t      # AVAR (d m)²/2 = 3× the noise's
        else:
            s = 2.0 * np.sin(2 * np.pi * cycles * t / n + rng.uniform(0, 2 * np.pi))
        x = rng.normal(size=n) + np.cumsum(rng.normal(scale=np.sqrt(q2), size=n)) + s
        est.append(oavar(x))
        clean_avar.append(oavar(s))
    signal = float(np.mean(clean_avar))
    truth = noise_avar + signal
    seen = 2 * truth**2 / float(np.mean((np.array(est) - truth) ** 2))
    one = allan_variance(rng.normal(size=n), 1.0, [float(m)], alpha=-2 if walk else 0)
    # the noise part's own EDF: the estimator's for the noise type at this τ
    edf_noise = edf_greenhall(-2 if walk and q2 * m > 1.0 / m else 0, 2, m, 1, n + 1)
    one = replace(one, edf=np.array([edf_noise]))

    def psd(nu: np.ndarray) -> np.ndarray:
        return 1.0 + q2 / (4 * np.sin(np.pi * nu) ** 2)

    got = float(parts_edf(one, [(np.array([signal]), cycles / n)], np.array([truth]),
                          np.array([noise_avar]), psd, within_support=False)[0])
    assert got == pytest.approx(seen, rel=0.25), (got, seen, signal / truth)
    f = signal / truth
    assert got > 1.5 * min(edf_noise / (1 - f * f), float(support(one)[0]))


def test_a_cross_term_that_cannot_be_computed_is_the_gaussian_bound() -> None:
    """A τ whose cross term is not a number (a spectrum that cannot be evaluated there) is
    given the largest cross term a Gaussian quadratic form allows, 4SN/ν, i.e. the
    non-central χ²'s ν/(1 − f²): a NaN is not read as "no scatter" and raised to the
    support."""
    n, m = 4096, 64
    r = allan_variance(np.random.default_rng(4).normal(size=n), 1.0, [float(m)])
    red = replace(r, edf=r.edf / 3)  # (a redder type's EDF, below the support)
    got = parts_edf(red, [(np.array([3.0 / m]), 0.0)], np.array([4.0 / m]),
                    np.array([1.0 / m]), lambda nu: np.full_like(nu, np.nan))
    np.testing.assert_allclose(got, edf_with_signal(red.edf, 0.75), rtol=1e-12)
    assert got[0] < float(support(red)[0])


def test_a_resolved_ramps_noise_part_is_its_rms_over_the_fits_uncertainty() -> None:
    """A ramp the time domain resolved apart from the AVAR: the estimate's variance 2N²/ν is
    an expectation over the uncertain split of the AVAR between ramp and noise, so the
    noise part is √(N̂² + Var N̂), not its value at the split's worst 1σ point (which
    counted that uncertainty into a 68 % interval twice: the 1 h drift records covered 80 %
    at 409.6 s). So the printed EDF lies between the worst-point rule's (the AVAR fit's own
    parts, within the support) and the EDF with the fit's uncertainty taken away, and it
    falls as that uncertainty grows."""
    y = _record(3e-4)
    ch = _analyze(y)
    assert ch.fit.resolved_apart == ("rate_ramp",)
    k = len(ch.allan.tau)
    est = replace(ch.allan, edf=allan_variance(y, RATE).edf[:k])
    cap = support(ch.allan)
    new = with_signal_edf(est, ch.fit).edf
    worst = with_signal_edf(est, replace(ch.fit, resolved_apart=())).edf
    sure = with_signal_edf(est, replace(ch.fit, theta_cov=np.zeros_like(ch.fit.theta_cov)))
    looser = with_signal_edf(est, replace(ch.fit, theta_cov=4.0 * ch.fit.theta_cov)).edf
    ok = np.isfinite(new)
    assert np.all(np.fmin(new, cap)[ok] >= worst[ok] * (1 - 1e-12))
    assert np.all(new[ok] <= sure.edf[ok] * (1 + 1e-12))
    assert np.all(looser[ok] <= new[ok] * (1 + 1e-12))
    assert new[-1] > worst[-1] and looser[-1] < new[-1] < sure.edf[-1]


def test_the_mixture_sets_the_edf_where_the_estimator_read_a_walk_on_a_mixture() -> None:
    """White + random walk meeting at 5 s: with many averages, where the estimator's lag-1
    identification reads the walk (α = −2, the least EDF of the FM types) on what the fit
    reads as a mixture, the printed EDF is the fitted mixture's (``model_edf``, within the
    support), above the walk's own; where it reads white FM, the mixture's too."""
    from avard.core.analysis.signal_edf import model_edf

    raised = 0
    for seed in (1, 2, 3):
        rng = np.random.default_rng(seed)
        y = rng.normal(size=N) + np.cumsum(rng.normal(scale=np.sqrt(3.0 / 50**2), size=N))
        ch = _analyze(y)
        assert not ch.fit.resolved_apart and not np.any(signal_share(ch.fit, ch.allan) > 0)
        r = allan_variance(y, RATE)
        k = len(ch.allan.tau)
        own = r.edf[:k]
        many = N / ch.allan.m >= SPREAD_LAG1
        walk = many & (ch.allan.alpha == -2)
        other = many & (ch.allan.alpha > -2)
        assert walk.any() and other.any()
        # every identified τ, the walk's and white FM's alike: the fitted mixture's, within
        # the support and never below the estimator's (the stream's sums against one
        # array's: the last bits of the AVAR)
        want = np.maximum(own, np.fmin(model_edf(ch.fit, ch.allan), support(ch.allan)))
        np.testing.assert_allclose(ch.allan.edf[many], want[many], rtol=1e-6)
        raised += int(np.sum(ch.allan.edf[walk] > own[walk] * 1.05))
    assert raised >= 3
