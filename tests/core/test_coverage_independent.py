"""Coverage of the printed OADEV intervals on records from a generator written apart from
avard (tests/support/coverage_gen.py; issue 24): the slow set runs the benchmark's own
function (benchmarks/bench_coverage.py, its table in docs/analysis.md) on what ``avard
analyze`` prints (the fit's EDF included, core/analysis/signal_edf.py)."""

from __future__ import annotations

import pytest

from benchmarks.bench_coverage import BAND, coverage
from tests.support.coverage_gen import Mix

#: measured on the sine rows (200 records, seed 1; docs/log/analysis.md): records where the
#: slow-sinusoid search resolved the sinusoid, and the highest coverage share over τ
SINE_FOUND = {1: 95, 12: 148, 60: 178}
SINE_HIGHEST = {1: 0.855, 12: 0.77, 60: 0.805}


@pytest.mark.slow
@pytest.mark.parametrize("hours", [1, 12, 60])
def test_intervals_cover_the_truth_on_noise(hours: int) -> None:
    """White + flicker + random walk, 200 records: at every τ with ≥ 5 averages the 68.3 %
    interval holds the closed-form AVAR in at least 60 % of the records, and in 60–76 % at
    all but one τ, none above 80 % (measured on 8196a88: 1 h 66.5–74.0 %, 12 h 67.0–72.5 %,
    60 h 63.5–75.0 %, every τ inside; a share of 200 records has a standard error of 3.3
    points, and neighbouring τ share their records)."""
    c = coverage(hours, "plain", 200, seed=1)
    detail = list(zip(c.tau, c.share, strict=True))
    assert all(c.share >= BAND[0]), detail
    assert len(c.outside()) <= 1 and all(c.share <= 0.80), detail
    # the slow-sinusoid search (analysis/slow_sine.py, 1 % a record) claims one on at most
    # 5 of 200 (P ≈ 5 % at a true 1 %; measured 1, 3 and 3 at 1 h, 12 h, 60 h): a false one
    # narrows the intervals
    assert c.slow_found <= 5, c.slow_found


@pytest.mark.slow
@pytest.mark.parametrize("hours", [1, 12, 60])
def test_intervals_cover_the_truth_beside_a_drift(hours: int) -> None:
    """White + flicker + random walk and a linear drift whose AVAR equals the noise's at
    T/10, 200 records: the time domain resolves the drift in 46–85 % of them, the others
    carry its slope interval's near end as a floor (analysis/drift.py, signal_edf.py); at
    every τ with ≥ 5 averages the interval holds the truth in at least 60 %, in 60–76 % at
    all but one τ, none above 80 % (measured on 8196a88: 1 h 61.5–73.0 %, 12 h 64.0–77.0 %
    with 77.0 % at 8192 s, 60 h 59.5–75.0 %: 64 s is one record short of 60 %, where the
    printed EDF is the generator's exact one and these records scatter 18 % below it, so
    the 60 h case fails on that tree; docs/log/analysis.md, "Every row re-measured"; before the
    floor and the resolved ramp's rms noise part up to 83.5 %, at four τ of 12 h). The
    assertion is kept as the issue states it (cov27, cov28: the 60 h records' noise alone,
    at the generator's exact EDF, covers 64 s in 59.5 % too; more records chosen after
    seeing the failure would be a seed chosen by another name): a failure reports each τ's
    share with its binomial standard error, so one record short reads as what it is."""
    import math

    c = coverage(hours, "drift", 200, seed=1)
    detail = [(float(t), f"{s:.1%} ± {math.sqrt(s * (1 - s) / 200):.1%}", float(g))
              for t, s, g in zip(c.tau, c.share, c.signal, strict=True)]
    below = [f"τ {t:g} s: {s}" for (t, s, _g), v in zip(detail, c.share, strict=True)
             if v < BAND[0]]
    assert all(c.share >= BAND[0]), f"below 60 %: {below}; every τ: {detail}"
    assert len(c.outside()) <= 1 and all(c.share <= 0.80), detail


@pytest.mark.slow
@pytest.mark.parametrize("hours", [12, 60])
def test_the_floor_records_cover_as_often_as_claimed_at_the_longest_tau(hours: int) -> None:
    """The drift rows' records where the drift test stays short of its level but the slope's
    68 % interval is clear of zero (a floor; about half of them): at the longest τ the
    ramp's cross term, the slope's error times Rτ², dominates the estimate's scatter, and the
    verdict is made of that slope, so these records' estimates fell low. A χ² about the
    estimate covered them in 82 % (12 h, 112 records) and 86 % (60 h, 81) on seed 1, past a
    68.3 % interval's binomial 99 % range; the bounds from the slope's interval
    (``signal_edf.floor_bounds``) cover 69 % and 72 % (docs/log/2026-11-28-cov24h.md)."""
    import math

    c = coverage(hours, "drift", 200, seed=1)
    verdicts = {v: (n, share) for v, n, share in c.by_verdict}
    n, share = verdicts["floor"]
    assert n >= 40, n
    half = 2.58 * math.sqrt(0.683 * 0.317 / n)
    assert 0.683 - half <= share[-1] <= 0.683 + half, (n, share[-1])


@pytest.mark.slow
@pytest.mark.parametrize("mix", ["sine"])
@pytest.mark.parametrize("hours", [1, 12, 60])
def test_intervals_are_never_too_narrow_with_a_signal(hours: int, mix: str) -> None:
    """With a slow sinusoid or a drift added: the interval holds the truth in at least 60 %
    of the records at every τ. Where the signal makes much of the AVAR they over-cover
    (measured up to 85.5 % on the sine rows, 83.5 % on the drift ones): the slow-sinusoid
    search does not find every sinusoid (analysis/slow_sine.py), and the time domain finds
    the drift (about three standard errors of its slope) in 46–85 % of
    the records (analysis/drift.py), so elsewhere the printed EDF is the noise's, and a
    deterministic part scatters less than any noise type's χ² says (docs/analysis.md,
    "Coverage of the intervals")."""
    c = coverage(hours, mix, 200, seed=1)
    detail = list(zip(c.tau, c.share, c.signal, strict=True))
    assert all(c.share >= BAND[0]), detail
    assert all(c.share <= 0.92), detail
    if mix == "drift":
        # a drift is not a sinusoid (the search fits a slope beside it): at most 5 of 200
        # (measured 2, 3 and 4)
        assert c.slow_found <= 5, c.slow_found
    else:
        # the slow-sinusoid search resolves the sinusoid (six cycles a record, its AVAR at
        # half a period the noise's) in about half the 1 h records and most of the longer
        # ones (measured SINE_FOUND), and the highest share falls from 87.5, 84.5 and 90 %
        # to the measured SINE_HIGHEST (1 h: 409.6 s, where the noise's own EDF, the least
        # of the types it cannot rule out, sets the width; docs/analysis.md)
        assert c.slow_found >= SINE_FOUND[hours] - 25, c.slow_found
        assert c.share.max() <= SINE_HIGHEST[hours] + 0.03, detail


@pytest.mark.slow
def test_a_resolved_ramp_narrows_the_interval_and_never_too_far() -> None:
    """A drift ten times as steep ("steep", 1 h): the time domain resolves it as a ramp in
    most records (analysis/drift.py) and the printed EDF rises where it holds the AVAR,
    past the record's support (the part is known apart from the AVAR); the interval still
    holds the truth in at least 60 % of the records at every τ, and no longer in 100 % where
    the ramp dominates (docs/analysis.md)."""
    c = coverage(1, "steep", 200, seed=1)
    detail = list(zip(c.tau, c.share, c.fit_share, c.edf_mean, strict=True))
    assert all(c.share >= BAND[0]), detail
    assert c.share.max() <= 0.90, detail  # (100 % before the drift test)
    assert c.fit_raised.max() >= 0.9, detail
    assert c.fit_share[-1] > 0.5, detail
    plain = coverage(1, "plain", 200, seed=1)
    assert c.edf_mean[-1] > 1.2 * plain.edf_mean[-1], detail


@pytest.mark.slow
@pytest.mark.parametrize(("hours", "mix"), [(1, "steep"), (12, "steep"), (1, "drift"),
                                            (12, "drift")])
def test_the_exact_cross_term_covers_given_the_true_part(hours: int, mix: str) -> None:
    """The printed rule (the noise part's EDF and the exact cross term, signal_edf.parts_edf)
    given the true deterministic part and the generator's spectrum, past the support for
    that part (the oracle): the same records' intervals hold the truth in 60–78 % at every
    τ (measured 62.5–77 %). The printed ones, where the time domain resolves the drift
    (analysis/drift.py), are never narrower than that allows (docs/analysis.md)."""
    c = coverage(hours, mix, 200, seed=1, detail=True)
    detail = list(zip(c.tau, c.share, c.share_known, c.signal, strict=True))
    assert all(BAND[0] <= k <= 0.78 for k in c.share_known), detail
    assert all(c.share >= BAND[0]), detail


def test_the_generators_noise_edf_is_its_scatter() -> None:
    """``noise_edf`` (the benchmark's ``--detail`` column that says whether a row's records
    are lucky at a τ): one type alone gives that type's Greenhall–Riley EDF, and on a short
    white + flicker + random-walk record the simulated scatter of the noise's OADEV over
    400 records, as an EDF, lies within 25 % of it (about 3.5 of its standard errors)."""
    import numpy as np
    from avard.core.allan.deviations import allan_variance
    from avard.core.allan.edf import edf_greenhall

    from benchmarks.bench_coverage import noise_edf
    from tests.support.coverage_gen import Mix, noise_avar, record

    n, ms = 4096, np.array([4, 32, 128])
    white = noise_edf(Mix(s2=1.0, h=0.0, q2=0.0), n, ms)
    assert white == pytest.approx([edf_greenhall(0, 2, int(m), 1, n + 1, rate_data=True)
                                   for m in ms], rel=1e-9)
    mix = Mix(s2=1.0, h=0.05, q2=1e-5)
    expected = noise_edf(mix, n, ms)
    truth = noise_avar(mix, n, ms)
    rng = np.random.default_rng(12)
    est = np.array([allan_variance(record(mix, n, rng)[0], 1.0, ms).var for _ in range(400)])
    seen = 2.0 * truth**2 / np.mean((est - truth) ** 2, axis=0)
    np.testing.assert_allclose(seen, expected, rtol=0.25)


def _exact_generator_edf(mix: Mix, n: int, m: int) -> float:
    """The EDF 2E²/Var of the OADEV at averaging factor m of the generator's own process,
    exactly, with numpy alone: the OADEV is (1/2M)Σ_k D_k², D_k the difference of adjacent
    m-averages, a stationary Gaussian sequence whose covariance C(l) is the white's and the
    walk's (their weights' autocorrelation) plus the flicker's line spectrum
    Σ_j P_j|H_m(f_j)|² cos(2π f_j l) (one FFT on the series' own period), so
    EDF = M²C(0)² / Σ_l (M − |l|)C(l)²."""
    import numpy as np

    from tests.support.coverage_gen import PERIODS, _flicker_power

    big_m = n - 2 * m + 1
    length = PERIODS * n
    f, p = _flicker_power(n, mix.h)
    x = np.pi * f
    g = np.zeros(length)
    g[1:length // 2] = p * 4 * np.sin(x * m) ** 2 * (np.sin(x * m) / (m * np.sin(x))) ** 2
    c = np.fft.fft(g).real[:big_m]
    w = np.concatenate([-np.ones(m), np.ones(m)]) / m  # the samples' weights in D
    c[:2 * m] += mix.s2 * np.correlate(w, w, "full")[2 * m - 1:]
    v = np.concatenate([np.arange(1, m + 1), np.arange(m - 1, 0, -1)]) / m  # the walk's steps'
    c[:2 * m - 1] += mix.q2 * np.correlate(v, v, "full")[2 * m - 2:]
    lag = np.arange(1, big_m)
    return float(big_m**2 * c[0] ** 2
                 / (big_m * c[0] ** 2 + 2 * np.sum((big_m - lag) * c[1:] ** 2)))


@pytest.mark.parametrize(("hours", "taus"), [(1, (12.8, 204.8, 409.6)),
                                             (12, (16.0, 1024.0, 8192.0)),
                                             (60, (4.0, 64.0, 32768.0))])
def test_the_generators_noise_edf_is_its_exact_edf(hours: int, taus: tuple[float, ...]
                                                   ) -> None:
    """``noise_edf`` (Greenhall–Riley's quadratic form of the mixture, ``edf.edf_mixture``,
    rate data's phase) is the exact EDF of the generator's discrete process (a flicker of
    lines on four record lengths, not an ideal 1/f) within 1 % at the benchmark's own
    geometries and mixes, from the cells the coverage tables discuss: a row whose records'
    noise scatters far from it is lucky or unlucky there, whatever the printed rule, and
    where the printed EDF equals it the interval has the class's width (docs/analysis.md,
    "Coverage of the intervals")."""
    import numpy as np

    from benchmarks.bench_coverage import LENGTHS, mix_for, noise_edf

    rate = LENGTHS[hours]
    n = round(hours * 3600 * rate)
    mix = mix_for("plain", n, rate)
    ms = np.array([round(t * rate) for t in taus])
    exact = [_exact_generator_edf(mix, n, int(m)) for m in ms]
    np.testing.assert_allclose(noise_edf(mix, n, ms), exact, rtol=0.01)
    # the exact form itself, on white noise alone: Greenhall–Riley's white FM (rate data) is
    # that process's exact EDF
    from avard.core.allan.edf import edf_greenhall

    m = int(ms[-1])
    assert _exact_generator_edf(Mix(s2=1.0, h=0.0, q2=0.0), n, m) == pytest.approx(
        edf_greenhall(0, 2, m, 1, n + 1, rate_data=True), rel=1e-4)
