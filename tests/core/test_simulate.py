"""The sensor simulator: streaming invariance, every term's statistics, chip and thermal model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.allan.deviations import oavar
from avard.core.errors import ConfigError
from avard.core.model.terms import BI_FACTOR, lowpass_white_avar
from avard.core.sim.noise_gen import ar1_avar, flicker_ladder, lerp, white_plus_ar1_filter
from avard.core.sim.presets import G0, PRESETS, make_config, parse_override
from avard.core.sim.simulate import (
    COUNTS_MAX,
    COUNTS_MIN,
    SensorSimulator,
    adxl355_lowpass_sos,
    analog_white_sigma,
)
from scipy import signal

QUIET = dict(velocity_random_walk=0.0, bias_instability=0.0, bias_tempco_mps2_per_k=0.0,
             sensitivity_tempco_per_k=0.0, gravity_mps2=0.0)


def _concat(chunks, field):
    return np.concatenate([getattr(c, field) for c in chunks])


EVERYTHING = dict(
    quantization=1e-6, rate_random_walk=(1e-5, 0, 3e-5), rate_ramp=1e-8,
    gm_sigma_mps2=(1e-4, 0, 2e-4), gm_tau_s=(0.05, 1.0, 30.0),
    sinusoids=[[0, 1e-3, 7.0], [2, 5e-4, 0.3, 1.0]], bias_step_rate_per_h=3600.0,
    bias_step_sigma_mps2=1e-3, warmup_bias_mps2=(1e-3, 0, 0), warmup_tau_s=2.0,
    hvac_amplitude_c=1.0, hvac_period_s=5.0, room_drift_c_per_h=5.0, room_wander_c=0.3,
    odr_error_ppm=1234.0,
)


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_chunk_split_is_invariant(preset: str) -> None:
    """1000 then 1000 samples equal 2000 at once, bit for bit, in every output."""
    cfg = make_config(preset)
    whole = SensorSimulator(cfg, seed=7).next(2000)
    sim = SensorSimulator(cfg, seed=7)
    halves = [sim.next(1000), sim.next(1000)]
    for field in ("accel", "counts", "temp_c", "chip_temp_c"):
        assert np.array_equal(getattr(whole, field), _concat(halves, field)), field
    assert [h.index0 for h in halves] == [0, 1000]


def test_odd_splits_with_every_term_enabled() -> None:
    cfg = make_config("quiet-lab", **EVERYTHING)
    whole = SensorSimulator(cfg, seed=3).next(5000)
    sim = SensorSimulator(cfg, seed=3)
    parts = [sim.next(k) for k in (1, 0, 127, 128, 129, 1, 4614)]
    for field in ("accel", "counts", "temp_c", "chip_temp_c"):
        assert np.array_equal(getattr(whole, field), _concat(parts, field)), field


def test_seed_reproducible_and_distinct() -> None:
    cfg = make_config("adxl355-datasheet")
    a = SensorSimulator(cfg, seed=1).next(500).counts
    b = SensorSimulator(cfg, seed=1).next(500).counts
    c = SensorSimulator(cfg, seed=2).next(500).counts
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_output_types_and_shapes() -> None:
    chunk = SensorSimulator(make_config("quiet-lab"), seed=0).next(300)
    assert chunk.counts.dtype == np.int32 and chunk.counts.shape == (300, 3)
    assert chunk.accel.shape == (300, 3) and chunk.temp_c.shape == (300, 2)
    assert chunk.chip_temp_c.shape == (300,)
    # Z lies along gravity: +1 g is 256000 LSB at ±2 g
    assert abs(np.median(chunk.counts[:, 2]) - 256000) < 200


def test_white_noise_matches_filtered_white_model() -> None:
    """N only: OADEV follows the ADXL355-filtered white line (model.lowpass_white_avar), which
    tends to N/√τ (per-sample σ = N·√fs before the filter)."""
    n_coef = 2e-3
    cfg = make_config("adxl355-datasheet", **{**QUIET, "velocity_random_walk": n_coef})
    y = SensorSimulator(cfg, seed=11).next(1 << 17).accel
    taus = np.array([1, 2, 4, 16, 64, 256]) / cfg.rate_hz
    r = oavar(y, cfg.rate_hz, taus, ci=0.99)
    model = lowpass_white_avar(r.tau, n_coef, cfg.rate_hz, cfg.rate_hz / 4)
    assert np.all((r.lo <= model[:, None]) & (model[:, None] <= r.hi))
    # and the filter matters at one sample: well below N²/τ
    assert np.all(r.var[0] < 0.8 * n_coef**2 / r.tau[0])


def test_output_white_level_is_n_with_the_lsb_rounding_included() -> None:
    """N is the white level of the rounded output (what a datasheet or an analysis reports):
    the simulator draws the analog noise with σ² = N²fs − LSB²/12, so the counts' AVAR is
    N²/τ. Here σ = 1.5 LSB, where ignoring the rounding would make it 3.7 % high."""
    cfg0 = make_config("adxl355-datasheet")
    lsb = cfg0.lsb_mps2
    n_coef = 1.5 * lsb / math.sqrt(cfg0.rate_hz)
    assert analog_white_sigma([n_coef], cfg0.rate_hz, lsb)[0] == pytest.approx(
        math.sqrt((1.5 * lsb) ** 2 - lsb**2 / 12))
    # below half an LSB the rounding is no additive white term: N is left as it is
    assert analog_white_sigma([0.4 * lsb / math.sqrt(125.0)], 125.0, lsb)[0] == pytest.approx(
        0.4 * lsb)
    cfg = make_config("adxl355-datasheet", **{**QUIET, "velocity_random_walk": n_coef})
    counts = SensorSimulator(cfg, seed=5).next(1 << 20).counts
    taus = np.array([32, 64, 128, 256]) / cfg.rate_hz
    r = oavar(counts * lsb, cfg.rate_hz, taus)
    ratio = float(np.mean(r.var * r.tau[:, None]) / n_coef**2)
    assert abs(ratio - 1) < 0.012, ratio


def _pooled_ok(r, model, k: float = 4.0, slack: float = 0.0) -> np.ndarray:
    """Ratio of the axis-pooled AVAR to the model, checked against k standard errors of a
    chi-squared estimate with 3× the per-axis EDF (three independent axes)."""
    ratio = r.var.mean(axis=1) / model
    se = np.sqrt(2.0 / (3.0 * r.edf.mean(axis=1)))
    assert np.all(np.abs(ratio - 1) < k * se + slack), (ratio, se)
    return ratio


def test_flicker_floor_is_0664_b() -> None:
    """B only: the ADEV floor is 0.6643·B within a few % over two decades of τ (IEEE 952)."""
    b = 1e-3
    cfg = make_config("adxl355-datasheet", **{**QUIET, "bias_instability": b})
    y = SensorSimulator(cfg, seed=5).next(1 << 20).accel
    taus = np.array([0.1, 0.4, 1.6, 6.4, 25.6])
    r = oavar(y, cfg.rate_hz, taus)
    ratio = _pooled_ok(r, np.full(len(taus), (BI_FACTOR * b) ** 2), slack=0.005)
    assert np.all(np.abs(np.sqrt(ratio) - 1) < 0.02), np.sqrt(ratio)


def test_flicker_ladder_is_flat_from_two_samples() -> None:
    """The ladder's exact sampled AVAR (sum of ar1_avar) is (2 ln2/π)·B² within 0.3 % at every
    m from 2 to 10⁵ samples (it was 28 % high at m = 2, 12 % at m = 4, 2.4 % at m = 16 with
    the plain ladder from 1/(π·ODR), and the plain one from 1/ODR is 4 % low at m = 16)."""
    dt = 1 / 125
    ms = np.unique(np.r_[4, np.round(np.geomspace(2, 1e5, 25))].astype(int))
    target = 2 * math.log(2) / math.pi

    def avar(ladder):
        return np.array([sum(s[0] ** 2 * ar1_avar(t, dt, int(m)) for t, s in ladder)
                         for m in ms]) / target

    fixed = avar(flicker_ladder([1.0], dt, 1e6, 2.0, dt_s=dt))
    assert np.all(np.abs(fixed - 1) < 3e-3), dict(zip(ms, fixed, strict=True))
    old = avar(flicker_ladder([1.0], dt / math.pi, 1e6, 2.0))
    assert old[ms == 4][0] > 1.1          # the defect the end correction removes
    # ar1_avar itself: white (T = 0) gives 1/m; T ≫ m·dt a sampled random walk of step
    # variance 1 − φ² ≈ 2·dt/T, whose AVAR is step·(2m² + 1)/(6m)
    assert ar1_avar(0.0, dt, 8) == pytest.approx(1 / 8)
    assert ar1_avar(1e6, dt, 8) == pytest.approx(2 * dt / 1e6 * 129 / 48, rel=1e-4)


def _filtered_over_unfiltered(ladder, dt_s: float, ms, sos) -> np.ndarray:
    """AVAR of the ladder's sampled AR(1) sum after the chip filter over before it, from the
    spectrum: σ²(m) = 2∫₀^½ S(ν)·|H(ν)|²·|Σ±e^(−2πiνn)|²/(2m²) dν (ν in cycles/sample); only
    S·(|H|² − 1), smooth where |H|² ≠ 1, is integrated numerically."""
    nu = np.linspace(1e-6, 0.5, 100001)
    _, h = signal.sosfreqz(sos, worN=2 * np.pi * nu)
    z = np.exp(-2j * np.pi * nu)
    phis = [(math.exp(-dt_s / t), s[0] ** 2) for t, s in ladder]
    psd = sum(v * (1 - f * f) / np.abs(1 - f * z) ** 2 for f, v in phis)
    out = []
    for m in ms:
        kern = np.abs((1 - z**m) ** 2 / (1 - z)) ** 2 / (2 * m * m)
        raw = sum(s[0] ** 2 * ar1_avar(t, dt_s, int(m)) for t, s in ladder)
        out.append(1 + 2 * np.trapezoid(psd * (np.abs(h) ** 2 - 1) * kern, nu) / raw)
    return np.array(out)


def test_simulated_flicker_avar_is_the_floor_from_m_4() -> None:
    """B only, through the whole generator (ARMA stream, AR(1) banks on coarse grids, their
    interpolation): before the chip filter the pooled AVAR is (2 ln2/π)·B² within 1 % (plus
    4 standard errors) from m = 2 to 4096; after the filter (the output) from m = 4 up, where
    the filter lowers the 1/f level by 3.4 % at m = 4 and 0.9 % at m = 8 (computed here from the
    filter's |H|² and the ladder's spectrum), within 1 % of that."""
    b = 1e-3
    cfg = make_config("adxl355-datasheet", **{**QUIET, "bias_instability": b})
    ms = np.array([2, 4, 8, 16, 32, 64, 128, 512, 4096])
    sos = adxl355_lowpass_sos()
    pre, post = [], []
    for seed in (21, 22):
        sim = SensorSimulator(cfg, seed=seed)
        x = sim._top.totals(0, (1 << 21) - 1).copy()       # (3, n): the sum before the chip
        y, _ = signal.sosfilt(sos, x, axis=-1, zi=signal.sosfilt_zi(sos)[:, None, :] * x[:, :1])
        pre.append(oavar(x.T, cfg.rate_hz, ms / cfg.rate_hz))
        post.append(oavar(y.T, cfg.rate_hz, ms / cfg.rate_hz))
    floor = (BI_FACTOR * b) ** 2

    def pooled(rs):
        v = np.mean([r.var.mean(axis=1) for r in rs], axis=0)
        se = np.sqrt(2.0 / (3.0 * len(rs) * np.mean([r.edf.mean(axis=1) for r in rs], axis=0)))
        return v / floor, se

    v, se = pooled(pre)
    assert np.all(np.abs(v - 1) < 4 * se + 0.01), (v, se)
    v, se = pooled(post)
    dt = 1 / cfg.rate_hz
    filt = _filtered_over_unfiltered(flicker_ladder([b], dt, 1e6, 2.0, dt_s=dt), dt, ms, sos)
    ok = ms >= 4
    assert np.all(np.abs(v[ok] / filt[ok] - 1) < 4 * se[ok] + 0.01), (v, se)
    assert abs(v[ms == 4][0] - 1) < 0.05


def test_rate_random_walk_slope() -> None:
    """K only: AVAR K²τ/3 above the walk's 50 ms grid."""
    k = 1e-4
    cfg = make_config("adxl355-datasheet", **{**QUIET, "rate_random_walk": k})
    y = SensorSimulator(cfg, seed=9).next(1 << 19).accel
    r = oavar(y, cfg.rate_hz, np.array([0.5, 2.0, 8.0, 32.0]))
    _pooled_ok(r, k**2 * r.tau / 3)


def test_quantization_term() -> None:
    """Q: white phase noise, AVAR 3Q²/τ² at every τ (IEEE 952 C.7)."""
    q = 1e-4
    cfg = make_config("adxl355-datasheet", **{**QUIET, "quantization": q})
    y = SensorSimulator(cfg, seed=4).next(1 << 16).accel
    r = oavar(y, cfg.rate_hz, np.array([1, 4, 32]) / cfg.rate_hz, ci=0.99)
    model = 3 * q**2 / r.tau**2
    assert np.all((r.lo <= model[:, None]) & (model[:, None] <= r.hi))


def test_gauss_markov_term_variance() -> None:
    sig, tau = 2e-3, 0.5
    cfg = make_config("adxl355-datasheet",
                      **{**QUIET, "gm_sigma_mps2": sig, "gm_tau_s": tau})
    y = SensorSimulator(cfg, seed=8).next(1 << 18).accel
    # variance of a stationary GM is σ² (the filter barely touches a 0.5 s process)
    assert np.allclose(y.var(axis=0), sig**2, rtol=0.1)
    # lag correlation at one time constant is e^−1
    lag = round(tau * cfg.rate_hz)
    rho = np.mean([np.corrcoef(y[:-lag, a], y[lag:, a])[0, 1] for a in range(3)])
    assert abs(rho - math.exp(-1)) < 0.05


def test_ramp_sinusoid_and_warmup_pass_the_chip_filter() -> None:
    """Deterministic terms arrive exactly as the ADXL355 filter (Butterworth at ODR/4) makes
    them: the output equals the filtered sum of ramp, sinusoid and warm-up."""
    cfg = make_config("adxl355-datasheet", **{
        **QUIET, "rate_ramp": (1e-5, 0, 0), "sinusoids": [[1, 2e-3, 0.5, 0.3]],
        "warmup_bias_mps2": (0, 0, 1e-2), "warmup_tau_s": 30.0})
    n = 8000
    y = SensorSimulator(cfg, seed=0).next(n).accel
    t = np.arange(n) / cfg.rate_hz
    x = np.stack([1e-5 * t, 2e-3 * np.sin(2 * np.pi * 0.5 * t + 0.3), 1e-2 * np.exp(-t / 30)])
    sos = adxl355_lowpass_sos()
    ref, _ = signal.sosfilt(sos, x, axis=-1,
                            zi=signal.sosfilt_zi(sos)[:, None, :] * x[None, :, :1])
    # the ramp and warm-up live on a ≈1 s grid: linear interpolation error ≤ Δ²·max|f''|/8
    assert np.allclose(y, ref.T, atol=3e-6)
    assert np.all(np.abs(np.diff(y[:, 0])) > 0)          # the ramp never stalls


def test_bias_steps_arrive_at_the_poisson_rate() -> None:
    cfg = make_config("adxl355-datasheet", **{
        **QUIET, "bias_step_rate_per_h": 3600.0, "bias_step_sigma_mps2": 1e-2})
    y = SensorSimulator(cfg, seed=2).next(125 * 120).accel     # two minutes: ~120 steps
    big = np.abs(np.diff(y, axis=0)) > 2e-4
    # a step spreads over a few samples through the filter: count runs of big differences
    starts = np.count_nonzero(big[1:] & ~big[:-1]) + np.count_nonzero(big[0])
    assert 70 < starts < 170


def test_counts_quantize_and_clip() -> None:
    cfg = make_config("adxl355-datasheet")
    c = SensorSimulator(cfg, seed=1).next(1000)
    assert np.array_equal(c.counts, np.rint(c.accel / cfg.lsb_mps2).astype(np.int32))
    assert cfg.lsb_mps2 == pytest.approx(3.9e-6 * 9.80665, rel=0.002)     # 3.9 µg
    big = make_config("adxl355-datasheet", offset_mps2=(3 * G0, -3 * G0, 0.0))
    c = SensorSimulator(big, seed=1).next(100)
    assert np.all(c.counts[:, 0] == COUNTS_MAX) and np.all(c.counts[:, 1] == COUNTS_MIN)
    c8 = SensorSimulator(make_config("adxl355-datasheet", range_g=8), seed=1).next(100)
    assert abs(np.median(c8.counts[:, 2]) - 64000) < 100


def test_thermal_lag_and_coupling() -> None:
    """Plate follows a sinusoidal room through a first-order lag: amplitude 1/√(1+(ωτ)²);
    the output follows the die temperature by bias tempco + sensitivity tempco × g."""
    period, tau_p = 600.0, 100.0
    cfg = make_config("adxl355-datasheet", **{
        **QUIET, "gravity_mps2": (0, 0, G0), "hvac_amplitude_c": 1.0, "hvac_period_s": period,
        "plate_tau_s": tau_p, "chip_tau_s": 1.0, "bias_tempco_mps2_per_k": (1e-3, 0, 0),
        "sensitivity_tempco_per_k": (0, 0, 1e-4), "range_g": 8, "odr_hz": 15.625})
    c = SensorSimulator(cfg, seed=0).next(int(3 * period * cfg.rate_hz))
    plate, amb = c.temp_c[:, 0], c.temp_c[:, 1]
    w = 2 * np.pi / period
    assert np.ptp(amb) / 2 == pytest.approx(1.0, rel=0.01)
    assert np.ptp(plate) / 2 == pytest.approx(1 / math.hypot(1, w * tau_p), rel=0.02)
    d = c.chip_temp_c - 21.0
    assert np.allclose(c.accel[:, 0], 1e-3 * d, atol=1e-6)
    assert np.allclose(c.accel[:, 2] - G0, G0 * 1e-4 * d, atol=1e-6)


def test_real_odr_sets_the_time_scale() -> None:
    cfg = make_config("adxl355-datasheet", odr_error_ppm=-3000.0)
    assert cfg.rate_hz == pytest.approx(125.0 * 0.997)
    # a 1 Hz sinusoid completes exactly one cycle in rate_hz samples of the real ODR
    s = make_config("adxl355-datasheet", **{**QUIET, "odr_error_ppm": -3000.0,
                                             "sinusoids": [[0, 1e-2, 1.0]]})
    y = SensorSimulator(s, seed=0).next(2000).accel[:, 0]
    x = 1e-2 * np.sin(2 * np.pi * np.arange(2000) / s.rate_hz)
    sos = adxl355_lowpass_sos()
    ref, _ = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * x[0])
    assert np.allclose(y, ref, atol=1e-12)


def test_arma_merge_has_the_sum_spectrum() -> None:
    """White + several AR(1) from one stream: |H|² equals the sum of the PSDs."""
    sw, phis, sigs = 0.7, [0.1, 0.6, 0.95], [0.5, 1.0, 2.0]
    g, zeros, poles = white_plus_ar1_filter(sw, phis, sigs)
    wgrid = np.linspace(0.01, np.pi, 200)
    b = g * np.poly(zeros)
    _, h = signal.freqz(b, np.poly(poles), worN=wgrid)
    target = sw**2 + sum(s * s * (1 - f * f) / np.abs(1 - f * np.exp(-1j * wgrid)) ** 2
                         for f, s in zip(phis, sigs, strict=True))
    assert np.allclose(np.abs(h) ** 2, target, rtol=1e-9)
    assert np.all(np.abs(zeros) < 1)
    # the simulator's own case: the ladder members up to T ≈ 32 samples, tiny white part
    lad = [math.exp(-1 / 10 ** (k / 2)) for k in range(4)]
    g, zeros, poles = white_plus_ar1_filter(1e-3, lad, [1.0] * 4)
    _, h = signal.freqz(g * np.poly(zeros), np.poly(poles), worN=wgrid)
    target = 1e-6 + sum((1 - f * f) / np.abs(1 - f * np.exp(-1j * wgrid)) ** 2 for f in lad)
    assert np.allclose(np.abs(h) ** 2, target, rtol=1e-4)   # np.roots at degree 10
    g0, z0, _ = white_plus_ar1_filter(0.0, [0.5], [1.0])      # no white part: pure AR(1)
    assert g0 == pytest.approx(math.sqrt(0.75)) and np.allclose(z0, 0)


@pytest.mark.parametrize(("q", "start", "m"), [(4, 0, 12), (4, 3, 6), (8, 5, 2), (2, 1, 9),
                                               (16, 0, 1), (1, 2, 3)])
def test_lerp_matches_numpy_interp(q: int, start: int, m: int) -> None:
    coarse = np.random.default_rng(q + start).standard_normal((2, (start + m) // q + 2))
    out = np.empty((2, m))
    lerp(coarse, q, start, out)
    fine = np.arange(start, start + m)
    for r in range(2):
        assert np.allclose(out[r], np.interp(fine, np.arange(coarse.shape[1]) * q, coarse[r]))


def test_make_config_errors_name_the_problem() -> None:
    with pytest.raises(ConfigError, match=r"valid keys: .*velocity_random_walk"):
        make_config("quiet-lab", velocity_randomwalk=1e-4)
    with pytest.raises(ConfigError, match="choose one of"):
        make_config("paper-table4")
    with pytest.raises(ConfigError, match="one value or three"):
        make_config("quiet-lab", bias_instability=(1, 2))
    with pytest.raises(ConfigError, match="not an ADXL355 output data rate"):
        make_config("quiet-lab", odr_hz=100)
    with pytest.raises(ConfigError, match="≥ 0"):
        make_config("quiet-lab", velocity_random_walk=-1)
    with pytest.raises(ConfigError, match="Nyquist"):
        make_config("quiet-lab", sinusoids=[[0, 1e-3, 80.0]])
    assert parse_override("bias_instability=1e-5,2e-5,3e-5") == (
        "bias_instability", ["1e-5", "2e-5", "3e-5"])
    assert make_config("quiet-lab", **dict([parse_override("bias_instability=1e-5,2e-5,3e-5")])
                       ).bias_instability == (1e-5, 2e-5, 3e-5)
    with pytest.raises(ConfigError, match="key=value"):
        parse_override("bias_instability")


def test_state_stays_bounded_while_streaming() -> None:
    """Memory independent of duration: every grid keeps a few points between calls (what the
    lookahead of the finer grid generated), however long the stream runs."""
    sim = SensorSimulator(make_config("quiet-lab", rate_random_walk=1e-6), seed=1)
    sizes = []
    for _ in range(60):
        sim.next(997)
        level, per_call = sim._top, []
        while level is not None:
            per_call.append(level.buf.shape[1])
            level = level.coarser
        sizes.append(max([*per_call, sim._thermal._tbuf.shape[1]]))
    assert max(sizes) <= 4


@pytest.mark.parametrize("odr", [4000.0, 3.90625])
def test_extreme_output_rates_stream_and_scale(odr: float) -> None:
    cfg = make_config("quiet-lab", odr_hz=odr, hvac_period_s=600.0)
    whole = SensorSimulator(cfg, seed=2).next(3000)
    sim = SensorSimulator(cfg, seed=2)
    parts = [sim.next(k) for k in (5, 1000, 1995)]
    assert np.array_equal(whole.counts, _concat(parts, "counts"))
    # white noise per sample scales as √fs (before the filter), so the 1-sample ADEV does too
    r = oavar(whole.accel[:, :2], cfg.rate_hz, np.array([16 / cfg.rate_hz]))
    model = lowpass_white_avar(r.tau, cfg.velocity_random_walk[0], cfg.rate_hz, cfg.rate_hz / 4)
    assert np.all(np.abs(r.var[0] / model[0] - 1) < 0.25)
