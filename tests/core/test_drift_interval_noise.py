"""The noise the drift test's slope interval is computed under is recorded, and said where
analyze reports a drift (cov28).

Since cov27 the interval (and the slope's standard error, which a resolved ramp's
uncertainty is propagated with) is computed under the N and B of the AVAR refitted less the
fitted line; where that refit fails, or the means' covariance under its N and B does not
factor, ``drift_likelihood`` falls back to the AVAR fit's own N and B, whose interval is
wider on drift records (the drift lowers the fit's B). The fallback used to be silent."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from avard.core.allan.deviations import allan_variance
from avard.core.analysis import drift as dr
from avard.core.analysis.engine import analyze
from avard.core.analysis.formats import format_table
from avard.core.analysis.options import AnalyzeOptions
from avard.core.analysis.results import Analysis
from avard.core.errors import FitError
from avard.core.io.source import RecordFormat, RecordInfo, StreamSource
from avard.core.model.fit import fit_noise

from benchmarks.bench_coverage import mix_for
from tests.support import coverage_gen2 as gen
from tests.support.coverage_gen import record

# the independent generator's 12 h geometry (docs/scripts/coverage_gen2_run.py)
N12, RATE = 43_200, 1.0


def _drift_record(seed: int) -> tuple[np.ndarray, object, object, np.ndarray, float]:
    lv = gen.levels(N12, 300.0, 10_000.0, RATE, drift_at=1 / 20)
    y, _clean = gen.record(lv, N12, np.random.default_rng([seed, 2711]))
    allan = allan_variance(y, RATE)
    b = dr.drift_block(N12)
    means = y[: N12 // b * b].reshape(-1, b).mean(axis=1)
    return y, allan, fit_noise(allan), means, b / RATE


def _failing_refit(*_a: object, **_k: object) -> object:
    raise FitError("no fit")


@pytest.mark.parametrize("seed", [3, 5])
def test_a_refit_that_fails_falls_back_to_the_fits_noise_and_says_so(seed: int) -> None:
    """With the AVAR, the interval is the refit's and says so; without it (explain's call)
    the fit's, by design; with a refit that raises, the fit's N and B, said as a fallback,
    and the interval is exactly the one computed without the AVAR (nothing else moved);
    where the covariance under the refit's N and B does not factor, the same with its own
    reason. The test's z and slope never move."""
    _y, allan, fit, means, block_s = _drift_record(seed)
    refit = dr.channel_drift(fit, means, block_s, allan)
    plain = dr.channel_drift(fit, means, block_s)
    failed = dr.channel_drift(fit, means, block_s, allan, _failing_refit)
    assert refit is not None and plain is not None and failed is not None
    assert refit.interval_noise == "refit_less_line"
    assert plain.interval_noise == "fit"
    assert failed.interval_noise == "fit_refit_failed"
    assert (failed.slope_lo, failed.slope_hi, failed.slope_sd) == (
        plain.slope_lo, plain.slope_hi, plain.slope_sd)
    # the refit's interval differs from the fit's on these records (what the fallback costs)
    assert refit.slope_hi - refit.slope_lo != plain.slope_hi - plain.slope_lo
    assert failed.z == refit.z == plain.z and failed.slope == refit.slope
    for key in ("refit_less_line", "fit", "fit_refit_failed", "fit_not_factored"):
        assert key in dr.INTERVAL_NOISE


def test_a_covariance_that_does_not_factor_under_the_refit_is_said(monkeypatch) -> None:
    """The means' covariance under the refit's N and B raising ``LinAlgError`` (forced):
    the interval is the fit's, said as "fit_not_factored"."""
    _y, allan, fit, means, block_s = _drift_record(3)
    plain = dr.channel_drift(fit, means, block_s)
    assert plain is not None
    n_fit = float(fit.terms["velocity_random_walk"].value or 0.0)
    real = dr._Profile

    def profile(yb, t, block_s, n_white, b_inst):  # type: ignore[no-untyped-def]
        if n_white != n_fit:
            raise np.linalg.LinAlgError("forced")
        return real(yb, t, block_s, n_white, b_inst)

    monkeypatch.setattr(dr, "_Profile", profile)
    lik = dr.channel_drift(fit, means, block_s, allan)
    assert lik is not None and lik.interval_noise == "fit_not_factored"
    assert (lik.slope_lo, lik.slope_hi) == (plain.slope_lo, plain.slope_hi)


def _analyze(y: np.ndarray):  # type: ignore[no-untyped-def]
    info = RecordInfo(source="drift", format=RecordFormat.STREAM, rate_hz=RATE,
                      names=("x",), n_samples=len(y))
    blocks = [(y[a:b, None], None, b != len(y)) for a, b in itertools.pairwise([0, len(y)])]
    return analyze(StreamSource(info, blocks), AnalyzeOptions()).channels["x"]


def test_analyze_says_which_noise_the_resolved_ramps_interval_used(monkeypatch) -> None:
    """A 12 h record with a drift analyze resolves from the time domain (test_drift's): the
    JSON's drift says the interval was the refit's; with the refit less the line failing
    (forced) it says the fit's N and B were used, and the table says so too. No drift
    reported, nothing said."""
    mix = mix_for("plain", N12, RATE)
    y, _ = record(mix, N12, np.random.default_rng(3))
    y = y + 4 * mix_for("drift", N12, RATE).drift * np.arange(N12)
    ch = _analyze(y)
    d = ch.to_dict()["drift"]
    assert d["rate_ramp_from"] == "time_domain" and d["interval_noise"] == "refit_less_line"
    text = format_table(Analysis("drift", RATE, N12, {"x": ch}))
    assert "the slope's interval under" not in text  # the rule's own case: nothing to add

    monkeypatch.setattr(dr, "_noise_beside_line", lambda *a, **k: None)
    ch = _analyze(y)
    d = ch.to_dict()["drift"]
    assert d["rate_ramp_from"] == "time_domain" and d["interval_noise"] == "fit_refit_failed"
    text = format_table(Analysis("drift", RATE, N12, {"x": ch}))
    assert "the slope's interval under the AVAR fit's N and B: the refit less the line " \
           "failed" in text

    flat, _ = record(mix, N12, np.random.default_rng(4))
    said = _analyze(flat).to_dict()["drift"]
    reported = said["rate_ramp_from"] == "time_domain" or said["floor"] > 0
    assert (said["interval_noise"] is not None) == reported


def test_the_interval_noise_is_typed_by_its_keys() -> None:
    """``DriftLikelihood.interval_noise`` is one of ``INTERVAL_NOISE``'s keys, as a type
    (``IntervalNoise``): a misspelt key is a type error, not a blank in the JSON."""
    import dataclasses
    import typing

    assert set(typing.get_args(dr.IntervalNoise)) == set(dr.INTERVAL_NOISE)
    hints = typing.get_type_hints(dr.DriftLikelihood)
    assert hints["interval_noise"] == dr.IntervalNoise
    assert {f.name for f in dataclasses.fields(dr.DriftLikelihood)} >= {"interval_noise"}
