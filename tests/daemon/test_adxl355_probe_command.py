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


def test_probe_refuses_an_impossible_emulated_oscillator(capsys):
    for ppm in ("1e9", "nan"):
        assert main(["probe", "--emulate", "--ppm", ppm]) == 2
        assert "--ppm" in capsys.readouterr().err


def _rate(out: str) -> tuple[float, float]:
    m = re.search(r"\(([+-]\d+) ± (\d+) ppm off nominal", out)
    assert m is not None, out
    return float(m.group(1)), float(m.group(2))


def test_the_short_rate_fit_is_unbiased_and_says_it_is_short(capsys):
    """Fixed-period polls aliased against the ODR biased a 5 s fit by 4σ (+2372 ± 156 ppm
    for +3000 ppm). Over several oscillator errors the z-scores now scatter around zero,
    and a fit too short for ±50 ppm says so and how long would do."""
    zs = []
    for true in (-3000.0, -1200.0, 400.0, 1700.0, 3000.0, 4500.0):
        assert main(["probe", "--emulate", "--no-self-test", "--seconds", "5",
                     "--ppm", str(true)]) == 0
        out = capsys.readouterr().out
        ppm, u = _rate(out)
        assert u > 0, out  # a fit that aliases can even report zero uncertainty
        zs.append((ppm - true) / u)
        assert "too short to measure the rate to ±50 ppm; run --seconds" in out
    assert max(abs(z) for z in zs) < 3, zs
    assert abs(sum(zs)) / len(zs) ** 0.5 < 3, zs     # no common bias


def test_probe_says_what_it_checked_and_what_it_skipped(capsys):
    assert main(["probe", "--emulate", "--seconds", "20", "--ppm", "3000"]) == 0
    out = capsys.readouterr().out
    ppm, u = _rate(out)
    assert u < 50 and abs(ppm - 3000) < 3 * u
    assert "too short" not in out
    assert "checked: IDs, self-test, output rate, 1 g, chip temperature" in out
    assert "skipped: DS18B20s (--emulate has no 1-Wire bus)" in out
    assert main(["probe", "--emulate", "--no-self-test", "--seconds", "1"]) == 0
    assert "skipped: self-test (--no-self-test); DS18B20s" in capsys.readouterr().out


def test_probe_takes_its_backend_and_start_up_from_the_rig_factory(capsys, monkeypatch):
    """$AVARD_BACKEND=simulate:PRESET probes the simulated rig of daemon/hw/rig.py, through the
    rig's one start-up sequence (with the self-test), like `avard run` would use it."""
    from avard.daemon.hw import rig

    calls = []
    real = rig.bring_up

    def spy(dev, sensor, **kw):
        calls.append(kw.get("self_test"))
        return real(dev, sensor, **kw)

    monkeypatch.setattr(rig, "bring_up", spy)
    monkeypatch.setenv(rig.BACKEND_ENV, "simulate:quiet-lab")
    assert main(["probe", "--seconds", "2"]) == 0
    out = capsys.readouterr().out
    assert calls == [True]
    assert "ADXL355 found" in out and "self-test passed" in out and "gaps: 0" in out
    assert "skipped: DS18B20s (the simulated rig quiet-lab has no real 1-Wire bus)" in out
    monkeypatch.setenv(rig.BACKEND_ENV, "simulate:no-such-preset")
    assert main(["probe", "--seconds", "2"]) == 2
    assert "unknown preset" in capsys.readouterr().err
