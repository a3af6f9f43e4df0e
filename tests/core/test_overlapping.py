"""Streaming fully overlapping ADEV: equal to the batch estimator and to allantools, exact
against Stable32's published values through `avard analyze --json`, and its noise
identification against Stable32's own."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path

import allantools
import numpy as np
import pytest
from avard.core.allan.deviations import oavar
from avard.core.allan.overlapping import PIECE, OverlappingAllan
from avard.core.analysis.options import AnalyzeOptions
from avard.core.errors import DataError
from avard.core.io.source import RecordFormat, RecordInfo, StreamSource, open_record

from .stable32 import all_tau, octave_fixed_white_fm
from .test_allan import STABLE32, nbs14_1000
from .test_allan_noise_id import power_law

# Stable32's noise identification ("Alpha" column) in its Overlapping Allan run on PHASE.DAT
# (the NBS14 1000-point set integrated to 1001 phase points), every averaging factor Stable32
# printed (tests/core/stable32/phase_dat_oadev_all.txt; the same for its OHDEV run).
STABLE32_PHASE_DAT_ALPHA = {r.af: r.alpha for r in all_tau("oavar")}
# That run skips AF 128 (it steps by 2 there). In an octave run (analyze's grid) AF 128 has 7
# averages, fewer than the 8 below which Stable32 keeps the α of the next shorter τ of the run
# (noise_id.HOLD_BELOW_AVERAGES): 0 from AF 64, the "Alpha 0" its octave table prints.
STABLE32_OCTAVE_ALPHA_128 = 0
# Stable32 OADEV of the same set (octave run): m → σ, printed to 5 digits.
STABLE32_PHASE_DAT_OADEV = {r.af: r.dev for r in octave_fixed_white_fm()["oavar"]}


def _stream(y: np.ndarray, rate: float, ms: np.ndarray, block: int,
            gaps: tuple[int, ...] = (), covariance: bool = False) -> OverlappingAllan:
    acc = OverlappingAllan(1 if y.ndim == 1 else y.shape[1], rate, ms, covariance=covariance)
    edges = [0, *gaps, len(y)]
    for s0, s1 in itertools.pairwise(edges):
        for i in range(s0, s1, block):
            acc.update(y[i:min(i + block, s1)])
        acc.gap()
    return acc


@pytest.mark.parametrize("block", [1, 77, PIECE + 3, 1 << 16])
def test_streaming_equals_batch_and_allantools(block: int) -> None:
    y = nbs14_1000() if block == 1 else np.random.default_rng(block).normal(2.0, 0.3, 30000)
    n = 1000 if block == 1 else 30000
    y = y[:n]
    ms = 2 ** np.arange(int(np.log2(n // 2)) + 1)
    res = _stream(y, 10.0, ms, block).result()
    batch = oavar(y, 10.0, ms / 10.0)
    np.testing.assert_allclose(res.var, batch.var, rtol=1e-12)
    np.testing.assert_array_equal(res.n, batch.n)
    np.testing.assert_array_equal(res.alpha, batch.alpha)  # one α per τ for both
    np.testing.assert_allclose(res.edf, batch.edf, rtol=1e-12)
    _, dev, _, ns = allantools.oadev(y, rate=10.0, data_type="freq", taus=ms / 10.0)
    np.testing.assert_allclose(res.dev, dev, rtol=1e-10)
    np.testing.assert_array_equal(res.n, ns)


def test_integer_counts_exact_multichannel_with_gaps() -> None:
    rng = np.random.default_rng(2)
    y = rng.integers(-(1 << 19), 1 << 19, size=(40000, 3))
    y[:, 2] += 1 << 30  # a large offset: int64 sums stay exact
    ms = 2 ** np.arange(12)
    acc = _stream(y, 4.0, ms, 4093, gaps=(12345,), covariance=True)
    res = acc.result()
    batch = oavar(y, 4.0, ms / 4.0, gaps=[12345])
    np.testing.assert_allclose(res.var, batch.var, rtol=1e-13)
    assert res.cov is not None and batch.cov is not None
    np.testing.assert_allclose(res.cov, batch.cov, rtol=1e-12, atol=1e-9)
    no_cov = _stream(y, 4.0, ms, 4093, gaps=(12345,)).result()
    assert no_cov.cov is None
    np.testing.assert_array_equal(no_cov.var, res.var)
    np.testing.assert_array_equal(no_cov.alpha, res.alpha)
    # the exact sum for one channel and one τ, straight from the definition
    m = 64
    k = int(np.flatnonzero(ms == m)[0])
    total = 0
    for seg in (y[:12345, 0], y[12345:, 0]):
        x = np.concatenate([[0], np.cumsum(seg)]).astype(object)
        total += sum((x[i + 2 * m] - 2 * x[i + m] + x[i]) ** 2 for i in range(len(x) - 2 * m))
    assert res.var[k, 0] == pytest.approx(float(total) / (2 * m * m * res.n[k]), rel=1e-15)


def test_window_sum_and_three_cursor_paths_give_the_same_sums() -> None:
    """Every τ once through the window-sum path (m below the piece) and once through the
    three-cursor path (piece of 1): the same sums to the rounding of the float64 sums of
    squares (the differences themselves are exact for counts)."""
    rng = np.random.default_rng(8)
    ms = 2 ** np.arange(11)
    counts = rng.integers(-(1 << 19), 1 << 19, size=(9000, 2))
    floats = np.cumsum(rng.normal(0.0, 1e-3, (9000, 2)), axis=0) + 9.81
    for y in (counts, floats):
        runs = []
        for piece in (4096, 1):
            acc = OverlappingAllan(2, 10.0, ms, piece=piece)
            for i in range(0, len(y), 1000):
                acc.update(y[i:i + 1000])
            runs.append(acc.result())
        np.testing.assert_allclose(runs[0].var, runs[1].var, rtol=1e-12)
        np.testing.assert_array_equal(runs[0].n, runs[1].n)
        np.testing.assert_array_equal(runs[0].alpha, runs[1].alpha)


def test_memory_is_a_ring_of_two_m_max() -> None:
    acc = OverlappingAllan(2, 100.0, [1, 8, 512])
    acc.update(np.zeros((100000, 2)))
    assert acc._ring is not None and acc._ring.shape == (2, 2 * 512 + PIECE)


def test_bad_input_is_a_data_error() -> None:
    with pytest.raises(DataError, match="averaging"):
        OverlappingAllan(1, 1.0, [0, 2])
    acc = OverlappingAllan(2, 1.0, [1])
    with pytest.raises(DataError, match="shape"):
        acc.update(np.zeros((5, 3)))
    with pytest.raises(DataError, match="NaN"):
        acc.update(np.array([[0.0, np.nan]]))


def test_noise_identification_matches_stable32_on_phase_dat() -> None:
    """Where Stable32 uses the lag-1 ACF (≥ 30 averages) every α agrees; in its B1 region
    (4–29 averages) at least 80 % do: Stable32 separates white from flicker PM there with
    R(n) = MVAR/AVAR, which avard takes as flicker PM, and B1 on 4–7 averages is fragile."""
    ms = np.array(sorted(STABLE32_PHASE_DAT_ALPHA))
    res = oavar(nbs14_1000(), 1.0, ms)
    ref = np.array([STABLE32_PHASE_DAT_ALPHA[int(m)] for m in ms])
    lag1 = 1000 // ms >= 30
    np.testing.assert_array_equal(res.alpha[lag1], ref[lag1])
    agree = float(np.mean(res.alpha[~lag1] == ref[~lag1]))
    assert agree >= 0.80, agree


def test_streaming_identifies_every_power_law() -> None:
    """Every α from −2 to 2: exact with the lag-1 ACF (m = 1, 4: thousands of averages); with
    B1 on 20 averages (Stable32's method below 30, R(n) = MVAR/AVAR where B1 says PM) the
    ratio is a noisy statistic: measured 35 of 50 exact, never more than one B1 class off."""
    n = 1 << 15
    hits, total = 0, 0
    for alpha in (2, 1, 0, -1, -2):
        rng = np.random.default_rng(40 + alpha)
        for _ in range(10):
            y = power_law(alpha, n, rng)
            res = _stream(y, 1.0, np.array([1, 4, n // 20]), 5000).result()
            assert list(res.alpha[:2]) == [alpha, alpha]
            # B1's classes are −2, −1, 0 and PM (split into 1 and 2 by R(n)): a miss is a
            # neighbouring class, so white PM may read as white FM (0), never as −1
            assert abs(min(res.alpha[2], 1) - min(alpha, 1)) <= 1
            hits += int(res.alpha[2] == alpha)
            total += 1
    assert hits >= 0.6 * total, (hits, total)


def test_b1_at_the_count_of_averages_beats_stable32s_overlapping_count() -> None:
    """Why avard's overlapping estimators compare B1 at N = the n averages its ratio comes
    from, not at Stable32's count of overlapping differences (N − 2m + 1): on the FM power laws
    of ``test_streaming_identifies_every_power_law`` (20 averages), the latter names fewer
    records right (B1's flicker-FM expectation grows with N, so the ratio reads one type too
    white). docs/analysis.md gives the counts."""
    from avard.core.allan.noise_id import Lag1Ladder, alpha_from_b1

    n = 1 << 15
    m = n // 20
    ours, theirs = 0, 0
    for alpha in (0, -1, -2):
        rng = np.random.default_rng(40 + alpha)
        for _ in range(10):
            y = power_law(alpha, n, rng)
            lad = Lag1Ladder(1)
            k = n // m
            lad.push(y[:k * m].reshape(k, m).mean(axis=1))
            b1 = float(lad.b1()[0])
            ours += int(alpha_from_b1(b1, k) == alpha)
            theirs += int(alpha_from_b1(b1, n - 2 * m + 1) == alpha)
    assert ours > theirs, (ours, theirs)


def test_the_record_length_hint_keeps_r_n_only_where_b1_decides_and_changes_nothing() -> None:
    """``n_total`` (analyze of a file knows it) drops the R(n) sums of τ that will hold
    ≥ 30 averages from the start; on a gapless record every α, variance and bound is the
    same as without the hint, white PM told from flicker PM by R(n) at the long τ included."""
    n = 1 << 14
    grid = np.array([1, 4, 64, n // 20, n // 8, n // 4])
    for alpha in (2, 1):
        y = power_law(alpha, n, np.random.default_rng(7 + alpha))
        plain = OverlappingAllan(1, 1.0, grid)
        hinted = OverlappingAllan(1, 1.0, grid, n_total=n)
        assert [r is None for r in hinted._rn] == [n // m >= 30 for m in grid]
        for i in range(0, n, 3000):
            plain.update(y[i:i + 3000])
            hinted.update(y[i:i + 3000])
        a, b = plain.result(), hinted.result()
        assert list(a.alpha) == list(b.alpha)
        np.testing.assert_array_equal(a.var, b.var)
        np.testing.assert_array_equal(a.lo, b.lo)
        np.testing.assert_array_equal(a.hi, b.hi)
    with pytest.raises(DataError, match="n_total"):
        OverlappingAllan(1, 1.0, grid, n_total=-1)


def test_deferred_r_n_read_again_where_b1_says_pm_equals_keeping_it() -> None:
    """``defer_rn=True`` keeps no R(n) sums; where B1 then says PM, the channel fed again to an
    accumulator of those τ supplies them (``set_rn``) and every α, variance and bound is the
    one of keeping them all along. On FM noise nothing is asked for."""
    n = 1 << 14
    grid = np.array([1, 4, 64, n // 20, n // 8, n // 4])
    long_tau = [k for k, m in enumerate(grid) if n // m < 30]
    for alpha in (2, 1, 0):
        y = power_law(alpha, n, np.random.default_rng(17 + alpha))
        y2 = np.stack([y, power_law(-1, n, np.random.default_rng(3))], axis=1)  # PM, FM
        kept = OverlappingAllan(2, 1.0, grid, n_total=n)
        deferred = OverlappingAllan(2, 1.0, grid, n_total=n, defer_rn=True)
        assert all(r is None for r in deferred.rn_sums())
        for i in range(0, n, 3000):
            kept.update(y2[i:i + 3000])
            deferred.update(y2[i:i + 3000])
        need = deferred.rn_needed()
        if alpha == 0:
            assert need == {}
        else:
            # B1 says PM on the PM channel only, at the τ of its range
            assert need and set(need) <= set(long_tau)
            assert all(chans == [0] for chans in need.values())
        for ch in sorted({c for chans in need.values() for c in chans}):
            ks = list(need)
            extra = OverlappingAllan(1, 1.0, grid[ks])
            for i in range(0, n, 3000):
                extra.update(y2[i:i + 3000, ch])
            deferred.set_rn(ch, dict(zip(ks, extra.rn_sums(), strict=True)))
        a, b = kept.result(), deferred.result()
        np.testing.assert_array_equal(a.alpha, b.alpha)
        np.testing.assert_array_equal(a.var, b.var)
        np.testing.assert_array_equal(a.lo, b.lo)
        np.testing.assert_array_equal(a.hi, b.hi)
    with pytest.raises(DataError, match="n_total"):
        OverlappingAllan(1, 1.0, grid, defer_rn=True)
    with pytest.raises(DataError, match="not deferred"):
        OverlappingAllan(1, 1.0, grid, n_total=n).set_rn(0, {0: kept.rn_sums()[-1]})


def test_deferred_r_n_is_not_asked_for_where_the_shorter_tau_s_alpha_is_kept() -> None:
    """Below 8 averages the overlapping estimator keeps the α of the next shorter τ
    (HOLD_BELOW_AVERAGES): B1 may say PM there, but R(n) would go unread, so ``rn_needed``
    (taken from ``result()``'s own identification) does not ask for it; the result is still
    the one of keeping R(n) all along."""
    n = 1 << 14
    grid = np.array([1, 4, 64, n // 20, n // 6])  # 20 and 6 averages at the last two
    y = power_law(2, n, np.random.default_rng(31))
    kept = OverlappingAllan(1, 1.0, grid, n_total=n)
    deferred = OverlappingAllan(1, 1.0, grid, n_total=n, defer_rn=True)
    for acc in (kept, deferred):
        for i in range(0, n, 3000):
            acc.update(y[i:i + 3000])
    need = deferred.rn_needed()  # (which also pushes the averages still waiting)
    assert deferred._ladders[4].needs_rn()[0]  # B1 says PM at 6 averages ...
    assert need == {3: [0]}  # ... but only the 20-average τ's R(n) is asked for
    extra = OverlappingAllan(1, 1.0, grid[[3]])
    for i in range(0, n, 3000):
        extra.update(y[i:i + 3000])
    deferred.set_rn(0, {3: extra.rn_sums()[0]})
    a, b = kept.result(), deferred.result()
    np.testing.assert_array_equal(a.alpha, b.alpha)
    np.testing.assert_array_equal(a.lo, b.lo)


def test_analyze_of_a_file_reads_a_channel_again_only_for_r_n(tmp_path, monkeypatch,
                                                              caplog) -> None:
    """analyze of a file defers R(n) and reads again only the channel whose long τ B1 calls
    PM; its result is that of a one-shot stream of the same blocks, which keeps R(n) in the
    one pass."""
    from avard.core.analysis import engine as report

    n = 1 << 15
    y = np.stack([power_law(2, n, np.random.default_rng(21)) * 1e-3,
                  power_law(0, n, np.random.default_rng(22)) * 1e-3], axis=1)
    path = tmp_path / "pm_fm.npz"
    np.savez(path, accel=y, rate_hz=10.0, axes=np.array(["pm", "fm"]))
    reads: list[list[int]] = []
    lazy = report._accel

    def spy(source, block, columns, verify=True):
        reads.append(list(columns))
        return lazy(source, block, columns, verify)

    monkeypatch.setattr(report, "_accel", spy)
    with caplog.at_level("INFO", logger="avard.core.analysis.engine"):
        from_file = report.analyze(open_record(str(path)), AnalyzeOptions(find_sinusoids=False))
    # the pass over both channels, then the PM channel again for its R(n), said in the log
    assert reads == [[0, 1], [0]]
    assert [r.getMessage().split(" read again")[0] for r in caplog.records] == ["channel pm"]
    info = RecordInfo(source="stream", format=RecordFormat.STREAM, rate_hz=10.0,
                      names=("pm", "fm"), n_samples=n)
    blocks = ((y[i:i + (1 << 16)], None, False) for i in range(0, n, 1 << 16))  # the file's
    kept = report.analyze(StreamSource(info, blocks), AnalyzeOptions(find_sinusoids=False))
    pm = from_file.channels["pm"].allan
    assert 2 in pm.alpha[n // pm.m < 30]  # R(n) told white PM in B1's range
    for name in ("pm", "fm"):
        a, b = kept.channels[name].allan, from_file.channels[name].allan
        np.testing.assert_array_equal(b.alpha, a.alpha)
        np.testing.assert_array_equal(b.var, a.var)
        np.testing.assert_array_equal(b.lo, a.lo)


def test_nbs14_through_analyze_json_equals_stable32(tmp_path: Path) -> None:
    """`avard analyze nbs14.csv --rate 1 --json`: OADEV to Stable32's printed digits, α as
    Stable32 identifies it, and the 68.3 % bounds of the white-FM τ against Stable32's."""
    p = tmp_path / "nbs14.csv"
    p.write_text("y\n" + "".join(f"{float(v)!r}\n" for v in nbs14_1000()))
    out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "analyze", str(p),
                          "--rate", "1", "--json"], capture_output=True, text=True, check=True)
    d = json.loads(out.stdout)
    assert d["estimator"] == "oadev"
    ch = d["channels"]["y"]
    assert ch["estimator"] == "oadev"
    tau = [int(t) for t in ch["tau_s"]]
    assert tau == [1, 2, 4, 8, 16, 32, 64, 128]
    for m, ref in STABLE32_PHASE_DAT_OADEV.items():
        assert float(f"{ch['adev'][tau.index(m)]:.4e}") == ref
    assert float(f"{ch['adev'][tau.index(128)]:.4e}") == STABLE32[128][0]
    assert ch["alpha"] == [STABLE32_PHASE_DAT_ALPHA[m] if m != 128 else STABLE32_OCTAVE_ALPHA_128
                           for m in tau]
    k = tau.index(128)  # so its bounds are Stable32's (EDF 9.6 ≤ 100: exact quantiles, as its)
    np.testing.assert_allclose([ch["adev_lo"][k], ch["adev_hi"][k]], STABLE32[128][1:],
                               rtol=6e-4)
    # the CLI's α, EDF and bounds are the Python API's at every τ (one α per τ and estimator)
    api = oavar(nbs14_1000(), 1.0, tau)
    assert ch["alpha"] == list(api.alpha)
    np.testing.assert_allclose(ch["edf"], api.edf, rtol=1e-12)
    np.testing.assert_allclose([ch["adev_lo"], ch["adev_hi"]], [api.dev_lo, api.dev_hi],
                               rtol=1e-12)
    # bounds (exact χ² quantiles, the default): within 5e-5 at m = 64, about one unit of the
    # last printed digit; at m = 1 and 8, 1.4e-4 to 3.7e-4 relative, because Stable32 takes
    # its χ² quantile above 100 EDF from an approximation (A&S 26.4.17/26.2.22); the EDF is
    # GR's (782 and 166, as allantools). With --quantiles stable32 they equal its digits
    # (tests/core/test_allan.py).
    k = tau.index(64)
    np.testing.assert_allclose([ch["adev_lo"][k], ch["adev_hi"][k]], STABLE32[64][1:],
                               rtol=5e-5)  # 4.4e-5: about one unit of the last digit
    for m in (1, 8):
        k = tau.index(m)
        np.testing.assert_allclose([ch["adev_lo"][k], ch["adev_hi"][k]], STABLE32[m][1:],
                                   rtol=4e-4)


def test_the_oadev_reaches_n_over_4_or_says_where_memory_stopped_it(tmp_path, monkeypatch):
    """With room, the grid reaches m = N/4 (Stable32's range); with too little memory for the
    history, analyze stops earlier and says so in the table and the JSON."""
    from avard.core.analysis import engine as report

    n = 1 << 16
    rng = np.random.default_rng(5)
    path = tmp_path / "w.npz"
    np.savez(path, accel=rng.normal(0, 1e-3, (n, 3)), rate_hz=100.0)
    full = report.analyze(open_record(str(path)), AnalyzeOptions(find_sinusoids=False))
    assert int(full.channels["x"].allan.m[-1]) == n // 4 and "oadev_cut" not in full.to_dict()
    monkeypatch.setattr(report, "ring_budget_bytes", lambda: 8 * 3 * (PIECE + 2 * 1024))
    cut = report.analyze(open_record(str(path)), AnalyzeOptions(find_sinusoids=False))
    assert int(cut.channels["x"].allan.m[-1]) == 1024
    d = cut.to_dict()["oadev_cut"]
    assert d["tau_max_s"] == pytest.approx(10.24) and d["tau_full_s"] == pytest.approx(163.84)
    from avard.core.analysis.formats import format_table

    assert "OADEV stops at τ = 10.24 s, short of N/4 (163.8 s)" in format_table(cut)


def test_one_pass_per_channel_equals_one_pass_for_all(tmp_path, monkeypatch):
    """A long record is read once per channel (only one channel's history live); the result
    is the one pass over every channel's, channel for channel, spectrum and fit included."""
    from avard.core.analysis import engine as report

    n = 1 << 15
    rng = np.random.default_rng(6)
    y = rng.normal(0, 1e-3, (n, 3)) + np.array([0.0, 0.1, 9.81])
    y[:, 1] += 3e-4 * np.sin(2 * np.pi * 1.7 * np.arange(n) / 50.0)
    path = tmp_path / "three.npz"
    np.savez(path, accel=y, rate_hz=50.0)
    assert report.oadev_pass_groups([0, 1, 2], n) == [[0, 1, 2]]
    one = report.analyze(open_record(str(path)))
    # a budget for one channel's history at a time: three passes over the file
    monkeypatch.setattr(report, "PASS_BUDGET_BYTES", 8 * (2 * (n // 4) + PIECE))
    assert report.oadev_pass_groups([0, 1, 2], n) == [[0], [1], [2]]
    seen: list[tuple[int, int | None]] = []
    three = report.analyze(open_record(str(path)), progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (3 * n, 3 * n)
    assert list(three.channels) == ["x", "y", "z"]
    for name in "xyz":
        a, b = one.channels[name], three.channels[name]
        np.testing.assert_allclose(b.allan.var, a.allan.var, rtol=1e-13)
        np.testing.assert_array_equal(b.allan.alpha, a.allan.alpha)
        assert b.lines == a.lines
        assert b.fit.to_dict() == a.fit.to_dict()
    assert len(three.channels["y"].lines) == 1
    only_z = report.analyze(open_record(str(path)), AnalyzeOptions(channels=("z",)))
    np.testing.assert_allclose(only_z.channels["z"].allan.var, one.channels["z"].allan.var,
                               rtol=1e-13)
    # a CSV: the first pass takes the rows its reader has already parsed, the others reopen it
    csv = tmp_path / "three.csv"
    csv.write_text("x,y,z\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in y.tolist()))
    from_csv = report.analyze(open_record(str(csv), rate_hz=50.0))
    for name in "xyz":
        np.testing.assert_allclose(from_csv.channels[name].allan.var,
                                   one.channels[name].allan.var, rtol=1e-12)
