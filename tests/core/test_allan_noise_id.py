"""Power-law noise identification: lag-1 ACF (Riley & Greenhall 2004), B1 and R(n) below 30
averages (Stable32), and the slope fallback."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.deviations import allan_variance, oavar
from avard.core.allan.noise_id import (
    Lag1Ladder,
    RnSums,
    alpha_from_b1,
    alpha_from_lag1,
    alpha_from_rn,
    alpha_from_slope,
    b1_theory,
    identify_alpha,
    lag1_acf,
)
from avard.core.errors import DataError


def power_law(alpha: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """Rate noise with S_y ∝ f^alpha by Kasdin & Walter's fractional differencing filter."""
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 1 - alpha / 2) / k)])
    w = rng.normal(size=n)
    size = 2 * n
    return np.fft.irfft(np.fft.rfft(h, size) * np.fft.rfft(w, size), size)[:n]


@pytest.mark.parametrize("alpha", [2, 1, 0, -1, -2])
def test_identify_alpha_on_generated_noise(alpha: int) -> None:
    rng = np.random.default_rng(100 + alpha)
    y = power_law(alpha, 2**15, rng)
    assert [identify_alpha(y, m) for m in (1, 4)] == [alpha, alpha]
    # the accumulators' own identification (same ACF ladder on their difference sums)
    assert list(oavar(y, 1.0, [1, 4], noise_id="powerlaw").alpha) == [alpha, alpha]


def test_lag1_formulas() -> None:
    assert alpha_from_lag1(0.0, 0) == 0.0  # white rate noise
    assert alpha_from_lag1(-0.5, 1) == pytest.approx(0.0)  # differenced white
    assert alpha_from_lag1(0.0, 1) == pytest.approx(-2.0)  # differenced random walk
    assert np.isnan(alpha_from_lag1(-1.0, 0))
    x = np.array([1.0, 2.0, 1.0, 2.0, 1.0, 2.0])
    assert lag1_acf(x) < -0.8


def test_slope_fallback() -> None:
    assert alpha_from_slope(-1.0) == 0
    assert alpha_from_slope(0.0) == -1
    assert alpha_from_slope(1.0) == -2
    assert alpha_from_slope(-2.0) == 2
    assert alpha_from_slope(3.0, d=2) == -2  # clipped where AVAR converges
    assert alpha_from_slope(3.0, d=3) == -4


def test_short_data_fall_back_to_slope_in_results() -> None:
    """Fewer than 30 averages at a τ: the result still has an alpha (from the slope)."""
    y = np.random.default_rng(5).normal(size=400)
    res = oavar(y, 1.0)
    assert np.all(np.isfinite(res.alpha)) and np.all(np.isfinite(res.edf))
    with pytest.raises(DataError, match="30"):
        identify_alpha(y, 64)


def test_identify_alpha_rejects_bad_input() -> None:
    with pytest.raises(DataError, match="NaN"):
        identify_alpha(np.array([1.0, np.nan] * 50), 1)
    with pytest.raises(DataError, match="1-D"):
        identify_alpha(np.ones((100, 2)), 1)
    with pytest.raises(DataError, match="data_type"):
        identify_alpha(np.ones(100), 1, data_type="volts")


def _pooled_r1(segments: list[np.ndarray]) -> float:
    """Lag-1 ACF about the pooled mean, pairs only within a segment (the ladder's definition;
    for one segment it is NIST SP 1065's r1)."""
    allv = np.concatenate(segments)
    mu = allv.mean()
    num = sum(float(np.dot(s[:-1] - mu, s[1:] - mu)) for s in segments)
    return num / float(np.dot(allv - mu, allv - mu))


def test_lag1_ladder_sums_are_exact_for_any_split_gap_and_merge() -> None:
    rng = np.random.default_rng(12)
    # a huge offset (as an axis carrying 1 g) must not leak into r1
    z = 9.81 + 1e-4 * np.cumsum(rng.normal(size=(3000, 2)), axis=0) * [1.0, 0.01] \
        + 1e-4 * rng.normal(size=(3000, 2))
    one = Lag1Ladder(2, dmax=2)
    for part in np.array_split(z, [1, 2, 500, 1700]):
        one.push(part)
    for k in range(3):
        series = np.diff(z, n=k, axis=0)
        for ch in range(2):
            assert one.r1(k)[ch] == pytest.approx(lag1_acf(series[:, ch]), abs=1e-9)
    # two segments: fed with a gap, or as two ladders added, give the same sums
    gapped, a = Lag1Ladder(2), Lag1Ladder(2)
    gapped.push(z[:1200])
    gapped.gap()
    gapped.push(z[1200:])
    a.push(z[:1200])
    c = Lag1Ladder(2)
    c.push(z[1200:])  # its reference is its own first value: the merge re-references it
    c.add(Lag1Ladder(2))  # adding an empty ladder changes nothing
    a.add(c)
    for k in range(3):
        segs = [np.diff(z[:1200], n=k, axis=0), np.diff(z[1200:], n=k, axis=0)]
        for ch in range(2):
            want = _pooled_r1([s[:, ch] for s in segs])
            assert gapped.r1(k)[ch] == pytest.approx(want, abs=1e-9)
            assert a.r1(k)[ch] == pytest.approx(want, abs=1e-9)
    # a weighted channel, and a state round trip
    w = np.array([1.0, -3.0])
    wl = one.weighted(w)
    assert wl.r1(0)[0] == pytest.approx(lag1_acf(z @ w), abs=1e-9)
    back = Lag1Ladder.from_state(one.state())
    np.testing.assert_array_equal(back.r1(1), one.r1(1))
    np.testing.assert_array_equal(back.alpha(-2), one.alpha(-2))


def test_b1_theory_and_classes() -> None:
    """Barnes' B1: 1 for white FM, N/2 for random-walk FM, (N+1)/(1.5 N) for PM; the
    measured ratio is classified at the geometric means between neighbours."""
    assert b1_theory(10, -1) == pytest.approx(1.0)
    assert b1_theory(10, 1) == pytest.approx(5.0)
    assert b1_theory(10, -2) == pytest.approx(11 / 15)
    assert b1_theory(10, 0) == pytest.approx(10 * np.log(10) / (18 * np.log(2)))
    assert alpha_from_b1(1.0, 10) == 0
    assert alpha_from_b1(5.0, 10) == -2
    assert alpha_from_b1(b1_theory(10, 0), 10) == -1
    assert alpha_from_b1(0.7, 10) is None  # PM: B1 cannot say which


def test_lag1_ladder_short_segments_per_channel_sums_and_state() -> None:
    """Segments shorter than the ladder's end buffers, per-channel (cross=False) sums, and a
    state taken with a segment open: all give the directly computed pooled r1."""
    rng = np.random.default_rng(21)
    offset = np.array([5.0, -2.0, 0.0])
    segs = [rng.normal(size=(k, 3)) + offset for k in (5, 2, 40, 7, 300)]
    full, diag = Lag1Ladder(3), Lag1Ladder(3, cross=False)
    for lad in (full, diag):
        for seg in segs[:-1]:
            lad.push(seg)
            lad.gap()
        lad.push(segs[-1][:100])
    diag = Lag1Ladder.from_state(diag.state())  # open segment carried in the state
    for lad in (full, diag):
        lad.push(segs[-1][100:])
    for k in range(3):
        parts = [np.diff(s, n=k, axis=0) for s in segs]
        parts = [q for q in parts if len(q)]
        for ch in range(3):
            want = _pooled_r1([q[:, ch] for q in parts])
            assert full.r1(k)[ch] == pytest.approx(want, abs=1e-9)
            assert diag.r1(k)[ch] == pytest.approx(want, abs=1e-9)
    np.testing.assert_array_equal(full.alpha(-2), diag.alpha(-2))


def _mvar_avar_literal(x: np.ndarray, m: int) -> tuple[float, float]:
    """MVAR and overlapping AVAR of phase x (sample units) straight from NIST SP 1065
    eqs. 14 and 12, with the double loop of eq. 14 written out."""
    n = x.size
    d = [x[i + 2 * m] - 2 * x[i + m] + x[i] for i in range(n - 2 * m)]
    mod = [sum(d[j:j + m]) for j in range(n - 3 * m + 1)]
    return (float(np.mean(np.square(mod))) / (2 * m**4),
            float(np.mean(np.square(d))) / (2 * m**2))


def test_rn_sums_equal_the_definition_for_any_split_and_gap() -> None:
    rng = np.random.default_rng(5)
    y = rng.normal(size=(700, 2)) + np.array([3.0, 0.0])
    m = 9
    segs = [y[:300], y[300:]]
    acc = RnSums(2, m)
    for seg in segs:
        x = np.vstack([np.zeros((1, 2)), np.cumsum(seg, axis=0)])
        d = (x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]).T
        for part in np.array_split(d, [1, 5, 17, 200], axis=1):
            acc.push(part)
        acc.gap()
    for ch in range(2):
        parts = [_mvar_avar_literal(np.concatenate([[0.0], np.cumsum(sg[:, ch])]), m)
                 for sg in segs]
        # pooled over the two segments, weighted by their counts (300 and 400 samples)
        n_mod = [300 - 3 * m + 2, 400 - 3 * m + 2]  # L + 1 phase points per segment
        n_d = [300 - 2 * m + 1, 400 - 2 * m + 1]
        mvar = sum(p[0] * k for p, k in zip(parts, n_mod, strict=True)) / sum(n_mod)
        avar = sum(p[1] * k for p, k in zip(parts, n_d, strict=True)) / sum(n_d)
        assert acc.ratio()[ch] == pytest.approx(mvar / avar, rel=1e-12)


# Stable32 on the Keysight 53230A time-interval noise floor (55 688 phase points; allantools'
# test suite, tests/Keysight53230A_ti_noise_floor/tic_oadev.txt and tic_mdev.txt): averaging
# factor → (OADEV, MDEV, Stable32's "Alpha"). White PM up to m = 1024 (lag-1 ACF, ≥ 30
# averages), flicker PM from m = 2048 (27 averages and fewer: B1 says PM, R(n) decides).
STABLE32_TIC = {8: (2.2296e-12, 7.9280e-13, 2), 16: (1.1110e-12, 2.8456e-13, 2),
                32: (5.5853e-13, 1.0271e-13, 2), 64: (2.7960e-13, 4.0708e-14, 2),
                128: (1.4018e-13, 1.8420e-14, 2), 256: (7.0538e-14, 7.4228e-15, 2),
                512: (3.5291e-14, 2.9908e-15, 2), 1024: (1.7663e-14, 1.4367e-15, 2),
                2048: (8.8933e-15, 9.4879e-16, 1), 4096: (4.4960e-15, 6.0549e-16, 1),
                8192: (2.2694e-15, 3.5547e-16, 1)}


def test_rn_classifies_stable32s_own_mdev_and_oadev_as_stable32_does() -> None:
    """R(n) = (MDEV/OADEV)² of Stable32's published columns, classified by ``alpha_from_rn``,
    gives Stable32's Alpha at every τ of the run (where Stable32 itself used R(n), and where
    the lag-1 ACF found the same white PM)."""
    for m, (oadev, mdev, alpha) in STABLE32_TIC.items():
        assert alpha_from_rn((mdev / oadev) ** 2, m) == alpha, m
    assert alpha_from_rn(1.0, 1) is None  # MVAR = AVAR at m = 1: no information
    assert alpha_from_rn(float("nan"), 64) is None


@pytest.mark.parametrize("alpha", [2, 1])
def test_white_and_flicker_pm_told_apart_below_30_averages(alpha: int) -> None:
    """Phase noise with 16 averages per τ (B1's range): where B1 says PM, R(n) names white or
    flicker PM correctly (measured: in all 32 of 40 runs where B1 said PM, for each type);
    in the other runs B1 itself missed (white FM read), which R(n) cannot repair."""
    rng = np.random.default_rng(7 + alpha)
    m = 256
    pm_said, right_pm, exact = 0, 0, 0
    for _ in range(40):
        y = power_law(alpha, 16 * m, rng)
        a = int(oavar(y, 1.0, [m], noise_id="powerlaw").alpha[0])
        if a in (1, 2):
            pm_said += 1
            right_pm += int(a == alpha)
        exact += int(a == alpha)
    assert right_pm == pm_said
    assert exact >= 28, exact


def test_identify_alpha_is_the_estimators_ladder_and_matches_stable32() -> None:
    """``identify_alpha`` is the estimators' computation (one ladder), for rate and phase
    input alike, and gives Stable32's Alpha at every τ of PHASE.DAT where Stable32 uses the
    lag-1 ACF (≥ 30 averages; PHASE.DAT is NBS14 integrated to phase)."""
    from .stable32 import all_tau
    from .test_allan import nbs14_1000

    s32_alpha = {r.af: r.alpha for r in all_tau("oavar")}

    y = nbs14_1000()
    phase = np.concatenate([[0.0], np.cumsum(y)])
    ms = [m for m in sorted(s32_alpha) if 1000 // m >= 30]
    assert len(ms) == 33
    for m in ms:
        assert identify_alpha(y, m) == s32_alpha[m], m
        assert identify_alpha(phase, m, data_type="phase") == s32_alpha[m], m
    rng = np.random.default_rng(3)
    for alpha in (2, 1, 0, -1, -2):
        z = power_law(alpha, 1 << 13, rng) + 9.81  # an offset (an axis at 1 g) changes nothing
        for m in (1, 3, 16, 200):
            assert identify_alpha(z, m) == int(oavar(z, 1.0, [m], noise_id="powerlaw").alpha[0])
            assert identify_alpha(z, m, dmax=3) == int(
                allan_variance(z, 1.0, [m], kind="ohvar", noise_id="powerlaw").alpha[0])


def test_per_channel_ladder_fast_path_equals_the_general_sums() -> None:
    """The per-channel ladder's vectorised end corrections (``_open_sums_diag``) give the
    diagonal of the general C×C computation, for open segments of any length and split."""
    rng = np.random.default_rng(17)
    for n in (25, 26, 40, 333, 5000):
        z = 9.81 + np.cumsum(rng.normal(size=(n, 3)), axis=0) * 1e-3
        full, diag = Lag1Ladder(3), Lag1Ladder(3, cross=False)
        for lad in (full, diag):
            for part in np.array_split(z, [3, 7, n // 2]):
                lad.push(part)
        tf, td = full.totals(), diag.totals()
        for f in Lag1Ladder.FIELDS:
            want = np.diagonal(tf[f], axis1=1, axis2=2) if f in ("s2", "p") else tf[f]
            got = np.diagonal(td[f], axis1=1, axis2=2) if f in ("s2", "p") else td[f]
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_ladder_alpha_follows_every_change_of_its_sums() -> None:
    """α is remembered between calls while the sums stay the same; any push or merge that
    changes them gives the α of the new sums (a gap moves nothing and keeps it)."""
    rng = np.random.default_rng(9)
    lad = Lag1Ladder(1, cross=False)
    lad.push(rng.normal(size=(400, 1)))
    assert lad.alpha(-2)[0] == 0 and lad.alpha(-2)[0] == 0  # white, twice (remembered)
    lad.push(np.cumsum(rng.normal(size=(20000, 1)), axis=0) * 10.0)  # a random walk
    assert lad.alpha(-2)[0] == -2
    lad.gap()
    assert lad.alpha(-2)[0] == -2
    other = Lag1Ladder(1, cross=False)
    other.push(rng.normal(size=(10 ** 5, 1)) * 1e3)  # much more white noise, merged
    lad.add(other)
    fresh = Lag1Ladder.from_state(lad.state())
    assert lad.alpha(-2)[0] == fresh.alpha(-2)[0] == 0


def test_below_ten_averages_the_shorter_taus_alpha_is_kept() -> None:
    """Stable32's rule (noise_id.HOLD_BELOW_AVERAGES): a τ with fewer than 10 averages (8 for
    an overlapping estimator) takes the α of the next shorter τ of the grid, when there is
    one; alone it is identified from its own averages. Flicker PM here, so B1 at the long τ
    alone reads a noisy class that the kept α does not follow."""
    n = 1 << 12
    held_any = False
    for seed in range(6):
        y = power_law(1, n, np.random.default_rng(300 + seed))
        for kind, m2, fewest in (("avar", n // 9, 10), ("oavar", n // 9, 8),
                                 ("oavar", n // 7, 8)):
            alone = allan_variance(y, 1.0, [m2], kind=kind, noise_id="powerlaw").alpha[0]
            grid = allan_variance(y, 1.0, [n // 64, m2], kind=kind, noise_id="powerlaw").alpha
            if n // m2 < fewest:  # kept from n // 64 (64 averages: the lag-1 ACF's α)
                assert grid[1] == grid[0]
                held_any |= bool(alone != grid[0])
            else:
                assert grid[1] == alone
    assert held_any  # the rule changed something somewhere (else the test shows nothing)


def test_b1_compared_at_the_count_of_differences_for_non_overlapping_estimators() -> None:
    """B1's expected values are taken at N = the estimator's count of differences for ADEV
    (n − 1 of n averages), at N = n for OADEV (Stable32's larger overlapping count is not
    copied: it reads flicker FM as white FM). On 20 averages of flicker FM the large N does
    change the class, so the two paths are told apart."""
    n, m = 1 << 15, (1 << 15) // 20
    changed = 0
    for seed in range(10):
        y = power_law(-1, n, np.random.default_rng(39 + seed))
        ladder = Lag1Ladder(1, dmax=2, cross=False)
        ladder.push(y[: 20 * m].reshape(20, m).sum(axis=1))
        own = int(ladder.alpha(-2)[0])
        assert oavar(y, 1.0, [m]).alpha[0] == own
        assert allan_variance(y, 1.0, [m], kind="avar").alpha[0] == \
            int(ladder.alpha(-2, n_terms=19)[0])
        changed += int(ladder.alpha(-2, n_terms=n - 2 * m + 1)[0]) != own
    assert changed >= 5  # Stable32's overlapping N would move most of them (measured 8)
