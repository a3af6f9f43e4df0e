"""The held-out test's calibration on described sensors (heldcal27, issue 23 item 5).

The held-out χ² weighs each τ's residual with the held-out estimator's covariance. That
covariance is the Whittle form of the model's spectrum, a quadratic form in the noise terms'
θ, and θ was fitted on the other half: ``holdout._noise_scatter`` adds its expectation over
θ's distribution (E[C(θ)] − C(θ̂)), so a half that under-reads a random walk or a flicker
does not judge the other half's long τ with too small a variance. Here: that addition is the
expectation it claims to be (an exact check on a quadratic form), the fold χ² of halves of a
white + flicker + random-walk sensor is not piled below 1 % (nor inflated away from it), and
a held-out half with a signal the model does not have still fails at 1 %.
"""

from __future__ import annotations

import math

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from avard.core.explain import holdout as ho
from avard.core.explain.verdict import ALPHA, _chi2_sf
from avard.core.model.fit import avar_estimate_covariance, fit_noise

#: the weekend benchmark's sensor (tests/support/weekend.py): N m/s/√s, B m/s², K m/s²·√s
N, B, K = 1.6e-4, 2e-5, 2e-6
RATE, BLOCK, HOURS = 10.0, 16, 4.0  # explain's slow view of a 10 Hz record: 1.6 s blocks


def _flicker(n: int, rng: np.random.Generator) -> np.ndarray:
    """Kasdin's fractional-difference flicker (α = 1) on unit white noise: AVAR 2 ln 2/π per
    unit B² (written here apart from the project's simulator, as the weekend generator's)."""
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 0.5) / k)])
    size = 1 << math.ceil(math.log2(2 * n))
    w = rng.standard_normal(n)
    return np.fft.irfft(np.fft.rfft(w, size) * np.fft.rfft(h, size), size)[:n]


def _slow_axis(seed: int) -> tuple[np.ndarray, float]:
    """Block means of one described-sensor axis (white + flicker + random walk) and their
    rate."""
    rng = np.random.default_rng(seed)
    n = int(HOURS * 3600 * RATE)
    a = (N * math.sqrt(RATE) * rng.standard_normal(n) + B * _flicker(n, rng)
         + K * math.sqrt(1 / RATE) * np.cumsum(rng.standard_normal(n)))
    m = (n // BLOCK) * BLOCK
    return a[:m].reshape(-1, BLOCK).mean(axis=1), RATE / BLOCK


def _p_heldout(y: np.ndarray, rate_b: float, y_held_b: np.ndarray | None = None) -> float:
    """The verdict's held-out p of an axis that claims nothing: both folds of its halves (the
    second half replaced by ``y_held_b`` when given), χ² with the prediction's variance."""
    h = len(y) // 2
    second = y[h:] if y_held_b is None else y_held_b
    A = ho.Part(y[:h], 0.0, "first half", True)
    Bp = ho.Part(second, h / rate_b, "second half", False)
    folds = [ho._fold(f, g, ho.Claims(), rate_b, True, None, None) for f, g in ((A, Bp),
                                                                              (Bp, A))]
    return _chi2_sf(sum(f.chi2_ext_pred for f in folds), sum(f.n_points for f in folds))


def _avar(y: np.ndarray, rate: float):  # type: ignore[no-untyped-def]
    sa = StreamingAllan(1, rate)
    sa.update(np.asarray(y, dtype=float)[:, None])
    return sa.result()


def test_the_noise_scatter_is_the_estimators_covariance_averaged_over_the_fitted_terms():
    """E[C(θ)] for θ ~ (θ̂, Cov θ), C quadratic in θ, is exactly the mean of C over the 2d
    sigma points θ̂ ± √d·Lₖ (L a Cholesky factor of Cov θ): the scatter added must be that
    mean less C(θ̂), whatever factor of Cov θ the function itself uses."""
    y, rb = _slow_axis(7)
    h = len(y) // 2
    model = fit_noise(_avar(y[:h], rb))
    held = _avar(y[h:], rb)
    got = ho._noise_scatter(model, held)
    comps = model.components
    cov = np.array(model.theta_cov, dtype=float)
    for k, c in enumerate(comps):  # the absent terms' standard error U²/z, θ̂ = 0
        te = model.terms.get(c.label)
        if te is not None and not te.present and te.upper:
            cov[k, k] += (te.upper**2 / model.z_present) ** 2
    act = [k for k in range(len(comps)) if cov[k, k] > 0]
    assert act, "the fit has no uncertain term: nothing to check"
    L = np.linalg.cholesky(cov[np.ix_(act, act)] + 1e-30 * np.eye(len(act)))
    m = np.asarray(held.m)
    stride = np.asarray(getattr(held, "stride", np.ones_like(m)), dtype=float)
    n_samp = (np.asarray(held.n, float) - 1.0) * stride + 2.0 * m
    theta = np.asarray(model.theta, dtype=float)

    def C(th: np.ndarray) -> np.ndarray:
        return avar_estimate_covariance(comps, th, m, n_samp, float(held.rate_hz), stride)

    d = len(act)
    mean = np.zeros((len(m), len(m)))
    for k in range(d):
        for s in (1.0, -1.0):
            th = theta.copy()
            th[act] += s * math.sqrt(d) * L[:, k]
            mean += C(th) / (2 * d)
    want = mean - C(theta)
    ok = np.isfinite(want)
    scale = np.sqrt(np.outer(np.diag(want), np.diag(want)))[ok]
    assert np.all(np.abs(got[ok] - want[ok]) <= 1e-4 * scale + 1e-300)
    assert np.all(np.diag(got) >= 0) and np.diag(got).max() > 0


def test_described_sensor_halves_are_not_piled_below_one_percent():
    """Sixty 4 h records of white + flicker + random walk (the weekend benchmark's levels),
    each judged as the verdict judges an axis that claims nothing: a calibrated test at 1 %
    fails ≤ 3 of 60 with probability 99.7 %, at 10 % ≤ 12 with 99.3 %; and it is not
    inflated out of use either (below p 0.5 on ≥ 15 of 60: a calibrated one falls below 14
    with probability 1e-5). Without the noise terms' scatter the held-out p of these records
    fell below 10 % on 16 of 60."""
    p = np.array([_p_heldout(*_slow_axis(seed)) for seed in range(1120, 1180)])
    assert np.all(np.isfinite(p))
    assert np.count_nonzero(p < ALPHA) <= 3, np.sort(p)[:6]
    assert np.count_nonzero(p < 0.10) <= 12, np.sort(p)[:14]
    assert np.count_nonzero(p < 0.50) >= 15, np.sort(p)


def test_a_signal_the_model_does_not_have_still_fails_the_held_out_test():
    """Outside the candidate set: a relay switching the bias by ±2·B every 5 minutes (a
    10-minute square wave; no IEEE term, no line the fit carries) in the second half only.
    The scatter the noise terms' uncertainty adds does not absorb it: the held-out test still
    fails at 1 %, on each of five records."""
    for seed in range(5):
        y, rb = _slow_axis(300 + seed)
        h = len(y) // 2
        t = np.arange(len(y) - h) / rb
        relay = 2.0 * B * np.sign(np.sin(2 * np.pi * t / 600.0 + seed))
        p = _p_heldout(y, rb, y[h:] + relay)
        assert p < ALPHA, (seed, p)


def _drive_axis(seed: int, size_b: float) -> tuple[np.ndarray, float]:
    """A described-sensor axis plus a sinusoidal drive of ``size_b``·B whose period is
    1.1–2.5× the record (random phase): slower than the record, outside every candidate
    (no logged channel, no line the fit resolves), read on each half as a random walk, a
    flicker or a rate ramp."""
    y, rb = _slow_axis(seed)
    rng = np.random.default_rng(seed + 777)
    period = len(y) / rb * rng.uniform(1.1, 2.5)
    t = np.arange(len(y)) / rb
    return y + size_b * B * np.sin(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi)), rb


def test_the_scatter_model_is_read_below_the_longest_octaves():
    """The noise terms whose uncertainty the held-out scatter carries are fitted on the fit
    part's τ up to a quarter of its longest (where a drive slower than the part cannot
    reach), with the same components; a part too short for that keeps the whole-range fit."""
    for seed in range(40, 43):
        y, rb = _drive_axis(seed, 15.0)
        h = len(y) // 2
        fit_avar = _avar(y[:h], rb)
        model = fit_noise(fit_avar)
        short = ho._scatter_model(fit_avar, model)
        assert short is not model
        assert short.tau_max_s <= model.tau_max_s / ho.SCATTER_TAU_FACTOR + 1e-9
        assert [c.label for c in short.components] == [c.label for c in model.components]
        # the short fit reads the same white noise (its τ are where white noise is known)
        n_full = model.terms["velocity_random_walk"].value
        n_short = short.terms["velocity_random_walk"].value
        assert n_full and n_short and abs(n_short / n_full - 1) < 0.05
    y, rb = _slow_axis(40)
    tiny = _avar(y[:600], rb)
    m = fit_noise(tiny)
    assert ho._scatter_model(tiny, m) is m or \
        ho._scatter_model(tiny, m).tau_max_s <= m.tau_max_s / ho.SCATTER_TAU_FACTOR + 1e-9


def test_the_scatter_model_is_refitted_with_the_models_own_options():
    """The scatter's terms are the held-out model's own fit redone below its longest
    octaves, with that fit's options: here a model made with a filter corner (kept, as
    analyze keeps an ADXL355's), a fixed rounding white, a line, a stricter presence level
    and no quantization term. The short refit has the same components (each its cause, its
    fixed parameters, its fixed value), the same corner and the same z (whose U²/z the
    scatter carries); before score29 it was refitted with fit_noise's defaults (no filter,
    z 2.33, the five terms, no rounding) whatever the model was."""
    rng = np.random.default_rng(2029)
    n = int(1.0 * 3600 * RATE)
    t = np.arange(n) / RATE
    a = (N * math.sqrt(RATE) * rng.standard_normal(n) + B * _flicker(n, rng)
         + K * math.sqrt(1 / RATE) * np.cumsum(rng.standard_normal(n))
         + 3e-4 * np.sin(2 * np.pi * 0.7 * t))
    fit_avar = _avar(a, RATE)
    terms = ("velocity_random_walk", "bias_instability", "rate_random_walk", "rate_ramp")
    model = fit_noise(fit_avar, terms=terms, filter_corner_hz=2.5, check_filter=False,
                      rounding_lsb=3.9e-5, z_present=3.0,
                      extra=[{"cause": "sinusoid", "params": {"frequency_hz": 0.7}}])
    short = ho._scatter_model(fit_avar, model)
    assert short is not model
    assert short.tau_max_s <= model.tau_max_s / ho.SCATTER_TAU_FACTOR + 1e-9

    def shape(f):  # type: ignore[no-untyped-def]
        return [(c.label, c.cause, c.params, c.fixed_value) for c in f.components]

    assert shape(short) == shape(model)
    assert short.filter_corner_hz == model.filter_corner_hz == 2.5
    assert short.z_present == model.z_present == 3.0
    assert short.ci == model.ci
