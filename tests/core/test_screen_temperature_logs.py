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
from avard.core.io.screen import ScreenLog, screen_blocks
from avard.core.io.screen.held_log import held_cadence
from avard.core.io.screen.units import units_note
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
    assert log.notes["t0"].kind == "held"
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
    assert log.notes["t0"].kind == "held"


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
    assert log.notes["t0"].kind == "held_unknown"
    assert "too few to tell" in log.notes["t0"].text


def test_units_rule_fahrenheit_off_grid_celsius_and_on_grid():
    rng = np.random.default_rng(2)
    c = np.round((21.5 + 0.5 * rng.standard_normal(500)) / 0.0625) * 0.0625
    note, refused = units_note(c * 1.8 + 32.0)
    assert note is not None and note.kind == "fahrenheit" and refused is not None
    assert "°F" in refused and "1.8" in refused
    note, refused = units_note(c + rng.normal(0, 0.01, len(c)))  # another logger, °C
    assert note is not None and note.kind == "off_grid" and refused is None
    assert units_note(c) == (None, None)  # a DS18B20 in °C: nothing to say
    note, refused = units_note(c + 50.0)  # on the grid at a °F room's values
    assert note is not None and note.kind == "celsius_assumed" and refused is None


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
    a recording's log (its daemon writes °C); the same values from elsewhere are noted as off
    the grid (they are on no DS18B20's °F grid either: no evidence of °F, not refused)."""
    rate, n = 10.0, 20_000
    col = np.full(n, np.nan)
    idx = np.arange(5, n, 10)
    col[idx] = np.round((55.0 + 0.3 * np.sin(idx / 900.0)) / 0.1105) * 0.1105
    _, log = _screened(col, rate, names=["chip"])
    assert log.notes == {} and log.refused == {}
    _, log = _screened(col, rate, check_units=False)
    assert log.notes == {} and log.refused == {}
    _, log = _screened(col, rate)
    assert log.notes["t0"].kind == "off_grid" and log.refused == {}


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
    assert log.notes["t0"].kind == "held" and "from" not in log.notes["t0"].text


def _ds18b20_f(c: np.ndarray) -> np.ndarray:
    """A DS18B20's °C readings written in °F and printed with 2 decimals (%.2f)."""
    return np.round(np.round(c / 0.0625) * 0.0625 * 1.8 + 32.0, 2)


def test_a_warm_celsius_log_off_the_grid_is_not_refused_as_fahrenheit():
    """Review of the units rule: a 55 °C plate logged by a thermistor to 0.01 K, an 80 °C
    oven to 0.001 K and a DS18B20 at 55 °C printed with %.2f in °C were refused as °F (off
    the 0.0625 K grid, median in 50–104). A refusal needs the readings on a DS18B20's grid
    in °F; these are taken as °C (off the grid: a note that says to convert if °F)."""
    rng = np.random.default_rng(0)
    n = 20_000
    plate = np.round(55 + 0.3 * np.sin(np.arange(n) / 3000) + 0.02 * rng.standard_normal(n), 2)
    oven = np.round(80 + 0.1 * rng.standard_normal(n), 3)
    for col in (plate, oven):
        note, refused = units_note(col)
        assert refused is None and note is not None and note.kind == "off_grid"
        assert "taken as °C" in note.text and "convert" in note.text
    # a DS18B20 in °C printed with 2 decimals (55.06, 55.12, 55.19): on its grid within
    # its printing, so °C is assumed, not refused
    ds = np.round(np.round((55 + 0.5 * rng.standard_normal(n)) / 0.0625) * 0.0625, 2)
    assert {55.06, 55.19} <= set(ds.tolist())
    note, refused = units_note(ds)
    assert refused is None and note is not None and note.kind == "celsius_assumed"
    # a stable room logged to 0.01 K whose few values happen to sit on the °F grid (23.45 °C
    # is 32 + 0.1125·(−76)): judged on its distinct values, too few to be evidence
    stable = np.full(n, 23.45)
    stable[::97] = 23.46
    assert units_note(stable)[1] is None
    # a real DS18B20 in °F, printed with 2 decimals too, at a room's and at a plate's values:
    # refused
    for mid in (21.5, 45.0):
        note, refused = units_note(_ds18b20_f(mid + 0.5 * rng.standard_normal(500)))
        assert note is not None and note.kind == "fahrenheit" and refused is not None
        assert "°F" in refused


def test_a_heated_plate_in_celsius_off_the_grid_keeps_its_coupling(tmp_path):
    """End to end (the reviewer's plate.py): a record coupled to its plate, the plate's log
    moved to 55 °C and printed to 2 decimals: explain uses the channel (it was refused as °F
    and the coupling lost) and claims the coupling; the log is a DS18B20's °C grid within its
    printing, so the note says °C is assumed."""
    from dataclasses import replace

    rec, _ = make_record(12, hours=1.0, logged=("plate",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=60.0, drive="plate"))
    hot = np.round(np.asarray(rec.temperature_c, float) + 34.0, 2)
    ex = explain_file(open_record(save(replace(rec, temperature_c=hot), tmp_path / "p.npz")),
                      ExplainOptions(channels=("x",), heldout=False))
    assert "plate" not in ex.temperature_unused
    d = json.loads(json.dumps(ex.to_dict(), default=str))
    assert d["screened"]["notes"]["plate"]["kind"] == "celsius_assumed"
    assert [f.cause for f in ex.channels["x"].claimed] == ["temperature"]


def test_a_steady_ramp_read_on_every_sample_is_not_taken_for_held():
    """Review of the held rule: a room warming 1 K/h read by a DS18B20 on every sample at
    1 Hz, without noise, has runs of exactly 225 samples, all changes upward: main took it
    for a log held on a 225-sample cadence and kept 292 of 65536 readings (read up to a run
    early). Indistinguishable from a held log whose every reading changes: left as it is and
    said ("cannot tell"); a thermistor's 0.01 K ramp likewise."""
    n = 1 << 16
    t = np.arange(n)
    for col in (np.round((21 + t / 3600.0) / 0.0625) * 0.0625, np.round(21 + 2 * t / 3600.0, 2)):
        c, why = held_cadence(col)
        assert c == 0.0 and "cannot tell" in why and "steady ramp" in why
        out, log = _screened(col, 1.0)
        assert np.isfinite(out[:, 0]).all()
        assert log.notes["t0"].kind.startswith("held_unknown")
    # a held log of a ramp that dwells and turns (several multiples, both ways) is still held
    rate, n = 12.5, 150_000
    col = _readings(n, rate, 12)
    assert held_cadence(_held(col)[:1 << 16])[0] == 12.0


def test_a_held_log_starting_with_nan_is_judged_from_its_first_value():
    """Review: density was judged on the first block's rows including leading NaN, so a held
    log whose first 4000 rows (6 % of the block) are NaN was taken as readings, silently.
    Judged over its finite span, it is read as its readings."""
    rate, n = 12.5, 300_000
    col = _readings(n, rate, 12)
    hl = _held(col)
    hl[:4000] = np.nan
    out, log = _screened(hl, rate)
    assert log.notes["t0"].kind == "held"
    # from its first change on (the first run is cut by the NaN: its readings' phase is not
    # in the log), exactly the readings
    s1 = 4001 + int(np.flatnonzero(np.diff(hl[4000:]) != 0)[0])
    want = np.isfinite(col[s1:])
    np.testing.assert_array_equal(np.isfinite(out[s1:, 0]), want)
    np.testing.assert_array_equal(out[s1:, 0][want], col[s1:][want])


def test_a_held_log_whose_cadence_cannot_be_tried_is_said():
    """Review: a held log at 125 Hz (a reading every 0.75 s) in a room that changes seldom
    has its first changes so far apart that more cadences than ``HELD_MAX_CANDIDATES`` were
    to be tried: main took it as readings with no note. Now it says it cannot tell."""
    from avard.core.io.screen.held_log import HELD_WAIT_SAMPLES

    rate, n = 125.0, HELD_WAIT_SAMPLES
    t = np.arange(n) / rate
    room = 21.3 + 0.4 * np.sin(2 * np.pi * t / 1500.0)
    col = np.full(n, np.nan)
    idx = np.unique(np.floor(np.arange(5, n / 93.75) * 93.75).astype(int))
    idx = idx[idx < n]
    col[idx] = np.round(room[idx] / 0.0625) * 0.0625
    c, why = held_cadence(_held(col), final=True)
    assert c == 0.0 and "cannot tell" in why and "judged on its first rows" in why


def test_a_fahrenheit_log_printed_coarsely_or_on_few_values_is_not_taken_for_celsius_silently(
        ) -> None:
    """review25b: a °F log printed to one decimal holds neither grid (its rounding is wider
    than both steps), and a stable °F room dwelling on three or four values fell below the
    five distinct values the °F evidence asked for: both were taken as °C with the plain
    off-grid note. Now a stable room's three values on the °F grid suffice at a °F room's
    values (chance about 1 in 800), and a coarse log at those values says that it cannot
    tell °C from °F (no refusal without evidence: a heated plate's °C printed to 0.1 keeps
    its use)."""
    rng = np.random.default_rng(1)
    room = 20 + np.cumsum(rng.normal(0, 0.01, 5000))
    ds = np.round(room / 0.0625) * 0.0625
    note, refused = units_note(np.round(ds * 1.8 + 32, 1))
    assert note is not None and note.kind == "units_unknown" and refused is None
    assert "cannot tell" in note.text
    few = np.repeat([20.0, 20.0625, 20.125], 50) * 1.8 + 32
    note, refused = units_note(np.round(few, 2))
    assert note is not None and note.kind == "fahrenheit" and refused is not None
    note, refused = units_note(np.round(room + 35, 1))   # a 55 °C plate printed to 0.1
    assert refused is None and note is not None and note.kind == "units_unknown"
    note, refused = units_note(np.round(room, 1))        # a 20 °C room printed to 0.1
    assert refused is None and note is not None and note.kind == "off_grid"
