"""The dT/dt term's stated minimum against one lag (cand26, issue 23 item 4): the smallest r
a fit tells from every one-lag reading, not r against zero."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.explain.causes import noise_psd
from avard.core.explain.thermal_paths import (
    min_detectable_path,
    min_detectable_rate,
    rate_lag_separation,
)
from numpy.typing import NDArray

N, B, K, REC = 1.4e-4, 1.6e-5, 1.5e-6, 4 * 3600.0


def _s2(period: float) -> float:
    return 2 * noise_psd(1.0 / period, N, B, K) / REC


def _triangle(period: float, room: float, plate: float = 1100.0, die: float = 45.0):
    """An HVAC triangle's odd harmonics at the die, through the plate's and the die's lags."""
    out = []
    for k in range(1, 16, 2):
        w = 2 * math.pi * k / period
        out.append((8 * room / (math.pi**2 * k * k) / math.hypot(1, w * plate)
                    / math.hypot(1, w * die), period / k))
    return tuple(out)


def test_one_line_a_lead_is_told_from_one_lag_only_past_the_lead_lags_phase():
    """On one line a lead c + jωr (r/c > 0) is one lag's lead-lag (1 + 2jωa)/(1 + jωa) up
    to its largest phase asin(1/3): the distance of the point G from the nearest ray c'·H is
    |G|·sin(φ − asin(1/3)), so λ = (a/σ_a)²|G|² sin²(φ − asin 1/3) at the minimum is z²; a
    lag (r/c < 0) is a phase every one lag reaches: no finite minimum."""
    a, P, c = 0.15, 1800.0, 1e-3
    w = 2 * math.pi / P
    r = min_detectable_rate(N, B, K, REC, ((a, P),), c, lead=True)
    phi = math.atan(w * r / c)
    lam = a * a / _s2(P) * (c * c + (w * r) ** 2) * math.sin(phi - math.asin(1 / 3)) ** 2
    assert lam == pytest.approx(25.0, rel=1e-6)
    assert min_detectable_rate(N, B, K, REC, ((a, P),), c, lead=False) == math.inf
    assert min_detectable_rate(N, B, K, REC, ((a, P),), -c, lead=False) == math.inf
    # (the sign of c does not matter, only that of r/c)
    assert min_detectable_rate(N, B, K, REC, ((a, P),), -c, lead=True) == pytest.approx(r)


def test_the_separation_is_the_least_distance_to_any_one_lag_reading():
    """λ against a brute-force search of one-lag readings (c' on a dense grid, L' both ways)
    on three lines: no reading is closer, and the reading it returns is that close."""
    lines = _triangle(1500.0, 0.7)[:3]
    c, r = -9e-4, 0.25
    lam, L, cp = rate_lag_separation(N, B, K, REC, lines, c, r)
    a = np.array([x[0] for x in lines])
    w = np.array([2 * math.pi / x[1] for x in lines])
    q = a * a / np.array([_s2(x[1]) for x in lines])
    G = c + 1j * w * r
    best = math.inf
    for Lp in np.concatenate([-np.geomspace(1, 1e4, 300), [0.0], np.geomspace(1, 1e4, 300)]):
        h = (1 / (1 + 1j * w * Lp) if Lp >= 0 else (1 - 2j * w * Lp) / (1 - 1j * w * Lp))
        cq = np.linspace(-5e-3, 5e-3, 4001)[:, None]
        best = min(best, float(np.min(np.sum(q * np.abs(G - cq * h) ** 2, axis=1))))
    assert lam <= best * (1 + 1e-6)
    assert lam == pytest.approx(best, rel=0.02)
    h = 1 / (1 + 1j * w * L) if L >= 0 else (1 - 2j * w * L) / (1 - 1j * w * L)
    assert float(np.sum(q * np.abs(G - cp * h) ** 2)) == pytest.approx(lam, rel=1e-9)
    # a lag's sign of dT/dt term is read as a lag near r/c's
    assert L == pytest.approx(-r / c, rel=0.1)


def test_three_times_the_against_zero_minimum_is_not_told_from_one_lag():
    """The adversary's dT/dt class at 3× the minimum against zero (r = 15σ_a/(ωa)) beside a
    coupling at 3× its own (c = 15σ_a/a, so r/c = ±1/ω): on an HVAC triangle through a
    plate (its harmonics 1/27, 1/125 … of the fundamental at the die) a lag-signed term is
    z ≈ 2–3 from the closest one lag, where the record's choice needs z ≥ 5; its stated
    minimum against one lag is 4–7× the one against zero, a lead's about 2×. On the old
    minimum the class sat below what any test of the mechanism resolves."""
    for P, room in ((1350.0, 0.6), (1800.0, 0.7), (2200.0, 0.85)):
        lines = _triangle(P, room)
        a, w = lines[0][0], 2 * math.pi / P
        s = math.sqrt(_s2(P))
        # (the adversary's minimum: the fundamental's, against zero)
        old = min_detectable_path("rate", N, B, K, REC, a, P, lags_known=True)
        c, r = 15 * s / a, 15 * s / (w * a)
        assert r == pytest.approx(3 * old, rel=1e-9)
        lam_lag, _, _ = rate_lag_separation(N, B, K, REC, lines, -c, r)
        lam_lead, _, _ = rate_lag_separation(N, B, K, REC, lines, c, r)
        assert lam_lag < 25.0 < lam_lead
        lag_min = min_detectable_rate(N, B, K, REC, lines, -c, lead=False)
        lead_min = min_detectable_rate(N, B, K, REC, lines, c, lead=True)
        assert 4.0 * old < lag_min < 8.0 * old
        assert 1.5 * old < lead_min < 3.0 * old
        assert rate_lag_separation(N, B, K, REC, lines, -c, lag_min)[0] == pytest.approx(
            25.0, rel=1e-3)


def test_the_adversarys_dtdt_sizes_follow_this_minimum():
    """The adversary's generator (numpy only, apart from avard) recomputes each stated
    minimum from the docs' derivation; its dT/dt class's r is its factor × the minimum
    against one lag (``adversary_gen.rate_min`` on ``drive_lines``). Held here to the
    project's ``min_detectable_rate`` on the generator's drives (HVAC alone and with the
    compressor, either sign of c), so a change of the one shows in the other."""
    from tests.support import adversary_gen as gen

    nx = gen.DEFAULT_NOISE["x"]
    for drive in ({"hvac_period": 1500.0, "hvac_amp": 0.7},
                  {"hvac_period": 2100.0, "hvac_amp": 0.6, "comp_amp": 0.25,
                   "comp_period": 800.0}):
        lines = gen.drive_lines(drive, 1100.0, 45.0)
        sig = [gen.sigma_a(w / (2 * math.pi), REC, *nx) for _, w in lines]
        ours = tuple((a, 2 * math.pi / w) for a, w in lines)
        w0, a0 = lines[0][1], lines[0][0]
        r_zero = 5 * sig[0] / (w0 * a0)
        for c in (9e-4, -9e-4):
            theirs = gen.rate_min(lines, sig, c, r_zero, lead=c > 0)
            assert theirs == pytest.approx(
                min_detectable_rate(*nx, REC, ours, c, lead=c > 0), rel=0.01)


# ------------------------------------------------------- as explain's fit sees the lines (cand26b)


def test_the_analytic_rounding_floor_is_the_one_explain_finds_on_the_record():
    """``minima.rounding_floor`` (the drive's AVAR against 10× the sawtooth's, on the octave τ
    2ʲ/rate) is ``thermal_fit.rounding_floor_tau`` on a rounded record of that drive: the
    floor the fit's τ start at, which the minima below depend on."""
    from avard.core.explain.thermal_fit.rounding import rounding_floor_tau
    from avard.core.explain.thermal_paths import rounding_floor

    rate, rec = 10.0, 4 * 3600.0
    t = np.arange(int(rate * rec)) / rate
    rng = np.random.default_rng(3)
    for amp, period in ((0.214, 1800.0), (0.09, 1500.0), (0.6, 2400.0)):
        u = 21.3 + amp * np.sin(2 * math.pi * t / period) + 0.003 * rng.standard_normal(t.size)
        T = np.round(u / 0.0625) * 0.0625
        assert rounding_floor(((amp, period),), rate, rec) == pytest.approx(
            rounding_floor_tau(T, rate), rel=1e-9)


def test_the_fits_minimum_is_never_below_the_whole_spectrums():
    """The fit weighs the lines by what the Allan covariance at τ ≥ the floor sees (W), the
    noise at each line is σ²: its estimate's non-centrality (ΣW|ΔY|²)²/ΣW²σ²|ΔY|² is at most
    Σ|ΔY|²/σ² (Cauchy–Schwarz). So on one line a dT/dt term's minimum is the whole
    spectrum's (W cancels), on several it is no lower, and a floor past the harmonics
    raises the relay's: its harmonics stop counting."""
    from avard.core.explain.thermal_paths import (
        fit_weights,
        min_detectable_hysteresis_fit,
        min_detectable_rate_fit,
        one_lag_separation_fit,
        relay_harmonics,
    )

    a, P, c = 0.2, 1800.0, 8e-4
    one = ((a, P),)
    assert min_detectable_rate_fit(N, B, K, REC, one, c, True, 204.8) == pytest.approx(
        min_detectable_rate(N, B, K, REC, one, c, lead=True), rel=2e-3)
    lines = _triangle(1500.0, 0.7)
    for lead in (True, False):
        assert (min_detectable_rate_fit(N, B, K, REC, lines, c, lead, 327.68)
                >= 0.999 * min_detectable_rate(N, B, K, REC, lines, c, lead=lead))
    # the relay on a sine: with W ∝ 1/σ² the separation is the whole spectrum's (the
    # stated minimum on harmonics 3–39, the fundamental within one lag's reach)
    per = P / np.arange(1, 40)
    s2 = np.array([_s2(p) for p in per])
    U = np.zeros(39, complex)
    U[0] = a
    R = relay_harmonics(U, 0.05)
    old = min_detectable_path("hysteresis", N, B, K, REC, a, P)
    lam = one_lag_separation_fit(per, U, c * U + old * R, 1 / s2, s2)[0]
    assert lam == pytest.approx(25.0, rel=0.02)
    h_fit = [min_detectable_hysteresis_fit(N, B, K, REC, P, U[:1], c, 0.05, fl)
             for fl in (51.2, 204.8, 819.2)]
    assert old * 0.999 <= h_fit[0] <= h_fit[1] < h_fit[2]
    # the relay's harmonics are what W weighs less past the floor
    W = fit_weights(N, B, K, REC, per, 819.2)
    assert W[4] * s2[4] < 1e-2 * W[0] * s2[0]


def test_the_relays_fundamental_counts_only_beyond_one_lags_reach():
    """A relay switching once a sine drive a·cos θ has moved w back from its extreme turns at
    cos θ = 1 − w/a after each peak: its +1 window is centred 90° − acos(1 − w/a) ahead of
    the drive, so its fundamental leads by that (30° at w = a/2). Beside a coupling c the
    response at the drive's line is c·a + h·R₁: where its phase is within one lag's reach
    (−90°…asin(1/3) with either sign of c') the one-lag reading takes it whole (λ = 0), and
    beyond it the distance to the lead-lag's ray is |Y|·sin(φ − asin 1/3)."""
    from avard.core.explain.thermal_paths import one_lag_separation_fit, relay_harmonics

    a, P = 0.12, 1800.0
    U = np.array([a + 0j])
    R1 = relay_harmonics(U, 0.5 * a, k_max=1)[0]
    assert math.degrees(np.angle(R1)) == pytest.approx(30.0, abs=0.5)
    assert abs(R1) == pytest.approx(4 / math.pi, rel=1e-3)
    per, s2 = np.array([P]), np.array([_s2(P)])
    W = 1.0 / s2
    h = 6e-5
    # a coupling of the relay's sign and larger: the phase under asin(1/3)
    Y = 6e-4 * a + h * R1
    assert math.degrees(np.angle(Y)) < 19.0
    assert one_lag_separation_fit(per, U, np.array([Y]), W, s2)[0] < 1e-6
    # a small coupling: the relay's 30° lead shows, beyond the lead-lag's 19.5°
    Y = 5e-5 * a + h * R1
    phi = float(np.angle(Y))
    assert math.radians(21.0) < phi < math.radians(90.0)
    want = abs(Y) ** 2 / s2[0] * math.sin(phi - math.asin(1 / 3)) ** 2
    assert one_lag_separation_fit(per, U, np.array([Y]), W, s2)[0] == pytest.approx(
        want, rel=1e-3)


def test_the_adversarys_fit_minima_are_these():
    """The adversary's generator (numpy only) recomputes the minima as the fit sees the lines
    (``adversary_gen.rate_min_fit``, ``hyst_min_fit``, its floor and rounding): held here to
    the project's ``min_detectable_rate_fit`` and ``min_detectable_hysteresis_fit`` within
    1 % on its drives (HVAC triangle alone and with the compressor, either sign of c), so a
    change of the one shows in the other."""
    from avard.core.explain.thermal_paths import (
        min_detectable_hysteresis_fit,
        min_detectable_rate_fit,
        rounding_floor,
        rounding_time,
    )

    from tests.support import adversary_gen as gen

    nx = gen.DEFAULT_NOISE["x"]
    spec = gen.Spec(kind="dtdt", hours=4.0, rate=12.5, noise=gen.DEFAULT_NOISE)
    for drive in ({"hvac_period": 1500.0, "hvac_amp": 0.7},
                  {"hvac_period": 2100.0, "hvac_amp": 0.6, "comp_amp": 0.25,
                   "comp_period": 800.0}):
        lines = gen.drive_lines(drive, 1100.0, 45.0)
        ours = tuple((a, 2 * math.pi / w) for a, w in lines)
        logged = tuple((a, 2 * math.pi / w) for a, w in gen.drive_lines(drive, 1100.0, 45.0))
        floor = rounding_floor(logged, 12.5, REC)
        for c in (9e-4, -9e-4):
            g_floor, g_c2tc = gen._fit_view(drive, spec, 12.5, REC, c)
            assert g_floor == floor
            c2tc = c * c * 0.0625**2 / 12 * rounding_time(logged)
            assert g_c2tc == pytest.approx(c2tc, rel=1e-9)
            assert gen.rate_min_fit(lines, REC, nx, c, c > 0, g_floor, g_c2tc) == pytest.approx(
                min_detectable_rate_fit(*nx, REC, ours, c, c > 0, floor, c2tc), rel=0.01)
            if "comp_amp" in drive:
                continue
            U = gen.triangle_at_die(drive["hvac_period"], drive["hvac_amp"], 1100.0, 45.0)
            width = 0.5 * abs(U[0])
            assert gen.hyst_min_fit(U, drive["hvac_period"], REC, nx, c, width, g_floor,
                                    g_c2tc) == pytest.approx(
                min_detectable_hysteresis_fit(*nx, REC, drive["hvac_period"], U, c, width,
                                              floor, c2tc), rel=0.01)


def test_the_analytic_rounding_floor_takes_a_coarse_logs_step():
    """A coarse log's floor is its own step's (``step``): the one ``rounding_floor_tau``
    finds on the record rounded to that step, not the 12-bit one's."""
    from avard.core.explain.thermal_fit.rounding import rounding_floor_tau
    from avard.core.explain.thermal_paths import rounding_floor

    rate, rec = 10.0, 4 * 3600.0
    t = np.arange(int(rate * rec)) / rate
    rng = np.random.default_rng(3)
    for q, amp, period in ((0.25, 0.6, 2400.0), (0.125, 0.214, 1800.0)):
        u = 21.3 + amp * np.sin(2 * math.pi * t / period) + 0.003 * rng.standard_normal(t.size)
        T = np.round(u / q) * q
        got = rounding_floor(((amp, period),), rate, rec, step=q)
        assert got == pytest.approx(rounding_floor_tau(T, rate, step=q), rel=1e-9)
        assert got > rounding_floor(((amp, period),), rate, rec)


def test_the_relays_minimum_counts_the_readings_rounding_through_the_coupling_as_noise():
    """hyst29: the one-lag column is built on the rounded readings, so c·lag(rounding) is in
    the residual the relay is told from: white noise of N² = c²(q²/12)t_c to the estimate as
    well as to its weights. So the minimum with that rounding equals the minimum of an
    accelerometer whose white noise is N² + c²(q²/12)t_c and no rounding, and a brute-force
    sandwich (every one-lag reading on a lag grid, c' by W-weighted least squares, σ² with
    the rounding's PSD) puts it at z = 5. Before hyst29 σ² held the accelerometer's alone:
    the minimum was optimistic by 1.15–1.57× on the adversary's records."""
    from avard.core.explain.causes import noise_psd
    from avard.core.explain.thermal_paths import (
        fit_weights,
        min_detectable_hysteresis_fit,
        relay_harmonics,
    )

    P, c, wk, fl = 1800.0, 1.1e-3, 0.05, 327.68
    U = np.zeros(39, complex)
    for k in range(1, 40, 2):  # a triangle through a 1100 s plate
        U[k - 1] = (8 * 0.7 / (math.pi * k) ** 2 * (-1) ** ((k - 1) // 2) * -1j
                    / complex(1, 2 * math.pi * k / P * 1100.0))
    tc = 120.0
    c2tc = c * c * 0.0625**2 / 12 * tc
    assert c2tc > N * N  # the adversary's range: the rounding outweighs the white noise
    h = min_detectable_hysteresis_fit(N, B, K, REC, P, U, c, wk, fl, c2tc)
    assert h == pytest.approx(min_detectable_hysteresis_fit(
        math.sqrt(N * N + c2tc), B, K, REC, P, U, c, wk, fl, 0.0), rel=1e-6)
    # brute force, written apart from one_lag_separation_fit
    per = P / np.arange(1, 40)
    w = 2 * np.pi / per
    W = fit_weights(N, B, K, REC, per, fl, c2tc)
    s2 = np.array([2 * (noise_psd(1 / p, N, B, K) + 2 * c2tc) / REC for p in per])
    R = relay_harmonics(U, wk)

    def lam(hh: float, s2: NDArray = s2) -> float:
        Y = c * U + hh * R
        best = (math.inf, 0.0)
        for L in np.concatenate([-np.geomspace(0.5, 1e6, 4000), [0.0],
                                 np.geomspace(0.5, 1e6, 4000)]):
            H = (1 / (1 + 1j * w * L) if L >= 0 else
                 (1 - 2j * w * L) / (1 - 1j * w * L)) * U
            cp = np.sum(W * np.real(Y * H.conj())) / np.sum(W * np.abs(H) ** 2)
            d2 = np.abs(Y - cp * H) ** 2
            if np.sum(W * d2) < best[0]:
                best = (float(np.sum(W * d2)), float(np.sum(W * d2) ** 2
                                                    / np.sum(W * W * s2 * d2)))
        return best[1]

    assert lam(h) == pytest.approx(25.0, rel=0.02)
    # with the accelerometer's noise alone (the minimum before) the same h claimed far more
    s2_accel = np.array([2 * noise_psd(1 / p, N, B, K) / REC for p in per])
    assert lam(h, s2_accel) > 1.5 * 25.0
