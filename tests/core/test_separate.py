"""core/analysis/separate.py: the Groslambert covariance and the three-cornered hat against
allantools, negative estimates as upper limits, and the alignment of records."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from avard.core.analysis.separate import (
    SensorRecord,
    align,
    covariance_interval,
    separate,
)
from avard.core.errors import DataError

allantools = pytest.importorskip("allantools")

RATE = 50.0


def _sensors(seed: int, n: int = 1 << 14, common: float = 0.5,
             own: tuple[float, ...] = (1.0, 2.0, 1.5)) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    c = np.cumsum(rng.normal(0, 0.02, n)) + rng.normal(0, common, n)   # a drifting bed
    return [(c + rng.normal(0, s, n))[:, None] * 1e-3 for s in own]


def _phase(y: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(y) / RATE])


def test_two_sensors_common_mode_equals_allantools_gcodev() -> None:
    ys = _sensors(1)[:2]
    ax = separate(ys, RATE, sensors=["a", "b"], axes=["z"], fit=False).axes[0]
    taus, gd, _err, _ns = allantools.gcodev(_phase(ys[0][:, 0]), _phase(ys[1][:, 0]), rate=RATE,
                                 data_type="phase", taus=ax.tau)
    assert len(taus) >= len(ax.tau) - 1          # allantools drops n ≤ 1 only
    compared = 0
    for t, g in zip(taus, gd, strict=True):
        k = int(np.argmin(np.abs(ax.tau - t)))
        assert ax.tau[k] == pytest.approx(t, rel=1e-12)
        # gcodev returns √|covariance| (it drops the sign)
        assert math.sqrt(abs(ax.common.var[k])) == pytest.approx(g, rel=1e-9)
        compared += 1
    assert compared >= 8


def test_three_sensors_self_noise_equals_allantools_three_cornered_hat() -> None:
    ys = _sensors(2)
    ax = separate(ys, RATE, sensors=["a", "b", "c"], axes=["z"], fit=False).axes[0]
    y = [v[:, 0] for v in ys]
    ab, bc, ca = _phase(y[0] - y[1]), _phase(y[1] - y[2]), _phase(y[2] - y[0])
    compared = 0
    for i, (p1, p2, p3) in enumerate(((ab, bc, ca), (bc, ca, ab), (ca, ab, bc))):
        taus, dev, _err, _ns = allantools.three_cornered_hat_phase(
            p1, p2, p3, RATE, ax.tau, allantools.oadev)
        for t, d in zip(taus, dev, strict=True):
            k = int(np.argmin(np.abs(ax.tau - t)))
            assert ax.tau[k] == pytest.approx(t, rel=1e-12)
            ours = ax.self_noise[i].var[k]
            if d > 0:   # allantools sets a negative variance to 0; ours keeps the sign
                assert math.sqrt(ours) == pytest.approx(d, rel=1e-9), (i, t)
                compared += 1
            else:
                assert ours <= 0.0
    assert compared >= 24


def test_a_sensor_without_own_noise_gets_upper_limits_never_a_negative_or_nan() -> None:
    """Sensor b is the bed itself (no own noise): its estimate is negative at some τ; the
    output says 'at most' there and nothing is NaN or negative."""
    ys = _sensors(3, own=(1.0, 0.0, 1.0))
    for s in (2, 3):
        sep = separate(ys[:s], RATE, sensors=["a", "b", "c"][:s], axes=["z"], fit=False)
        b = sep.axes[0].self_noise[1]
        assert np.any(b.var < 0) and np.all(b.upper_limit[b.var <= 0])
        for part in (*sep.axes[0].self_noise, sep.axes[0].common):
            assert np.all(np.isfinite(part.lo)) and np.all(part.lo >= 0)
            assert np.all(np.isfinite(part.hi)) and np.all(part.hi > 0)
            assert np.all(part.lo <= part.hi)
        d = sep.to_dict()
        json.dumps(d, allow_nan=False)     # no NaN anywhere in --json
        ul = d["axes"]["z"]["sensors"]["b"]["self_noise"]
        assert all(v is None for v, u in zip(ul["adev"], ul["upper_limit"], strict=True) if u)


def test_the_interval_for_a_single_channel_holds_the_chi_squared_one() -> None:
    """With U = V (P = Q = S) eq. 3 is one scaled χ²_ν, whose interval is the familiar
    [ν S / χ²_ν(1 − p), ν S / χ²_ν(p)]. The construction holds √(PQ) at the observed P̂Q̂
    for every S tested (covariance_interval), so its upper end is that one exactly, and its
    lower end lies below it (never narrower), by less as ν grows (P̂'s own spread shrinks)."""
    from avard.core.allan.chi2 import chi2_ppf

    s, nu = np.full(3, 2.0), np.array([10.0, 40.0, 1000.0])
    lo, hi, ul, nu_eff = covariance_interval(s, s, s, nu, 0.683)
    want_lo = nu * s / chi2_ppf(0.8415, nu)
    want_hi = nu * s / chi2_ppf(0.1585, nu)
    assert np.allclose(hi, want_hi, rtol=0.04)
    assert np.all(lo <= want_lo * 1.01)
    assert np.all(np.diff(lo / want_lo) > 0)             # the widening shrinks with ν
    assert lo[-1] >= 0.96 * want_lo[-1] and lo[0] >= 0.85 * want_lo[0]
    assert not ul.any() and np.allclose(nu_eff, nu)


def test_the_interval_is_the_same_with_quantiles_one_probability_at_a_time(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """covariance_interval takes its χ² quantiles from chi2_ppf_grid (one call for the whole
    grid); with them from chi2_ppf one probability at a time (the general path) every end,
    flag and EDF must be the same, for estimates above, at and below zero and EDF from 1 to
    10⁵ (series, fraction and quadrature)."""
    from avard.core.allan import chi2
    from avard.core.analysis import separate

    rng = np.random.default_rng(7)
    nu = np.concatenate([[1.0, 1.7, 40.0, 99.9, 100.0, 3e3], np.geomspace(2.0, 1e5, 14)])
    s = rng.uniform(0.5, 2.0, nu.size)
    s[::4] *= -0.4
    s[3] = 0.0
    big_p, big_q = s + rng.uniform(0.0, 3.0, nu.size), s + rng.uniform(0.0, 3.0, nu.size)
    fast = covariance_interval(s, big_p, big_q, nu, 0.683)
    calls: list[int] = []

    def one_at_a_time(ps: list[float], k: np.ndarray) -> np.ndarray:
        calls.append(len(ps))
        return np.array([chi2.chi2_ppf(float(p), k) for p in ps])

    monkeypatch.setattr(separate, "chi2_ppf_grid", one_at_a_time)
    general = covariance_interval(s, big_p, big_q, nu, 0.683)
    assert calls == [separate._GRID]
    assert fast[2].any() and not fast[2].all()          # both kinds of interval are held
    for f, g in zip(fast, general, strict=True):
        np.testing.assert_allclose(f, g, rtol=1e-9, atol=0)


def test_an_estimate_far_below_zero_keeps_the_upper_limit_a_zero_estimate_gives() -> None:
    """The sensitivity floor (Feldman & Cousins 1998 §V): inverting eq. 3 at an estimate far
    below 0 alone puts the upper end near 0 (every S then makes the observation a lower-tail
    one); the upper end must never fall below the one a zero estimate with the same P, Q and
    ν gives, and an estimate further below 0 never gets a tighter limit than a higher one."""
    big_p, big_q, nu = 1.0e4, 2.0, 50.0         # the bed 10⁴ × this sensor's own noise
    sd = math.sqrt(big_p * big_q / nu)          # Var Ŝ at S = 0 (eq. 3)
    s = np.array([-30.0, -10.0, -3.0, -1.0, -0.3, 0.0, 0.3, 1.0, 3.0]) * sd
    k = len(s)
    lo, hi, ul, _ = covariance_interval(s, np.full(k, big_p), np.full(k, big_q),
                                        np.full(k, nu), 0.683)
    at_zero = hi[5]
    assert at_zero > 0.5 * sd                   # about one standard deviation of Ŝ at S = 0
    assert np.all(hi[:5] >= at_zero * (1 - 1e-12)), hi / at_zero
    np.testing.assert_allclose(hi[:3], at_zero, rtol=1e-12)   # far below: exactly the floor
    assert np.all(np.diff(hi) >= -1e-12 * at_zero), hi / at_zero
    assert np.all(ul[:6]) and np.all(lo[:6] == 0.0)
    # a positive estimate's interval is the plain inversion of eq. 3 (the floor never binds)
    alone = covariance_interval(s[6:], np.full(3, big_p), np.full(3, big_q), np.full(3, nu))
    np.testing.assert_array_equal(alone[1], hi[6:])
    np.testing.assert_array_equal(alone[0], lo[6:])


def test_a_sensor_far_below_the_bed_gets_limits_that_do_not_collapse() -> None:
    """Two sensors whose own noise is 0.01× the bed's (records from the generator written
    apart from core/sim): the self-noise estimates are often far below 0; no upper end may
    fall orders of magnitude below the truth (without the floor some reached 10⁻³ of it)."""
    from tests.support.colocated import draw_record

    rng = np.random.default_rng(4)
    n, rate, worst, negative = 1 << 13, 20.0, np.inf, 0
    for _ in range(12):
        rec = draw_record(rng, 2, length=n, rate_hz=rate, ratio=100.0)
        sep = separate(list(rec.y[:, :, None]), rate, sensors=["a", "b"], axes=["z"],
                       fit=False)
        ax = sep.axes[0]
        for i, noise in enumerate(rec.sensors):
            part = ax.self_noise[i]
            negative += int(np.sum(part.var < 0))
            worst = min(worst, float(np.min(part.hi / noise.avar(ax.m, n, rate))))
    assert negative >= 20
    assert worst >= 0.1, worst


def _rec(n: int, rate: float = RATE, t0: float | None = None, seed: int = 0,
         names: tuple[str, ...] = ("x", "z"), u: float = 0.0) -> SensorRecord:
    a = np.random.default_rng(seed).normal(size=(n, len(names)))
    return SensorRecord(a, names, rate, u, t0, f"r{seed}")


def test_records_are_cut_to_the_time_they_share() -> None:
    a = _rec(1000, t0=100.0, seed=1)
    b = _rec(1000, t0=104.0, seed=2)              # starts 4 s = 200 samples later
    al = align([a, b])
    assert al.accels[0].shape == al.accels[1].shape == (800, 2)
    np.testing.assert_array_equal(al.accels[0], a.accel[200:1000])
    np.testing.assert_array_equal(al.accels[1], b.accel[:800])
    assert "aligned by time" in al.notes[0]


def test_records_that_do_not_overlap_are_refused() -> None:
    with pytest.raises(DataError, match="do not overlap in time"):
        align([_rec(1000, t0=0.0), _rec(1000, t0=50.0)])


def test_without_start_times_the_alignment_is_by_index_and_says_so() -> None:
    al = align([_rec(900, seed=1), _rec(1000, t0=3.0, seed=2)], ["z"])
    assert al.accels[0].shape == (900, 1) and al.axes == ("z",)
    assert "aligned by index" in al.notes[0]


def test_compatible_rates_are_not_resampled_and_incompatible_ones_are() -> None:
    a, b = _rec(2000, RATE, seed=1), _rec(2000, RATE * (1 + 20e-6), seed=2)
    al = align([a, b])
    np.testing.assert_array_equal(al.accels[1], b.accel)       # 20 ppm: one rate
    assert not any("resampled" in n for n in al.notes)
    c = _rec(4000, 2 * RATE, seed=3)
    al = align([a, c])
    assert al.rate_hz == RATE and al.accels[1].shape == (2000, 2)
    # each new sample is the mean of the two old ones it spans
    np.testing.assert_allclose(al.accels[1], c.accel.reshape(2000, 2, 2).mean(axis=1),
                               rtol=1e-9, atol=1e-12)
    assert any("resampled" in n for n in al.notes)


def test_bad_inputs_say_what_is_wrong() -> None:
    with pytest.raises(DataError, match="2 or 3"):
        align([_rec(100)])
    with pytest.raises(DataError, match="share no channel"):
        align([_rec(100, names=("x",)), _rec(100, names=("y",))])
    with pytest.raises(DataError, match="--channels q"):
        align([_rec(100), _rec(100)], ["q"])
    with pytest.raises(DataError, match="distinct sensor names"):
        separate(_sensors(1)[:2], RATE, sensors=["a", "a"], axes=["z"])


def test_sensors_started_a_fraction_of_a_sample_apart_pair_as_the_live_aligner_does() -> None:
    """The first record's samples are the ticks; each other's sample is the one nearest in
    time (daemon/service/separation_stage.Aligner), not each rounded from the latest start:
    b starts 0.625 samples after a, c 1.25: a's tick 1 pairs b's 0 and c's 0."""
    a = _rec(1000, t0=100.0, seed=1)
    b = _rec(1000, t0=100.0 + 0.625 / RATE, seed=2)
    c = _rec(1000, t0=100.0 + 1.25 / RATE, seed=3)
    al = align([a, b, c])
    n = al.accels[0].shape[0]
    np.testing.assert_array_equal(al.accels[0], a.accel[1:1 + n])
    np.testing.assert_array_equal(al.accels[1], b.accel[:n])
    np.testing.assert_array_equal(al.accels[2], c.accel[:n])
    assert n == 999


def test_a_recording_with_a_loss_is_separated_without_differences_across_it() -> None:
    """Recordings whose index jumps (samples lost by one sensor, others by the other) go the
    run-by-run way: the rows a sensor lacks are missing for its pairs, no difference
    straddles a loss, and the moments up to m = 8 (fully overlapping there) are those of the
    contiguous stretches both sensors hold, pooled by their counts of differences."""
    from avard.core.allan.deviations import allan_variance
    from avard.core.analysis.separate import aligned_runs, is_multi_run, separate_runs

    rng = np.random.default_rng(21)
    n, rate = 20_000, 125.0
    bed = rng.normal(0, 2e-4, n)
    ys = [bed + rng.normal(0, s, n) for s in (3e-4, 5e-4)]
    lost = [np.arange(5000, 5050), np.arange(12000, 12100)]        # a's loss, b's loss
    recs = []
    for name, y, gone in zip("ab", ys, lost, strict=True):
        keep = np.setdiff1d(np.arange(n), gone)
        recs.append(SensorRecord(y[keep][:, None], ("z",), rate, source=name, meta={
            "index": keep, "headers": [{"run": "r1", "i0": 0, "t_real": 1000.0,
                                        "rate_hz": rate}]}))
    assert is_multi_run(recs)
    runs = aligned_runs(recs)
    assert len(runs) == 1
    both = (runs[0].index >= 0).all(axis=0)
    assert int(both.sum()) == n - 150
    sep = separate_runs(runs, rate, sensors=["a", "b"], axes=["z"])
    assert sep.n_samples == n - 150
    ax = sep.axes[0]
    # the reference: each contiguous stretch both hold, batch OAVAR, pooled by differences
    edges = [0, 5000, 5050, 12000, 12100, n]
    num = np.zeros(len(ax.m))
    den = np.zeros(len(ax.m))
    for lo, hi in zip(edges[::2], edges[1::2], strict=True):
        a, b = ys[0][lo:hi], ys[1][lo:hi]
        res = allan_variance(np.column_stack([a, b, a - b]), rate, ax.m / rate, kind="oavar")
        k = np.isin(ax.m, res.m)
        at = np.searchsorted(res.m, ax.m[k])
        num[k] += (res.var[at, 0] - res.cov[at, 0, 1]) * res.n[at]
        den[k] += res.n[at]
    short = ax.m <= 8
    np.testing.assert_allclose(ax.self_noise[0].var[short], (num / den)[short], rtol=1e-9)


def test_with_few_averages_the_interval_is_never_narrower_than_either_construction() -> None:
    """Below ν = _FEW_NU (fewer than about 5 averages) P̂ and Q̂ are too uncertain to be held
    in the spread: the belt alone held the truth in only 49-57 % of the 68 % intervals at
    2 and 4 averages (docs/separate.md). There the interval must hold both the belt's and the
    central inversion's (other parts at the estimate, sensitivity floor); above, the belt's."""
    from avard.core.analysis import separate as sep

    s = np.array([-3.0, -1.0, 0.0, 0.5, 1.0, 2.0, 4.0])
    k = len(s)
    big_p, big_q = np.full(k, 6.0), np.full(k, 3.0)
    for nu_value in (1.5, 2.2, 3.9, 6.0):
        nu = np.full(k, nu_value)
        lo, hi, ul, _ = covariance_interval(s, big_p, big_q, nu, 0.683)
        x_over = sep.chi2_ppf_grid((np.arange(sep._GRID) + 0.5) / sep._GRID, nu) / nu
        b_lo, b_hi, b_ul = sep._belt(s, sep._Spread(big_p, big_q, x_over, None), 0.683)
        f_lo, f_hi, f_ul = sep._central_with_floor(s, big_p, big_q, x_over, 0.683)
        if nu_value < sep._FEW_NU:
            assert np.all(lo <= np.minimum(b_lo, f_lo)) and np.all(hi >= np.maximum(b_hi, f_hi))
            assert np.array_equal(ul, b_ul | f_ul)
            assert np.any(hi > b_hi) or np.any(lo < b_lo)      # the hull widens somewhere
        else:
            np.testing.assert_array_equal(lo, b_lo)
            np.testing.assert_array_equal(hi, b_hi)
        assert np.all(lo[ul] == 0.0) and np.all(lo <= hi)
