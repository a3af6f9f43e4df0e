"""The input screen on temperature logs as a whole (issue 23, found by an adversary on
``avard explain``): a log held at each reading (each reading repeated on every sample until
the next, as some loggers write) is read as its readings, as a recording's are; a log in °F
is refused for the thermal model with its reason, a log off the DS18B20's grid in °C is
taken with a note. Each is said in one line (text, JSON, report)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.report import summary
from avard.core.io.screen import ScreenLog, held_cadence, screen_blocks, units_note
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save


def _held(col: np.ndarray) -> np.ndarray:
    """A logger's held column: each reading repeated on every sample until the next."""
    idx = np.flatnonzero(np.isfinite(col))
    pos = np.searchsorted(idx, np.arange(len(col)), side="right") - 1
    out = np.full(len(col), np.nan)
    out[pos >= 0] = col[idx[pos[pos >= 0]]]
    return out


def _screened(temp: np.ndarray, rate: float, block: int = 1 << 16,
              names: list[str] | None = None, check_units: bool = True
              ) -> tuple[np.ndarray, ScreenLog]:
    n = len(temp)
    a = np.random.default_rng(0).normal(0.0, 1e-3, (n, 3))
    t2 = temp.reshape(n, -1)
    blocks = ((a[o:o + block], t2[o:o + block], o + block >= n) for o in range(0, n, block))
    log = ScreenLog(rate)
    names = names or [f"t{j}" for j in range(t2.shape[1])]
    out = np.concatenate([t for _, t, _ in screen_blocks(blocks, rate, list("xyz"), names,
                                                          log, check_units=check_units)])
    return out, log


def _readings(n: int, rate: float, every: int, seed: int = 1, stable: bool = False
              ) -> np.ndarray:
    """A DS18B20 log with NaN between readings every ``every`` samples: a room moving
    (or, ``stable``, held on one step for a long stretch in the middle)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    room = 21.3 + 0.4 * np.sin(2 * np.pi * t / 1500.0) + 0.003 * rng.standard_normal(n)
    if stable:
        room[n // 3:2 * n // 3] = 21.30
    col = np.full(n, np.nan)
    idx = np.arange(7, n, every)
    col[idx] = np.round(room[idx] / 0.0625) * 0.0625
    return col


@pytest.mark.parametrize("block", [1 << 16, 5000])
def test_a_held_log_is_read_as_its_readings_and_said(block):
    """12.5 Hz, a reading every 12 samples, held: the screen hands on exactly the readings'
    rows and values (NaN between), as the log with NaN between would be, including a
    stable room's 40-minute stretch on one step (its readings stay one per cadence, not one
    reading and a hole), and says so in one line. Main handed the held values on: every
    block mean of the slow view read the temperature half a reading late."""
    rate, n = 12.5, 150_000
    col = _readings(n, rate, 12, stable=True)
    out, log = _screened(_held(col), rate, block)
    np.testing.assert_array_equal(np.isfinite(out[:, 0]), np.isfinite(col))
    np.testing.assert_array_equal(out[np.isfinite(col), 0], col[np.isfinite(col)])
    assert log.notes["t0"]["kind"] == "held"
    (line,) = [ln for ln in log.lines() if "temperature t0" in ln]
    assert "held at each reading" in line and "12-sample cadence" in line
    assert log.to_dict()["notes"]["t0"]["kind"] == "held"
    # the readings log itself is not touched, has nothing to note, and the screen's
    # verdicts on the two are the same (the stable stretch is judged alike: here, 67 min on
    # one step in a room that moves every few minutes, a stuck run on both)
    out2, log2 = _screened(col, rate, block)
    np.testing.assert_array_equal(np.isfinite(out2[:, 0]), np.isfinite(col))
    assert log2.notes == {}
    assert log.stretches == log2.stretches and log.readings == log2.readings


def test_a_held_log_whose_cadence_is_no_whole_number_of_samples():
    """0.75 s at 10 Hz is 7.5 samples: the runs are 7 and 8 samples and no common divisor
    exists; the changes' phases agree on 7.5 and each reading lands within a sample of its
    row (the run starts exactly: those are the changes)."""
    rate, n = 10.0, 120_000
    rng = np.random.default_rng(4)
    t = np.arange(n) / rate
    room = 21.3 + 0.4 * np.sin(2 * np.pi * t / 1300.0) + 0.003 * rng.standard_normal(n)
    idx = np.ceil(np.arange(1, int(n / 7.5)) * 7.5 - 1e-9).astype(int)
    idx = idx[idx < n]
    col = np.full(n, np.nan)
    col[idx] = np.round(room[idx] / 0.0625) * 0.0625
    c, why = held_cadence(_held(col)[:1 << 16])
    assert c == pytest.approx(7.5, abs=0.01) and why == ""
    out, log = _screened(_held(col), rate)
    got = np.flatnonzero(np.isfinite(out[:, 0]))
    assert abs(len(got) - len(idx)) <= 2
    near = np.searchsorted(idx, got)
    d = np.minimum(np.abs(got - idx[np.clip(near, 0, len(idx) - 1)]),
                   np.abs(got - idx[np.clip(near - 1, 0, len(idx) - 1)]))
    assert d.max() <= 1
    # a change is a reading at its own row: the value changes where the readings' does
    ch = idx[1:][np.diff(col[idx]) != 0]
    assert np.all(np.isfinite(out[ch, 0]))
    assert log.notes["t0"]["kind"] == "held"


def test_a_log_read_on_every_sample_is_not_taken_for_held():
    """A DS18B20 read every second at 1 Hz (every sample a reading: runs of one value of any
    length) and a thermistor's noisy log at 50 Hz: left as they are, on 200 rooms."""
    for seed in range(200):
        rng = np.random.default_rng(seed)
        n = 4096
        walk = 21 + np.cumsum(rng.normal(0, rng.choice([1e-3, 3e-3, 1e-2]), n))
        ds = np.round((walk + rng.normal(0, 3e-3, n)) / 0.0625) * 0.0625
        assert held_cadence(ds)[0] == 0.0
        assert held_cadence(np.round(walk + rng.normal(0, 0.01, n), 3))[0] == 0.0


def test_a_dense_log_with_too_few_changes_says_it_cannot_tell():
    rate, n = 12.5, 60_000
    col = np.full(n, 21.3125)
    col[20_000:] = 21.375
    col[41_000:] = 21.4375
    _, log = _screened(col, rate)
    assert log.notes["t0"]["kind"] == "held_unknown"
    assert "too few to tell" in log.notes["t0"]["text"]


def test_units_rule_fahrenheit_off_grid_celsius_and_on_grid():
    rng = np.random.default_rng(2)
    c = np.round((21.5 + 0.5 * rng.standard_normal(500)) / 0.0625) * 0.0625
    note, refused = units_note(c * 1.8 + 32.0)
    assert note is not None and note["kind"] == "fahrenheit" and refused is not None
    assert "°F" in refused and "1.8" in refused
    note, refused = units_note(c + rng.normal(0, 0.01, len(c)))  # another logger, °C
    assert note is not None and note["kind"] == "off_grid" and refused is None
    assert units_note(c) == (None, None)  # a DS18B20 in °C: nothing to say
    note, refused = units_note(c + 50.0)  # on the grid at a °F room's values
    assert note is not None and note["kind"] == "celsius_assumed" and refused is None


def test_explain_refuses_a_log_in_fahrenheit_and_says_so(tmp_path):
    """A coupled record whose only log is in °F: main fitted a coupling 1.8× too small per
    K and called it found; now the channel is refused for the thermal model with the reason
    in the text (one screen line and the not-used line), the JSON and the report."""
    rec, _ = make_record(5, hours=2.0, logged=("ambient",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=120.0))
    rec.temperature_c[:, 0] = rec.temperature_c[:, 0] * 1.8 + 32.0
    ex = explain_file(open_record(save(rec, tmp_path / "f.npz")),
                      ExplainOptions(channels=("x",), heldout=False))
    assert "ambient" in ex.temperature_unused and "°F" in ex.temperature_unused["ambient"]
    assert not any(f.cause == "temperature" and f.claimed for f in ex.channels["x"].findings)
    text = summary(ex)
    assert "temperature channel ambient not used: taken for °F" in text
    d = json.loads(json.dumps(ex.to_dict(), default=str))
    assert d["screened"]["notes"]["ambient"]["kind"] == "fahrenheit"
    assert "°F" in d["temperature_unused"]["ambient"]


def test_explain_on_a_held_log_fits_the_lag_of_its_readings(tmp_path):
    """The adversary's generator's negative-lag record (12.5 Hz, a reading every 0.96 s),
    written with NaN between readings and held: explain fits the very same lag on both (main
    fitted the held one 0.87 s earlier) and says the log was held."""
    from tests.support.adversary_gen import make_record as adversary_record

    p = tmp_path / "neglag.npz"
    adversary_record("neglag", 1, p, hours=2.0)
    d = dict(np.load(p))
    t = d["temperature_c"].copy()
    for j in range(t.shape[1]):
        t[:, j] = _held(t[:, j])
    ph = tmp_path / "neglag_held.npz"
    np.savez(ph, **{**d, "temperature_c": t})
    opts = ExplainOptions(channels=("x",), heldout=False)
    a = explain_file(open_record(p), opts).channels["x"].thermal
    ex = explain_file(open_record(ph), opts)
    b = ex.channels["x"].thermal
    assert a is not None and b is not None
    assert b.lag_s == pytest.approx(a.lag_s, abs=0.05)
    assert "held at each reading" in summary(ex)


def test_the_units_rule_leaves_the_chips_own_temperature_and_a_recording_alone():
    """avard's ADXL355 die temperature ("chip", on its own ~0.11 K step) at 55 °C in a warm
    enclosure is off the DS18B20's grid at a °F room's values: no DS18B20, not judged; nor is
    a recording's log (its daemon writes °C); the same values from elsewhere are refused."""
    rate, n = 10.0, 20_000
    col = np.full(n, np.nan)
    idx = np.arange(5, n, 10)
    col[idx] = np.round((55.0 + 0.3 * np.sin(idx / 900.0)) / 0.1105) * 0.1105
    _, log = _screened(col, rate, names=["chip"])
    assert log.notes == {} and log.refused == {}
    _, log = _screened(col, rate, check_units=False)
    assert log.notes == {} and log.refused == {}
    _, log = _screened(col, rate)
    assert log.notes["t0"]["kind"] == "fahrenheit" and "t0" in log.refused


def test_a_held_log_of_a_stable_room_is_judged_on_more_than_its_first_block():
    """125 Hz, a reading every 94 samples (0.752 s), held: the room sits on one step for the
    first 9 minutes (the first block of 65536 rows holds no complete run) and then moves. The
    blocks wait until the log tells (at most 2^19 rows): the readings are read from the
    record's first row, and the text says nothing of "too few"."""
    rate, n = 125.0, 400_000
    col = np.full(n, np.nan)
    idx = np.arange(10, n, 94)
    t = idx / rate
    room = np.where(t < 540.0, 21.31, 21.31 + 0.3 * np.sin((t - 540.0) / 300.0))
    col[idx] = np.round(room / 0.0625) * 0.0625
    out, log = _screened(_held(col), rate)
    np.testing.assert_array_equal(np.isfinite(out[:, 0]), np.isfinite(col))
    np.testing.assert_array_equal(out[idx, 0], col[idx])
    assert log.notes["t0"]["kind"] == "held" and "from" not in log.notes["t0"]["text"]
