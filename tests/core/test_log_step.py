"""A temperature log's reading step, found from its values (``screen.log_step``) and said
where it is coarser than the 12-bit 0.0625 K the thermal model's rounding assumes (issue 23
items 1 and 5): a DS18B20 set to 9–11 bits (0.5, 0.25, 0.125 K), a °F log taken as °C (a
0.1125 K step from 32 °F), a coarse print. The screen lists it in analyze's and explain's
text, JSON and report, and an axis left unexplained through such a log names it as a
possible cause of the misfit."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.report import summary, write_report
from avard.core.explain.verdict import judge
from avard.core.io.screen import ScreenLog, coarse_text, log_step, screen_blocks
from avard.core.io.source import open_record
from avard.daemon.cli import main

import tests.support.hidden as hidden
from tests.support.hidden import Truth, make_record, save

TRUTH_C = 3e-3


def _room(seed: int = 1, n: int = 20000) -> np.ndarray:
    """A room's temperature at one reading per 0.75 s: a ±0.5 K cycle and a slow wander."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.75
    return 22.0 + 0.5 * np.sin(2 * math.pi * t / 1800.0) + 0.02 * np.cumsum(
        rng.standard_normal(n)) / math.sqrt(n)


@pytest.mark.parametrize("q", [0.5, 0.25, 0.125, 0.0625])
def test_each_ds18b20_resolution_is_found(q):
    T = np.round(_room() / q) * q
    assert log_step(T) == (q, 0.0)


def test_a_fahrenheit_log_is_on_its_own_grid_from_32():
    T = np.round(np.round(_room() / 0.0625) * 0.0625 * 1.8 + 32.0, 2)
    q, origin = log_step(T)
    assert q == pytest.approx(0.1125) and origin == pytest.approx(0.05, abs=1e-3)


def test_prints_and_no_grid():
    fine = np.round(_room() / 0.0625) * 0.0625
    assert log_step(np.round(fine, 2)) == (0.0625, 0.0)
    assert log_step(np.round(fine, 1)) == (0.1, 0.0)
    rng = np.random.default_rng(2)
    assert log_step(_room() + 0.003 * rng.standard_normal(20000)) is None


def test_a_step_of_no_candidate_is_the_values_own_spacing():
    # a thermistor logger rounding to 0.2 K, from an origin of 0.07, in a room swinging ±2 K
    # (enough values to show a spacing)
    T = np.round((4.0 * _room() - 0.07) / 0.2) * 0.2 + 0.07
    q, origin = log_step(T)
    assert q == pytest.approx(0.2) and origin == pytest.approx(0.07, abs=1e-3)


def test_a_stable_room_keeps_the_12_bit_step():
    # two values a coarse step apart: a 0.0625 K log dwelling on two of its levels looks the
    # same, so the DS18B20's default stands
    assert log_step(np.array([21.5, 21.625, 21.5, 21.625])) == (0.0625, 0.0)
    # a 12-bit log visits the level between two it crosses: never taken for 0.125
    T = np.round(_room() / 0.0625) * 0.0625
    assert log_step(T[:4000]) == (0.0625, 0.0)
    # the DS18B20's error and power-on values are no reading of the room
    assert log_step(np.concatenate([T, [85.0, -127.0]])) == (0.0625, 0.0)


def test_the_text_names_the_step_and_what_it_may_be():
    assert coarse_text((0.25, 0.0)) == (
        "readings on a 0.25 K step (a DS18B20 at 10 bits?), coarser than the 12-bit "
        "0.0625 K the thermal model's rounding assumes")
    assert "9 bits?" in coarse_text((0.5, 0.0))
    assert "12 bits read in °F and taken as °C?" in coarse_text((0.1125, 0.05))
    log = ScreenLog(10.0, steps={"a": (0.0625, 0.0), "b": None, "c": (0.125, 0.0)})
    assert log.coarse("a") is None and log.coarse("b") is None and log.coarse("x") is None
    assert log.coarse("c") == coarse_text((0.125, 0.0))


def _screened(col: np.ndarray, units: str = "auto") -> ScreenLog:
    n, block = len(col), 5000
    a = np.random.default_rng(0).normal(0.0, 1e-3, (n, 3))
    t2 = col.reshape(n, 1)
    blocks = ((a[o:o + block], t2[o:o + block], o + block >= n) for o in range(0, n, block))
    log = ScreenLog(10.0, units=units)
    for _ in screen_blocks(blocks, 10.0, list("xyz"), ["plate"], log):
        pass
    return log


def _logged(q: float, n: int = 40000) -> np.ndarray:
    col = np.full(n, np.nan)
    idx = np.arange(4, n, 8)
    col[idx] = np.round(_room(n=len(idx)) / q) * q
    return col


def test_the_screen_notes_a_coarse_log_and_only_a_coarse_one():
    log = _screened(_logged(0.25))
    assert log.steps == {"plate": (0.25, 0.0)}
    note = log.notes["plate"]
    assert note.kind == "coarse_step"
    assert note.text == coarse_text((0.25, 0.0))
    assert f"temperature plate: {coarse_text((0.25, 0.0))}" in "\n".join(log.lines())
    d = log.to_dict()
    assert d["reading_steps"]["plate"] == {"step_k": 0.25, "origin": 0.0, "coarse": True}
    fine = _screened(_logged(0.0625))
    assert fine.notes == {}
    assert fine.to_dict()["reading_steps"]["plate"]["coarse"] is False


def test_a_fahrenheit_log_refused_gets_no_step_note_and_one_taken_as_c_does():
    col = _logged(0.0625)
    col = np.round(col * 1.8 + 32.0, 4)
    refused = _screened(col)
    assert "plate" in refused.refused
    assert "coarse_step" not in refused.notes["plate"].kind
    taken = _screened(col, "C")
    assert "plate" not in taken.refused
    assert taken.notes["plate"].kind == "units_given"
    assert "0.1125 K step" in taken.notes["plate"].text


def _record(tmp_path: Path, q: float, seed: int = 3, hours: float = 2.0) -> Path:
    """A correct one-lag record (3e-3 m/s²/K through 300 s) whose log reads on ``q``."""
    old = hidden.DS18B20_STEP_C
    hidden.DS18B20_STEP_C = q
    try:
        rec, _ = make_record(seed, hours=hours, logged=("ambient",),
                             truth=Truth(coefficient=(TRUTH_C, 0, 0), lag_s=300.0))
    finally:
        hidden.DS18B20_STEP_C = old
    return save(rec, tmp_path / f"q{q}.npz")


def test_analyze_lists_a_coarse_log_in_its_text_and_json(tmp_path, capsys):
    # analyze reads a temperature log when it compensates with it (``--temperature``)
    path = str(_record(tmp_path, 0.25, hours=0.5))
    said = coarse_text((0.25, 0.0))
    assert main(["analyze", path, "--temperature", "ambient"]) == 0
    assert f"temperature ambient: {said}" in capsys.readouterr().out
    assert main(["analyze", path, "--temperature", "ambient", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["screened"]["notes"]["ambient"]["text"] == said
    assert d["screened"]["reading_steps"]["ambient"]["step_k"] == 0.25


def test_explain_says_it_and_an_unexplained_axis_names_it(tmp_path):
    ex = explain_file(open_record(_record(tmp_path, 0.25)), ExplainOptions(channels=("x",)))
    said = coarse_text((0.25, 0.0))
    text = summary(ex)
    assert f"temperature ambient: {said}" in text
    d = json.loads(json.dumps(ex.to_dict(), default=str))
    assert d["screened"]["notes"]["ambient"]["text"] == said
    report = write_report(ex, tmp_path / "rep").read_text()
    assert said in report
    v = ex.channels["x"].verdict
    assert v is not None and ex.channels["x"].thermal is not None
    if not v.explained:
        # the misfit is not left undiagnosed: the coarse log is named beside it
        assert v.line().endswith(f"a possible cause: temperature 'ambient' {said}")
        assert d["channels"]["x"]["verdict"]["possible_cause"] == f"temperature 'ambient' {said}"
    else:
        assert d["channels"]["x"]["verdict"]["possible_cause"] is None


def test_a_12_bit_log_is_said_nowhere(tmp_path):
    ex = explain_file(open_record(_record(tmp_path, 0.0625)), ExplainOptions(channels=("x",)))
    d = json.loads(json.dumps(ex.to_dict(), default=str))
    assert d["screened"]["notes"] == {}
    assert d["screened"]["reading_steps"]["ambient"] == {"step_k": 0.0625, "origin": 0.0,
                                                         "coarse": False}
    assert "possible cause" not in summary(ex)


def test_the_verdict_says_the_possible_cause_only_when_unexplained():
    from dataclasses import replace

    bad = replace(judge(9.0, 12, [{"direction": "above", "tau_range_s": [100.0, 800.0],
                                   "max_sigma": 50.0}]), suspect="temperature 'a' X")
    assert not bad.explained
    assert bad.line().startswith("UNEXPLAINED") and bad.line().endswith(
        "; a possible cause: temperature 'a' X")
    assert bad.to_dict()["possible_cause"] == "temperature 'a' X"
    good = replace(judge(1.0, 12, []), suspect="temperature 'a' X")
    assert good.explained and "possible cause" not in good.line()
    assert good.to_dict()["possible_cause"] is None
