"""`avard analyze --temperature CH` in text: the verdict of the temperature test (z against
its threshold) comes first, and the lag is printed with its interval, open ("≥") when the
interval reaches the longest lag tried."""

from __future__ import annotations

import re

from avard.daemon import cli
from avard.daemon.commands.analyze import _comp_line

from tests.support.hidden import make_record, save


def _fit(**kw: object) -> dict:
    d = {"channel": "ambient", "coefficient_mps2_per_k": -0.004096,
         "coefficient_interval": [-0.007762, -0.000429], "lag_s": 3600.0,
         "lag_interval_s": [1200.0, 3600.0], "lag_interval_open": True, "z": 1.12,
         "threshold": 5.0, "passed": False}
    d.update(kw)
    return d


def test_a_failed_test_says_not_detected_and_an_edge_lag_is_open():
    line = _comp_line("x", _fit())
    assert "not detected (z 1.12 < 5)" in line
    assert "lag of 3600 s [1200 s, ≥ 3600 s, the longest lag tried] (68 %)" in line
    assert "[-0.007762, -0.000429] (68 %)" in line


def test_a_passed_test_says_detected_with_a_closed_lag_interval():
    line = _comp_line("x", _fit(z=12.5, passed=True, lag_s=300.0,
                                lag_interval_s=[250.0, 360.0], lag_interval_open=False))
    assert "detected (z 12.5 ≥ 5)" in line and "not detected" not in line
    assert "lag of 300 s [250 s, 360 s] (68 %)" in line and "≥ 360" not in line


def test_analyze_temperature_on_a_record_without_coupling(tmp_path, capsys):
    """No coupling hidden: the printed line says the test failed, with its z and its
    threshold (5, or the t of the se's degrees of freedom at 5's tail: more on a short
    record, whose slow octaves' noise rests on few)."""
    rec, _ = make_record(21, hours=1.0, logged=("ambient",))
    path = save(rec, tmp_path / "null.npz")
    assert cli.main(["analyze", str(path), "--channels", "x", "--temperature", "ambient"]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("channel x: temperature"))
    got = re.search(r"not detected \(z ([0-9.e+-]+) < ([0-9.e+-]+)\)", line)
    assert got is not None, line
    assert float(got[1]) < float(got[2]) and float(got[2]) >= 5.0
    assert "first-order lag of" in line and "(68 %)" in line
