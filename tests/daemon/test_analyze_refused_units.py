"""`avard analyze --temperature CH` on a log the input screen refuses as °F said "the channel
is constant or the record too short", the wrong reason: the line now names the refusal with
its evidence and the option that overrules it (``--temperature-units F`` or ``C``); a channel
unused for another reason is said with that reason, and the option is not offered there."""

from __future__ import annotations

import json

import numpy as np
from avard.daemon import cli

from tests.support.hidden import Truth, make_record, save


def _record(tmp_path, name: str, fahrenheit: bool = False, constant: bool = False):
    rec, _ = make_record(5, hours=1.0, logged=("ambient",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=120.0))
    t = rec.temperature_c
    if fahrenheit:
        t[:, 0] = t[:, 0] * 1.8 + 32.0
    if constant:
        t[np.isfinite(t[:, 0]), 0] = 21.5
    return save(rec, tmp_path / name)


def _line(capsys) -> str:
    (line,) = [ln for ln in capsys.readouterr().out.splitlines()
               if ln.startswith("channel x:")]
    return line


def test_a_log_refused_as_fahrenheit_says_so_and_names_the_option(tmp_path, capsys):
    path = _record(tmp_path, "weekend_f.npz", fahrenheit=True)
    assert cli.main(["analyze", str(path), "--temperature", "ambient", "--channels", "x"]) == 0
    line = _line(capsys)
    assert "constant or the record too short" not in line
    assert "no temperature fit" in line and "'ambient' not used by the screen" in line
    # the evidence, as the screen has it
    assert "taken for °F" in line and "grid in °F" in line
    assert "--temperature-units F" in line and "--temperature-units C" in line
    # the JSON carries the refusal (the screen's) beside no compensation
    assert cli.main(["analyze", str(path), "--temperature", "ambient", "--channels", "x",
                     "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["channels"]["x"]["temperature_compensation"] is None
    assert "taken for °F" in d["screened"]["refused"]["ambient"]


def test_the_option_given_the_refusal_is_gone(tmp_path, capsys):
    """With ``--temperature-units F`` the same log is converted and fitted: a coupling line,
    no refusal."""
    path = _record(tmp_path, "weekend_f.npz", fahrenheit=True)
    assert cli.main(["analyze", str(path), "--temperature", "ambient", "--channels", "x",
                     "--temperature-units", "F"]) == 0
    line = _line(capsys)
    assert "temperature coupling detected" in line and "not used" not in line


def test_a_log_of_one_value_says_that_and_offers_no_units_option(tmp_path, capsys):
    path = _record(tmp_path, "flat.npz", constant=True)
    assert cli.main(["analyze", str(path), "--temperature", "ambient", "--channels", "x"]) == 0
    line = _line(capsys)
    assert "no temperature fit" in line and "one value throughout" in line
    assert "--temperature-units" not in line and "by the screen" not in line
