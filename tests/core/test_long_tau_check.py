"""analyze tests a claimed rate ramp against the TOTVAR out to T/2 (issue 24;
core/analysis/long_tau_check.py, fit.refuted_by): the τ the OADEV (to N/4) cannot give."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.allan.total import ramp_totvar_ratio
from avard.core.analysis import long_tau_check as ltc
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.io.source import open_record
from avard.core.model.fit import LongTauCurve, fit_noise, refuted_by, with_long_tau_refuted
from avard.core.model.fit.results import NOT_RESOLVED
from avard.core.sim.presets import make_config
from avard.core.sim.simulate import SensorSimulator

from .test_fit import octave_oavar


def test_the_ramps_totvar_bias_is_exact_on_the_grid() -> None:
    """TOTVAR of a noise-free ramp, computed as analyze computes it (averaged, centred
    phase, eq. 25), over the ramp's AVAR R²τ²/2 is ``ramp_totvar_ratio``: about
    1 − (14/15)·τ/T, 0.53 at T/2, where the OADEV of a ramp is R²τ²/2 at every τ."""
    rate, n, R = 10.0, 40_000, 3e-6
    y = R * np.arange(n) / rate
    blocks = [(y[i:i + 4096, None], False) for i in range(0, n, 4096)]
    fit = fit_noise(octave_oavar(y + np.random.default_rng(0).normal(0, 1e-3, n), rate))
    curve = ltc.totvar_curve(fit, iter(blocks), n, rate)
    assert curve is not None and len(curve.tau) >= 2
    assert curve.tau[-1] == pytest.approx(n / rate / 2, rel=1e-3)
    np.testing.assert_allclose(curve.var / (R**2 * curve.tau**2 / 2), curve.ramp_factor,
                               rtol=1e-6)
    np.testing.assert_allclose(curve.ramp_factor, 1 - 14 / 15 * curve.tau / curve.record_s,
                               atol=2e-3)
    assert math.isnan(ramp_totvar_ratio(101, 51))


def _ramp_fit(seed: int, R: float, minutes: float = 55.0):
    cfg = make_config("adxl355-datasheet", rate_ramp=(R, R, R))
    rate = cfg.rate_hz
    y = SensorSimulator(cfg, seed=seed).next(int(minutes * 60 * rate)).counts * cfg.lsb_mps2
    return y[:, 0], rate


def test_a_curve_below_the_ramp_refutes_it_and_one_on_it_does_not() -> None:
    """The one refutation (``refuted_by``) on a TOTVAR curve: the record's own TOTVAR beyond
    the fit, where a true ramp is, does not refute it; the same curve with the ramp's part
    taken out (what a record whose rise turns over shows) does, and the terms are then
    flagged as ``fit_noise`` flags them."""
    x, rate = _ramp_fit(2, 2e-7)
    fit = fit_noise(octave_oavar(x, rate), filter_corner_hz=rate / 4)
    assert fit.terms["rate_ramp"].present and fit.terms["rate_ramp"].note is None
    blocks = [(x[i:i + 8192, None], False) for i in range(0, len(x), 8192)]
    curve = ltc.totvar_curve(fit, iter(blocks), len(x), rate)
    assert curve is not None
    assert not refuted_by(fit, curve)
    R2 = fit.terms["rate_ramp"].value ** 2
    flat = LongTauCurve("totvar", curve.tau, curve.var - 0.9 * R2 * curve.tau**2 / 2
                        * curve.ramp_factor, curve.edf, curve.record_s, curve.ramp_factor)
    assert refuted_by(fit, flat)
    flagged = with_long_tau_refuted(fit)
    assert flagged.terms["rate_ramp"].note == NOT_RESOLVED
    assert fit.terms["rate_ramp"].note is None  # a copy: the fit given is not changed
    with pytest.raises(Exception, match="kind"):
        LongTauCurve("mvar", curve.tau, curve.var, curve.edf)


def test_a_fit_without_a_ramp_reads_nothing_again() -> None:
    """Only a claimed ramp triggers the re-read: a fit with K alone (usual on long records)
    leaves the blocks unread, so analyze's cost there is unchanged."""
    rng = np.random.default_rng(1)
    rate, n = 10.0, 200_000
    y = rng.normal(size=n) + np.cumsum(rng.normal(scale=3e-3, size=n))
    fit = fit_noise(octave_oavar(y, rate))
    assert not fit.terms["rate_ramp"].present

    def never():
        raise AssertionError("the channel was read again")

    assert ltc.check_ramp(fit, never, n, rate) is fit


def test_the_longest_segment_is_tested() -> None:
    """A recording's gaps: the TOTVAR is computed on its longest stretch (no average
    straddles a gap), whose T sets τ's reach."""
    a = np.arange(10.0)
    blocks = [(a[:, None], False), (a[:4, None], True), (a[:3, None], False),
              (a[:3, None], True), (a[:5, None], False)]
    seg = ltc._longest_segment(iter(blocks), 2)
    np.testing.assert_allclose(seg, [0.5, 2.5, 4.5, 6.5, 8.5, 0.5, 2.5])


def _analyze(y, rate, tmp_path, name):
    path = tmp_path / f"{name}.npz"
    np.savez(path, accel=y, rate_hz=rate, axes=np.array(["x", "y", "z"]))
    return analyze(open_record(path), AnalyzeOptions(filter_corner_hz=rate / 4,
                                                     find_sinusoids=False))


def test_analyze_no_longer_claims_the_quiet_lab_ramp_the_live_fit_refutes(tmp_path,
                                                                          monkeypatch) -> None:
    """Seed 5 of quiet-lab, 55 min: the live fit refutes x's ramp with the cascade's τ
    beyond its fit (524 and 1049 s); analyze's OADEV stopped at 524 s (0.45× the ramp's
    prediction: z 1.8, not enough) and claimed R = 1.9e-7 m/s³ resolved. The TOTVAR out to
    T/2 refutes it; without the check analyze claims it again. (Since drift24 the block
    means' drift test, which finds no drift there, leaves it unclaimed as well: the check
    is then tested with that verdict set aside.)"""
    from dataclasses import replace

    from avard.core.analysis import drift as dr

    from tests.daemon.test_snapshot_fit_honesty import quiet_lab

    y, rate = quiet_lab(55, seed=5)
    ramp = _analyze(y, rate, tmp_path, "a0").channels["x"].fit.terms["rate_ramp"]
    assert not ramp.present
    monkeypatch.setattr(dr, "_no_ramp", lambda fit, allan, lik, refit, level:
                        replace(fit, drift_floor=lik.floor))
    ramp = _analyze(y, rate, tmp_path, "a").channels["x"].fit.terms["rate_ramp"]
    assert ramp.present and ramp.note == NOT_RESOLVED
    monkeypatch.setattr(ltc, "check_ramp", lambda fit, *a, **k: fit)
    ramp = _analyze(y, rate, tmp_path, "b").channels["x"].fit.terms["rate_ramp"]
    assert ramp.present and ramp.note is None


def test_a_true_ramp_is_claimed_as_often_with_the_check(tmp_path, monkeypatch) -> None:
    """R = 2e-7 m/s³ on 55 min of datasheet noise (the size of quiet-lab's false one), four
    seeds × three axes: analyze claims it resolved exactly as often with the TOTVAR check as
    without it (measured 8 of 12 both ways; the 12 h, 5e-8 m/s³ row: ``python -m benchmarks
    ramp_refute``)."""
    cfg = make_config("adxl355-datasheet", rate_ramp=(2e-7, 2e-7, 2e-7))
    rate = cfg.rate_hz
    claims = {True: 0, False: 0}
    for seed in (1, 2, 5, 6):
        y = SensorSimulator(cfg, seed=seed).next(int(55 * 60 * rate)).counts * cfg.lsb_mps2
        for on in (True, False):
            with monkeypatch.context() as mp:
                if not on:
                    mp.setattr(ltc, "check_ramp", lambda fit, *a, **k: fit)
                an = _analyze(y, rate, tmp_path, f"r{seed}{on}")
            claims[on] += sum(an.channels[a].fit.terms["rate_ramp"].present
                              and an.channels[a].fit.terms["rate_ramp"].note is None
                              for a in "xyz")
    assert claims[True] == claims[False] >= 6
