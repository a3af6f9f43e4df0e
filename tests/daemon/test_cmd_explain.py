"""`avard explain` end to end through the CLI dispatcher: summary, --json shape (SI units,
analyze's channel dict as the base), --report files, and user errors as one line with exit
status 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from avard.daemon import cli

from tests.support.hidden import Truth, make_record, save


@pytest.fixture(scope="module")
def thermal_file(tmp_path_factory):
    rec, truth = make_record(4, truth=Truth(coefficient=(1e-3, 0.0, 0.0), lag_s=300.0),
                             logged=("ambient",), hours=3.0)
    return save(rec, tmp_path_factory.mktemp("explain") / "t.npz"), truth


def test_json_output(thermal_file, capsys):
    path, _ = thermal_file
    assert cli.main(["explain", str(path), "--json", "--channels", "x,y"]) == 0
    assert cli.main(["analyze", str(path), "--json", "--channels", "x", "y"]) == 0
    out_ex, out_an = _two_json(capsys)
    assert out_ex["units"] == "SI"
    assert set(out_ex["channels"]) == {"x", "y"}
    for name, ch in out_ex["channels"].items():
        assert ch["base"] == out_an["channels"][name]
    x = out_ex["channels"]["x"]
    assert [f["cause"] for f in x["findings"] if f["claimed"]] == ["temperature"]
    th = x["thermal"]
    assert th["channel"] == "ambient" and th["passed"]
    assert th["coefficient_mps2_per_k"] == pytest.approx(1e-3, rel=0.2)
    lo, hi = th["coefficient_interval"]
    assert lo < th["coefficient_mps2_per_k"] < hi
    assert len(x["compensated"]["adev"]) == len(x["base"]["tau_s"])
    assert x["gain"] > 1
    # the held-out gain: the halves of the record predict each other, with its definition
    ho = out_ex["holdout"]
    assert ho["mode"] == "split" and ho["units"] == "SI" and "χ²" in ho["definition"]
    hx = ho["channels"]["x"]
    assert hx["causes"] == ["temperature"] and hx["n_points"] > 0
    assert [f["fit_part"] for f in hx["folds"]] == ["first half", "second half"]
    assert hx["chi2_base"] == pytest.approx(sum(f["chi2_base"] for f in hx["folds"]))
    # only x claims a cause, so the record's gain is x's (this weak 3 h effect on 1.5 h
    # halves: the sign is the data's; tests/core/test_holdout.py asserts it on a clear one)
    assert out_ex["holdout_gain"] == hx["gain"] == pytest.approx(
        1 - hx["chi2_extended"] / hx["chi2_base"])
    assert ho["channels"]["y"]["gain"] is None and ho["channels"]["y"]["causes"] == []


@pytest.mark.parametrize("options", [["--estimator", "cascade"], ["--filter-corner", "2.5"]])
def test_explain_takes_analyzes_model_options_and_its_base_follows(thermal_file, capsys,
                                                                   options):
    """explain's base is analyze's fit of the same file run with the same options."""
    path, _ = thermal_file
    assert cli.main(["explain", str(path), "--json", "--channels", "y", *options]) == 0
    assert cli.main(["analyze", str(path), "--json", "--channels", "y", *options]) == 0
    out_ex, out_an = _two_json(capsys)
    assert out_ex["channels"]["y"]["base"] == out_an["channels"]["y"]
    assert cli.main(["analyze", str(path), "--json", "--channels", "y"]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert plain["channels"]["y"] != out_an["channels"]["y"]  # the option did change the fit


def _two_json(capsys):
    text = capsys.readouterr().out
    dec = json.JSONDecoder()
    a, i = dec.raw_decode(text)
    b, _ = dec.raw_decode(text[i:].lstrip())
    return a, b


def test_summary_and_report(thermal_file, tmp_path, capsys):
    path, _ = thermal_file
    rep = tmp_path / "rep"
    assert cli.main(["explain", str(path), "--report", str(rep), "--channels", "x"]) == 0
    text = capsys.readouterr().out
    assert "FOUND temperature" in text and "m/s²/K" in text and "ambient" in text
    assert "held-out gain" in text and "x: held-out χ² base" in text
    md = (rep / "report.md").read_text()
    assert "## Channel x" in md and "Every cause tested" in md
    assert "## Held-out gain" in md and "Definition: gain = 1 − χ²_ext/χ²_base" in md
    assert "| x | temperature | " in md
    for png in ("adev_x.png", "misfit_x.png", "temperature_adev.png"):
        assert (rep / png).stat().st_size > 1000


def test_user_errors_exit_2(tmp_path, capsys):
    assert cli.main(["explain", str(tmp_path / "missing.npz")]) == 2
    assert "does not exist" in capsys.readouterr().err
    np.savez(tmp_path / "norate.npz", accel=np.zeros((5000, 1)))
    assert cli.main(["explain", str(tmp_path / "norate.npz")]) == 2
    assert "rate" in capsys.readouterr().err
    np.savez(tmp_path / "short.npz", accel=np.ones((10, 1)), rate_hz=50.0)
    assert cli.main(["explain", str(tmp_path / "short.npz")]) == 2
    assert "samples" in capsys.readouterr().err
    assert cli.main(["explain", str(tmp_path / "short.npz"), "--report",
                     str(tmp_path / "no" / "such" / "dir")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_holdout_of_another_sensor_set_up_exit_2(thermal_file, tmp_path, capsys):
    """--holdout with another rate or other channels: one line naming both, exit 2."""
    path, _ = thermal_file
    rec, _ = make_record(12, logged=("ambient",), hours=0.2, rate_hz=20.0)
    other = save(rec, tmp_path / "o.npz")
    assert cli.main(["explain", str(path), "--holdout", str(other)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "--holdout" in err and "20 Hz" in err and "10 Hz" in err
    rec, _ = make_record(13, logged=("plate",), hours=0.2)
    other = save(rec, tmp_path / "p.npz")
    assert cli.main(["explain", str(path), "--holdout", str(other)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "temperatures plate" in err
    assert cli.main(["explain", str(path), "--holdout", str(tmp_path / "none.npz")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_the_record_itself_as_its_holdout_is_refused(thermal_file, capsys):
    """The models then 'predicted' the samples they were fitted on: a held-out gain with
    nothing held out, exit status 0."""
    path, _ = thermal_file
    same = str(Path(path).parent / "." / Path(path).name)
    assert cli.main(["explain", str(path), "--holdout", same]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "is the record explained" in err, err


def test_analyze_temperature_option(thermal_file, capsys):
    """`avard analyze --temperature CH`: the same terms as plain analyze, plus the coefficient
    and the compensated ADEV in the JSON."""
    path, _ = thermal_file
    assert cli.main(["analyze", str(path), "--json", "--channels", "x"]) == 0
    assert cli.main(["analyze", str(path), "--json", "--channels", "x",
                     "--temperature", "ambient"]) == 0
    plain, comp = _two_json(capsys)
    x = comp["channels"]["x"]
    tc = x.pop("temperature_compensation")
    assert x == plain["channels"]["x"]
    assert tc["channel"] == "ambient"
    assert tc["coefficient_mps2_per_k"] == pytest.approx(1e-3, rel=0.2)
    assert len(tc["compensated_adev"]) == len(x["tau_s"])
    k = min(range(len(x["tau_s"])), key=lambda i: abs(x["tau_s"][i] - 400.0))
    assert tc["compensated_adev"][k] < 0.8 * x["adev"][k]
    assert cli.main(["analyze", str(path), "--temperature", "plate"]) == 2
    assert "not in this record" in capsys.readouterr().err
