"""The explain pipeline's contract: JSON shape and units, held-out data (second half or another
record), the claim rule, the misfit ranges, and errors the user can act on."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from avard.core import effects, explain, model
from avard.core.causes import CAUSES, PARAMS
from avard.core.errors import DataError

N = 1 << 18


@pytest.fixture(scope="module")
def sinusoid_case():
    """One long record with a sinusoid, cut into two records of the same sensor."""
    rec, truth = effects.make_case(11, "sinusoid", n=2 * N)
    first = replace(rec, accel=rec.accel[:N], temperature_c=rec.temperature_c[:N])
    second = replace(rec, accel=rec.accel[N:], temperature_c=rec.temperature_c[N:],
                     source="second part")
    return first, second, truth


def _check_shape(out: dict) -> None:
    assert set(out) == {"channels"}
    for ch in out["channels"].values():
        assert set(ch) == {"base", "findings", "extended", "gain", "holdout_gain"}
        assert set(ch["base"]) == {"terms", "chi2_dof"}
        assert set(ch["extended"]) == {"terms", "extra", "chi2_dof"}
        for part in ("base", "extended"):
            assert set(ch[part]["terms"]) == set(model.TERMS)
            for name, t in ch[part]["terms"].items():
                assert t["unit"] == model.UNITS[name]
                assert {"value", "lo", "hi", "unit", "present"} <= set(t)
        for f in ch["findings"]:
            assert set(f) == {"cause", "params", "tau_range_s", "evidence"}
            assert f["cause"] in CAUSES
            assert set(f["params"]) == set(PARAMS[f["cause"]])
            assert len(f["tau_range_s"]) == 2 and f["tau_range_s"][0] <= f["tau_range_s"][1]
            assert isinstance(f["evidence"], str) and "test" in f["evidence"]
        for e in ch["extended"]["extra"]:
            assert set(e) == {"cause", "params"} and set(e["params"]) == set(PARAMS[e["cause"]])


def test_json_shape_and_gain(sinusoid_case):
    first, _, truth = sinusoid_case
    ex = explain.explain(first)
    out = json.loads(json.dumps(ex.to_json()))
    _check_shape(out)
    ch = out["channels"]["x"]
    assert [f["cause"] for f in ch["findings"]] == ["sinusoid"]
    assert ch["gain"] > 2 and ch["holdout_gain"] > 2
    assert ch["extended"]["chi2_dof"] < ch["base"]["chi2_dof"]
    # the base model misfits around the Allan bump τ ≈ 0.371/f0, and says so in sigmas
    tau_peak = 0.371 / truth.params["frequency_hz"]
    rng = [r for r in ex.channels["x"].misfit
           if r["tau_range_s"][0] / 2 <= tau_peak <= 2 * r["tau_range_s"][1]]
    assert rng and max(abs(r["max_sigma"]) for r in rng) > 3


def test_holdout_record_that_shares_the_cause(sinusoid_case):
    first, second, _truth = sinusoid_case
    ex = explain.explain(first, holdout=second)
    ch = ex.channels["x"]
    assert ex.holdout_source == "second part"
    assert [f["cause"] for f in ch.findings] == ["sinusoid"]
    assert ch.holdout_gain > 10


def test_cause_whose_gain_does_not_hold_is_not_claimed(sinusoid_case):
    first, _, _ = sinusoid_case
    null, _ = effects.make_case(12, None, n=N)
    ex = explain.explain(first, holdout=null)
    ch = ex.channels["x"]
    assert ch.findings == []
    assert ch.dropped and ch.dropped[0].startswith("sinusoid")


def test_effect_in_first_half_only_is_not_claimed():
    rec, _truth = effects.make_case(13, None, n=N)
    t = np.arange(N) / rec.rate_hz
    y = rec.accel[:, 0].copy()
    half = t < t[-1] / 2
    y[half] += 5e-4 * np.sin(2 * np.pi * 0.3 * t[half])
    ex = explain.explain(replace(rec, accel=y[:, None]))
    ch = ex.channels["x"]
    assert all(f["cause"] != "sinusoid" for f in ch.findings)
    assert any(d.startswith("sinusoid") for d in ch.dropped)


def test_null_record_has_no_findings_and_unit_gain():
    rec, _ = effects.make_case(14, None, n=N)
    ch = explain.explain(rec).channels["x"]
    assert ch.findings == [] and ch.tests and not any(t.passed for t in ch.tests)
    # nothing accepted: the extended model is the base model
    assert ch.gain == pytest.approx(1.0)
    assert ch.holdout_gain == pytest.approx(1.0)


def test_channel_selection_and_errors():
    rec, _ = effects.make_case(15, None, n=1 << 15)
    with pytest.raises(DataError, match="unknown channel"):
        explain.explain(rec, channels=["q"])
    bad = replace(rec, accel=np.full((1 << 15, 1), np.nan))
    with pytest.raises(DataError, match="NaN"):
        explain.explain(bad)
    with pytest.raises(DataError, match="too few"):
        explain.explain(replace(rec, accel=rec.accel[:1000], temperature_c=None))
    other = replace(rec, rate_hz=100.0)
    with pytest.raises(DataError, match="same rate"):
        explain.explain(rec, holdout=other)


def test_temperature_channels_with_gaps_are_filled():
    rec, truth = effects.make_case(16, "temperature", n=N)
    t = rec.temperature_c.copy()
    t[1::50, :] = np.nan  # a DS18B20 reading only every so often, NaN between (as sim_io)
    ch = explain.explain(replace(rec, temperature_c=t)).channels["x"]
    assert effects.check_case(truth, ch.findings)[0]


def test_measurement_is_the_allan_module_estimator_where_strides_agree():
    """explain measures with its own strided pass (speed); at m = 2^k its stride is the
    partially overlapping estimator's m/8, and the numbers must be the same."""
    from avard.core import allan
    from avard.core import causes as cz

    y = np.random.default_rng(3).standard_normal(1 << 16) * 1e-3
    ours = explain.measure(y, 50.0)
    ref = allan.allan_variance(y, 50.0, ours.tau, kind="pavar")
    p2 = (ours.m & (ours.m - 1)) == 0
    assert np.all(ref.stride[p2] == [cz.stride_for(int(k)) for k in ours.m[p2]])
    np.testing.assert_allclose(ours.var[p2], ref.var[p2], rtol=1e-9)
