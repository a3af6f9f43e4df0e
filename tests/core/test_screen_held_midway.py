"""A held log is judged on the whole log, stretch by stretch (issue 23 item 1): the screen
judged a log held at each reading on its first rows only, so a temperature log read on every
sample for its first part and held (a logger repeating its last reading) from midway on was
handed on as it was, silently; and a held log with a dropout after its first block lost its
readings' phase after the hole (the first value after it was taken for a reading, and its
run's readings placed from there). Now the whole log is watched, in bounded memory, and the
note says which stretches were read how."""

from __future__ import annotations

import json

import numpy as np
import pytest
from avard.core.io.screen import ScreenLog, screen_blocks
from avard.core.io.screen.held_log import HELD_RING

from tests.core.test_screen_temperature_logs import _held, _readings, _screened


def _room(n: int, rate: float, seed: int, period_s: float = 1500.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    return 21.3 + 0.4 * np.sin(2 * np.pi * t / period_s) + 0.003 * rng.standard_normal(n)


def _every_sample(n: int, rate: float, seed: int) -> np.ndarray:
    """A DS18B20's values read on every sample (a value on each row, changing anywhere)."""
    return np.round(_room(n, rate, seed) / 0.0625) * 0.0625


def _first_change_from(col: np.ndarray, row: int) -> int:
    """The first row ≥ ``row`` where the value changes between two finite rows."""
    d = np.flatnonzero(np.isfinite(col[row:]) & np.isfinite(col[row - 1:-1])
                       & (col[row:] != col[row - 1:-1]))
    return row + int(d[0])


@pytest.mark.parametrize("block", [1 << 16, 5000])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_log_held_from_midway_on_is_read_as_its_readings_there(block, seed):
    """12.5 Hz, read on every sample for 50 h… here 3.3 h, then held on a 12-sample cadence:
    from the held stretch's first change on, the screen hands on exactly the readings (main
    handed the held values on: every row of the stretch, half a reading late on average),
    and the note names both stretches, read as it is and held."""
    rate, n, mid = 12.5, 300_000, 150_000
    col = _readings(n, rate, 12, seed=seed)
    mixed = _held(col)
    mixed[:mid] = _every_sample(n, rate, seed + 10)[:mid]
    out, log = _screened(mixed, rate, block)
    s1 = _first_change_from(mixed, mid + 1)
    want = np.isfinite(col[s1:])
    np.testing.assert_array_equal(np.isfinite(out[s1:, 0]), want)
    np.testing.assert_array_equal(out[s1:, 0][want], col[s1:][want])
    # before it, the log as it is
    np.testing.assert_array_equal(out[:mid, 0], mixed[:mid])
    note = log.notes["t0"]
    assert note.kind == "held"
    assert "read in 2 stretches" in note.text and "read as it is" in note.text
    assert "12-sample cadence" in note.text
    d = json.loads(json.dumps(log.to_dict()))
    st = d["notes"]["t0"]["stretches"]
    assert [x["read"] for x in st] == ["as_is", "held"]
    assert st[1]["start_s"] == pytest.approx(s1 / rate)
    assert st[1]["cadence_samples"] == 12.0 and st[1]["end_s"] == pytest.approx(n / rate)
    # the screen's verdicts on the held stretch are those on its readings
    ref, _rlog = _screened(np.where(np.arange(n) < mid, mixed, col), rate, block)
    np.testing.assert_array_equal(np.isfinite(out[s1:, 0]), np.isfinite(ref[s1:, 0]))


def test_a_log_held_from_midway_on_a_cadence_no_whole_number_of_samples():
    """10 Hz, a reading every 0.75 s (7.5 samples) from midway on: read as readings there,
    each within a sample of its instant (the rows the logger's values change on are kept)."""
    rate, n, mid = 10.0, 240_000, 100_000
    room = _room(n, rate, 4, period_s=1300.0)
    idx = np.ceil(np.arange(1, int(n / 7.5)) * 7.5 - 1e-9).astype(int)
    idx = idx[idx < n]
    col = np.full(n, np.nan)
    col[idx] = np.round(room[idx] / 0.0625) * 0.0625
    mixed = _held(col)
    mixed[:mid] = np.round(room[:mid] / 0.0625) * 0.0625
    out, log = _screened(mixed, rate)
    assert log.notes["t0"].kind == "held"
    st = log.notes["t0"].stretches
    assert [x["read"] for x in st] == ["as_is", "held"]
    assert st[1]["cadence_samples"] == pytest.approx(7.5, abs=0.01)
    # a run of the log read on every sample lies within a sample of a multiple of 7.5 by
    # chance (about one in three): a few of them before the switch may join the held
    # stretch (their changes are kept, with their value every 7.5 samples)
    assert mid / rate - 120.0 <= st[1]["start_s"] < mid / rate + 300.0
    # (compared from the held stretch's first change after the switch: a run joined before
    # it is read on its own change's phase until the next change)
    s1 = max(round(st[1]["start_s"] * rate), _first_change_from(mixed, mid + 1))
    got = np.flatnonzero(np.isfinite(out[s1:, 0])) + s1
    ref = idx[idx >= s1]
    assert abs(len(got) - len(ref)) <= 2
    near = np.searchsorted(ref, got)
    dist = np.minimum(np.abs(got - ref[np.clip(near, 0, len(ref) - 1)]),
                      np.abs(got - ref[np.clip(near - 1, 0, len(ref) - 1)]))
    assert dist.max() <= 1


def test_a_held_log_that_is_read_on_every_sample_from_midway_is_said():
    """The other way: held for its first part, then read on every sample: the held stretch
    ends at its first change off the cadence, the rest is handed on as it is."""
    rate, n, mid = 12.5, 300_000, 150_000
    col = _readings(n, rate, 12, seed=5)
    mixed = _held(col)
    every = _every_sample(n, rate, 15)
    mixed[mid:] = every[mid:]
    out, log = _screened(mixed, rate)
    st = log.notes["t0"].stretches
    assert [x["read"] for x in st] == ["held", "as_is"]
    end = round(st[0]["end_s"] * rate)
    assert mid <= end < mid + 2000
    np.testing.assert_array_equal(out[end:, 0], mixed[end:])
    want = np.isfinite(col[:mid])
    np.testing.assert_array_equal(np.isfinite(out[:mid, 0]), want)
    np.testing.assert_array_equal(out[:mid, 0][want], col[:mid][want])


@pytest.mark.parametrize("block", [1 << 16, 5000])
@pytest.mark.parametrize("hole", [(100_000, 18_005), (70_001, 377), (200_000, 60_000)])
def test_a_held_log_keeps_its_phase_across_a_dropout(block, hole):
    """A held log (12.5 Hz, 12-sample cadence) with a NaN stretch after its first block,
    ending between two reading instants: after the hole the readings are on the logger's
    instants again (main took the first value after the hole for a reading and placed its
    run's readings from there: up to 11 samples off, for the whole run), and the hole is a
    dropout."""
    rate, n = 12.5, 300_000
    col = _readings(n, rate, 12, seed=7)
    h = _held(col)
    a, w = hole
    h[a:a + w] = np.nan
    want = col.copy()
    want[a:a + w] = np.nan
    out, log = _screened(h, rate, block)
    np.testing.assert_array_equal(np.isfinite(out[:, 0]), np.isfinite(want))
    np.testing.assert_array_equal(out[np.isfinite(want), 0], want[np.isfinite(want)])
    assert log.notes["t0"].kind == "held"
    if w / rate > 10:
        assert [s.kind for s in log.stretches] == ["dropout"]


def test_a_held_log_with_a_dropout_in_its_first_rows_is_still_held():
    """A stable room's held log (125 Hz, 94 samples) whose first rows hold a 5-minute hole
    before its first complete runs: the hole is a dropout, not NaN between readings (main
    judged the waited rows 'not dense' and handed the held values on)."""
    rate, n = 125.0, 500_000
    col = np.full(n, np.nan)
    idx = np.arange(10, n, 94)
    t = idx / rate
    room = np.where(t < 540.0, 21.31, 21.31 + 0.3 * np.sin((t - 540.0) / 300.0))
    col[idx] = np.round(room / 0.0625) * 0.0625
    h = _held(col)
    h[20_000:20_000 + 37_501] = np.nan
    want = col.copy()
    want[20_000:20_000 + 37_501] = np.nan
    out, log = _screened(h, rate)
    assert log.notes["t0"].kind == "held"
    np.testing.assert_array_equal(np.isfinite(out[:, 0]), np.isfinite(want))
    np.testing.assert_array_equal(out[np.isfinite(want), 0], want[np.isfinite(want)])


def test_logs_read_on_every_sample_are_never_taken_for_held_anywhere():
    """The whole log is tested, block after block: a log read on every sample must not show
    a held stretch by chance anywhere. 40 long logs (a DS18B20 read at 1 Hz in rooms of
    several speeds, a thermistor at 12.5 Hz, a slow room at 125 Hz) are handed on as they
    are, and nothing is said of them."""
    for seed in range(40):
        rng = np.random.default_rng(seed)
        rate = [1.0, 12.5, 125.0][seed % 3]
        n = 400_000
        walk = 21 + np.cumsum(rng.normal(0, rng.choice([3e-4, 1e-3, 3e-3]) / np.sqrt(rate), n))
        col = (np.round((walk + rng.normal(0, 3e-3, n)) / 0.0625) * 0.0625 if seed % 2
               else np.round(walk + rng.normal(0, 0.01, n), 3))
        out, log = _screened(col, rate, block=1 << 15)
        np.testing.assert_array_equal(out[:, 0], col)
        # nothing taken for held (a log that hardly changes may be said to be one that
        # cannot be told: "too few to tell")
        note = log.notes.get("t0")
        assert note is None or note.kind in ("off_grid", "held_unknown"), (seed, note)
        assert note is None or "stretches" not in note.text, (seed, note)


def test_a_steady_ramp_from_midway_is_not_taken_for_held_and_is_said():
    """A room read on every sample, moving, then warming steadily (runs all one length, one
    way): cannot tell a held log from it; handed on as it is and said of that stretch."""
    rate, n, mid = 1.0, 200_000, 60_000
    every = _every_sample(n, rate, 3)
    t = np.arange(n, dtype=float)
    every[mid:] = np.round((every[mid - 1] + (t[mid:] - mid) / 3600.0) / 0.0625) * 0.0625
    out, log = _screened(every, rate)
    np.testing.assert_array_equal(out[:, 0], every)
    note = log.notes["t0"]
    assert note.kind.startswith("held_unknown") and "steady ramp" in note.text


def test_the_watch_keeps_bounded_memory():
    """The watch keeps at most ``HELD_RING`` changes per channel whatever the log's length,
    and the stretches list only the stretches still to be handed on."""
    rate, n = 12.5, 600_000
    col = _every_sample(n, rate, 9)
    a = np.zeros((n, 3))
    blocks = ((a[o:o + 4096], col[o:o + 4096, None], o + 4096 >= n) for o in range(0, n, 4096))
    log = ScreenLog(rate)
    from avard.core.io.screen import stream as screen

    made: list[screen._Dehold] = []
    real = screen._Dehold

    class Spy(real):  # type: ignore[misc, valid-type]
        def __init__(self) -> None:
            super().__init__()
            made.append(self)

    screen._Dehold = Spy  # type: ignore[misc]
    try:
        for _ in screen_blocks(blocks, rate, list("xyz"), ["t0"], log):
            (d,) = made
            assert len(d._rp) <= HELD_RING and len(d.segs) <= 2
    finally:
        screen._Dehold = real  # type: ignore[misc]


def test_a_held_log_at_a_real_ds18b20_cadence_keeps_its_readings_over_hours():
    """125 Hz, a reading every 0.75 s (93.75 samples), held, 6 h in a room that dwells two
    hours on one step: the cadence read from the first changes' phases is refined as the log
    goes on (a straight line through the changes), so the watch finds no change off it and
    every reading stays within a sample of its instant."""
    rate, n, cad = 125.0, int(6 * 3600 * 125.0), 93.75
    rng = np.random.default_rng(1)
    idx = np.ceil(np.arange(1, int(n / cad)) * cad - 1e-9).astype(int)
    idx = idx[idx < n]
    t = idx / rate
    room = 21.31 + 0.25 * np.sin(2 * np.pi * t / 20000.0) + 0.004 * rng.standard_normal(len(t))
    room[(t > 3600) & (t < 3 * 3600)] = 21.31
    col = np.full(n, np.nan)
    col[idx] = np.round(room / 0.0625) * 0.0625
    out, log = _screened(_held(col), rate)
    note = log.notes["t0"]
    assert note.kind == "held" and note.stretches == ()  # one stretch, held throughout
    got = np.flatnonzero(np.isfinite(out[:, 0]))
    near = np.searchsorted(idx, got)
    dist = np.minimum(np.abs(got - idx[np.clip(near, 0, len(idx) - 1)]),
                      np.abs(got - idx[np.clip(near - 1, 0, len(idx) - 1)]))
    assert abs(len(got) - len(idx)) <= 1 and np.mean(dist <= 1) >= 0.9999


def test_a_held_log_whose_cadence_changes_is_read_on_each():
    """A logger set from a reading every 12 samples to one every 20 midway: two held
    stretches, each read as its readings (from the second's first change on)."""
    rate, n, mid = 12.5, 300_000, 150_007
    a = _readings(n, rate, 12, seed=8)
    b = _readings(n, rate, 20, seed=9)
    col = np.where(np.arange(n) < mid, a, np.nan)
    col[mid:] = b[mid:]
    h = _held(col)
    out, log = _screened(h, rate)
    st = log.notes["t0"].stretches
    assert [x["cadence_samples"] for x in st if x["read"] == "held"] == [12.0, 20.0]
    s2 = round(st[-1]["start_s"] * rate)
    assert mid <= s2 < mid + 3000
    want = np.isfinite(col[s2:])
    np.testing.assert_array_equal(np.isfinite(out[s2:, 0]), want)
    np.testing.assert_array_equal(out[s2:, 0][want], col[s2:][want])
    want = np.isfinite(col[:mid])
    np.testing.assert_array_equal(np.isfinite(out[:mid, 0]), want)


@pytest.mark.parametrize("block", [1 << 16, 5000])
def test_a_faulty_held_log_is_screened_as_its_readings(block):
    """A held log with a DS18B20's faults (85.0 °C power-on values, −127 °C read errors, a
    25-minute dropout, all after its first block): the screen's verdicts and readings equal
    those on the same log written with NaN between readings."""
    rate, n = 12.5, 400_000
    col = _readings(n, rate, 12, seed=11)
    idx = np.flatnonzero(np.isfinite(col))
    col[idx[9000]] = 85.0
    col[idx[15000]] = -127.0
    col[idx[21000]] = 85.0
    col[idx[12000]:idx[12000] + 18_750] = np.nan  # 25 min, from a reading to mid-interval
    h = _held(col)
    h[idx[12000]:idx[12000] + 18_750] = np.nan
    out, log = _screened(h, rate, block)
    ref, rlog = _screened(col, rate, block)
    np.testing.assert_array_equal(np.isfinite(out[:, 0]), np.isfinite(ref[:, 0]))
    ok = np.isfinite(ref[:, 0])
    np.testing.assert_array_equal(out[ok, 0], ref[ok, 0])
    assert log.stretches == rlog.stretches
    assert sorted(s.kind for s in log.stretches) == ["dropout", "power_on_85", "power_on_85",
                                                      "read_error"]
    assert log.notes["t0"].kind == "held"


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_held_log_whose_clock_jitters_after_its_first_rows_stays_one_stretch(seed):
    """A whole 12-sample cadence in the first rows, then 2 % of the readings a sample late:
    a jittering clock, not a log read otherwise. One held stretch throughout, every reading
    within a sample of its row (a break at each late reading left ~9 runs a time as they
    were, and the note a list of stretches)."""
    rate, n = 12.5, 400_000
    col = _readings(n, rate, 12, seed=seed)
    idx = np.flatnonzero(np.isfinite(col))
    rng = np.random.default_rng(seed)
    late = idx[(idx > 200_000) & (rng.random(len(idx)) < 0.02)]
    late = late[late + 1 < n]
    col[late + 1] = col[late]
    col[late] = np.nan
    out, log = _screened(_held(col), rate)
    assert log.notes["t0"].kind == "held" and log.notes["t0"].stretches == ()
    ri = np.flatnonzero(np.isfinite(col))
    got = np.flatnonzero(np.isfinite(out[:, 0]))
    assert len(got) == len(ri)
    near = np.searchsorted(ri, got)
    dist = np.minimum(np.abs(got - ri[np.clip(near, 0, len(ri) - 1)]),
                      np.abs(got - ri[np.clip(near - 1, 0, len(ri) - 1)]))
    assert dist.max() <= 1


def test_a_held_log_that_goes_over_to_nan_between_readings_keeps_every_reading():
    """Held for its first part, then written with NaN between readings on another phase and
    cadence (10 samples, 5 after the switch): every reading of the second part is handed on
    (a reading alone between NaN is a reading whatever the held cadence's phase)."""
    rate, n, mid = 12.5, 400_000, 200_003
    h = _held(_readings(n, rate, 12, seed=4))
    c2 = np.full(n, np.nan)
    i2 = np.arange(mid + 5, n, 10)
    c2[i2] = np.round((21.3 + 0.2 * np.sin(i2 / 5000.0)) / 0.0625) * 0.0625
    mixed = h.copy()
    mixed[mid:] = c2[mid:]
    out, _log = _screened(mixed, rate)
    np.testing.assert_array_equal(np.isfinite(out[mid:, 0]), np.isfinite(c2[mid:]))
    np.testing.assert_array_equal(out[i2, 0], c2[i2])
