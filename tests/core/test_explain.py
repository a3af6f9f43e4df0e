"""`avard explain` on analyze's engine: the base model is analyze's fit of the same file; the
thermal model (first-order lag from the logged channel that drives the sensor) and the
transients are found with their parameters on records from a generator written apart from
the simulator (tests/support/hidden.py); null records stay clean."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.explain.causes import (
    min_detectable_sinusoid,
    min_detectable_step,
    min_detectable_warmup,
)
from avard.core.explain.engine import explain_file
from avard.core.explain.gauss_markov import (
    Z_GAUSS_MARKOV,
    gm_fisher,
    min_detectable_gauss_markov,
)
from avard.core.explain.options import ExplainOptions
from avard.core.explain.thermal_fit import min_detectable_tempco
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save


def _file(tmp_path, seed, truth=None, **kw):
    rec, truth = make_record(seed, truth=truth, **kw)
    return str(save(rec, tmp_path / f"h{seed}.npz")), truth


def test_base_model_is_analyzes_fit_of_the_same_file(tmp_path):
    path, _ = _file(tmp_path, 3, Truth(coefficient=(3e-4, 0, 0), lag_s=600.0), hours=2.0)
    an = analyze(open_record(path))
    ex = explain_file(open_record(path))
    assert list(ex.channels) == list(an.channels)
    for name, ch in an.channels.items():
        mine = ex.channels[name].base
        # same τ, same AVAR, same terms: values, intervals, presence and upper limits
        assert mine.to_dict() == ch.to_dict()
        for t, e in ch.fit.terms.items():
            assert mine.fit.terms[t] == e
        assert mine.fit.chi2_dof == ch.fit.chi2_dof


def _three_times_minimum(logged_amp: float, lag_s: float) -> float:
    """3× the stated minimum coefficient for the lag to 10 % (1 σ) and detection, for the
    generator's noise on a 4 h record and its 30-minute cycle (docs/explain.md)."""
    args = (1.6e-4, 2e-5, 2e-6, 4 * 3600.0, logged_amp, 1800.0, lag_s)
    return 3 * max(min_detectable_tempco(*args), min_detectable_tempco(*args, lag_rel=0.1))


AMBIENT = 0.5
PLATE = 0.5 / math.hypot(1.0, 2 * math.pi * 600.0 / 1800.0)  # the plate lags 10 min


@pytest.mark.parametrize(("logged", "drive", "lag_s"), [
    (("ambient",), "ambient", 120.0),
    (("ambient",), "ambient", 600.0),
    (("plate",), "plate", 300.0),
    (("plate", "ambient"), "ambient", 120.0),
    (("plate", "ambient"), "plate", 300.0),
])
def test_thermal_lag_coefficient_and_driving_channel(tmp_path, logged, drive, lag_s):
    """±0.5 °C ambient, 30-minute HVAC cycle, 4 h at 10 Hz, lags 2–20 min, plate- or
    ambient-logged, at 3× the stated minimum: lag and coefficient within 20 %, intervals
    holding the truth at 3 σ, the driving channel named."""
    c = _three_times_minimum(AMBIENT if drive == "ambient" else PLATE, lag_s)
    truth = Truth(coefficient=(c, 0.0, -c), lag_s=lag_s, drive=drive)
    path, _ = _file(tmp_path, 11 + int(lag_s), truth, logged=logged)
    ex = explain_file(open_record(path))
    for axis, coef in (("x", c), ("z", -c)):
        ch = ex.channels[axis]
        th = ch.thermal
        assert th is not None and th.passed, th
        # with both channels logged, the one that drives is named (the other is the same
        # signal through one more lag, which a single first-order lag cannot match)
        assert th.channel == drive
        assert th.coefficient == pytest.approx(coef, rel=0.2)
        assert abs(th.coefficient - coef) < 3 * th.coef_se
        assert th.lag_s == pytest.approx(lag_s, rel=0.2)
        assert th.lag_lo <= th.lag_s <= th.lag_hi
        assert [f.cause for f in ch.claimed] == ["temperature"]
        # the base model (analyze's) misfits where the cycle shows, and says so in σ
        assert any(r["tau_range_s"][0] <= 800.0 and r["tau_range_s"][1] >= 100.0
                   and r["max_sigma"] > 3 for r in ch.misfit), ch.misfit
        # the compensated ADEV is below the measured one where the HVAC cycle shows
        tau = ch.base.allan.tau
        k = int(np.argmin(np.abs(tau - 400.0)))
        assert ch.compensated_var is not None
        assert ch.compensated_var[k] < 0.7 * ch.base.allan.var[k]
        assert ch.gain > 1.0
    y = ex.channels["y"]
    assert not [f for f in y.claimed if f.cause != "sinusoid"], [f.evidence for f in y.claimed]


@pytest.mark.parametrize("logged", [("ambient",), ("plate", "ambient")])
def test_long_lag_is_found_on_its_channel(tmp_path, logged):
    """A 20-minute lag (ωτ ≈ 4 at the 30-minute cycle) at 3× the stated minimum for the lag
    to 10 %: found on the right channel, lag and coefficient within 20 %. Below that the
    channel is ambiguous: the plate (the ambient through 10 minutes) seen through another
    minute is 2° of phase from the ambient through 20 minutes at the cycle's period, and at
    1e-3 m/s²/K the plate won on 1 of 4 seeds."""
    c = _three_times_minimum(AMBIENT, 1200.0)
    truth = Truth(coefficient=(c, 0.0, 0.0), lag_s=1200.0, drive="ambient")
    path, _ = _file(tmp_path, 21, truth, logged=logged)
    th = explain_file(open_record(path),
                      ExplainOptions(channels=("x",), heldout=False)).channels["x"].thermal
    assert th is not None and th.passed
    if len(logged) == 2 and th.channel == "plate":
        # with both logged the channels are compared by held-out likelihood (chan23c): here
        # the plate through a short lag predicts the held-out halves as well as the ambient
        # through 20 minutes (within 2.26 standard errors of the difference), so the record
        # cannot tell them apart and the rule reports the shorter path; the ambient must be
        # named beside it, with its own lag and coefficient within 20 %
        assert "'ambient'" in th.channel_note and "cannot tell" in th.channel_note
        amb = th.others["ambient"]
        assert amb["lag_s"] == pytest.approx(1200.0, rel=0.2)
        assert amb["coefficient"] == pytest.approx(c, rel=0.2)
        return
    assert th.channel == "ambient"
    assert th.coefficient == pytest.approx(c, rel=0.2)
    assert th.lag_s == pytest.approx(1200.0, rel=0.2)


def test_null_record_is_clean(tmp_path):
    path, _ = _file(tmp_path, 5)
    ex = explain_file(open_record(path))
    for ch in ex.channels.values():
        assert not ch.claimed, [f.evidence for f in ch.claimed]
        assert ch.extended is ch.base.fit
        assert math.isclose(ch.gain, 1.0)


@pytest.fixture(scope="module")
def warmup_case(tmp_path_factory):
    """One warm-up record explained once for the two tests that read it."""
    size = 3 * min_detectable_warmup(1.6e-4, 2e-5, 2e-6, 900.0)
    path, _ = _file(tmp_path_factory.mktemp("warmup"), 7, Truth(warmup=(size, 900.0)))
    return size, explain_file(open_record(path))


def test_warmup_found_with_its_size(warmup_case):
    """A 15-minute warm-up at 3× its stated minimum size, on every axis: found, nothing
    else claimed, its size within 20 %."""
    size, ex = warmup_case
    for ch in ex.channels.values():
        claimed = {f.cause: f for f in ch.claimed}
        assert set(claimed) == {"warmup"}, [f.evidence for f in ch.claimed]
        assert claimed["warmup"].params["size"] == pytest.approx(size, rel=0.2)


def test_warmup_time_constant_within_20_percent(warmup_case):
    """Its time constant by generalised least squares with analyze's noise model (ordinary
    least squares scattered 15 % here and missed 20 % on one axis)."""
    _, ex = warmup_case
    for ch in ex.channels.values():
        p = {f.cause: f for f in ch.claimed}["warmup"].params
        assert p["time_constant_s"] == pytest.approx(900.0, rel=0.2)


def test_bias_step_found_where_it_is(tmp_path):
    """A bias step at 3× its stated minimum size, on every axis."""
    size = 3 * min_detectable_step(1.6e-4, 2e-5, 2e-6, 4 * 3600.0)
    truth = Truth(step=(5000.0, size))
    path, _ = _file(tmp_path, 8, truth)
    ex = explain_file(open_record(path))
    for ch in ex.channels.values():
        claimed = {f.cause: f for f in ch.claimed}
        assert set(claimed) == {"bias_step"}, [f.evidence for f in ch.claimed]
        assert claimed["bias_step"].params["time_s"] == pytest.approx(5000.0, rel=0.02)
        assert claimed["bias_step"].params["size"] == pytest.approx(size, rel=0.2)


def test_lag_scan_on_a_coarser_view_finds_the_same(tmp_path, monkeypatch):
    """Long records scan the lags on at most SCAN_POINTS block means; the result holds."""
    from avard.core.explain.thermal_fit import axes

    c = _three_times_minimum(AMBIENT, 600.0)
    path, _ = _file(tmp_path, 31, Truth(coefficient=(c, 0.0, 0.0), lag_s=600.0),
                    logged=("ambient",))
    monkeypatch.setattr(axes, "SCAN_POINTS", 1024)  # read where the lags are scanned
    th = explain_file(open_record(path), ExplainOptions(channels=("x",))).channels["x"].thermal
    assert th is not None and th.passed
    assert th.coefficient == pytest.approx(c, rel=0.2)
    assert th.lag_s == pytest.approx(600.0, rel=0.2)


def test_gauss_markov_bump_as_a_component_of_the_gls_fit(tmp_path):
    """A first-order Gauss–Markov process on every axis, at 3× the stated minimum for its
    parameters (σ and T to 10 %, 4 h at 10 Hz, T 10 s): claimed as a component of analyze's
    GLS fit, the fit improved, σ and T within 20 %."""
    sigma = 3 * min_detectable_gauss_markov(1.6e-4, 2e-5, 2e-6, 10.0, 4 * 3600, 10.0, rel=0.1)
    path, _ = _file(tmp_path, 41, Truth(gauss_markov=(sigma, 10.0)))
    ex = explain_file(open_record(path), ExplainOptions(heldout=False))
    for ch in ex.channels.values():
        gm = {f.cause: f for f in ch.claimed}.get("gauss_markov")
        assert gm is not None, [f.evidence for f in ch.findings]
        assert gm.params["sigma"] == pytest.approx(sigma, rel=0.2)
        assert gm.params["time_constant_s"] == pytest.approx(10.0, rel=0.2)
        lo, hi = gm.intervals["sigma"]
        assert lo < gm.params["sigma"] < hi
        # T's profile interval brackets it, half-width the Fisher error (5.4 %) within 2×
        t_lo, t_hi = gm.intervals["time_constant_s"]
        T = gm.params["time_constant_s"]
        assert t_lo < T < t_hi
        assert 0.027 < (t_hi - t_lo) / (2 * T) < 0.11
        assert any(e["cause"] == "gauss_markov" and e["present"] for e in ch.extended.extra)
        assert ch.gain > 1.0


@pytest.mark.parametrize(("times", "found"), [(3.0, True), (1 / 3, False)])
def test_sinusoid_at_its_stated_minimum(tmp_path, times, found):
    """A sinusoid on every axis at 3× the stated minimum for analyze's line finder (4 h,
    10 Hz, 0.137 Hz, between Welch bins): found on every axis with its amplitude within
    20 %; at a third of it, on none."""
    f0 = 0.137
    amp = times * min_detectable_sinusoid(1.6e-4, 2e-5, 2e-6, 4 * 3600, 10.0, f0)
    path, _ = _file(tmp_path, 51, Truth(sinusoid=(amp, f0)), logged=("ambient",))
    ex = explain_file(open_record(path), ExplainOptions(heldout=False))
    for ch in ex.channels.values():
        near = [f for f in ch.claimed if f.cause == "sinusoid"
                and abs(f.params["frequency_hz"] - f0) < 3 * 10.0 / 16384]
        assert bool(near) is found, [f.evidence for f in ch.findings]
        if found:
            assert near[0].params["amplitude"] == pytest.approx(amp, rel=0.2)
        assert not [f for f in ch.claimed if f.cause != "sinusoid"]


def test_gauss_markov_minimum_is_where_the_fisher_errors_reach_their_target():
    """The stated minimum is the σ at which the GLS fit's Fisher errors of σ and T reach
    10 % (just below it they do not); a longer record lowers it; a T too long for the record
    (its own scatter's floor above 10 %) or outside the scanned range has none."""
    args = (1.6e-4, 2e-5, 2e-6)
    s = min_detectable_gauss_markov(*args, 30.0, 4 * 3600, 10.0, rel=0.1)
    assert math.isfinite(s)
    assert max(gm_fisher(s, 30.0, *args, 4 * 3600, 10.0)[:2]) <= 0.1
    assert max(gm_fisher(0.95 * s, 30.0, *args, 4 * 3600, 10.0)[:2]) > 0.1
    assert min_detectable_gauss_markov(*args, 30.0, 24 * 3600, 10.0, rel=0.1) < s
    assert math.isinf(min_detectable_gauss_markov(*args, 600.0, 4 * 3600, 10.0, rel=0.1))
    assert math.isinf(min_detectable_gauss_markov(*args, 1e5, 4 * 3600, 10.0))
    d = min_detectable_gauss_markov(*args, 30.0, 4 * 3600, 10.0)
    assert gm_fisher(d, 30.0, *args, 4 * 3600, 10.0)[2] >= Z_GAUSS_MARKOV > gm_fisher(
        0.95 * d, 30.0, *args, 4 * 3600, 10.0)[2]


def test_base_model_is_analyzes_fit_of_a_restarted_recording(tmp_path):
    """Back-to-back runs with zero-length restart gaps: the index is contiguous, yet the
    service split its accumulators at every run change. explain reads the recording through
    analyze's one segment iterator, so its base model is analyze's fit here too (a copy that
    split only at index jumps once averaged across the restarts)."""
    from .test_recording_walk import _write_run

    i0 = 0
    for k in range(4):
        _write_run(tmp_path, f"n0000000{k + 1}-20260101T00000{k}Z-r", i0, 60, seed=40 + k,
                   restart_gap=k > 0, offset=5000.0 * k)
        i0 += 60 * 50
    an = analyze(open_record(str(tmp_path)), AnalyzeOptions(find_sinusoids=False))
    ex = explain_file(open_record(str(tmp_path)), ExplainOptions(heldout=False))
    for name, ch in an.channels.items():
        mine = ex.channels[name].base
        np.testing.assert_array_equal(mine.allan.tau, ch.allan.tau)
        np.testing.assert_allclose(mine.allan.dev, ch.allan.dev, rtol=1e-12)


def test_coupled_weekend_record_start_is_not_a_warm_up(tmp_path) -> None:
    """A 6 h, 1 Hz record of the weekend generator (tests/support/weekend.py, written apart
    from the simulator): the datasheet-typical 2e-4 m/s²/K through a 300 s die lag from the
    ambient channel, nothing else hidden. With the lag filter's start state fitted against
    the whole record's line, this seed's x axis was claimed a warm-up (T ≈ the lag) beside
    the coupling; the coupling is claimed, and nothing else on any axis."""
    from tests.support.weekend import Weekend
    from tests.support.weekend import save as save_weekend

    w = Weekend(hours=6.0, rate_hz=1.0, logged=("ambient",), plate_tau_s=0.0,
                die_tau_s=300.0, coefficient=(2e-4, 0.0, 0.0))
    ex = explain_file(open_record(str(save_weekend(6, w, tmp_path / "w.npz"))),
                      ExplainOptions(heldout=False))
    claims = {a: sorted(f.cause for f in ch.claimed if f.cause not in ("sinusoid", "periodic"))
              for a, ch in ex.channels.items()}
    assert claims == {"x": ["temperature"], "y": [], "z": []}


def test_a_warm_up_on_a_coupled_axis_is_claimed_beside_the_coupling(tmp_path) -> None:
    """A 4 h weekend record (tests/support/weekend.py): 1.98e-3 m/s²/K from the ambient
    channel through a 300 s lag and a 2.39e-3 m/s², 900 s warm-up on x (each 3× its stated
    minimum). The thermal model's start state (its own settling, of any size) and its paths
    took the warm-up over: this seed was read as a dT/dt path with a 856 s lag and no warm-up
    (issue 23, wu23's seeds 100–103). The warm-up is now tested against the start state and
    taken out before the path is chosen: the coupling and the warm-up are both claimed, with
    their parameters within 20 %."""
    from tests.support.weekend import Weekend
    from tests.support.weekend import save as save_weekend

    w = Weekend(hours=4.0, rate_hz=10.0, logged=("ambient",), plate_tau_s=0.0,
                die_tau_s=300.0, coefficient=(1.98e-3, 0.0, 0.0), warmups=[(2.39e-3, 900.0)])
    ex = explain_file(open_record(str(save_weekend(101, w, tmp_path / "w.npz"))),
                      ExplainOptions(heldout=False))
    x = {f.cause: f for f in ex.channels["x"].claimed if f.cause not in ("sinusoid",
                                                                         "periodic")}
    assert sorted(x) == ["temperature", "warmup"], sorted(x)
    assert x["temperature"].mechanism == "one_lag"
    assert x["temperature"].params["lag_s"] == pytest.approx(300.0, rel=0.2)
    assert x["temperature"].params["coefficient"] == pytest.approx(1.98e-3, rel=0.2)
    assert x["warmup"].params["time_constant_s"] == pytest.approx(900.0, rel=0.2)
    assert x["warmup"].params["size"] == pytest.approx(2.39e-3, rel=0.2)
    for a in ("y", "z"):
        assert not [f for f in ex.channels[a].claimed if f.cause not in ("sinusoid", "periodic")]
