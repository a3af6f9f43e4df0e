"""The hidden-effect generator: seeded, truth kept apart, every cause reachable, and the null
records really carry no effect."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core import effects
from avard.core.causes import CAUSES, PARAMS
from avard.core.errors import DataError

SMALL = 1 << 15


def test_same_seed_same_record_and_truth():
    a, ta = effects.make_case(7, "random", n=SMALL)
    b, tb = effects.make_case(7, "random", n=SMALL)
    np.testing.assert_array_equal(a.accel, b.accel)
    np.testing.assert_array_equal(a.temperature_c, b.temperature_c)
    assert ta == tb
    c, _ = effects.make_case(8, "random", n=SMALL)
    assert not np.array_equal(a.accel, c.accel)


@pytest.mark.parametrize("cause", CAUSES)
def test_truth_names_the_explain_parameters(cause):
    rec, truth = effects.make_case(3, cause, n=SMALL)
    assert truth.cause == cause
    assert set(truth.params) - {"channel"} == set(PARAMS[cause])
    assert rec.accel.shape == (SMALL, 1) and np.all(np.isfinite(rec.accel))
    # the record itself does not say what was hidden
    assert "cause" not in rec.meta and cause not in rec.source


def test_random_choice_reaches_every_kind():
    kinds = {effects.make_case(s, "random", n=SMALL)[1].cause for s in range(60)}
    assert kinds == {None, *CAUSES}


def test_temperature_channels_look_like_ds18b20():
    rec, _ = effects.make_case(1, None, n=SMALL)
    t = rec.temperature_c
    assert t.shape == (SMALL, 2) and rec.temperature_names == ["plate", "ambient"]
    np.testing.assert_allclose(t / 0.0625, np.round(t / 0.0625))
    assert 15 < t.mean() < 30


def test_hidden_effect_changes_the_record_by_its_own_signal():
    # the same seed with and without a step differs exactly by the step
    rec0, _ = effects.make_case(5, None, n=SMALL)
    rec1, truth = effects.make_case(5, "bias_step", n=SMALL)
    d = rec1.accel[:, 0] - rec0.accel[:, 0]
    # draws after the parameters differ, so compare only the deterministic shape of the jump
    t = np.arange(SMALL) / rec1.rate_hz
    before, after = d[t < truth.params["time_s"]], d[t >= truth.params["time_s"]]
    assert abs(np.median(after) - np.median(before) - truth.params["size"]) \
        < 0.5 * abs(truth.params["size"])


def test_check_case_rules():
    _, truth = effects.make_case(2, "sinusoid", n=SMALL)
    good = [{"cause": "sinusoid", "params": dict(truth.params)}]
    assert effects.check_case(truth, good)[0]
    off = [{"cause": "sinusoid", "params": {**truth.params,
                                            "frequency_hz": truth.params["frequency_hz"] * 1.03}}]
    ok, why = effects.check_case(truth, off)
    assert not ok and "frequency_hz" in why
    extra = [*good, {"cause": "filter", "params": {"bandwidth_hz": 5.0}}]
    assert not effects.check_case(truth, extra)[0]
    _, null = effects.make_case(2, None, n=SMALL)
    assert effects.check_case(null, [])[0]
    assert not effects.check_case(null, good)[0]


def test_rejects_bad_requests():
    with pytest.raises(DataError, match="too short"):
        effects.make_case(1, None, n=100)
    with pytest.raises(DataError, match="unknown cause"):
        effects.make_case(1, "earthquake", n=SMALL)
