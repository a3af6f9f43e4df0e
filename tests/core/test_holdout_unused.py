"""A held-out record's temperature log that the record's own rule would not use (one value
throughout; a DS18B20 that never converted, all 85.0 °C) carries no held-out prediction:
the held-out test says NOT HELD OUT with that reason, never a gain of −3e3 that calls a
correct model UNEXPLAINED (fix26)."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save


def _pair(tmp_path, value: float):
    truth = Truth(coefficient=(3e-3, 0, 0), lag_s=300.0)
    rec, _ = make_record(3, hours=2.0, logged=("ambient",), truth=truth)
    held, _ = make_record(4, hours=2.0, logged=("ambient",), truth=truth)
    fin = np.isfinite(held.temperature_c)
    held.temperature_c[fin] = value
    return save(rec, tmp_path / "base.npz"), save(held, tmp_path / "held.npz")


@pytest.mark.parametrize(("value", "why"), [
    (85.0, "85.0 °C throughout"),
    (22.0, "one value throughout (22 °C)"),
])
def test_a_held_out_log_of_one_value_is_not_held_out(tmp_path, value, why):
    base, held = _pair(tmp_path, value)
    ex = explain_file(open_record(base), ExplainOptions(channels=("x",)),
                      holdout=open_record(held))
    ch = ex.channels["x"]
    assert any(f.cause == "temperature" for f in ch.claimed)
    assert ex.holdout is not None
    ho = ex.holdout.channels["x"]
    assert ho.reason is not None and why in ho.reason
    assert ch.verdict is not None
    assert ex.to_dict()["holdout_gain"] is None
    assert ch.verdict.line().startswith("NOT HELD OUT")
    assert ch.verdict.heldout_missing is not None and why in ch.verdict.heldout_missing


def test_the_record_itself_all_85_is_said_by_the_screen(tmp_path):
    """As the main record, an all-85 °C log is named as what it is (the screen's rule), not
    read as a room at 85 °C."""
    _base, held = _pair(tmp_path, 85.0)
    ex = explain_file(open_record(held), ExplainOptions(channels=("x",)))
    assert "85.0 °C throughout" in ex.temperature_unused["ambient"]
    assert "DS18B20" in ex.temperature_unused["ambient"]


@pytest.mark.parametrize(("span", "kind"), [
    (slice(int(0.1 * 72000), None), "log_ends_early"),
    (slice(0, int(0.7 * 72000)), "log_starts_late"),
])
def test_a_held_out_log_that_starts_late_or_ends_early_is_a_hole(tmp_path, span, kind):
    """NaN after the held-out log's first 12 min, or for its first 84 min: a hole of the
    held-out Allan variance (the screen says it), not a log held at its last value that
    made a correct model's held-out gain −3e3 / −1.5e3 and its verdict UNEXPLAINED."""
    truth = Truth(coefficient=(3e-3, 0, 0), lag_s=300.0)
    rec, _ = make_record(3, hours=2.0, logged=("ambient",), truth=truth)
    held, _ = make_record(4, hours=2.0, logged=("ambient",), truth=truth)
    assert len(held.temperature_c) == 72000
    held.temperature_c[span] = np.nan
    ex = explain_file(open_record(save(rec, tmp_path / "base.npz")),
                      ExplainOptions(channels=("x",)),
                      holdout=open_record(save(held, tmp_path / "held.npz")))
    assert ex.holdout is not None and ex.holdout.screen is not None
    assert [s.kind for s in ex.holdout.screen.stretches] == [kind]
    ch = ex.channels["x"]
    assert any(f.cause == "temperature" for f in ch.claimed)
    assert ch.verdict is not None and not ch.verdict.line().startswith("UNEXPLAINED")
    gain = ex.to_dict()["holdout_gain"]
    assert gain is None or gain > 0
