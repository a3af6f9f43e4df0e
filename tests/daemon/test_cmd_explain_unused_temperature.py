"""A temperature channel the thermal model cannot use (no readings, or one value throughout)
is said in the text and the JSON, never dropped in silence; asked for by ``avard explain
--temperature`` it is one line and exit status 2 (it was a summary that never mentioned the
channel, exit 0); ``avard analyze --temperature`` keeps its analysis and says the fit is absent."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from avard.daemon import cli

from tests.support.hidden import Truth, make_record, save


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    """2 h, two logged channels: the plate dead (its DS18B20 never answered), the ambient
    stuck on one value (a log with nothing to regress on); the axis couples to the ambient."""
    rec, _ = make_record(7, truth=Truth(coefficient=(1e-3, 0.0, 0.0), lag_s=300.0),
                         logged=("plate", "ambient"), hours=2.0)
    t = np.array(rec.temperature_c, dtype=float)
    t[:, 0] = np.nan
    t[:, 1] = np.where(np.isfinite(t[:, 1]), 21.5, np.nan)
    return save(replace(rec, temperature_c=t), tmp_path_factory.mktemp("unused") / "u.npz")


def test_unusable_channels_are_named_with_why(record, capsys):
    assert cli.main(["explain", str(record), "--json", "--channels", "x"]) == 0
    out = json.loads(capsys.readouterr().out)
    unused = out["temperature_unused"]
    assert set(unused) == {"plate", "ambient"}
    assert "fewer than two readings" in unused["plate"]
    assert "one value throughout" in unused["ambient"] and "21.5" in unused["ambient"]
    assert out["channels"]["x"]["thermal"] is None
    assert cli.main(["explain", str(record), "--channels", "x"]) == 0
    text = capsys.readouterr().out
    assert "temperature channel plate not used: fewer than two readings" in text
    assert "temperature channel ambient not used: one value throughout" in text


@pytest.mark.parametrize("channel", ["plate", "ambient"])
def test_an_unusable_channel_asked_for_is_one_line_and_exit_2(record, capsys, channel):
    assert cli.main(["explain", str(record), "--channels", "x", "--temperature", channel]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    assert f"--temperature {channel}: the channel has" in err[0]
    assert "name another channel" in err[0]


def test_analyze_with_an_unusable_channel_keeps_its_analysis(record, capsys):
    """analyze --temperature runs explain's thermal fit beside its own result: a channel it
    cannot use costs the thermal lines, never the analysis (the reviewer's regression)."""
    assert cli.main(["analyze", str(record), "--channels", "x", "--temperature", "ambient"]) == 0
    out = capsys.readouterr().out
    assert "adev" in out.lower() and "no temperature fit" in out
