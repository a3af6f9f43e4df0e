"""The transient causes of `avard explain` (``core/explain/causes.py``): a warm-up and a bias
step in the same record are both found (they compose), and each comes with 68 % intervals
from its generalised least-squares fit that hold the truth about 68 % of the time.

Records come from tests/support/hidden.py, a generator written apart from the simulator;
explain sees only the file. Sizes are 3× the stated minima (docs/explain.md "Stated detection
power (transients)")."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.explain import causes as cz
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save

N, B, K = 1.6e-4, 2e-5, 2e-6
HOURS = 4.0
T_WARM, T_STEP = 900.0, 5000.0
WARM = 3 * cz.min_detectable_warmup(N, B, K, T_WARM)
STEP = 3 * cz.min_detectable_step(N, B, K, HOURS * 3600)
BOTH = Truth(warmup=(WARM, T_WARM), step=(T_STEP, STEP))
#: the truth of each transient parameter, by (cause, parameter)
TRUE = {("warmup", "size"): WARM, ("warmup", "time_constant_s"): T_WARM,
        ("bias_step", "size"): STEP, ("bias_step", "time_s"): T_STEP}


def _explain(tmp_path, seed: int, truth: Truth):
    rec, _ = make_record(seed, hours=HOURS, truth=truth, logged=("ambient",))
    return explain_file(open_record(str(save(rec, tmp_path / f"c{seed}.npz"))),
                        ExplainOptions(heldout=False))


def _claimed(ch) -> dict:
    return {f.cause: f for f in ch.claimed if f.cause != "sinusoid"}


def test_warmup_and_step_in_one_record_are_both_found(tmp_path):
    """Each at 3× its stated minimum on every axis: both claimed, parameters within 20 %
    (step time within 1 % of the record), each parameter with an interval around its value."""
    ex = _explain(tmp_path, 11, BOTH)
    for name, ch in ex.channels.items():
        got = _claimed(ch)
        assert set(got) == {"warmup", "bias_step"}, (name, [f.evidence for f in ch.findings])
        w, s = got["warmup"], got["bias_step"]
        assert w.params["size"] == pytest.approx(WARM, rel=0.2)
        assert w.params["time_constant_s"] == pytest.approx(T_WARM, rel=0.2)
        assert s.params["size"] == pytest.approx(STEP, rel=0.2)
        assert abs(s.params["time_s"] - T_STEP) < 0.01 * HOURS * 3600
        for f in (w, s):
            assert set(f.intervals) == set(f.params)
            for k, (lo, hi) in f.intervals.items():
                assert lo < f.params[k] < hi, (f.cause, k, lo, hi)


def test_transient_intervals_reach_the_json(tmp_path):
    """The intervals are part of the finding's JSON (``--json``), not only of the text."""
    ex = _explain(tmp_path, 12, Truth(warmup=(WARM, T_WARM)))
    f = _claimed(ex.channels["x"])["warmup"].to_dict()
    assert set(f["intervals"]) == {"size", "time_constant_s"}
    lo, hi = f["intervals"]["size"]
    assert 0 < lo < f["params"]["size"] < hi


def test_no_heldout_headline_when_every_claimed_cause_is_an_event(tmp_path):
    """A warm-up and a step predict no other data (their held-out gain is near 0 by design),
    so the headline held-out gain is null with that reason; each axis keeps its own χ²."""
    rec, _ = make_record(14, hours=HOURS, truth=BOTH, logged=("ambient",))
    ex = explain_file(open_record(str(save(rec, tmp_path / "e.npz"))),
                      ExplainOptions(channels=("x",)))
    assert ex.holdout is not None
    assert {f.cause for f in ex.channels["x"].claimed} == {"warmup", "bias_step"}
    d = ex.to_dict()
    assert d["holdout_gain"] is None
    assert "event" in d["holdout"]["reason"]
    ch = d["holdout"]["channels"]["x"]
    assert ch["gain"] is not None and ch["note"] is not None


@pytest.mark.parametrize(("truth", "cause"), [
    (Truth(warmup=(WARM, T_WARM)), "warmup"),
    (Truth(step=(T_STEP, STEP)), "bias_step"),
])
def test_single_transient_is_not_also_claimed_as_the_other(tmp_path, truth, cause):
    """Composing the tests must not turn one transient into two: a warm-up alone is not
    also reported as a step (its fitted shape removed, the step test sees only its leftover),
    and a step alone not as a warm-up."""
    ex = _explain(tmp_path, 13, truth)
    for name, ch in ex.channels.items():
        assert set(_claimed(ch)) == {cause}, (name, [f.evidence for f in ch.findings])


def test_profile_interval_reads_the_crossings_between_grid_points():
    """Δχ² = 1 on a parabola χ² = (x − 3)²/0.5²: the interval is 3 ± 0.5, whatever the grid;
    a profile that never rises far enough stops at the grid's edge (open)."""
    x = np.linspace(0.0, 7.0, 15)
    lo, hi = cz._profile_interval(x, ((x - 3.0) / 0.5) ** 2, 1.0)
    # linear interpolation of a parabola between grid points 0.5 apart: within 0.05
    assert lo == pytest.approx(2.5, abs=0.05)
    assert hi == pytest.approx(3.5, abs=0.05)
    lo, hi = cz._profile_interval(x, 1e-3 * (x - 1.0) ** 2, 1.0)
    assert (lo, hi) == (0.0, 7.0)


@pytest.mark.parametrize(("seed", "row", "axis"), [
    # plate-logged, 5-minute lag: a 2.4e-4 m/s² "step" 147 s in, under c·0.0625 K = 2.9e-4
    (14017, "temperature plate 5 min", "x"),
    # warm-up: a 1.2e-4 m/s² step 430 s before the end on the residual, under the minimum
    (10001, "warmup", "z"),
])
def test_the_benchmarks_false_claims_are_not_claimed(tmp_path, seed, row, axis):
    """The two false claims the benchmark made (docs/log/explain.md "Benchmark") are below their
    floor: the step is still tested and reported, but not claimed; the hidden cause is."""
    from benchmarks.bench_explain import cases_at_3x

    case = {c.name: c for c in cases_at_3x(HOURS, 10.0, N, B, K)}[row]
    rec, _ = make_record(seed, hours=HOURS, truth=case.truth, logged=case.logged)
    ex = explain_file(open_record(str(save(rec, tmp_path / "f.npz"))),
                      ExplainOptions(heldout=False))
    ch = ex.channels[axis]
    assert {f.cause for f in ch.claimed} - {"sinusoid"} == {case.kind}, \
        [f.evidence for f in ch.claimed]
    # the transients were still tested and are reported, not claimed
    assert [f for f in ch.findings if f.cause in ("bias_step", "warmup", "excursion")
            and not f.claimed]


def test_absent_noise_terms_enter_the_transients_gls_at_their_upper_limit():
    """A term the fit calls absent is not zero noise: the transients' GLS covariance (and
    their floor) takes it at its upper limit; a present one at its value."""
    from avard.core.explain.engine.removal import _noise_levels
    from avard.core.model.fit import NoiseFit, TermEstimate

    def term(value, upper=None):
        if value is None:
            return TermEstimate(None, None, None, "", False, upper=upper)
        return TermEstimate(value, value, value, "", True)

    fit = NoiseFit({"velocity_random_walk": term(1.6e-4),
                    "bias_instability": term(None, upper=3e-5),
                    "rate_random_walk": term(None, upper=2.5e-6),
                    "quantization": term(None)}, [], [], 1.0, 100.0, 1.0)
    assert _noise_levels(fit) == {"N": 1.6e-4, "B": 3e-5, "K": 2.5e-6}
    fit.terms["rate_random_walk"] = term(None)  # not tested: no limit, nothing to add
    assert _noise_levels(fit)["K"] == 0.0


DRAWS = 400


def test_step_intervals_on_white_noise():
    """On white noise alone the GLS is ordinary least squares of [1, t, H]. Over 400 draws:
    the step size's ±1 σ interval holds the truth in 68 % of them (binomial σ 2.3 %: ±3 σ),
    its half-width is σ·√(1/n₁ + 1/n₂) doubled by the drift column (a step at the middle has
    correlation √3/2 with t: variance × 1/(1 − 3/4) = 4), within 15 %; the step time's
    interval (the central 68 % of its likelihood) holds the truth in 60–80 % of them (1000
    draws gave 72 % at this size, 75 % at half of it: a little wide, never narrow; Δχ² = 1
    gave 31 %)."""
    rng = np.random.default_rng(5)
    rate, n, sigma, size, ts = 1.0, 1024, 1.0, 1.0, 512.0
    noise = {"N": sigma / math.sqrt(rate), "B": 0.0, "K": 0.0}
    hits, t_hits, widths = 0, 0, []
    for _ in range(DRAWS):
        y = sigma * rng.standard_normal(n) + np.where(np.arange(n) >= ts, size, 0.0)
        cand = cz.Candidate("bias_step", True, {"time_s": ts, "size": size})
        (got,) = cz.refine_transients(y, rate, noise, step=cand, max_blocks=n // 2)  # blocks of 2
        lo, hi = got.intervals["size"]
        hits += lo <= size <= hi
        widths.append((hi - lo) / 2)
        t_lo, t_hi = got.intervals["time_s"]
        t_hits += t_lo <= ts <= t_hi
    assert 0.61 <= hits / DRAWS <= 0.75
    assert 0.60 <= t_hits / DRAWS <= 0.80
    # block means of 2 samples: σ/√2 each, n/4 either side of the step; × 2 for the drift
    se = 2 * sigma / math.sqrt(2) * math.sqrt(2 / (n / 4))
    assert float(np.median(widths)) == pytest.approx(se, rel=0.15)


def test_white_noise_fast_path_equals_the_cholesky_path():
    """White noise alone is whitened by dividing by σ; with a random walk too small to
    matter (K = 1e-30) the general Cholesky path runs: same parameters and intervals."""
    rng = np.random.default_rng(8)
    n, rate = 2048, 1.0
    t = np.arange(n) / rate
    y = rng.standard_normal(n) + 3.0 * np.exp(-t / 150.0) + np.where(t >= 1200.0, 0.8, 0.0)
    w = cz.Candidate("warmup", True, {"time_constant_s": 120.0, "size": 3.0})
    s = cz.Candidate("bias_step", True, {"time_s": 1210.0, "size": 0.8})
    fast = cz.refine_transients(y, rate, {"N": 1.0}, warmup=w, step=s)
    slow = cz.refine_transients(y, rate, {"N": 1.0, "K": 1e-30}, warmup=w, step=s)
    for a, b in zip(fast, slow, strict=True):
        for k in a.params:
            assert a.params[k] == pytest.approx(b.params[k], rel=1e-9)
            assert a.intervals[k] == pytest.approx(b.intervals[k], rel=1e-9)


def _coverage(tmp_path, seeds) -> dict[tuple[str, str], tuple[int, int]]:
    """(held, counted) of the 68 % intervals of every transient parameter over the axes of
    warm-up + step records, by (cause, parameter)."""
    tally = {k: [0, 0] for k in TRUE}
    for seed in seeds:
        ex = _explain(tmp_path, seed, BOTH)
        for ch in ex.channels.values():
            for cause, f in _claimed(ch).items():
                for p, (lo, hi) in f.intervals.items():
                    tally[cause, p][0] += lo <= TRUE[cause, p] <= hi
                    tally[cause, p][1] += 1
    return {k: (v[0], v[1]) for k, v in tally.items()}


def test_transient_interval_plumbing_on_a_few_records(tmp_path):
    """Two records: every parameter of both causes has an interval on every axis and most
    of them hold the truth (the statistical check is the slow test below)."""
    cov = _coverage(tmp_path, range(300, 302))
    for k, (_held, counted) in cov.items():
        assert counted == 6, (k, cov)
    assert sum(h for h, _ in cov.values()) >= 12, cov


#: the slow coverage study, computed once for the two tests that read it
_STUDY: dict[tuple[str, str], tuple[int, int]] = {}


def _study(tmp_path) -> dict[tuple[str, str], tuple[int, int]]:
    if not _STUDY:
        _STUDY.update(_coverage(tmp_path, range(400, 450)))
        print({f"{c}.{p}": f"{h}/{n}" for (c, p), (h, n) in _STUDY.items()})  # for the docs
    return _STUDY


@pytest.mark.slow
def test_transient_intervals_hold_the_truth_about_68_percent(tmp_path):
    """50 warm-up + step records (150 axes): each parameter's 68 % interval holds the truth
    in 60–76 % of them (binomial σ 3.8 % at 68 %: about ± 2 σ); the warm-up's T at least
    60 % here, its upper side is the known gap below. Before absent noise terms entered the
    GLS at their upper limit (not 0), the warm-up size held it in 88/150 = 59 %."""
    cov = _study(tmp_path)
    for k, (held, counted) in cov.items():
        assert counted >= 145, (k, cov)
        assert held / counted >= 0.60, (k, cov)
        if k != ("warmup", "time_constant_s"):
            assert held / counted <= 0.76, (k, cov)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="known gap: the warm-up's T interval is a little wide "
                   "(115/150 = 77 % here, 221/300 = 74 % over seeds 400–449 and 500–549; "
                   "docs/log/explain.md 'Transients')")
def test_warmup_time_constant_interval_is_not_wide(tmp_path):
    """The warm-up T's 68 % interval holds the truth in at most 76 % of the 150 axes."""
    held, counted = _study(tmp_path)[("warmup", "time_constant_s")]
    assert held / counted <= 0.76, (held, counted)


def test_a_gauss_markov_bump_from_the_temperature_rounding_is_not_claimed(tmp_path):
    """Benchmark seed 99000, plate-logged through a 2-minute lag: after the coupling is
    removed, the logged temperature's rounding sawtooth (c·0.0625 K, crossing a step every
    ≈ 80 s) leaves a bump the Gauss–Markov scan passes (z 3.6, T ≈ 96 s); its σ is below
    the rounding's RMS through the coupling, so it is reported, not claimed."""
    from benchmarks.bench_explain import cases_at_3x

    case = {c.name: c for c in cases_at_3x(HOURS, 10.0, N, B, K)}["temperature plate 2 min"]
    rec, _ = make_record(99000, hours=HOURS, truth=case.truth, logged=case.logged)
    ex = explain_file(open_record(str(save(rec, tmp_path / "g.npz"))),
                      ExplainOptions(heldout=False))
    ch = ex.channels["x"]
    assert {f.cause for f in ch.claimed} == {"temperature"}
    # and the lag is one lag: two lags of opposite sign (0.0106 and −0.0077 m/s²/K at 240
    # and 480 s) once won held out by smoothing the readings' rounding, which makes up
    # nearly all of this coupling's residual deviance (thermal_paths' rounding share)
    (th,) = [f for f in ch.claimed if f.cause == "temperature"]
    assert th.mechanism == "one_lag"
    assert th.params["coefficient"] == pytest.approx(case.truth.coefficient[0], rel=0.2)
    assert abs(th.params["lag_s"] - 120.0) <= 30.0
    (gm,) = [f for f in ch.findings if f.cause == "gauss_markov"]
    assert not gm.claimed
    # with the one lag kept (see above) the bump passes the scan again; where it does, the
    # rounding floor is named as a reason it is not claimed (beside any other, such as T not
    # located)
    if gm.statistic >= gm.threshold:
        assert "rounding through the coupling" in gm.evidence


def test_the_gls_noise_whitener_is_kept_and_whitens_as_a_fresh_factorisation() -> None:
    """The noise covariance's factor is kept per (blocks, levels): a second GLS on the same
    noise reuses it and whitens exactly as a fresh Cholesky factorisation does, to the bit;
    other levels get their own; white noise alone keeps its diagonal fast path."""
    from avard.core.explain.causes import _Gls, _noise_cov, _noise_whitener
    from avard.core.model.triangular import LowerSolver

    rng = np.random.default_rng(8)
    rate = 2.0
    y = np.cumsum(rng.standard_normal(8192)) * 1e-6 + 1e-4 * rng.standard_normal(8192)
    for noise in ({"N": 1.5e-4, "B": 2e-5, "K": 4e-7}, {"N": 1.5e-4, "B": 2e-5, "K": 0.0},
                  {"N": 1.5e-4, "B": 0.0, "K": 0.0}):
        first = _Gls(y, rate, noise, 256)
        hits = _noise_whitener.cache_info().hits
        again = _Gls(y + 1e-5, rate, noise, 256)
        assert _noise_whitener.cache_info().hits == hits + 1
        c = _noise_cov(first.t, first.dt, noise["N"], noise["B"], noise["K"])
        if noise["B"] == noise["K"] == 0.0:
            want_wy = again.yb / np.sqrt(np.diag(c))
            assert again._sd is not None
            assert again.wy.tobytes() == want_wy.tobytes()
            continue
        fresh = LowerSolver(np.linalg.cholesky(c))
        assert again.wy.tobytes() == fresh.solve(again.yb).tobytes()
        base = np.column_stack([np.ones_like(first.t), first.t])
        assert again.wbase.tobytes() == fresh.solve(base).tobytes()
        assert first.wy.tobytes() == fresh.solve(first.yb).tobytes()
