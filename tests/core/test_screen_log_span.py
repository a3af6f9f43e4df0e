"""A log that starts late or ends early (NaN before its first reading or after its last) is
a hole like a dropout, said with its times; a log with NaN between every reading (avard's
own recordings) is not; an all-85 °C log is named; a °C log converted as °F as asked says
the evidence against it (fix26)."""

from __future__ import annotations

import json

import numpy as np
from avard.core.io.screen import ScreenLog, screen_blocks

RATE = 10.0


def _screened(temp: np.ndarray, units: str = "auto", block: int = 5000) -> ScreenLog:
    n = len(temp)
    a = np.random.default_rng(0).normal(0.0, 1e-3, (n, 3))
    t2 = temp.reshape(n, -1)
    blocks = ((a[o:o + block], t2[o:o + block], o + block >= n) for o in range(0, n, block))
    log = ScreenLog(RATE, units=units)
    for _ in screen_blocks(blocks, RATE, list("xyz"), ["t0"], log):
        pass
    return log


def _log(n: int, every: int = 8, seed: int = 1) -> np.ndarray:
    """A DS18B20 read every ``every`` samples (NaN between), a room drifting 0.5 K."""
    rng = np.random.default_rng(seed)
    col = np.full(n, np.nan)
    idx = np.arange(3, n, every)
    room = 21.4 + 0.5 * np.sin(idx / 3000.0) + 0.01 * rng.standard_normal(len(idx))
    col[idx] = np.round(room / 0.0625) * 0.0625
    return col


def _kinds(log: ScreenLog) -> list[tuple[str, float, float]]:
    return [(s.kind, s.start_s, s.end_s) for s in log.stretches if s.channel == "t0"]


def test_a_log_that_ends_early_is_a_hole_to_the_end():
    n = int(2 * 3600 * RATE)
    col = _log(n)
    cut = int(720 * RATE)
    col[cut:] = np.nan
    last = np.flatnonzero(np.isfinite(col))[-1] / RATE
    log = _screened(col)
    assert _kinds(log) == [("log_ends_early", last, n / RATE)]
    assert log.holes("t0") == [(last, n / RATE)]
    assert "log ends early" in log.lines()[0]
    assert f"{last:.6g}–{n / RATE:.6g} s" in log.lines()[1]
    d = json.loads(json.dumps(log.to_dict()))
    assert d["stretches"][0]["kind"] == "log_ends_early"


def test_a_log_that_starts_late_is_a_hole_from_the_start():
    n = int(2 * 3600 * RATE)
    col = _log(n)
    col[:int(84 * 60 * RATE)] = np.nan
    first = np.flatnonzero(np.isfinite(col))[0] / RATE
    log = _screened(col)
    assert _kinds(log) == [("log_starts_late", 0.0, first)]
    assert log.holes("t0") == [(0.0, first)]
    assert "log starts late" in log.lines()[0]


def test_nan_between_readings_and_a_short_start_or_end_are_no_hole():
    """avard's own logs: a reading every ~0.75 s, NaN between; a log a few seconds late to
    start or early to end (under the dropout rule's 10 s and 8 reading intervals)."""
    n = int(3600 * RATE)
    for every in (1, 8, 75):
        col = _log(n, every)
        assert _kinds(_screened(col)) == []
        short = col.copy()
        short[:int(6 * RATE)] = np.nan
        short[n - int(6 * RATE):] = np.nan
        assert _kinds(_screened(short)) == []
    # a log read every 75 samples (7.5 s): the rule's 8 intervals (60 s), not 10 s
    col = _log(n, 75)
    col[:int(40 * RATE)] = np.nan
    assert _kinds(_screened(col)) == []
    col[:int(70 * RATE)] = np.nan
    assert [k for k, _, _ in _kinds(_screened(col))] == ["log_starts_late"]


def test_a_log_all_85_is_named_and_refused():
    col = _log(int(3600 * RATE))
    col[np.isfinite(col)] = 85.0
    log = _screened(col)
    assert "85.0 °C throughout" in log.notes["t0"].text
    assert "DS18B20" in log.refused["t0"]
    assert "no glitch, shock, read error, 85 °C" not in log.lines()[0]
    # one 85 °C reading among a room's is masked as before, and the log is used
    col = _log(int(3600 * RATE))
    col[np.flatnonzero(np.isfinite(col))[200]] = 85.0
    log = _screened(col)
    assert [k for k, _, _ in _kinds(log)] == ["power_on_85"]
    assert "t0" not in log.refused


def test_f_on_a_celsius_log_says_the_evidence_against_it():
    col = _log(int(3600 * RATE))
    log = _screened(col, "F")
    text = log.notes["t0"].text
    assert "converted from °F to °C as asked" in text
    assert "its readings look like °C (100 % of its" in text
    assert "look like °C" in log.to_dict()["notes"]["t0"]["text"]
    # a log in °F, converted as asked: nothing against it
    f = np.round(col * 1.8 + 32.0, 4)
    text = _screened(f, "F").notes["t0"].text
    assert "converted from °F to °C as asked" in text
    assert "look like °C" not in text
