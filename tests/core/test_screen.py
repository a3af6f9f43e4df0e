"""The input screen (core/io/screen.py): what a real weekend's logs hold besides the sensor's
noise (DS18B20 85.0 °C power-on values, −127 °C read errors, spikes, dropouts, stuck readings;
acceleration start-up glitches and isolated shocks) masked, counted and listed by analyze and
explain alike, a masked stretch a gap to the estimators."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.screen import (
    ScreenLog,
    screen_accel,
    screen_blocks,
    screen_temperature,
    stuck_runs,
)
from avard.core.io.screen.temperature import STUCK_MIN_S
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save


def _noise(n, seed=0, rw=1e-4):
    rng = np.random.default_rng(seed)
    a = 1e-3 * rng.standard_normal((n, 3))
    a += np.cumsum(rw * rng.standard_normal((n, 3)), axis=0)  # a wander the rule must ignore
    return a


def test_clean_noise_a_step_and_a_drift_are_not_masked():
    a = _noise(200_000)
    a[100_000:, 0] += 0.02  # a bias step of 20 sample-σ: real, never masked
    a[:, 1] += np.linspace(0, 0.5, len(a))
    assert not screen_accel(a).any()


def test_glitch_and_shock_are_masked_with_their_margin():
    a = _noise(50_000, 1)
    a[:3] += 0.5  # a 3-sample start-up glitch, every axis
    a[30_000, 2] -= 0.05  # one shocked sample on one axis
    bad = screen_accel(a)
    assert set(np.flatnonzero(bad)) == {0, 1, 2, 3, 4, *range(29_998, 30_003)}


def test_temperature_rules():
    v = 21.0 + 0.0625 * np.round(np.sin(np.arange(400) / 40.0) * 8) / 1.0
    v[0] = 85.0  # power-on value as the first reading
    v[50] = 85.0
    v[120] = -127.0
    v[200] += 1.0  # a one-reading spike
    got = dict((i, k) for i, k in screen_temperature(v))
    assert got == {0: "power_on_85", 50: "power_on_85", 120: "read_error", 200: "spike"}
    # a room really at 85 °C is not a power-on value; a real 1 K step is not a spike
    hot = np.full(50, 85.0)
    hot[::2] = 84.9375
    step = np.r_[np.full(20, 21.0), np.full(20, 22.0)]
    assert screen_temperature(hot) == [] and screen_temperature(step) == []


def test_stuck_is_judged_by_the_rooms_own_variation():
    t = np.arange(0, 24 * 3600, 1.0)
    # a stable room: the same 0.0625 K step for hours at a time is normal, never "stuck"
    stable = 21.0 + 0.0625 * np.floor(t / (5 * 3600))
    assert stuck_runs(t, stable) == []
    # a room whose reading changes every few minutes, then the sensor freezes for 2 h
    cycling = 21.0 + 0.0625 * np.round(8 * np.sin(2 * math.pi * t / 1800))
    i0, i1 = 36_000, 36_000 + 7200
    cycling[i0:i1] = cycling[i0]
    runs = stuck_runs(t, cycling)
    assert len(runs) == 1 and t[runs[0][1]] - t[runs[0][0]] > STUCK_MIN_S
    assert runs[0][0] <= i0 and runs[0][1] >= i1 - 1


def test_masked_rows_become_a_segment_end_and_the_log_lists_them():
    a = _noise(3 * 4096, 2)
    a[5000] += 0.5
    blocks = [(a[i:i + 4096], None, i + 4096 >= len(a)) for i in range(0, len(a), 4096)]
    log = ScreenLog(100.0)
    out = list(screen_blocks(iter(blocks), 100.0, ["x", "y", "z"], [], log))
    assert sum(len(b[0]) for b in out) == len(a) - 5  # the shock and its margin, nothing else
    ends = [b[2] for b in out]
    assert ends.count(True) == 2 and ends[-1]  # one before the cut, one at the record's end
    assert log.done and [(s.kind, s.first, s.last) for s in log.stretches] == [
        ("shock", 4998, 5002)]
    assert log.to_dict()["samples_masked"] == 5


def test_analyze_cuts_a_startup_glitch_as_a_gap(tmp_path):
    """A 3-sample start-up glitch sent analyze's χ²/dof to thousands; screened, the fit is the
    clean record's, and the text and JSON say what was cut."""
    rec, _ = make_record(3, hours=1.0, logged=("ambient",))
    clean = analyze(open_record(save(rec, tmp_path / "clean.npz")), AnalyzeOptions(channels=("x",)))
    rec.accel[:3] += 0.5
    an = analyze(open_record(save(rec, tmp_path / "glitch.npz")), AnalyzeOptions(channels=("x",)))
    assert an.channels["x"].fit.chi2_dof < 2 * clean.channels["x"].fit.chi2_dof + 1
    d = an.to_dict()["screened"]
    assert d["counts"] == {"startup_glitch": 1} and d["stretches"][0]["start_s"] == 0.0
    from avard.core.analysis.formats import format_table

    assert "start-up glitch at 0–0.5 s" in format_table(an)


def test_power_on_values_do_not_hide_a_coupling_and_a_dropout_is_no_step(tmp_path):
    """Three 85.0 °C readings hid a z = 142 coupling; a 25-minute hole in the temperature log
    was claimed as a bias step on the accelerometer. Screened: the coupling is found, the hole
    is listed and no transient is claimed on the axis."""
    rec, _ = make_record(3, hours=4.0, logged=("ambient",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=300.0))
    t = rec.temperature_c
    i0 = int(0.4 * len(t))
    t[i0:i0 + int(1500 * rec.rate_hz)] = np.nan
    ok = np.flatnonzero(np.isfinite(t[:, 0]))
    for k in (100, 5000, 9000):
        t[ok[k], 0] = 85.0
    ex = explain_file(open_record(save(rec, tmp_path / "faulty.npz")),
                      ExplainOptions(channels=("x",), heldout=False))
    ch = ex.channels["x"]
    assert ch.thermal is not None and ch.thermal.passed and ch.thermal.z > 20
    assert abs(ch.thermal.coefficient / 3e-3 - 1) < 0.1
    # the hole and the lag's settling after it are gaps of the regression, not its data
    assert abs(ch.thermal.lag_s - 300.0) < 0.2 * 300.0
    assert [f.cause for f in ch.claimed] == ["temperature"]
    assert ex.screen is not None
    assert ex.screen.counts() == {"power_on_85": 3, "dropout": 1}
    d = ex.to_dict()["screened"]
    assert {s["kind"] for s in d["stretches"]} == {"power_on_85", "dropout"}


def test_a_chip_filters_correlated_samples_are_not_shocks():
    """Heavily low-passed noise (AR(1), ρ = 0.95: first differences a third of the spread)
    over 2e6 samples: nothing masked; a shock of 15 spreads still is."""
    rng = np.random.default_rng(7)
    n = 2_000_000
    e = rng.standard_normal(n)
    rho = 0.95
    from itertools import accumulate

    x = np.fromiter(accumulate(e, lambda s, v: rho * s + v), float, n)
    a = np.column_stack([x, x[::-1], -x])
    assert not screen_accel(a).any()
    a[1_000_000, 0] += 15 * x.std()
    assert set(np.flatnonzero(screen_accel(a))) == set(range(999_998, 1_000_003))


def test_a_second_read_cuts_the_same_rows_without_judging_again(tmp_path, monkeypatch):
    """Every pass over a record (one per channel group) cuts the same rows: the first read's
    verdicts are reused, the axes are not judged again."""
    import avard.core.io.screen.stream as screen_mod
    from avard.core.io.screen.stream import ScreenedSource

    rng = np.random.default_rng(2)
    y = rng.normal(0, 1e-3, (50_000, 3))
    y[30_000:30_002] += 0.5
    path = tmp_path / "s.npz"
    np.savez(path, accel=y, rate_hz=100.0)
    src = ScreenedSource(open_record(path))
    first = list(src.blocks(4096, columns=[0, 1, 2], temperature=False))
    calls = []
    real = screen_mod.screen_accel
    monkeypatch.setattr(screen_mod, "screen_accel", lambda a: calls.append(1) or real(a))
    again = list(src.blocks(4096, columns=[2], temperature=False))
    assert not calls
    assert [len(a) for a, _t, _e in again] == [len(a) for a, _t, _e in first]
    assert [e for _a, _t, e in again] == [e for _a, _t, e in first]
    for (a, _t, _e), (b, _u, _f) in zip(first, again, strict=True):
        np.testing.assert_array_equal(a[:, 2], b[:, 0])
    assert src.log is not None and src.log.counts() == {"shock": 1}


def test_the_median_floor_skips_only_blocks_the_exact_scale_also_passes(monkeypatch):
    """The screen skips a block's median where a proven floor of it already leaves every
    sample below the test (``_median_floor``): on blocks from clean Gaussian noise to tails
    heavy enough that samples sit at the threshold, quantised to a few LSB (ties), a dead
    axis (median 0) and a non-finite value, the verdicts are those of the exact median on
    every block, and the floor is never above the median it stands for."""
    import avard.core.io.screen.accel as screen_mod

    rng = np.random.default_rng(2024)
    blocks = []
    for k in range(48):
        n = int(rng.choice([40, 1000, 65536]))
        kind = k % 6
        if kind == 0:
            a = rng.standard_normal((n, 3))
        elif kind in (1, 2):  # Student t: 3 and 6 dof put samples either side of 12 σ
            a = rng.standard_t(3 if kind == 1 else 6, (n, 3))
        elif kind == 3:  # a few LSB of noise: the distances take few values
            a = np.round(rng.standard_normal((n, 3)) * 1.5) * 0.25
        elif kind == 4:  # a dead axis beside a live one with a shock
            a = rng.standard_normal((n, 3))
            a[:, 1] = 9.81
            a[n // 2, 0] += 40.0
        else:  # a shock near the threshold on a wandering axis
            a = np.cumsum(0.01 * rng.standard_normal((n, 3)), axis=0)
            a += rng.standard_normal((n, 3))
            a[n // 3, 2] += rng.uniform(6.0, 14.0)
        blocks.append(a)
    inf_block = rng.standard_normal((1000, 3))
    inf_block[500, 0] = np.inf
    blocks.append(inf_block)

    floors = []
    real = screen_mod._median_floor

    def recorded(x):
        v = real(x)
        floors.append((v, float(np.median(x))))
        return v

    # (numpy's path of the statistic warns on inf − inf; analyze never hands it an inf)
    with np.errstate(invalid="ignore"):
        monkeypatch.setattr(screen_mod, "_median_floor", recorded)
        fast = [screen_accel(a) for a in blocks]
        monkeypatch.setattr(screen_mod, "_median_floor", lambda x: 0.0)
        exact = [screen_accel(a) for a in blocks]
    for f, e in zip(fast, exact, strict=True):
        np.testing.assert_array_equal(f, e)
    assert all(v <= med or math.isnan(med) for v, med in floors)
    assert sum(v > 0 for v, _m in floors) > len(floors) // 2  # the floor is found on most
    assert sum(v == 0 for v, _m in floors) > 0  # and refused where it is not proven
    assert sum(e.any() for e in exact) >= 8 and sum(not e.any() for e in exact) >= 8


def test_every_fault_of_a_generator_written_apart_is_screened_and_said_in_words(tmp_path):
    """The adversary's generator (tests/support/adversary_gen.py: its own DS18B20 model, read
    every 1 or 2 s, its own faults): every 85.0 °C, −127 °C, spike, dropout and 30-min+ stuck
    run it injects is masked at its time, and the text counts them in plain words (it read
    "2 read error (-127 °C or out of range)s" and "(1 readings)")."""
    from avard.core.io.screen.stream import ScreenedSource

    from tests.support.adversary_gen import make_record as adversary_record

    truth = adversary_record("null_faulty", 202, tmp_path / "faulty.npz", hours=2.0)
    src = ScreenedSource(open_record(tmp_path / "faulty.npz"))
    for _ in src.blocks():
        pass
    log = src.log
    assert log is not None
    f = truth["faults"]
    assert log.counts() == {"power_on_85": 3, "read_error": 2, "spike": 2, "dropout": 1,
                            "stuck": 1, "startup_glitch": 1, "shock": 1}
    for kind, key in (("power_on_85", "power_on_85_s"), ("read_error", "read_error_s"),
                      ("spike", "spike_s")):
        starts = [s.start_s for s in log.stretches if s.kind == kind]
        assert all(min(abs(t - s) for s in starts) < 1.0 for t in f[key]), (kind, starts)
    (d0, d1), = f["dropout_s"]
    (drop,) = [s for s in log.stretches if s.kind == "dropout"]
    assert abs(drop.start_s - d0) < 3.0 and abs(drop.end_s - d1) < 3.0
    text = "\n".join(log.lines(limit=20))
    assert "2 read errors (-127 °C or out of range)" in text and ")s" not in text
    assert "1 dropout (no reading)" in text and "3 85.0 °C power-on values" in text
    assert "(1 reading)" in text and "(1 readings)" not in text


@pytest.mark.parametrize("compiled", [True, False])
def test_a_record_on_its_lsb_grid_is_not_cut_by_the_sums_rounding(compiled, monkeypatch):
    """Noise of 0.2 LSB rounded to the ADXL355's 3.83e-5 m/s²: most samples equal their
    neighbours' mean, the exact robust scale is 0 and nothing is judged. The compiled moving
    sum left a residue of ~1e-21 there, which became the scale: every ±1 LSB sample was cut
    as a 12 σ shock and analyze then called the channel constant."""
    from avard.core.allan import kernels
    from avard.core.io.screen import screen_accel

    if compiled and kernels.compiled() is None:
        pytest.skip("no compiled kernels here")
    if not compiled:
        monkeypatch.setattr(kernels, "compiled", lambda: None)
    rng = np.random.default_rng(7)
    lsb = 3.9e-6 * 9.80665
    # a block as long as analyze reads (the residue grows with the window's run)
    a = np.round(rng.normal(0.0, 0.2, (1 << 16, 3))) * lsb
    assert np.count_nonzero(a) > 1000    # there are steps to cut
    assert not screen_accel(a).any()
