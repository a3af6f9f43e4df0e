"""Thermal paths beyond one lag (issue 23 item 4): the candidates, the choice by held-out
likelihood, and the stated minima; records from the independent weekend generator."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from avard.core.explain import alarm
from avard.core.explain.thermal_fit import fit_thermal_axes
from avard.core.explain.thermal_fit.rounding import rounding_correlation_s, rounding_floor_tau
from avard.core.explain.thermal_fit.scan import _axes_reference
from avard.core.explain.thermal_fit.settings import DS18B20_CONVERSION_S
from avard.core.explain.thermal_fit.sums import octave_sums_by_part
from avard.core.explain.thermal_paths import HELDOUT_MARGIN, choose_path, min_detectable_path
from avard.core.explain.thermal_paths.columns import _relay, crossing_reconstruction, trials
from avard.core.explain.thermal_paths.profile import _grid_cell, _jk_se, profile_delta
from avard.core.explain.thermal_paths.readings import _derivative_limit
from avard.core.explain.thermal_paths.settings import LEAN_MARGIN, LEAN_T, PARTS

from tests.support.weekend import Weekend, make

C = 2e-3
BASE = Weekend(hours=4.0, rate_hz=10.0, die_tau_s=30.0, sensor_tau_s=30.0,
               coefficient=(C, 0.0, 0.0))


def _slow(w: Weekend, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """x and the logged plate as 1 s block means (readings interpolated across blocks)."""
    acc, temps, _names, _truth = make(seed, w)
    b = int(w.rate_hz)
    n = len(acc) // b * b
    y = acc[:n, 0].reshape(-1, b).mean(axis=1)
    blocks = temps[:n, 0].reshape(-1, b)
    has = np.isfinite(blocks).any(axis=1)
    T = np.full(len(blocks), np.nan)
    T[has] = np.nanmean(blocks[has], axis=1)
    T = np.interp(np.arange(len(T)), np.flatnonzero(has), T[has])
    return y, T


def _path(y: np.ndarray, T: np.ndarray):
    th = fit_thermal_axes(y[:, None], T[:, None], ["plate"], 1.0, lag_intervals=False)[0]
    ref = _axes_reference(y[:, None], 1.0)
    edf = np.asarray(ref.edf, dtype=float).reshape(len(ref.tau), -1)[:, 0]
    return choose_path(y, T, 1.0, th.lag_s, np.asarray(ref.tau, float), edf,
                       rounding_floor_tau(T, 1.0))


@pytest.fixture(scope="module")
def base_path():
    """The plain one-lag record's path choice, made once for the tests that only read it."""
    return _path(*_slow(BASE, 5))


@pytest.fixture(scope="module")
def two_path_record():
    """A second path through 900 s beside the lag-0 coupling: the record and its path
    choice, made once for the tests that read it."""
    y, T = _slow(replace(BASE, second_path=(-4 * C, 900.0)), 5)
    return y, T, _path(y, T)


def test_the_relay_switches_once_the_temperature_turns_back_by_its_width():
    v = np.concatenate([np.linspace(0, 1, 101), np.linspace(1, 0, 101)[1:]])
    r = _relay(v, 0.2)
    assert r[100] == 1.0  # at the top, after the rise
    # still +1 while the temperature turns back by less than the width, −1 beyond it
    assert r[119] == 1.0 and r[121] == -1.0
    assert r[-1] == -1.0 and set(np.unique(r)) == {-1.0, 1.0}


def _relay_by_sample(v: np.ndarray, w: float) -> np.ndarray:
    """The relay sample by sample (the reference ``_relay`` equals)."""
    state, ext = 1.0, float(v[0])
    out = []
    for x in np.asarray(v, dtype=float).tolist():
        if state > 0:
            if x > ext:
                ext = x
            elif ext - x > w:
                state, ext = -1.0, x
        else:
            if x < ext:
                ext = x
            elif x - ext > w:
                state, ext = 1.0, x
        out.append(state)
    return np.array(out)


@pytest.mark.parametrize("seed", range(6))
def test_the_relay_switch_by_switch_equals_the_relay_sample_by_sample(seed: int):
    # a random walk, a noisy sine (switches at the turns) and rounded readings (ties at the
    # extremum), at widths from 0 (every turn) to one no sample reaches, lengths across the
    # search window's 256 and its doublings
    rng = np.random.default_rng(seed)
    for n in (1, 2, 255, 256, 257, 1500, 6000):
        for v in (np.cumsum(rng.standard_normal(n)) * 0.01,
                  0.2 * np.sin(np.arange(n) / rng.uniform(5, 300))
                  + 0.01 * rng.standard_normal(n),
                  np.round(rng.standard_normal(n) * 3) / 16):
            for w in (0.0, 0.0125, 0.05, 0.4, 5.0):
                assert np.array_equal(_relay(v, w), _relay_by_sample(v, w)), (n, w)


def test_the_reconstruction_from_the_readings_crossings_is_closer_than_the_readings():
    # a slowly turning room read at 0.0625 K: the staircase is off by up to half a step, the
    # spline through the times it crosses each step's middle follows the temperature itself
    t = np.arange(14400.0)
    T = 21.0 + 0.2 * np.sin(2 * np.pi * t / 1800.0) + 0.03 * np.sin(2 * np.pi * t / 9000.0)
    r = np.round(T / 0.0625) * 0.0625
    s = crossing_reconstruction(r)
    assert np.std(s - T) < np.std(r - T) / 4
    # and never leaves a plain reading's own cell
    assert np.all(np.abs(s - r) <= 0.0625 / 2 + 1e-12)
    # a stable room (one reading throughout) is left as read, and readings that toggle
    # between two steps every second (a real DS18B20's noise at a step's edge) stay finite,
    # inside their cells
    flat = np.full(3600, 21.0625)
    assert np.array_equal(crossing_reconstruction(flat), flat)
    toggling = 21.0 + 0.0625 * (np.arange(3600) % 2)
    z = crossing_reconstruction(toggling)
    assert np.all(np.isfinite(z)) and np.all(np.abs(z - toggling) <= 0.0625 / 2 + 1e-12)


def test_one_lag_stays_one_lag(base_path):
    pf = base_path
    assert pf.kind == "one_lag"
    assert pf.chosen.beta[0] == pytest.approx(C, rel=0.1)
    # a plain lag: no non-linear candidate predicts better, the parameters keep intervals
    assert pf.leaning == () and not pf.model_dependent and pf.params()[1]


def test_a_quadratic_response_is_chosen_by_held_out_likelihood_with_its_parameters():
    y, T = _slow(replace(BASE, quadratic=40 * C), 5)
    pf = _path(y, T)
    assert pf.kind == "quadratic"
    p, iv = pf.params()
    assert p["quadratic"] == pytest.approx(40 * C, rel=0.1)
    assert p["coefficient"] == pytest.approx(C, rel=0.2)
    assert iv["quadratic"][0] < p["quadratic"] < iv["quadratic"][1]
    # the held-out −2 ln L of the chosen one beats one lag by more than the margin
    assert pf.scores["quadratic"].heldout < pf.scores["one_lag"].heldout - pf.margin


def test_the_rounding_is_a_sawtooth_on_a_slow_room_and_its_floor_is_above_the_white_one():
    """A slowly turning room crosses a 0.0625 K step every minute or two: one rounding error
    lasts that long, not a read interval, and the floor is octaves above the white rule's."""
    _y, T = _slow(BASE, 5)
    assert rounding_correlation_s(T, 1.0) > 20 * DS18B20_CONVERSION_S
    # the floor with the rounding white at the read interval: ≥ 2 octaves lower
    assert rounding_floor_tau(T, 1.0) >= 4 * rounding_floor_tau(
        T, 1.0, snr=10.0 * DS18B20_CONVERSION_S / rounding_correlation_s(T, 1.0))


def test_the_paths_share_is_in_the_per_axis_level():
    assert alarm.THERMAL_PATHS > 0
    assert alarm.bonferroni_z(alarm.THERMAL_PATHS, 100) > 4.5
    # the extra term's z is a jackknife ratio over PARTS parts: Student's t with PARTS − 1
    # dof (t₉ two-sided at 1e-3 is 4.781 in the tables), far above the normal quantile at a
    # Bonferroni share
    assert alarm.bonferroni_t(1e-3, 1, 9) == pytest.approx(4.781, abs=5e-4)
    assert alarm.bonferroni_t(alarm.THERMAL_PATHS, 100, PARTS - 1) > 9.0
    assert (alarm.bonferroni_t(alarm.THERMAL_PATHS, 100, PARTS - 1)
            > 1.8 * alarm.bonferroni_z(alarm.THERMAL_PATHS, 100))


def test_a_null_jackknife_z_passes_the_t_threshold_at_its_rate_and_the_normal_one_far_more():
    # the delete-a-part jackknife of a linear statistic over PARTS parts with no effect: the
    # ratio estimate/se is t with PARTS − 1 dof, so the t threshold holds its level and the
    # normal quantile (the old threshold) lets several times the level through
    rng = np.random.default_rng(23)
    reps, alpha = 200_000, 1e-3
    parts = rng.standard_normal((PARTS, reps))
    est = parts.mean(axis=0)
    loo = (parts.sum(axis=0) - parts) / (PARTS - 1)  # the mean with each part left out
    z = np.abs(est) / _jk_se(loo)
    rate_t = float(np.mean(z >= alarm.bonferroni_t(alpha, 1, PARTS - 1)))
    rate_n = float(np.mean(z >= alarm.bonferroni_z(alpha, 1)))
    sd = math.sqrt(alpha * (1 - alpha) / reps)
    assert abs(rate_t - alpha) < 4 * sd
    assert rate_n > 5 * alpha


def test_a_path_fit_uses_the_t_threshold(base_path):
    pf = base_path
    assert pf.z_threshold > 9.0


@pytest.mark.parametrize("kind", ["two_path", "quadratic", "rate", "hysteresis"])
def test_stated_minima_scale_with_z_and_fall_with_the_record(kind: str):
    """Two paths on two drive lines (on one they have no finite minimum with the lags
    unknown); the dT/dt term's is the minimum of r − c·L (the lag known: with it free r
    alone has none at a true lag of 0)."""
    args = (1.6e-4, 2e-5, 2e-6)
    kw = {"lines": ((0.05, 1200.0),)} if kind == "two_path" else {}
    kw = {"lags_known": True} if kind == "rate" else kw
    a = min_detectable_path(kind, *args, 4 * 3600, 0.2, 1800.0, 0.0, 870.0, **kw)
    b = min_detectable_path(kind, *args, 16 * 3600, 0.2, 1800.0, 0.0, 870.0, **kw)
    c = min_detectable_path(kind, *args, 4 * 3600, 0.2, 1800.0, 0.0, 870.0, z=10.0, **kw)
    assert c == pytest.approx(2 * a)
    assert b == pytest.approx(a / 2)  # σ_a ∝ 1/√T
    assert math.isfinite(a) and a > 0


@pytest.mark.parametrize("phi", [0.3, 0.84, 1.6])
def test_the_hysteresis_minimum_is_the_fishers_with_the_coupling_and_the_switch_unknown(phi):
    """The fit estimates the linear coupling (c, L) and the switch (L, w) beside h. The
    Fisher information of (c, L·c, h, φ) from the complex amplitudes the model puts at each
    odd harmonic of the drive (c·a·e^(−iωL) at f0 only, 4h/(πk)·e^(−ikφ) at k·f0), noise
    σ_a(k·f0) per quadrature: h's standard error times z is the stated minimum, whatever the
    switch's phase; the minimum of h alone (the coupling and the switch known, the sum from
    the fundamental) is smaller, so a row at 3× that one hid h at 2.4 of the fit's own σ."""
    from avard.core.explain.causes import noise_psd

    N, B, K, rec, a, period = 1.6e-4, 2e-5, 2e-6, 4 * 3600.0, 0.2, 1800.0
    w0 = 2 * math.pi / period

    def sig(f: float) -> float:
        return math.sqrt(2 * noise_psd(f, N, B, K) / rec)

    info = np.zeros((4, 4))
    known = 0.0
    for k in range(1, 40, 2):
        d = np.zeros(4, complex)
        if k == 1:
            d[0], d[1] = a, -1j * w0 * a  # ∂/∂c, ∂/∂(cL) at L = 0
        d[2] = 4 / (math.pi * k) * np.exp(-1j * k * phi)
        d[3] = -1j * 4 / math.pi * np.exp(-1j * k * phi)  # ∂/∂φ per unit h
        info += np.real(np.outer(d, d.conj())) / sig(k / period) ** 2
        known += abs(d[2]) ** 2 / sig(k / period) ** 2
    se_h = math.sqrt(np.linalg.inv(info)[2, 2])
    got = min_detectable_path("hysteresis", N, B, K, rec, a, period, 0.0, 870.0)
    assert got == pytest.approx(5.0 * se_h, rel=1e-9)
    assert got > 1.2 * 5.0 / math.sqrt(known)


def test_an_average_over_theta_weighs_the_points_within_the_profile_by_their_likelihood():
    """The hysteresis's coefficients are averaged over the grid points within the 68 %
    profile's Δ of the best (exp(−ΔD/2Δ) each), not read at the best point: two points
    equally good give their midpoint, a point a little worse counts less, a point beyond Δ
    not at all; θ likewise (a width in ln, a lag of either sign as it is)."""
    from avard.core.explain.thermal_paths.columns import Trial
    from avard.core.explain.thermal_paths.profile import _averaged, _averaged_theta, _weights

    devs = np.array([10.0, 10.0, 10.5, 13.0])
    w = _weights(devs, 1.0)
    assert w[3] == 0.0 and w[0] == w[1] > w[2] > 0 and w.sum() == pytest.approx(1.0)
    assert w[2] / w[0] == pytest.approx(math.exp(-0.25))
    # a Birge factor of 4 widens the set and flattens the weights
    w4 = _weights(devs, 4.0)
    assert w4[3] > 0 and w4[2] / w4[0] == pytest.approx(math.exp(-0.5 / 8))
    fits = [np.array([1.0, 2.0, 9.0]), np.array([3.0, 4.0, 9.0]), np.array([2.0, 3.0, 9.0]),
            np.array([100.0, 100.0, 9.0])]
    got = _averaged(fits, np.array([5.0, 5.0, 50.0, 50.0]), 2, 1.0)
    assert got == pytest.approx([2.0, 3.0])  # the midpoint; the start state's left out
    ts = [Trial((-30.0, 0.025), (), 2), Trial((30.0, 0.1), (), 2)]
    lag, width = _averaged_theta(ts, np.array([0.0, 0.0]), 1.0)
    assert lag == pytest.approx(0.0) and width == pytest.approx(0.05)


def test_the_hysteresis_tries_lags_of_either_sign():
    """The relay's lag and width trade along a ridge through a true lag of 0: the
    hysteresis's grid reaches the same short lags either side (the logged sensor may lag the
    die), not only the one-lag fit's own negative lag."""
    from avard.core.explain.thermal_paths.settings import HYSTERESIS_LEADS_S

    got = {t.theta[0] for t in trials("hysteresis", [0.0, 15.0, 30.0, -94.5])}
    assert {-x for x in HYSTERESIS_LEADS_S} <= got and {0.0, 15.0, 30.0, -94.5} <= got
    assert all(t.cols[1].lag == t.theta[0] for t in trials("hysteresis", [0.0]))


def test_a_response_one_lag_cannot_follow_is_claimed_by_its_own_test():
    # a quadratic response ten times the linear one: the one-lag z fails (it sees the
    # quadratic's 2f₀ as noise), the quadratic passes its own test and is the claim
    y, T = _slow(replace(BASE, quadratic=40 * C), 5)
    th = fit_thermal_axes(y[:, None], T[:, None], ["plate"], 1.0, paths=True)[0]
    assert th.passed and th.mechanism == "quadratic"
    f = th.finding()
    assert f.mechanism == "quadratic"
    assert f.params["quadratic"] == pytest.approx(40 * C, rel=0.1)


def test_a_null_axis_claims_no_path():
    y, T = _slow(replace(BASE, coefficient=(0.0, 0.0, 0.0)), 6)
    th = fit_thermal_axes(y[:, None], T[:, None], ["plate"], 1.0, paths=True)[0]
    assert not th.passed
    assert th.path is None


def test_a_rate_term_is_resolved_with_the_static_coupling_through_its_own_lag():
    """c·T + r·dT/dt. Parameterised as c·u_L + r·d(u_L)/dt the rate term and the lag traded
    along a ridge at one drive frequency ((c + jωr)/(1 + jωL) fixes two numbers of three: c
    crossed zero along it, "not resolved"); the derivative through a forward lag also
    delayed it by 30 s. Now r multiplies dT/dt of the logged channel (zero phase), the
    static coupling has its own lag L ≥ 0 (a negative one would be a second rate term):
    along what is left of the ridge c stays c₀(1 + ω²L²) > 0 and r = r₀ + c₀L."""
    y, T = _slow(replace(BASE, rate_coupling=1.0), 5)
    pf = _path(y, T)
    assert pf.kind == "rate"
    assert pf.chosen.resolved
    p, iv = pf.params()
    assert p["rate_coupling"] == pytest.approx(1.0, rel=0.1)
    assert p["coefficient"] == pytest.approx(C, rel=0.1)
    assert "not resolved" not in pf.summary()
    # A second path of short lag L₂ and large opposite coefficient c₂ passes
    # −c₂L₂/(1 + jωL₂)·jω, a dT/dt term at every ω ≪ 1/L₂, so a dT/dt truth has a two-path
    # rival at every frequency (the converse does not hold: the next test). That rival is
    # the dT/dt term's limit, its coefficients nearly cancelling; it is the same mechanism
    # with a parameter more, so it is named in a note, not as an alternative, and the rate
    # term's intervals hold the truth (r − c·L's own 68 % interval, no longer widened to the
    # split's: within two of its half-widths on this one record, its 68 % over records is
    # the slow row test's)
    mimic = pf.scores["two_path"]
    assert mimic.heldout <= pf.chosen.heldout + HELDOUT_MARGIN
    assert _derivative_limit(mimic)
    assert pf.alternatives == () and not pf.model_dependent
    assert "nearly cancel" in pf.summary() and "cannot tell them apart" not in pf.summary()
    lo, hi = iv["rate_coupling"]
    assert abs(p["rate_coupling"] - 1.0) <= hi - lo
    assert iv["coefficient"][0] <= C <= iv["coefficient"][1]
    # r and c are read through the rate column's smoothing gain (``_ungained``), a small
    # step on one HVAC line; the signal explain subtracts keeps the fitted coefficients of
    # the smoothed column, the least-squares ones
    s = pf.chosen
    assert len(s.fitted) == 2 and s.beta[1] != s.fitted[1]
    assert 0.95 < s.beta[1] / s.fitted[1] < 1.05
    # the rate candidate tries no negative lag
    assert all(t.theta[0] >= 0 for t in trials("rate", [-60.0, 0.0, 15.0]))


def test_a_lag_interval_is_never_narrower_than_its_grid_cell():
    # one lag chosen at a grid point every delete-a-part fit re-chooses: the interval spans
    # half way to the neighbouring grid points at least, never zero width
    y, T = _slow(replace(BASE, rate_coupling=0.25), 5)
    s = _path(y, T).scores["one_lag"]
    assert s.theta_lo[0] <= s.theta[0] <= s.theta_hi[0]
    assert s.theta_hi[0] - s.theta_lo[0] > 50.0  # the grid's neighbours here are ≥ 100 s off
    lo, hi = _grid_cell(trials("one_lag", [0.0, 15.0, 30.0, 60.0]), 2)
    assert (lo[0], hi[0]) == (22.5, 45.0)
    # (0, 15): L2 = 15 is the shortest L2 there is (L2 > L1)
    lo, hi = _grid_cell(trials("two_path", [0.0, 15.0, 30.0, 60.0]), 0)
    assert lo.tolist() == [0.0, 15.0] and hi.tolist() == [7.5, 22.5]


def test_the_rounding_gain_of_a_path_is_the_l1_norm_of_all_its_linear_terms():
    # a two-path fit of a plain lag (seed 99000 of the explain benchmark once read so):
    # 0.0106 and −0.0077 through 240 and 480 s pass the readings' rounding with up to
    # 0.0183 m/s²/K, not the first path's 0.0106 the engine's floors took before
    from avard.core.explain.engine.compound import _rounding_gain
    from avard.core.explain.thermal_paths import PathFit, PathScore
    from avard.core.explain.thermal_paths.columns import Column

    def fit(kind: str, theta: tuple[float, ...], beta: list[float],
            cols: tuple[Column, ...]) -> PathFit:
        s = PathScore(kind, 0.0, theta, np.array(beta), np.zeros(len(beta)), theta, theta,
                      20.0, False, cols)
        return PathFit(s, {kind: s}, 10.0, 1.0)

    two = fit("two_path", (240.0, 480.0), [0.0106, -0.0077],
              (Column("u", 240.0), Column("u", 480.0), Column("start", 240.0),
               Column("start", 480.0)))
    assert two.rounding_gain() == pytest.approx(0.0183)
    # a dT/dt column (δ − h_s)/s passes a step with L1 norm 2/s; a negative lag's lead-lag 3
    rate = fit("rate", (-60.0,), [1e-3, 0.3],
               (Column("u", -60.0), Column("rate", -60.0), Column("start", 60.0)))
    assert rate.rounding_gain() == pytest.approx(3 * (1e-3 + 0.3 * 2 / 30.0))
    y, T = _slow(BASE, 5)
    th = fit_thermal_axes(y[:, None], T[:, None], ["plate"], 1.0, lag_intervals=False)[0]
    assert _rounding_gain(replace(th, path=two)) == pytest.approx(0.0183)
    assert _rounding_gain(th) == pytest.approx(abs(th.coefficient))
    assert _rounding_gain(replace(th, coefficient=-C, lag_s=-60.0)) == pytest.approx(3 * C)


def test_two_paths_are_told_from_a_dt_term_by_the_wander_and_a_dt_term_is_named_with_two_paths(
        two_path_record):
    # a second path through 900 s beside the lag-0 coupling, the room one HVAC sine: a
    # dT/dt term sets the same gain and phase at that one frequency, and the room's weak
    # wander is all that tells them apart. Where it does not, the finding names both as
    # equally supported, with no interval, never one alone with one
    y, T, pf = two_path_record
    # Since the paths' fit sees every octave (lag23), the room's slow wander, where two
    # paths pass c₁ + c₂ and a dT/dt term its static c, tells them apart on this record:
    # the dT/dt term is held out +27 behind one lag, two paths −73 ahead. Two paths alone,
    # with intervals that hold the truth.
    assert pf.kind == "two_path" and pf.alternatives == ()
    assert not pf.model_dependent
    p, iv = pf.params()
    # θ continuous in the jackknife, the profile on the deviance's own scale: the intervals
    # are 68 % ones, so what one record must hold is its 95 % interval, each side twice the
    # 68 % one's. Each of c₁, c₂, L2 either keeps such an interval or is "not resolved" (no
    # interval: wider than ±10 %; on this record all four are, the first lag at 109 s
    # against a true 0 among them: they trade along the two paths' ridge)
    truth = {"coefficient": C, "coefficient_2": -4 * C, "lag_2_s": 900.0}
    for k, v in truth.items():
        assert k in p
        if k in iv:
            lo, hi = iv[k]
            assert p[k] - 2 * (p[k] - lo) <= v <= p[k] + 2 * (hi - p[k]), k
    loose = [k for k in ("coefficient", "coefficient_2", "lag_s", "lag_2_s") if k not in iv]
    assert loose and f"{', '.join(loose)} not resolved" in pf.summary()
    # what the record resolves: the response at the drive's period, against the
    # generator's own there (the die and the second path each against the logged sensor,
    # 30 s behind the plate): within 5 % in gain and 0.05 rad in phase
    assert p["drive_period_s"] == pytest.approx(1800.0, rel=0.01)
    jw = 2j * math.pi / p["drive_period_s"]
    g = C + (-4 * C) * (1 + 30 * jw) / (1 + 900 * jw)
    assert p["gain_at_drive"] == pytest.approx(abs(g), rel=0.05)
    assert abs(p["phase_at_drive_rad"] - np.angle(g)) < 0.05
    assert {"gain_at_drive", "phase_at_drive_rad"} <= set(iv)
    assert "cannot tell them apart" not in pf.summary()
    # the dT/dt record of the test above: its two-path rival is the derivative's limit, so
    # the finding names the dT/dt term alone, with its intervals
    y, T = _slow(replace(BASE, rate_coupling=1.0), 5)
    th = fit_thermal_axes(y[:, None], T[:, None], ["plate"], 1.0, paths=True)[0]
    f = th.finding()
    assert f.mechanism == "rate" and not f.alternatives
    assert not f.model_dependent and f.intervals
    assert "mechanism_alternatives" not in f.to_dict()


def test_the_rounding_a_long_lag_passes_is_less_and_a_lead_lag_more():
    from avard.core.explain.thermal_paths.rounding import sawtooth_avar

    rate = 0.625
    t = np.arange(9000) / rate
    T = np.round((21 + 0.2 * np.sin(2 * math.pi * t / 1800)) / 0.0625) * 0.0625
    tau = np.array([204.8, 409.6, 819.2])
    r0, r_long, r_neg = (sawtooth_avar(T, rate, tau, L) for L in (0.0, 1800.0, -60.0))
    # unfiltered: white at these τ, q²/12·t_c/τ (halves per octave)
    assert r0[1] / r0[0] == pytest.approx(0.5, rel=0.15)
    assert np.all(r_long < 0.1 * r0) and np.all(r_neg > r0)
    assert np.all(r0 <= 2 * 0.0625**2 / 12)


def test_an_extension_whose_theta_sits_at_the_end_of_its_grid_is_not_chosen():
    # a typical-tempco weekend record (2e-4 m/s²/K through 5 min from the ambient channel,
    # benchmark row "typical tempco 24 h", seed 25006): two lags of opposite sign through
    # 1800 and 3600 s, the lag grid's end, fitted the slow wander held out better than one
    # lag and were printed with ±6 % intervals. A θ at the grid's end is a bound, not an
    # estimate: whatever path is chosen, none with a lag at the grid's end has an interval.
    from avard.core.explain.thermal_paths.settings import LAG_GRID_S

    from benchmarks.bench_explain_weekend import explain_weekend, rows

    row = next(r for r in rows() if r.name.startswith("typical tempco 24"))
    ex, _cpu = explain_weekend(row.weekend, 25006)
    temps = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert temps  # the coupling is real and claimed
    # and an open extension is not chosen over one lag at all (OPEN_MARGIN)
    assert [f.mechanism for f in temps] == ["one_lag"], [(f.mechanism, f.params) for f in temps]
    for f in temps:
        lags = [v for k, v in f.params.items() if k.startswith("lag")]
        if f.mechanism not in (None, "one_lag") and max(lags) >= LAG_GRID_S[-1]:
            assert f.model_dependent and f.intervals == {}, (f.mechanism, f.params)


def test_the_profile_delta_is_one_parameters_68_percent_scaled_by_the_birge_factor():
    """A 68 % profile interval on one parameter is Δ(−2 ln L) = 1 (χ²₁'s 68.27 % point),
    times the best fit's Birge factor (deviance over its dof) where that exceeds 1, never
    less; not the held-out choice's margin."""
    from avard.core.explain.thermal_paths import HELDOUT_MARGIN
    from avard.core.explain.thermal_paths.settings import PROFILE_DELTA

    assert PROFILE_DELTA == 1.0 and HELDOUT_MARGIN == 6.0
    nu = np.array([60.0, 30.0, 14.0])
    assert profile_delta(90.0, nu, 2) == 1.0  # deviance below its 102 dof
    assert profile_delta(204.0, nu, 2) == pytest.approx(2.0)  # scatter twice the weights'
    assert profile_delta(1.0, np.array([1.0]), 2) == math.inf  # no dof: no interval closes
    # two-sided: the deviance on its own scale, narrower where it is under its dof
    assert profile_delta(51.0, nu, 2, two_sided=True) == pytest.approx(0.5)
    assert profile_delta(204.0, nu, 2, two_sided=True) == pytest.approx(2.0)


def test_the_path_intervals_use_the_68_percent_profile_on_the_deviances_own_scale(
        monkeypatch, two_path_record):
    """On a two-path calibration record (BASE with a second path through 900 s, seed 5) the
    chosen two paths' intervals are widened to the points within its ``profile_delta`` of
    the best, Δ = 1 times the Birge factor either way (``two_sided``): the weights are the
    one-lag residual, which holds the second path's signal, so the best fit's deviance is a
    small part of its dof and Δ = 1 on that scale reached far along the ridge (the
    benchmark's two-path intervals held the truth in 30 of 34). Not the held-out margin of
    6 either: with it the intervals are wider."""
    import avard.core.explain.thermal_paths.profile as tp_profile
    from avard.core.explain.thermal_paths import HELDOUT_MARGIN

    y, T, pf = two_path_record
    s = pf.scores["two_path"]
    assert pf.kind == "two_path"
    assert s.profile_delta < 1.0 == profile_delta(0.5, np.array([1.0, 2.0]), 2)
    monkeypatch.setattr(tp_profile, "PROFILE_DELTA", HELDOUT_MARGIN)
    wide = _path(y, T).scores["two_path"]
    assert wide.profile_delta == pytest.approx(HELDOUT_MARGIN * s.profile_delta)
    assert s.beta == pytest.approx(wide.beta)  # the fit itself does not depend on it
    assert wide.beta_lo[1] <= s.beta_lo[1] and s.beta_hi[1] <= wide.beta_hi[1]
    assert s.beta_hi[1] - s.beta_lo[1] < wide.beta_hi[1] - wide.beta_lo[1]


def test_one_lag_kept_beside_a_better_predicting_nonlinear_path_carries_no_interval():
    # a hysteresis record (benchmark row "path: hysteresis", seed 30006: ±8.2e-5 m/s²
    # switching 0.05 K after a turn beside 8.0e-4 m/s²/K) on which the relay's z stays under
    # the search's threshold, so one lag is kept at a lead of about 100 s; with the play on
    # the readings, the row's one-lag estimates lay at −100 to −200 s and 8.1e-4 to
    # 1.06e-3 m/s²/K with ±4 % intervals that held other seeds' estimates out. The relay
    # predicts the held-out halves better (Δ < −2 at z ≥ t₉'s 0.1 %): the linear reading is
    # a model's, printed with no interval
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: hysteresis")
    # the row's size before its minimum left the fundamental out (3× the minimum of h
    # alone): at the row's size now the relay is chosen on this seed
    ex, _cpu = explain_weekend(replace(row.weekend, hysteresis_c=8.22e-5), 30006)
    temps = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert [f.mechanism for f in temps] == ["one_lag"]
    f = temps[0]
    assert f.model_dependent and f.intervals == {}
    assert f.intervals_if_model_held and "coefficient" in f.intervals_if_model_held
    assert "one lag kept, but hysteresis" in f.evidence
    pf = ex.channels["x"].thermal.path
    assert pf.leaning == ("hysteresis",)
    h = pf.scores["hysteresis"]
    assert h.heldout < pf.scores["one_lag"].heldout - LEAN_MARGIN and h.z_extra >= LEAN_T


def test_a_hysteresis_is_chosen_with_its_size_and_the_linear_coupling():
    # benchmark row "path: hysteresis", seed 30002: a relay on the temperature behind the
    # readings is chosen, its size and the linear coefficient within 20 % and inside their
    # 68 % intervals (before, a play on the readings themselves: one lag at −134 s)
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: hysteresis")
    ex, _cpu = explain_weekend(row.weekend, 30002)
    temps = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert [f.mechanism for f in temps] == ["hysteresis"]
    p, iv = temps[0].params, temps[0].intervals
    for k, v in row.truth.items():
        assert p[k] == pytest.approx(v, rel=0.2), (k, p[k], v)
        assert iv[k][0] <= v <= iv[k][1], (k, iv[k], v)


def test_theta_is_refined_between_the_local_grid_points_with_the_coefficients():
    """``_vertex``: on a deviance quadratic in the warped lag, the vertex between grid points
    and the coefficients moved with it (their own quadratics); at the local grid's edge the
    grid point (a bound, not an extrapolation); two paths lag by lag along their ridge."""
    from avard.core.explain.thermal_paths.refine import _fine_trials, _unwarp, _vertex, _warp

    ts = _fine_trials("rate", (60.0,), [0.0, 15.0, 30.0, 60.0, 120.0, 240.0])
    assert ts[0].theta[0] == 15.0 and ts[-1].theta[0] == 240.0
    assert len(ts) == 4 * 3 + 1  # two coarse steps each side of 60 s, each split in three
    w = np.array([_warp(t.theta[0]) for t in ts])
    best = _warp(50.0)
    devs = 7.0 * (w - best) ** 2
    betas = np.column_stack([1e-3 + 2e-4 * (w - best), 0.3 - 0.1 * (w - best) ** 2])
    theta, beta = _vertex(ts, devs, betas)
    assert theta[0] == pytest.approx(50.0, rel=1e-6)
    assert theta[0] not in [t.theta[0] for t in ts]
    assert beta == pytest.approx([1e-3, 0.3], rel=1e-6)
    # the least deviance at the local grid's edge: the grid point
    theta, beta = _vertex(ts, (w - _warp(500.0)) ** 2, betas)
    assert theta == (240.0,) and beta == pytest.approx(betas[-1])
    # two paths: each lag in turn, L1 < L2 kept
    ts2 = _fine_trials("two_path", (30.0, 900.0), [0.0, 15.0, 30.0, 60.0, 480.0, 900.0])
    assert all(t.theta[0] < t.theta[1] for t in ts2)
    w2 = np.array([[_warp(x) for x in t.theta] for t in ts2])
    d2 = (w2[:, 0] - _warp(40.0)) ** 2 + 3 * (w2[:, 1] - _warp(700.0)) ** 2
    theta, _ = _vertex(ts2, d2, np.zeros((len(ts2), 2)))
    assert theta == pytest.approx((40.0, 700.0), rel=1e-6)
    assert _unwarp(_warp(123.0)) == pytest.approx(123.0)


def test_a_paths_rounding_is_its_own_transfer_and_a_lag_0_path_gains_nothing_by_smoothing():
    """``_path_gain2`` puts a path's |H|² in the rounding's AVAR integral: one lag through it
    is ``sawtooth_avar`` of that lag times the coefficient² (below the readings' cap); two
    paths with a first at lag 0 pass the rounding one lag at lag 0 does and more, so they
    gain nothing over it by smoothing (``_smoothing`` 0); two lags of opposite sign at 240
    and 480 s do."""
    from avard.core.explain.thermal_paths.columns import Column
    from avard.core.explain.thermal_paths.deviance import _view
    from avard.core.explain.thermal_paths.refine import _smoothing
    from avard.core.explain.thermal_paths.rounding import _path_gain2, sawtooth_avar

    y, T = _slow(BASE, 5)
    tau = np.array([204.8, 409.6, 819.2, 1638.4])
    one = sawtooth_avar(T, 1.0, tau, 120.0)
    via = sawtooth_avar(T, 1.0, tau, gain2=_path_gain2((Column("u", 120.0),), np.array([2.0])))
    assert via == pytest.approx(4.0 * one, rel=1e-9)
    lead = sawtooth_avar(T, 1.0, tau, -60.0)
    assert sawtooth_avar(T, 1.0, tau, gain2=_path_gain2(
        (Column("u", -60.0),), np.array([1.0]))) == pytest.approx(lead, rel=1e-9)
    # the sums of a record's halves, weighed as choose_path does (s: a noise AVAR)
    X = np.column_stack([y, T])
    halves = octave_sums_by_part(X, np.array([0, len(X) // 2, len(X)]))
    ms = halves[0].ms

    def weigh_r(h, r):
        k = len(h.ms)
        return _view(h, np.full(k, 50.0), h.n, np.ones(k, dtype=bool), np.full(k, 1e-12),
                     np.asarray(r)[:k])

    tau_h = ms / 1.0
    r_one = C**2 * sawtooth_avar(T, 1.0, tau_h, 0.0)
    same = (Column("u", 0.0), Column("u", 900.0), Column("start", 900.0))
    assert _smoothing(r_one, halves, weigh_r, T, 1.0, tau_h, same,
                      np.array([C, 0.5 * C, 0.0])) == 0.0
    apart = (Column("u", 240.0), Column("u", 480.0))
    assert _smoothing(r_one, halves, weigh_r, T, 1.0, tau_h, apart,
                      np.array([5 * C, -4 * C])) > 0.0


def test_two_paths_rival_a_dt_term_only_when_they_beat_it_by_the_margin():
    """Two paths hold the dT/dt term in their limit (a parameter more), so against a chosen
    dT/dt term they need the margin any extension needs over the model it holds, whether or
    not their coefficients cancel: on the dT/dt row's records a fit of cancellation 0.48
    (2.42e-3 and −4.62e-3 through 178 and 562 s) predicted 2.2 better and was named beside
    it under the cancellation rule this replaces."""
    from avard.core.explain.thermal_paths import PathScore
    from avard.core.explain.thermal_paths.readings import _mimic

    def score(kind: str, beta: list[float], heldout: float) -> PathScore:
        return PathScore(kind, heldout, (178.0, 562.0), np.array(beta), np.zeros(2),
                         (0.0, 0.0), (0.0, 0.0), 20.0, False)

    rate = score("rate", [8e-4, 0.23], -40.0)
    for beta in ([0.0200, -0.0199], [2.42e-3, -4.62e-3]):
        assert _mimic(score("two_path", beta, -40.0 - 2.2), rate)
        assert _mimic(score("two_path", beta, -40.0 - HELDOUT_MARGIN + 0.1), rate)
        # predicting better by the margin: a rival (named, or chosen)
        assert not _mimic(score("two_path", beta, -40.0 - HELDOUT_MARGIN - 0.1), rate)
    # the note's wording: two of opposite sign that nearly cancel, and not two of one sign
    assert _derivative_limit(score("two_path", [0.0200, -0.0199], -40.0))
    assert not _derivative_limit(score("two_path", [8e-4, -2.7e-3], -40.0))
    assert not _derivative_limit(score("two_path", [0.02, 0.0199], -40.0))


@pytest.mark.parametrize("seed", [48001, 48014])
def test_a_dt_term_is_named_alone_beside_rivals_it_holds_or_that_predict_worse_with_more(
        seed: int):
    """The benchmark's dT/dt row (8e-4 m/s²/K at lag 0 and r at 3× its stated minimum)
    through the whole engine, two development records named "dT/dt term or …": 48001 two
    paths predicting 2.2 better than the dT/dt term (cancellation 0.48: no cancellation
    rule held them), 48014 a hysteresis, a parameter more, predicting 5.9 worse. Neither is
    a rival (two paths need the margin over the term they hold; a candidate with more
    parameters that predicts worse is beaten by both measures): the dT/dt term alone, with
    its intervals."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: dT/dt")
    ex, _ = explain_weekend(row.weekend, seed)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th and th[0].mechanism == "rate" and not th[0].alternatives
    assert th[0].intervals
    assert th[0].params["rate_coupling"] == pytest.approx(row.truth["rate_coupling"], rel=0.2)


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "extra", "truth", "least"), [
    ("rate", {"rate_coupling": 0.23}, {"rate_coupling": 0.23}, 9),
    ("two_path", {"second_path": (-2.7e-3, 900.0)}, {"coefficient_2": -2.7e-3}, 8),
])
def test_the_path_rows_choose_alone_and_their_68_percent_intervals_hold_about_68_percent(
        kind: str, extra: dict, truth: dict, least: int):
    """The benchmark's dT/dt and two-path rows at their sizes (a coupling of 8e-4 m/s²/K at
    lag 0, the extra term at 3× its stated minimum), ten records each: the mechanism chosen
    alone on ``least`` (dT/dt: its short-lag two-path rival is its limit, not a rival, 10 of
    10 here; two paths: 8 of 10 here, 18 of 20 on the benchmark, the misses a dT/dt term
    named beside it or, once, alone: the issue's 95 % is not met) and the coefficients' 68 %
    intervals, θ continuous in the jackknife and the profile on the deviance's own scale,
    holding the truth in 45–90 % (the binomial band of 68 % on about twenty intervals: they
    over-covered, 30 of 34 and 14 of 16, with θ re-chosen on the coarse grid). Two paths on
    this one-line drive give c₁ and c₂ no interval ("not resolved", paths23c): theirs are the
    gain and phase at the drive, against the generator's own response there."""
    c = 8e-4
    w = replace(BASE, coefficient=(c, 0.0, 0.0), **extra)
    alone = inside = total = 0
    for seed in range(10):
        pf = _path(*_slow(w, 100 + seed))
        if pf.kind != kind or pf.alternatives:
            continue
        alone += 1
        p, iv = pf.params()
        want = {"coefficient": c, **truth}
        if "gain_at_drive" in p:
            # two paths: c₁ and c₂ mostly "not resolved" (no interval) on one drive line;
            # what is resolved is the response at the drive, the generator's own there
            jw = 2j * math.pi / p["drive_period_s"]
            g = c + extra["second_path"][0] * (1 + 30 * jw) / (1 + 900 * jw)
            want |= {"gain_at_drive": abs(g), "phase_at_drive_rad": float(np.angle(g))}
        for k, v in want.items():
            if k in iv:
                total += 1
                inside += iv[k][0] <= v <= iv[k][1]
    assert alone >= least, alone
    assert total >= 10 and 0.45 <= inside / total <= 0.9, (inside, total)


@pytest.mark.slow
def test_the_hysteresis_rows_parameters_and_their_68_percent_intervals():
    """The benchmark row ``path: hysteresis`` (h at 3× its minimum with the coupling and
    the switch unknown, beside c at 3× the one-lag minimum) on 12 seeds: the hysteresis
    chosen with c and h within 20 % on at least 11, and the 68 % intervals holding the truth
    in 11–21 of the 24 (68 % ± 2.4 binomial σ; 40 records gave 54/78 and 40/40 within 20 %,
    docs/log/explain.md). The largest of three standard errors held 82 %, above this band's
    centre by 1.7 σ on 24."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: hysteresis")
    within = inside = total = 0
    for seed in range(30020, 30032):
        ex, _cpu = explain_weekend(row.weekend, seed)
        temps = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
        if not temps or temps[0].mechanism != "hysteresis":
            continue
        p, iv = temps[0].params, temps[0].intervals
        within += all(p[k] == pytest.approx(v, rel=0.2) for k, v in row.truth.items())
        for k, v in row.truth.items():
            if k in iv:
                total += 1
                inside += iv[k][0] <= v <= iv[k][1]
    assert within >= 11
    assert total >= 20 and 11 <= inside <= 21, (inside, total)


@pytest.mark.parametrize("seed", [30001, 30004])
def test_a_quadratic_start_is_not_taken_out_as_a_warm_up_before_the_path_is_chosen(seed: int):
    """The benchmark's quadratic row (8e-4 m/s²/K and q at 3× its stated minimum, lag 0)
    through the whole engine: the plate settles from where it started, so q·(u − ū)² is
    largest in the record's first minutes, and one lag leaves it in its residual, where the
    warm-up test found it. Taken out before the path was chosen, it bent the quadratic fit on
    the record's first part (q 30 % low, the extra term's jackknife z under the threshold):
    one lag was chosen on 4 of 10 records, these two among them. The quadratic explains that
    start itself, so the warm-up goes back in and the quadratic is chosen, q within 20 %."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: quadratic")
    ex, _ = explain_weekend(row.weekend, seed)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th and th[0].mechanism == "quadratic"
    assert th[0].params["quadratic"] == pytest.approx(row.truth["quadratic"], rel=0.2)
    assert not [f for f in ex.channels["x"].claimed if f.cause == "warmup"]


def _fisher_se(G, p0, lines, sig, i, h=1e-6):
    """The standard error of parameter ``i`` of the complex response ``G(ω, p)`` from its
    numerical Jacobian (central differences, relative step ``h``) at each drive line
    (amplitude K, period s), noise σ_a per quadrature: an independent Fisher calculation."""
    info = np.zeros((len(p0), len(p0)))
    for a, period in lines:
        w = 2 * math.pi / period
        d = np.zeros(len(p0), complex)
        for j in range(len(p0)):
            step = h * max(abs(p0[j]), 1.0)
            up, dn = list(p0), list(p0)
            up[j] += step
            dn[j] -= step
            d[j] = (G(w, up) - G(w, dn)) / (2 * step)
        info += (a / sig(1 / period)) ** 2 * np.real(np.outer(d, d.conj()))
    ev = np.linalg.eigvalsh(info / np.outer(np.sqrt(np.diag(info)), np.sqrt(np.diag(info))))
    return math.inf if ev[0] < 1e-9 else math.sqrt(float(np.linalg.inv(info)[i, i]))


def test_the_two_path_minimum_is_the_fishers_with_the_lags_unknown():
    """The GLS fit estimates both lags beside both coefficients. The Fisher information of
    (c₁, c₂, L1, L2) from the response's numerical Jacobian at each drive line: on the HVAC
    line alone it is singular (one complex number, four unknowns: no finite minimum, where
    the lags known gave 9.0e-4 m/s²/K), on the HVAC and the compressor's fundamental c₂'s
    standard error times z is the stated minimum, whatever the coefficients' sizes, and
    about ten times the minimum with the lags known."""
    from avard.core.explain.causes import noise_psd

    N, B, K, rec = 1.6e-4, 2e-5, 2e-6, 4 * 3600.0

    def sig(f: float) -> float:
        return math.sqrt(2 * noise_psd(f, N, B, K) / rec)

    def G(w, p):
        return p[0] / (1 + 1j * w * p[2]) + p[1] / (1 + 1j * w * p[3])

    hvac, comp = (0.214, 1800.0), (0.0465, 1200.0)
    one = min_detectable_path("two_path", N, B, K, rec, *hvac, 0.0, 870.0)
    assert one == math.inf
    assert _fisher_se(G, [8e-4, -2.7e-3, 0.0, 870.0], [hvac], sig, 1) == math.inf
    known = min_detectable_path("two_path", N, B, K, rec, *hvac, 0.0, 870.0, lags_known=True)
    assert known == pytest.approx(9.0e-4, rel=0.01)
    got = min_detectable_path("two_path", N, B, K, rec, *hvac, 0.0, 870.0, lines=(comp,))
    for p0 in ([8e-4, -2.7e-3, 0.0, 870.0], [3e-3, 5e-3, 0.0, 870.0]):
        assert got == pytest.approx(5.0 * _fisher_se(G, p0, [hvac, comp], sig, 1), rel=1e-4)
    was = min_detectable_path("two_path", N, B, K, rec, *hvac, 0.0, 870.0, lines=(comp,),
                              lags_known=True)
    assert got > 5 * was


def test_the_rate_term_and_a_lag_of_zero_are_one_parameter_to_first_order():
    """c·lag(T, L) = c·T − c·L·dT/dt + O(L²): at a true static lag of 0 the lag's derivative
    is the dT/dt term's on every drive, so with L unknown r has no finite minimum (two lines
    or ten), and what the fit resolves is r − c·L, whose standard error (the Jacobian of
    (c, r − c·L) with L left free) is the stated minimum with the lag known."""
    from avard.core.explain.causes import noise_psd

    N, B, K, rec = 1.6e-4, 2e-5, 2e-6, 4 * 3600.0

    def sig(f: float) -> float:
        return math.sqrt(2 * noise_psd(f, N, B, K) / rec)

    def G(w, p):  # (c, r, L)
        return p[0] / (1 + 1j * w * p[2]) + 1j * w * p[1]

    def G_net(w, p):  # (c, m = r − c·L, L)
        return p[0] / (1 + 1j * w * p[2]) + 1j * w * (p[1] + p[0] * p[2])

    lines = [(0.214, 1800.0), (0.0465, 1200.0), (0.0043, 400.0)]
    assert min_detectable_path("rate", N, B, K, rec, *lines[0], lines=tuple(lines[1:])) \
        == math.inf
    assert _fisher_se(G, [8e-4, 0.06, 0.0], lines, sig, 1) == math.inf
    known = min_detectable_path("rate", N, B, K, rec, *lines[0], lines=tuple(lines[1:]),
                                lags_known=True)
    se = _fisher_se(lambda w, p: G(w, [p[0], p[1], 0.0]), [8e-4, 0.06], lines, sig, 1)
    assert known == pytest.approx(5.0 * se, rel=1e-4)
    # the L column of (c, m, L) vanishes at L = 0: m's se is the known-lag one
    eps = 1e-3
    for _a, period in lines:
        w = 2 * math.pi / period
        dL = (G_net(w, [8e-4, 0.06, eps]) - G_net(w, [8e-4, 0.06, -eps])) / (2 * eps)
        assert abs(dL) < 1e-6 * abs(1j * w * 0.06)


def test_a_short_static_lag_is_a_rate_term_to_first_order():
    """c·lag(T, L) = c·T − c·L·dT/dt + O(ω²L²): what is left after the first order falls as
    L², so at a true lag near 0 a lag and a dT/dt term trade (r − c·L fixed) and only the
    second order tells them apart."""
    from avard.core.explain.thermal_fit import lag_filter

    t = np.arange(0, 4 * 3600.0, 1.0)
    T = 0.2 * np.sin(2 * np.pi * t / 1800) + 0.05 * np.sin(2 * np.pi * t / 1200 + 1.0)
    dT = np.gradient(T, 1.0)
    keep = t > 1800  # past the filter's start
    left = []
    for L in (10.0, 20.0):
        first = T - L * dT
        left.append(float(np.sqrt(np.mean((lag_filter(T, L, 1.0) - first)[keep] ** 2))))
        assert left[-1] < 0.1 * L * float(np.sqrt(np.mean(dT[keep] ** 2)))
    assert left[1] / left[0] == pytest.approx(4.0, rel=0.15)


def test_a_rate_term_reports_r_net_of_its_static_lag_and_the_split_without_interval():
    """``describe`` of a refined dT/dt term: ``rate_coupling`` is r − c·L (``net_rate``,
    what the data resolve) with its own interval (the same anywhere along the ridge: not
    widened to the split's at the fitted L, a hull that held the truth on 96 % of records);
    the split r is ``rate_coupling_beside_lag`` with no interval; c and L keep theirs."""
    from avard.core.explain.thermal_paths import PathScore
    from avard.core.explain.thermal_paths.refine import net_rate
    from avard.core.explain.thermal_paths.scores import describe

    beta = np.array([1e-3, 0.08, 0.0])
    assert net_rate(beta, (20.0,)) == pytest.approx(0.06)
    s = PathScore("rate", 0.0, (20.0,), beta, np.array([1e-5, 2e-3]), (5.0,), (30.0,), 12.0,
                  False, (), (0.98e-3, 0.077), (1.02e-3, 0.083), True, 1.0,
                  (0.06, 0.058, 0.062))
    p, iv = describe(s)
    assert p["rate_coupling"] == 0.06 and iv["rate_coupling"] == [0.058, 0.062]
    assert p["rate_coupling_beside_lag"] == 0.08 and "rate_coupling_beside_lag" not in iv
    assert iv["coefficient"] == [0.98e-3, 1.02e-3] and iv["lag_s"] == [5.0, 30.0]
    # a dT/dt term that was not refined (never chosen) and two paths report as before
    p0, iv0 = describe(replace(s, net=()))
    assert p0["rate_coupling"] == 0.08 and iv0["rate_coupling"] == [0.077, 0.083]


def test_the_quadratic_tries_the_one_lag_fits_leads_through_the_same_filter():
    """The quadratic's grid reaches negative lags (the logged sensor lagging the die) as far
    as the one-lag fit's own search does on the record (``thermal_fit._lag_grid``), the
    extensions' grid mirrored, each regressor the lead-lag ``lag_filter`` gives; a lag at
    the longest lead is a search's edge (open), as one at the longest lag."""
    from avard.core.explain.thermal_fit import lag_filter
    from avard.core.explain.thermal_fit.scan import _lag_grid
    from avard.core.explain.thermal_paths import path_columns
    from avard.core.explain.thermal_paths.columns import Column, quadratic_leads
    from avard.core.explain.thermal_paths.profile import _at_end
    from avard.core.explain.thermal_paths.settings import LAG_GRID_S

    leads = quadratic_leads(4 * 3600.0, 1.0)
    reach = -float(np.min(_lag_grid(4 * 3600.0, 1.0)))
    assert leads and all(-reach <= x < 0 for x in leads)
    assert sorted(-x for x in leads) == [x for x in LAG_GRID_S if 0 < x <= reach]
    assert -60.0 in leads
    ts = trials("quadratic", [0.0, 15.0, 30.0, -94.5], leads)
    assert {t.theta[0] for t in ts} == {0.0, 15.0, 30.0, -94.5, *leads}
    # the other candidates keep their grids
    assert all(t.theta[0] >= 0 for t in trials("rate", [0.0, 15.0], leads))
    assert {t.theta[0] for t in trials("one_lag", [0.0, -94.5], leads)} == {0.0, -94.5}
    # the columns through the one-lag fit's lead-lag filter: the linear one on the readings,
    # the square on the temperature behind them (``crossing_reconstruction``)
    T = np.round((20 + 0.3 * np.sin(np.arange(3000) / 200.0)) / 0.0625) * 0.0625
    X = path_columns(T, [Column("u", -60.0), Column("quad", -60.0)], 1.0)
    u = lag_filter(T, -60.0, 1.0)
    assert np.allclose(X[:, 0], u - u.mean())
    v = lag_filter(crossing_reconstruction(T), -60.0, 1.0)
    q = (v - v.mean()) ** 2
    assert np.allclose(X[:, 1], q - q.mean())
    far = min(range(len(ts)), key=lambda i: ts[i].theta[0])
    assert _at_end(ts, far, leads=True) and not _at_end(ts, far)


@pytest.mark.parametrize("seed", [31001])
def test_a_quadratic_whose_die_leads_the_log_is_fitted_at_a_lead(seed: int):
    """The quadratic row's sizes with the logged sensor 90 s behind the plate and the die
    30 s (the die 60 s ahead of the log) and q of the opposite sign: the one-lag fit's lag
    is −380 s here, and the quadratic, with no other lead to try, took it (q 0.36 of the
    truth). With the one-lag fit's leads on its grid it fits near −60 s, q within 20 %."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: quadratic")
    q = -row.truth["quadratic"]
    w = replace(row.weekend, quadratic=q, die_tau_s=30.0, sensor_tau_s=90.0)
    ex, _ = explain_weekend(w, seed)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th and th[0].mechanism == "quadratic"
    assert th[0].params["quadratic"] == pytest.approx(q, rel=0.2)
    assert -120.0 <= th[0].params["lag_s"] <= -15.0


def test_the_quadratic_term_is_not_pulled_low_by_the_readings_rounding():
    """Squared, the readings' 0.0625 K rounding e is an error 2(u − ū)e + e² in the
    quadratic's regressor, locked to the drive's phase (every part shares it: the jackknife
    does not see it). On the readings themselves q came out 0.94–0.97 of the truth on these
    three low-noise records (mean 0.95, its ±1–2 % intervals short of the truth on two); on
    the temperature behind the readings (``crossing_reconstruction``, as the relay) 0.99–1.02,
    mean 1.00."""
    c, q = 8e-4, 4.42e-3
    got = []
    for seed in (2, 3, 4):
        w = replace(BASE, coefficient=(c, 0.0, 0.0), quadratic=q, N=1.6e-5, B=2e-6, K=2e-7)
        pf = _path(*_slow(w, seed))
        assert pf.kind == "quadratic"
        got.append(pf.chosen.beta[1] / q)
    assert all(abs(g - 1) < 0.04 for g in got), got
    assert abs(float(np.mean(got)) - 1) < 0.02, got


@pytest.mark.parametrize("seed", [49007, 49017])
def test_a_second_paths_start_is_not_taken_out_as_a_warm_up_before_the_path_is_chosen(
        seed: int):
    """The benchmark's two-path + compressor row through the whole engine: the second path
    runs through the plate's 900 s, which settles from where it started, so one lag leaves
    that path's start in its residual, where the warm-up test found it. Taken out before the
    path was chosen, it took the second path's start with it: one lag (49007) or a
    dT/dt term (49017) was chosen on the rest, where two paths predict the record as
    recorded better by 70 (4 of 20 development records of the row). The two paths explain
    that start from the logged temperature alone, so the warm-up goes back in and two paths
    are chosen alone, nothing claimed a warm-up."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path+compressor: two paths")
    ex, _ = explain_weekend(row.weekend, seed)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th and th[0].mechanism == "two_path" and not th[0].alternatives
    assert th[0].params["coefficient_2"] == pytest.approx(row.truth["coefficient_2"], rel=0.2)
    assert not [f for f in ex.channels["x"].claimed if f.cause == "warmup"]


def test_the_paths_fit_reads_its_blocks_as_the_plain_indexing_does() -> None:
    """``_fit`` and ``_resid`` read a regressor subset's covariance blocks once per view
    (``_blocks``: one gather, kept) and ``_fit`` keeps its solution: the same numbers to the
    bit as the plain indexing ``c[:, idx][:, :, idx]`` and a fresh solve (the candidates'
    deviances are compared and the least chosen: a last-bit change moved a chosen lag on
    near-ties), on views of many sizes, with dead regressors, asked twice."""
    from avard.core.explain.thermal_paths.deviance import _dev, _fit, _resid, _View
    from avard.core.model.nnls import _lstsq

    def plain_fit(v: _View, idx: list[int]) -> np.ndarray:
        c = v.cov
        w = v.nu / v.s
        A = np.einsum("k,kij->ij", w, c[:, idx][:, :, idx])
        b = w @ c[:, idx, 0]
        d = np.diag(A)
        live = np.flatnonzero(d > 1e-14 * max(float(d.max()), 1e-300))
        out = np.zeros(len(idx))
        if len(live):
            sc = np.sqrt(d[live])
            out[live] = np.array(_lstsq(A[np.ix_(live, live)] / np.outer(sc, sc),
                                        b[live] / sc, rcond=1e-10)) / sc
        return out

    def plain_resid(v: _View, idx: list[int], beta: np.ndarray) -> np.ndarray:
        c = v.cov
        return np.asarray(c[:, 0, 0] - 2 * c[:, idx, 0] @ beta
                          + np.einsum("i,kij,j->k", beta, c[:, idx][:, :, idx], beta))

    rng = np.random.default_rng(23)
    for _ in range(300):
        K, C = int(rng.integers(1, 16)), int(rng.integers(2, 60))
        X = rng.standard_normal((K, C, 3 * C))
        cov = X @ X.transpose(0, 2, 1)
        dead = rng.integers(1, C)
        cov[:, dead, :] = cov[:, :, dead] = 0.0  # a regressor the view does not see
        v = _View(cov, rng.random(K) * 40 + 3, rng.random(K) + 0.5)
        for _ in range(6):
            n = int(rng.integers(1, min(C - 1, 6) + 1))
            idx = sorted(int(i) for i in rng.choice(np.arange(1, C), n, replace=False))
            want = plain_fit(v, idx)
            for _ in range(2):  # the second reading is the kept one
                got = _fit(v, idx)
                assert np.array_equal(got, want)
                assert np.array_equal(_resid(v, idx, got), plain_resid(v, idx, want))
                assert _dev(v, idx, got) == float(np.sum(v.nu * plain_resid(v, idx, want) / v.s))
            got[:] = 0.0  # a caller's copy: the kept solution is not changed through it
            assert np.array_equal(_fit(v, idx), want)


def test_the_compressor_two_path_rows_truth_is_the_candidate_that_holds_the_generator():
    """The weekend generator's second path is lag(plate, 900 s) while the logged sensor is
    lag(plate, 30 s): by partial fractions that is exactly (30/900)·sensor + (29/30)·
    lag(sensor, 900 s), so the row's truth is the two-path candidate at lags 0 and 900 s
    with c + c₂/30 and 29c₂/30 (``two_path_truth``), not lag(sensor, 870 s) with c and c₂,
    which no candidate holds (the row's truth before: its intervals scored the generator's
    approximation)."""
    from avard.core.explain.thermal_fit import lag_filter

    from benchmarks.bench_explain_weekend import rows_paths, two_path_truth
    from tests.support.weekend import _lag

    rate = 1.0
    t = np.arange(4 * 3600) / rate
    room = (0.5 * np.sin(2 * np.pi * t / 1800) + np.tanh(4 * np.sin(2 * np.pi * t / 1200))
            + 0.05 * np.cumsum(np.random.default_rng(3).standard_normal(len(t))) / 120)
    plate = _lag(room, 600.0, 1 / rate)
    sensor, second = _lag(plate, 30.0, 1 / rate), _lag(plate, 900.0, 1 / rate)
    c, c2 = 8e-4, -1.4e-3
    y = c * sensor + c2 * second
    want = two_path_truth(c, c2, 900.0, 30.0)
    got = (want["coefficient"] * sensor
           + want["coefficient_2"] * lag_filter(sensor, want["lag_2_s"], rate))
    settled = slice(3600, None)  # past the filters' differing start states
    # (to the two discrete filters' rounding: 1e-5 of the second path's signal)
    scale = np.std(c2 * second[settled])
    assert np.max(np.abs(got - y)[settled]) < 1e-4 * scale
    # the old truth, lag(sensor, 870 s) with c and c₂, misses by a share of c₂'s signal
    old = c * sensor + c2 * lag_filter(sensor, 870.0, rate)
    assert np.std((old - y)[settled]) > 0.02 * scale
    row = next(r for r in rows_paths() if r.name == "path+compressor: two paths")
    c2_row = row.weekend.second_path[0]
    assert row.truth["lag_2_s"] == row.weekend.second_path[1] == 900.0
    assert row.truth["coefficient_2"] == pytest.approx(c2_row * 29 / 30)
    assert row.truth["coefficient"] == pytest.approx(row.weekend.coefficient[0] + c2_row / 30)
    # the row's size (comp23e): the candidate's c₂ at 3× the fit's own stated minimum, the
    # lags unknown, on the drive with the compressor's harmonics (docs/explain.md); the
    # cycle's fundamental is 1.238 of its ±1 °C, and with the lags known the minimum is
    # over ten times smaller (the row's size before, one the fit cannot resolve)
    from avard.core.explain.thermal_paths import min_detectable_path

    from benchmarks.bench_explain_weekend import (
        HOURS,
        PERIOD,
        B,
        K,
        N,
        _path_base,
        compressor_harmonics,
        min_two_path_compressor,
    )
    assert compressor_harmonics()[0][0] == pytest.approx(1.238, abs=1e-3)
    A = _path_base()[1]
    m = min_two_path_compressor(A)
    assert row.truth["coefficient_2"] == pytest.approx(-3 * m)
    more = tuple((a / math.hypot(1, 2 * math.pi / p * 600) / math.hypot(1, 2 * math.pi / p * 30),
                  p) for a, p in compressor_harmonics())
    known = min_detectable_path("two_path", N, B, K, HOURS * 3600, A, PERIOD, 0.0, 900.0,
                                lines=more, lags_known=True)
    assert 10 * known < m < math.inf


def test_the_drive_is_the_logged_channels_strongest_line_and_its_share():
    """``drive_line``: the periodogram's peak of the channel, its trend taken out, refined
    between bins: a 1800 s sine on a 4 h record at 1 Hz, beside a slow trend, a random walk
    and the readings' 0.0625 K rounding, within 1 %, holding over 90 % of the channel
    (``ONE_LINE_SHARE``: one line); a second line of 1.7× its size at 1200 s is the strongest
    then and holds under 90 %; NaN on a channel too short to hold one."""
    from avard.core.explain.thermal_paths.refine import drive_line
    from avard.core.explain.thermal_paths.settings import ONE_LINE_SHARE

    rng = np.random.default_rng(3)
    t = np.arange(4 * 3600.0)
    T = (21 + 0.2 * np.sin(2 * math.pi * t / 1800 + 0.4) + 1e-4 * t
         + 0.02 * np.cumsum(rng.standard_normal(len(t))) / math.sqrt(len(t)))
    per, share = drive_line(np.round(T / 0.0625) * 0.0625, 1.0)
    assert per == pytest.approx(1800.0, rel=0.01) and share >= ONE_LINE_SHARE
    assert drive_line(T[::10], 0.1)[0] == pytest.approx(1800.0, rel=0.01)
    per, share = drive_line(T + 0.35 * np.sin(2 * math.pi * t / 1200), 1.0)
    assert per == pytest.approx(1200.0, rel=0.01) and share < ONE_LINE_SHARE
    assert all(math.isnan(x) for x in drive_line(T[:8], 1.0))


def test_the_response_at_the_drive_is_one_number_along_the_two_paths_ridge():
    """Two splits into (c₁, L1, c₂, L2) with the same response at the drive's period have the
    same ``drive_response`` there (what one drive line resolves) and differ elsewhere (it is
    the drive's, not a constant of the fit); a lead is a positive phase."""
    from avard.core.explain.thermal_paths.refine import drive_response

    P = 1800.0
    w = 2 * math.pi / P
    a = drive_response(np.array([8e-4, -2.7e-3]), (0.0, 870.0), P)
    assert a == pytest.approx(8e-4 - 2.7e-3 / (1 + 1j * w * 870.0))
    # another split: lags 300 and 1500 s, coefficients solved to give the same G(ω₀)
    h = np.array([1 / (1 + 1j * w * 300.0), 1 / (1 + 1j * w * 1500.0)])
    M = np.array([[h[0].real, h[1].real], [h[0].imag, h[1].imag]])
    b2 = np.linalg.solve(M, [a.real, a.imag])
    assert drive_response(b2, (300.0, 1500.0), P) == pytest.approx(a)
    assert abs(drive_response(b2, (300.0, 1500.0), 600.0)
               - drive_response(np.array([8e-4, -2.7e-3]), (0.0, 870.0), 600.0)) > 0.1 * abs(a)
    assert np.angle(a) > 0  # a negative second path through a long lag leads the channel


def test_two_path_parameters_wider_than_ten_percent_are_not_resolved():
    """``describe`` of a refined two-path fit: the response at the drive with its interval,
    c₁, c₂ and the lags with theirs only where within ±10 % of the value (a lag: or ±15 s)
    and the drive is more than one line, the others "not resolved" (their values kept, no
    interval); on a drive of one line none of the four is resolved."""
    from avard.core.explain.thermal_paths import PathScore
    from avard.core.explain.thermal_paths.scores import describe, unresolved

    s = PathScore("two_path", -80.0, (0.0, 870.0), np.array([8e-4, -2.7e-3]), np.zeros(2),
                  (-10.0, 570.0), (10.0, 1170.0), 20.0, False,
                  beta_lo=(7.6e-4, -3.8e-3), beta_hi=(8.4e-4, -1.6e-3),
                  drive=(1800.0, 9.6e-4, 9.2e-4, 1.0e-3, 0.98, 0.94, 1.02, 0.7))
    p, iv = describe(s)
    assert set(p) >= {"coefficient", "coefficient_2", "lag_s", "lag_2_s", "drive_period_s",
                      "gain_at_drive", "phase_at_drive_rad"}
    assert iv["gain_at_drive"] == [9.2e-4, 1.0e-3] and iv["phase_at_drive_rad"] == [0.94, 1.02]
    # c₁ ±5 % and L1 ±10 s (the 15 s floor) kept; c₂ ±41 % and L2 ±300 s not
    assert "coefficient" in iv and "lag_s" in iv
    assert "coefficient_2" not in iv and "lag_2_s" not in iv
    assert unresolved(p, describe(replace(s, drive=()))[1]) == ["coefficient_2", "lag_2_s"]
    # without a drive (not refined) the fit's own intervals stand as before
    assert "coefficient_2" in describe(replace(s, drive=()))[1]
    # one line (96 % of the channel): none of the four keeps its interval
    one = describe(replace(s, drive=(*s.drive[:7], 0.96)))[1]
    assert set(one) == {"gain_at_drive", "phase_at_drive_rad"}


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "chosen"), [(30006, "rate"), (30017, "two_path")])
def test_two_paths_on_one_drive_line_report_what_the_record_resolves(seed: int, chosen: str):
    """The benchmark's two-path row on two records whose plate starts near its cycle (the
    dT/dt rival's non-centrality 5.2 and 1.3, under the 10.8 a 95 % choice needs): 30006
    keeps the dT/dt term and lists two paths as fitting as well (through the one-lag fit's
    3600 s, open: a bound, predicting better); 30017 chooses two paths, c₁, c₂ and the lags
    far along the ridge and "not resolved", the response at the drive within 5 % and
    0.1 rad of the generator's with 68 % intervals."""
    from benchmarks.bench_explain_weekend import _true_response, explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path: two paths")
    ex, _ = explain_weekend(row.weekend, seed)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th and th[0].mechanism == chosen
    pf = ex.channels["x"].thermal.path
    if chosen == "rate":
        assert "two_path" in pf.as_well and "two_path" not in th[0].alternatives
        assert pf.to_dict()["mechanism_fits_as_well"] == ["two_path"]
        return
    p, iv = th[0].params, th[0].intervals
    assert not {"coefficient", "coefficient_2", "lag_s", "lag_2_s"} & set(iv)
    assert "not resolved (no interval: the drive is one line" in th[0].evidence
    g = _true_response(row.weekend, p["drive_period_s"])
    assert p["gain_at_drive"] == pytest.approx(abs(g), rel=0.05)
    assert abs(p["phase_at_drive_rad"] - np.angle(g)) < 0.1
    assert {"gain_at_drive", "phase_at_drive_rad"} <= set(iv)


def _rounded_room(seed: int, rate: float = 0.625, n: int = 9000) -> tuple[np.ndarray, ...]:
    """(the temperature, its readings rounded to 0.0625 K): the HVAC's 0.2 K at 1800 s and
    a slow wander, as the dT/dt row's die and logged sensor see it (lag 0), at ``rate``."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    wander = np.cumsum(rng.normal(0.0, 2e-3, n))
    T = 21.03 + 0.2 * np.sin(2 * math.pi * t / 1800 + rng.uniform(0, 6.3)) + wander
    return T, np.round(T / 0.0625) * 0.0625


def test_a_rate_terms_fit_reads_the_octaves_where_the_rounding_is_no_larger_a_share():
    """The readings' rounding is an error in the regressors, the same in every part of the
    record (the jackknife does not see it), and a derivative passes its short periods ×ω²:
    fitted from the linear column's rounding floor, a noise-free c·T + r·dT/dt on rounded
    readings gives r ≥ 2 % low on average (errors in variables); from the octave where the
    rounding is no larger a share of the rate column than of the linear one at that floor
    (``_rate_floor``: an octave or more above it), more than half of that is gone and c
    stays within 1 %."""
    from avard.core.explain.thermal_fit.rounding import rounding_floor_tau
    from avard.core.explain.thermal_fit.sums import octave_sums
    from avard.core.explain.thermal_paths import path_columns
    from avard.core.explain.thermal_paths.columns import Column
    from avard.core.explain.thermal_paths.deviance import _fit, _View
    from avard.core.explain.thermal_paths.refine import _from_octave, _rate_floor

    rate, c, r = 0.625, 8e-4, 0.23
    cols = [Column("u", 0.0), Column("rate", 0.0)]
    low, high = [], []
    for seed in range(6):
        T, Tr = _rounded_room(seed, rate)
        y = path_columns(T, cols, rate) @ np.array([c, r])  # no noise: the regressors' error
        s = octave_sums(np.column_stack([y, path_columns(Tr, cols, rate)]))
        floor = rounding_floor_tau(Tr, rate)
        m_min = _rate_floor(Tr, rate, s, 1, 2, 0.0, floor)
        assert m_min >= 2 * floor * rate * (1 - 1e-9)
        for out, sums in ((low, s), (high, _from_octave(s, m_min))):
            use = (sums.ms / rate >= floor) & (sums.ms / rate <= 1700) & (sums.n > 0)
            cov = sums.cov()[use]
            out.append(_fit(_View(cov, np.ones(len(cov)), cov[:, 0, 0]), [1, 2]))
    _lo_c, lo_r = np.mean(low, axis=0)
    hi_c, hi_r = np.mean(high, axis=0)
    assert lo_r < 0.98 * r
    assert abs(hi_r - r) < 0.5 * abs(lo_r - r)
    assert hi_c == pytest.approx(c, rel=0.01)


def test_the_rate_floor_is_the_linear_floor_where_the_rate_column_passes_no_more_rounding():
    """``_rate_floor`` returns the linear column's floor itself where the rate column's
    rounding share there is already no larger (a column of a large, fast drive), and the
    first octave past it where it is (the modelled shares compared, not a fixed step)."""
    from avard.core.explain.thermal_fit.rounding import rounding_floor_tau
    from avard.core.explain.thermal_fit.sums import OctaveSums
    from avard.core.explain.thermal_paths.columns import Column
    from avard.core.explain.thermal_paths.refine import _rate_floor
    from avard.core.explain.thermal_paths.rounding import _path_gain2, sawtooth_avar

    rate = 0.625
    _T, Tr = _rounded_room(1, rate)
    ms = np.array([64, 128, 256, 512, 1024])
    tau = ms / rate
    su = sawtooth_avar(Tr, rate, tau)
    sr = sawtooth_avar(Tr, rate, tau, gain2=_path_gain2((Column("rate", 0.0),), np.ones(1)))
    floor = float(tau[1])

    def sums(var_u: np.ndarray, var_r: np.ndarray) -> OctaveSums:
        cov = np.zeros((len(ms), 3, 3))
        cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = 1.0, var_u, var_r
        n = np.full(len(ms), 100)
        from avard.core.allan.deviations import NORM
        return OctaveSums(ms, n, cov * (NORM[2] * ms.astype(float) ** 2 * n)[:, None, None])

    # the rounding 10 % of u at every τ; of the rate column 10 % from the third octave on
    share_r = np.array([0.5, 0.3, 0.1, 0.1, 0.1])
    assert _rate_floor(Tr, rate, sums(su / 0.1, sr / share_r), 1, 2, 0.0, floor) == 256
    assert _rate_floor(Tr, rate, sums(su / 0.1, sr / 0.05), 1, 2, 0.0, floor) == 128
    assert rounding_floor_tau(Tr, rate) > 0


def _count_path_choices(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Record, per ``with_paths`` call of explain's engine, the axes it chose a path on
    with nothing beside the candidates (0 for a call with warm-ups beside them)."""
    from avard.core.explain.engine import thermal

    calls: list[int] = []
    real = thermal.with_paths

    def counted(fits, Y, *args, **kw):  # type: ignore[no-untyped-def]
        calls.append(0 if kw.get("warmups") else len(fits))
        return real(fits, Y, *args, **kw)

    monkeypatch.setattr(thermal, "with_paths", counted)
    return calls


def _path_and_warm_up_claimed(ex, row):  # type: ignore[no-untyped-def]
    """x's claims of a path row's record beside a warm-up: the row's mechanism alone, its
    parameters within 20 %, and the warm-up (T within 20 % of 900 s), by cause."""
    x = {f.cause: f for f in ex.channels["x"].claimed}
    assert "temperature" in x and x["temperature"].mechanism == row.mechanism
    assert not x["temperature"].alternatives
    for k, v in row.truth.items():
        assert x["temperature"].params[k] == pytest.approx(v, rel=0.2), k
    assert "warmup" in x
    assert x["warmup"].params["time_constant_s"] == pytest.approx(900.0, rel=0.2)
    return x


def test_a_quadratic_beside_a_real_warm_up_is_chosen_and_the_warm_up_claimed(
        monkeypatch: pytest.MonkeyPatch):
    """The benchmark's quadratic row beside a real warm-up (2.39e-3 m/s², T 900 s, 3× the
    event rows' minimum). The warm-up was taken out before the path was chosen, and its
    first estimate, on the one-lag residual, took the quadratic's own start with it (the
    temperature farthest from its mean in the first minutes); or, on this seed, where the
    one lag failed its test, it was not looked for and stayed in the axis beside every
    candidate: nothing temperature was claimed, and the warm-up 1.4× its size (the row
    right on 4 of 40). Fitted as a nuisance beside each candidate, the quadratic is chosen
    alone, both found with their parameters within 20 %."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path+warm-up: quadratic")
    calls = _count_path_choices(monkeypatch)
    ex, _ = explain_weekend(row.weekend, 30001)
    # no extension but the quadratic gains over one lag beside the warm-up, so the choice
    # with nothing beside it could not replace it and is not made
    assert not any(calls), calls
    x = _path_and_warm_up_claimed(ex, row)
    assert x["warmup"].params["size"] == pytest.approx(row.weekend.warmups[0][0], rel=0.2)


def test_a_warm_up_beside_one_lag_is_not_read_as_a_dt_dt_term(
        monkeypatch: pytest.MonkeyPatch):
    """The path rows' record (a lag-0 coupling at 3× the one-lag minimum, no extension)
    beside the same real warm-up (2.39e-3 m/s², T 900 s). The one lag failed its test with
    the warm-up in (z 5.3 against 6.2), so no warm-up was looked for, and chosen with it
    left in, a dT/dt term with a 424 s lag read the warm-up from the logged temperature's own
    settling at the start (the put-back test passed: that signal leaves no warm-up). Beside
    the warm-up the dT/dt term predicts no better than one lag; one lag is claimed and the
    warm-up, each within 20 %."""
    from avard.core.explain.causes import min_detectable_warmup

    from benchmarks.bench_explain_weekend import _path_base, explain_weekend

    base, _a, c = _path_base()
    ww = 3 * min_detectable_warmup(base.N, base.B, base.K, 900.0)
    calls = _count_path_choices(monkeypatch)
    ex, _ = explain_weekend(replace(base, warmups=[(ww, 900.0)]), 61000)
    assert not any(calls), calls  # (as the quadratic's: one lag kept, nothing gains)
    x = {f.cause: f for f in ex.channels["x"].claimed}
    assert "temperature" in x and x["temperature"].mechanism == "one_lag"
    assert x["temperature"].params["coefficient"] == pytest.approx(c, rel=0.2)
    assert abs(x["temperature"].params["lag_s"]) <= 30.0
    assert "warmup" in x
    assert x["warmup"].params["size"] == pytest.approx(ww, rel=0.2)
    assert x["warmup"].params["time_constant_s"] == pytest.approx(900.0, rel=0.2)


def test_the_leverage_weighted_jackknife_is_unbiased_where_one_part_holds_most_information():
    """``_leverage_jk_se`` (two paths' coefficients, comp23e): a linear fit on ten parts of
    which the first holds half the information of the regressor, as a record's start holds
    most of what tells two paths' lags. Over many records the ordinary delete-a-part
    jackknife's variance overstates the estimate's scatter (deleting the rich part moves
    the fit by var_(−g) − var); the leverage-weighted one (Wu 1986) matches it, and with
    equal parts the two are the same number."""
    from avard.core.explain.thermal_paths.deviance import _View
    from avard.core.explain.thermal_paths.profile import _jk_se
    from avard.core.explain.thermal_paths.refine import _leverage_jk_se, _unit_map

    rng = np.random.default_rng(2323)
    sizes = [40] + [5] * 9  # the first part's regressor also 9× larger in spread below
    scale = [3.0] + [1.0] * 9
    M = _unit_map([1, 2], 3)
    est, v_ord, v_w, dofs = [], [], [], []
    for _ in range(250):
        grams = []
        for n, s in zip(sizes, scale, strict=True):
            X = np.column_stack([s * rng.standard_normal(n), np.ones(n)])
            y = X @ np.array([2.0, 0.5]) + rng.standard_normal(n)
            Z = np.column_stack([y, X])
            grams.append(Z.T @ Z)
        whole = sum(grams)

        def view(g: np.ndarray) -> _View:
            return _View(g[None], np.ones(1), np.ones(1))

        parts = [view(whole - g) for g in grams]
        fits = np.array([np.linalg.solve((whole - g)[1:, 1:], (whole - g)[1:, 0])
                         for g in grams])
        est.append(np.linalg.solve(whole[1:, 1:], whole[1:, 0])[0])
        v_ord.append(_jk_se(fits)[0] ** 2)
        se, nu = _leverage_jk_se(view(whole), parts, M, 2)
        v_w.append(se[0] ** 2)
        dofs.append(nu[0])
    true = float(np.var(est))
    assert np.mean(v_ord) > 3 * true
    assert np.mean(v_w) == pytest.approx(true, rel=0.3)
    # the one rich part leaves few degrees of freedom (Satterthwaite), not the parts' 9
    assert 1 <= np.median(dofs) < 4
    # equal parts: the weights are (G − 1)/G each, the ordinary jackknife's (about the
    # whole's value rather than the parts' mean: the same to the parts' spread's square)
    grams = []
    for _ in range(10):
        X = np.column_stack([rng.standard_normal(20), np.ones(20)])
        X = X - X.mean(axis=0) * [1, 0]
        Z = np.column_stack([X @ [2.0, 0.5] + rng.standard_normal(20), X])
        grams.append(Z.T @ Z)
    whole = sum(grams)
    fits = np.array([np.linalg.solve((whole - g)[1:, 1:], (whole - g)[1:, 0]) for g in grams])
    w, nu = _leverage_jk_se(_View(whole[None], np.ones(1), np.ones(1)),
                            [_View((whole - g)[None], np.ones(1), np.ones(1)) for g in grams],
                            M, 2)
    assert w[0] == pytest.approx(_jk_se(fits)[0], rel=0.15)
    assert nu[0] == pytest.approx(9, abs=1.5)



def _cycling_room(seed: int, drive: str, rate: float = 0.625,
                  n: int = 27000) -> tuple[np.ndarray, ...]:
    """(the die's temperature, its readings rounded to 0.0625 K): the HVAC's ±0.5 K at 1800 s
    and a slow wander behind the plate's 600 s and the die's 30 s, with the weekend
    generator's square-ish ±1 K compressor cycle of 1200 s on the room (tanh(4 sin ωt): odd
    harmonics) or a ±0.2 K line of 240 s on the plate (the die's 30 s only)."""
    from avard.core.explain.thermal_fit import lag_filter

    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    room = 0.5 * np.sin(2 * math.pi * t / 1800 + rng.uniform(0, 6.3))
    if drive == "compressor":
        room += np.tanh(4 * np.sin(2 * math.pi * t / 1200 + rng.uniform(0, 6.3)))
    room += np.cumsum(rng.normal(0.0, 2e-3, n))
    plate = lag_filter(room, 600.0, rate)
    if drive == "fast line":
        plate += 0.2 * np.sin(2 * math.pi * t / 240 + rng.uniform(0, 6.3))
    T = 21.03 + lag_filter(plate, 30.0, rate)
    return T, np.round(T / 0.0625) * 0.0625


@pytest.mark.parametrize(("drive", "lo", "hi"), [("HVAC", 0.9, 0.995),
                                                 ("compressor", 1.02, 1.1),
                                                 ("fast line", 1.3, 1.6)])
def test_a_rate_term_is_read_through_its_columns_smoothing_on_any_drive(
        drive: str, lo: float, hi: float):
    """The rate column is dT/dt smoothed forward and back through 30 s (the readings'
    0.0625 K steps), a gain 1/(1 + ω²s²): 0.99 at the HVAC's 1800 s, 0.82 at a compressor's
    third harmonic, 0.62 at 240 s. A noise-free c·T + r·dT/dt fitted on it reads r in
    [``lo``, ``hi``]·r: high where the drive has short periods (the fit makes up their lost
    gain), low on the HVAC alone (the rounding in the regressor). Read through the gain the
    fit's own columns and weights give the unsmoothed slope of the temperature behind the
    readings (``_ungained``), r is within 1 % on every drive and c does not move."""
    from avard.core.explain.thermal_fit.rounding import rounding_floor_tau
    from avard.core.explain.thermal_fit.sums import octave_sums
    from avard.core.explain.thermal_paths import path_columns
    from avard.core.explain.thermal_paths.columns import Column
    from avard.core.explain.thermal_paths.deviance import _fit, _ungained, _View

    rate, c, r = 0.625, 8e-4, 0.06
    cols = [Column("u", 0.0), Column("rate", 0.0), Column("slope", 0.0)]
    raw, read = [], []
    for seed in range(2):
        T, Tr = _cycling_room(seed, drive, rate)
        y = c * (T - T.mean()) + r * np.gradient(T, 1 / rate)  # no noise
        s = octave_sums(np.column_stack([y, path_columns(Tr, cols, rate)]))
        use = (s.ms / rate >= rounding_floor_tau(Tr, rate)) & (s.ms / rate <= 1700)
        cov = s.cov()[use & (s.n > 0)]
        v = _View(cov, np.ones(len(cov)), cov[:, 0, 0])
        b = _fit(v, [1, 2])
        raw.append(b)
        read.append(_ungained(v, [1, 2], b, 3))
    raw_r = np.array(raw)[:, 1] / r
    assert np.all((raw_r > lo) & (raw_r < hi)), raw_r
    got = np.array(read)
    assert np.all(np.abs(got[:, 1] / r - 1) < 0.01), got[:, 1] / r
    assert np.all(np.abs(got[:, 0] / c - 1) < 0.01), got[:, 0] / c


@pytest.mark.slow
def test_the_compressor_dt_rows_rate_term_is_not_read_high_through_the_smoothing():
    """The benchmark's dT/dt + compressor row through the whole engine, 16 development
    records (seeds 71000–71015): the rate column's 30 s smoothing loses the compressor's
    harmonics' gain (0.82 at the third) and the fit made r − c·L up for it, 1.039× the
    truth on average on these records (sd 4 %) against intervals of ±3–6 %; read through
    the column's gain (``_ungained``) the mean is 1.004×."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path+compressor: dT/dt")
    got = []
    for seed in range(71000, 71016):
        ex, _ = explain_weekend(row.weekend, seed)
        th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
        assert th and th[0].mechanism == "rate"
        got.append(th[0].params["rate_coupling"] / row.truth["rate_coupling"])
    assert abs(float(np.mean(got)) - 1) < 0.015, got


@pytest.mark.slow
@pytest.mark.parametrize("seed", [78000, 78014, 80003])
def test_a_dt_dt_term_beside_a_real_warm_up_keeps_its_fit_and_the_warm_up_claimed(seed: int):
    """The benchmark's dT/dt row beside the same real warm-up (2.39e-3 m/s², T 900 s). The
    path is chosen beside the warm-up (the dT/dt term) and with nothing beside it, which
    read the warm-up from the logged temperature's start into its own parameters: as the
    dT/dt term again (78000, r and c 20–40 % off), as two paths of opposite sign in the dT/dt
    term's limit (78014: 381 and 480 s cancelling to 0.16) or two paths that beside the
    warm-up predict no better than the dT/dt term by the margin (80003), and that choice
    replaced the one made beside the warm-up, which was then never claimed (4 of 8
    development records right). The same mechanism both ways keeps the fit made beside the
    warm-up: the dT/dt term alone, its parameters within 20 %, and the warm-up claimed."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    row = next(r for r in rows_paths() if r.name == "path+warm-up: dT/dt")
    ex, _ = explain_weekend(row.weekend, seed)
    _path_and_warm_up_claimed(ex, row)


@pytest.mark.parametrize(("row", "seed", "mechanism"), [
    ("path+warm-up: dT/dt", 38001, "rate"),
    ("path+warm-up: two paths", 40000, "two_path"),
])
def test_two_paths_in_the_dt_terms_limit_beside_a_warm_up_are_read_by_the_choice_alone(
        row: str, seed: int, mechanism: str):
    """Beside a warm-up, two paths of opposite sign that nearly cancel (the dT/dt term's
    limit, a parameter more, with two start states of free size) beat a true dT/dt term held
    out, and a second path's start is taken up by the warm-up's shapes, so two true paths
    fall into that limit too. The choice made with nothing beside the warm-up tells them:
    38001 (dT/dt, two paths at 191/240 s chosen beside the warm-up and the warm-up never
    claimed before) reads as the term alone too, so the term is chosen with the warm-up
    claimed and two paths listed as fitting as well; 40000 (two paths at 0 and 900 s) alone
    chooses two paths of their own response, and two paths stay (the dT/dt term named beside
    them where the fit beside the warm-up is in its limit: ``both_readings``)."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    r = next(x for x in rows_paths() if x.name == row)
    ex, _ = explain_weekend(r.weekend, seed)
    ch = ex.channels["x"]
    th = [f for f in ch.claimed if f.cause == "temperature"]
    assert th and th[0].mechanism == mechanism
    if mechanism == "rate":
        assert not th[0].alternatives
        assert any(f.cause == "warmup" for f in ch.claimed)
        assert ch.thermal is not None and ch.thermal.path is not None
        assert "two_path" in ch.thermal.path.as_well
        for k, v in r.truth.items():
            assert th[0].params[k] == pytest.approx(v, rel=0.2)


def test_the_dt_term_is_named_beside_one_lag_where_it_is_that_lag_at_the_drive(base_path):
    """c·T + r·dT/dt with r/c = −L is one lag L at the drive (c' = c(1 + ω²L²)): on a record
    of that truth (r/c = −300 s, a 1800 s drive: c' about twice c) one lag is kept with its
    coefficient about twice the coupling, and the finding must say the dT/dt term fits as
    well (or choose it); a lag-0 coupling, where both readings are one coefficient, names
    nothing beside it."""
    w = replace(BASE, coefficient=(C / 2, 0.0, 0.0), rate_coupling=-C / 2 * 300.0)
    pf = _path(*_slow(w, 1))
    assert pf.kind == "rate" or "rate" in pf.as_well
    if pf.kind == "one_lag":
        note = next(n for n in pf.notes if n.startswith(("the dT/dt term fits as well",
                                                         "one lag or a dT/dt term")))
        assert "r/c" in note
    assert "rate" not in base_path.as_well
    assert base_path.kind == "one_lag"


def test_the_dt_term_beside_a_warm_up_names_two_paths_the_choice_alone_finds():
    """Two paths at 0 and 900 s beside a 900 s warm-up (seed 40002): beside the warm-up's
    shapes the second path's start is the warm-up's and the dT/dt term is chosen; alone, two
    paths near their truth (not the term's limit). The record holds both readings, and the
    finding must name both rather than the term alone."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    r = next(x for x in rows_paths() if x.name == "path+warm-up: two paths")
    ex, _ = explain_weekend(r.weekend, 40002)
    ch = ex.channels["x"]
    th = [f for f in ch.claimed if f.cause == "temperature"]
    assert th and ch.thermal is not None and ch.thermal.path is not None
    pf = ch.thermal.path
    assert th[0].mechanism == "two_path" or (
        "two_path" in (*th[0].alternatives, *pf.as_well)
        and any(n.startswith("without the warm-up beside them, two paths") for n in pf.notes))


def test_two_paths_in_the_dt_terms_limit_beside_a_warm_up_name_the_term_where_alone_is_not():
    """A dT/dt term beside a warm-up (seed 98000): beside the warm-up two paths in the
    term's limit (125/172 s) are chosen, alone two paths of their own (106/611 s), the
    signature two true paths beside a warm-up show too. The record does not tell them
    apart, so the term must be named, not two paths claimed alone (``both_readings``)."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    r = next(x for x in rows_paths() if x.name == "path+warm-up: dT/dt")
    ex, _ = explain_weekend(r.weekend, 98000)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th and "rate" in (th[0].mechanism, *th[0].alternatives)
    if th[0].alternatives:
        assert not th[0].intervals


@pytest.mark.parametrize("hours", [1.0, 4.0, 24.0])
def test_an_extension_is_chosen_only_where_its_start_state_leaves_a_half_to_hold_out(hours):
    """resc24b: an extension chosen by held-out likelihood must be one explain's held-out
    measure can test: a lag whose unknown start state (``HELD_SETTLE_LAGS`` lags) fills a
    held-out half is refused, for every record length, at the lag where what is left falls
    below ``MIN_PART_POINTS``; a lag that leaves enough is not."""
    from avard.core.explain.holdout import HELD_SETTLE_LAGS, MIN_PART_POINTS
    from avard.core.explain.thermal_paths.refine import _settles_past_half

    rate = 1 / 1.6  # the slow view's blocks per second
    n = int(hours * 3600 * rate)
    edge = (n // 2 - MIN_PART_POINTS) / (HELD_SETTLE_LAGS * rate)  # longest lag held out
    for kind, theta in (("hysteresis", (1.05 * edge, 0.05)), ("two_path", (0.0, 1.05 * edge)),
                        ("rate", (-1.05 * edge,)), ("quadratic", (1.05 * edge,))):
        why = _settles_past_half(kind, theta, n, rate)
        assert why is not None and "not chosen" in why
    assert _settles_past_half("hysteresis", (0.9 * edge, 5.0), n, rate) is None
    assert _settles_past_half("two_path", (0.0, 0.9 * edge), n, rate) is None


def test_a_null_axis_is_not_read_as_hysteresis_through_a_lag_its_halves_cannot_hold(tmp_path):
    """The adversary's generator (tests/support/adversary_gen.py), dtdt 323 with the plate
    logged: its z axis holds no coupling, and a hysteresis through 1837 s on 4 h passed at
    z 14.1 against 10.95 while the held-out measure could not run, and the verdict said the
    model fits. Nothing is claimed on it now, and the verdict has a held-out test."""
    from avard.core.explain.engine import explain_file
    from avard.core.explain.options import ExplainOptions
    from avard.core.io.source import open_record

    from tests.support.adversary_gen import make_record as adversary_record

    path = tmp_path / "d.npz"
    truth = adversary_record("dtdt", 323, path, logged=("plate",))
    assert truth["axes"]["z"]["cause"] is None
    ex = explain_file(open_record(str(path)), ExplainOptions(channels=("z",)))
    ch = ex.channels["z"]
    assert not [f for f in ch.claimed if f.cause not in ("sinusoid", "periodic")]
    assert ch.verdict is not None and ch.verdict.heldout_missing is None


def test_two_paths_the_held_out_test_cannot_check_are_named_beside_the_reading_chosen():
    """A two-path record (the benchmark's row, seed 23014) whose second lag fits at 2102 s
    on 4 h: explain's held-out test cannot check it (its start state fills each half), so
    it is not chosen where the one lag fails its own test; the dT/dt term is, and the two
    paths, which predict better, are named beside it with no interval rather than dropped
    (dropped, the record read as a confident dT/dt term)."""
    from benchmarks.bench_explain_weekend import explain_weekend, rows_paths

    r = next(x for x in rows_paths() if x.name == "path: two paths")
    ex, _ = explain_weekend(r.weekend, 23014)
    (th,) = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert "two_path" in (th.mechanism, *th.alternatives)
    if th.mechanism != "two_path":
        assert not th.intervals


def test_paths_of_a_coarse_log_are_chosen_on_its_readings_as_logged():
    """``fit_thermal_axes(paths=True)`` hands ``with_paths`` the readings as logged, as the
    engine does: the path choice reconstructs them on the log's grid itself (handed the
    reconstruction, it reconstructed it again)."""
    from avard.core.explain.thermal_fit import with_paths

    y, T = _slow(BASE, 5)
    q = 0.25
    Tq = np.round(T / q) * q
    g = [(q, 0.0)]
    one = fit_thermal_axes(y[:, None], Tq[:, None], ["plate"], 1.0, paths=True, grids=g)[0]
    two = with_paths(fit_thermal_axes(y[:, None], Tq[:, None], ["plate"], 1.0, grids=g),
                     y[:, None], Tq[:, None])[0]
    assert one.path is not None and two.path is not None
    assert one.path.chosen.heldout == two.path.chosen.heldout
    assert one.coefficient == two.coefficient
