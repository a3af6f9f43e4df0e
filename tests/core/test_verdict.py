"""The honest "unexplained" of `avard explain` (core/explain/verdict.py): the extended model's
χ² test in-sample and held out, parameters marked model-dependent, no interval where the
held-out data reject the model, no compensated ADEV that makes the ADEV worse."""

from __future__ import annotations

import math

import numpy as np
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.report import summary
from avard.core.explain.verdict import compensation_worse_at, judge
from avard.core.io.source import open_record

from tests.support.hidden import make_record, save


def test_judge_in_sample_and_held_out():
    ok = judge(1.1, 12, [])
    assert ok.explained and math.isclose(ok.p_value, 0.355, abs_tol=0.01)
    assert "fits" in ok.line()
    bad = judge(3.0, 12, [{"tau_range_s": [10.0, 100.0], "max_sigma": 6.0,
                           "direction": "above"}])
    assert not bad.explained and bad.p_value < 1e-3 and not bad.heldout_rejects
    assert bad.line().startswith("UNEXPLAINED") and "10…100 s" in bad.line()
    # held out: χ² far beyond n fails even when the in-sample fit passes
    held = judge(1.0, 12, [], heldout_chi2=390.0, heldout_n=26)
    assert not held.explained and held.heldout_rejects and "n = 26" in held.line()
    # χ² a few times n on halves is the noise terms' rough prediction, not the mechanism
    assert judge(1.0, 12, [], heldout_chi2=45.0, heldout_n=11).explained


def test_judge_never_says_fits_without_a_test():
    """No dof or a χ² that is not finite: the line does not say the model fits."""
    for chi2, dof in ((math.nan, 12), (1.0, 0), (math.inf, 5)):
        v = judge(chi2, dof, [])
        assert not v.explained and not v.tested
        assert v.line().startswith("NOT TESTED") and "model-dependent" in v.line()
        assert v.to_dict()["tested"] is False


def test_a_held_out_p_under_alpha_within_the_ratio_says_why_it_is_not_a_rejection():
    v = judge(1.0, 12, [], heldout_chi2=45.0, heldout_n=11)
    assert v.explained and v.heldout_p is not None and v.heldout_p < 0.01
    assert "not a rejection" in v.line()
    assert "not a rejection" not in judge(1.0, 12, [], heldout_chi2=12.0,
                                          heldout_n=11).line()


def test_the_misfit_line_gives_each_range_its_size_in_adev():
    bad = judge(4.0, 12, [{"tau_range_s": [300.0, 1200.0], "max_sigma": 5.2,
                           "direction": "above", "adev_ratio": 1.83}])
    assert "300…1.2e+03 s (up to +5.2 σ, ADEV 1.83× the model's)" in bad.line()


def test_compensation_worse_at_every_tau_fitted_or_not():
    tau = np.array([1.0, 2.0, 4.0, 8.0])
    hi = 1.2 * np.ones(4)
    comp = np.array([0.5, 1.1, 1.5, 3.0])
    assert compensation_worse_at(tau, hi, comp) == [4.0, 8.0]
    comp[2:] = [np.nan, 1.0]
    assert compensation_worse_at(tau, hi, comp) == []


def test_a_dT_dt_coupling_is_unexplained_and_its_parameters_model_dependent(tmp_path):
    """The axis follows the rate of change of the ambient temperature, a mechanism outside
    the candidates: whatever is claimed, the output says "unexplained" and marks what it
    found as model-dependent."""
    rec, _ = make_record(41, hours=4.0, logged=("ambient",))
    t = rec.temperature_c[:, 0]
    ok = np.isfinite(t)
    idx = np.arange(len(t))
    temp = np.interp(idx, idx[ok], t[ok])
    k = np.ones(600) / 600  # a minute's smoothing of the 0.0625 K readings (10 Hz)
    dtdt = np.gradient(np.convolve(temp, k, mode="same")) * rec.rate_hz
    rec.accel[:, 0] += 4.0 * dtdt  # m/s² per K/s
    ex = explain_file(open_record(save(rec, tmp_path / "dtdt.npz")),
                      ExplainOptions(channels=("x",)))
    ch = ex.channels["x"]
    assert ch.verdict is not None and not ch.verdict.explained
    assert all(f.model_dependent for f in ch.claimed if f.cause not in ("sinusoid", "periodic"))
    text = summary(ex)
    assert "UNEXPLAINED" in text
    d = ex.to_dict()["channels"]["x"]
    assert d["verdict"]["explained"] is False and d["verdict"]["p_value"] < 0.01
