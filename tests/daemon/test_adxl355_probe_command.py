"""``avard probe --emulate``: the hardware check end to end over the emulator."""

from __future__ import annotations

import re

from avard.daemon.cli import main


def test_probe_reports_ids_self_test_rate_and_one_g(capsys, tmp_path):
    cfg = tmp_path / "avard.toml"
    cfg.write_text("[sensor]\nodr_hz = 1000.0\nrange_g = 4\n")
    rc = main(["probe", "--emulate", "--self-test", "--seconds", "3", "--ppm", "-1800",
               "--config", str(cfg)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "ADXL355 found" in out and "self-test passed" in out and "gaps: 0" in out
    m = re.search(r"\(([+-]\d+) ± (\d+) ppm off nominal", out)
    ppm, u = float(m.group(1)), float(m.group(2))
    assert abs(ppm + 1800) < max(5 * u, 50)
    m = re.search(r"\|a\| = ([\d.]+) m/s²", out)
    assert abs(float(m.group(1)) - 9.80665) < 1e-3
    assert "±4 g" in out and "all checks passed" in out


def test_probe_refuses_a_silly_duration(capsys):
    assert main(["probe", "--emulate", "--seconds", "0.1"]) == 2
    assert "--seconds" in capsys.readouterr().err
