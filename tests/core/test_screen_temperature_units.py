"""``--temperature-units auto|C|F`` (issue 23 item 1): a log the screen refuses as °F (a
DS18B20's readings on its 0.1125 °F grid) had no way for the user to say "it is °C" or "it is
°F, convert it". Now ``C`` takes every log as °C (the °F evidence said, not acted on), ``F``
converts every log from °F before every rule; the choice is named in the text and the JSON;
a bad value is one line and exit status 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
from avard.core.errors import ConfigError
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.report import summary
from avard.core.io.screen import ScreenLog, screen_blocks
from avard.core.io.screen.units import temperature_units
from avard.core.io.source import open_record
from avard.daemon.cli import main

from tests.support.hidden import Truth, make_record, save


def _screened(temp: np.ndarray, units: str, names: list[str] | None = None
              ) -> tuple[np.ndarray, ScreenLog]:
    n, block = len(temp), 5000
    a = np.random.default_rng(0).normal(0.0, 1e-3, (n, 3))
    t2 = temp.reshape(n, -1)
    blocks = ((a[o:o + block], t2[o:o + block], o + block >= n) for o in range(0, n, block))
    log = ScreenLog(10.0, units=units)
    names = names or [f"t{j}" for j in range(t2.shape[1])]
    out = np.concatenate([t for _, t, _ in screen_blocks(blocks, 10.0, list("xyz"), names,
                                                          log)])
    return out, log


def _fahrenheit_log(n: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
    """(°C readings of a DS18B20 every 10 samples, NaN between; the same written in °F)."""
    rng = np.random.default_rng(3)
    col = np.full(n, np.nan)
    idx = np.arange(4, n, 10)
    room = 21.4 + 0.5 * np.sin(idx / 3000.0) + 0.01 * rng.standard_normal(len(idx))
    col[idx] = np.round(room / 0.0625) * 0.0625
    return col, np.round(col * 1.8 + 32.0, 4)


def test_the_option_parses_auto_c_and_f_and_nothing_else():
    assert [temperature_units(w) for w in ("auto", "AUTO", "c", "°C", "F", "f", None)] == [
        "auto", "auto", "C", "C", "F", "F", "auto"]
    for bad in ("K", "celsius", "", "CF"):
        with pytest.raises(ConfigError, match="--temperature-units"):
            temperature_units(bad)


def test_f_converts_before_every_rule_and_c_overrides_the_refusal():
    c, f = _fahrenheit_log()
    f_bad = f.copy()
    i85 = np.flatnonzero(np.isfinite(f))[700]
    f_bad[i85] = 185.0  # the 85 °C power-on value, written in °F
    out, log = _screened(f, "auto")
    assert "t0" in log.refused and log.notes["t0"].kind == "fahrenheit"
    out, log = _screened(f_bad, "F")
    ok = np.isfinite(c)
    ok[i85] = False
    np.testing.assert_allclose(out[ok, 0], c[ok], atol=1e-9)
    assert np.isnan(out[i85, 0])  # 185 °F is 85 °C: masked as the power-on value
    assert [s.kind for s in log.stretches] == ["power_on_85"]
    assert log.refused == {} and log.notes["t0"].kind == "units_given"
    assert "--temperature-units F" in log.notes["t0"].text
    assert log.to_dict()["temperature_units"] == "F"
    out, log = _screened(f, "C")
    np.testing.assert_array_equal(out[:, 0][np.isfinite(f)], f[np.isfinite(f)])
    assert log.refused == {} and log.notes["t0"].kind == "units_given"
    text = log.notes["t0"].text
    assert "--temperature-units C" in text and "look like °F" in text
    assert any("--temperature-units C" in ln for ln in log.lines())
    # avard's own die temperature is °C whatever is said: not converted, and said
    out, log = _screened(c, "F", names=["chip"])
    np.testing.assert_array_equal(out[:, 0][np.isfinite(c)], c[np.isfinite(c)])
    assert "not converted" in log.notes["chip"].text


def test_explain_takes_a_fahrenheit_log_converted_or_as_said(tmp_path):
    """The record of ``test_explain_refuses_a_log_in_fahrenheit_and_says_so`` (a 3e-3 m/s²/K
    coupling, its only log in °F): refused with auto; with F the coupling is claimed at its
    per-K size; with C the channel is used as asked (a coupling per °F, 1.8× too small:
    what the user said), and the JSON names the choice."""
    rec, _ = make_record(5, hours=2.0, logged=("ambient",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=120.0))
    rec.temperature_c[:, 0] = rec.temperature_c[:, 0] * 1.8 + 32.0
    path = save(rec, tmp_path / "f.npz")
    got = {}
    for units in ("F", "C"):
        ex = explain_file(open_record(path), ExplainOptions(channels=("x",), heldout=False,
                                                            temperature_units=units))
        assert "ambient" not in ex.temperature_unused
        (f,) = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
        got[units] = f.params["coefficient"]
        d = json.loads(json.dumps(ex.to_dict(), default=str))
        assert d["screened"]["temperature_units"] == units
        assert d["screened"]["notes"]["ambient"]["kind"] == "units_given"
        assert f"--temperature-units {units}" in summary(ex)
    assert got["F"] == pytest.approx(3e-3, rel=0.1)
    assert got["C"] == pytest.approx(got["F"] / 1.8, rel=0.02)


def test_a_bad_value_is_one_line_and_exit_2(tmp_path, capsys):
    rec, _ = make_record(5, hours=0.2, logged=("ambient",))
    path = save(rec, tmp_path / "r.npz")
    for cmd in ("explain", "analyze"):
        assert main([cmd, str(path), "--temperature-units", "kelvin"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--temperature-units kelvin" in err[0]


def test_f_converts_the_held_out_record_too(tmp_path):
    """``--holdout FILE`` with ``F``: the held-out record's logs are converted as the
    record's are (the models fitted per K predict it per K): the explanation of a °F pair
    equals the °C pair's."""
    paths = {}
    for seed in (5, 6):
        rec, _ = make_record(seed, hours=1.0, logged=("ambient",),
                             truth=Truth(coefficient=(3e-3, 0, 0), lag_s=120.0))
        paths["c", seed] = save(rec, tmp_path / f"c{seed}.npz")
        rec.temperature_c[:, 0] = rec.temperature_c[:, 0] * 1.8 + 32.0
        paths["f", seed] = save(rec, tmp_path / f"f{seed}.npz")
    got = {}
    for u, units in (("c", "auto"), ("f", "F")):
        ex = explain_file(open_record(paths[u, 5]),
                          ExplainOptions(channels=("x",), temperature_units=units),
                          holdout=open_record(paths[u, 6]))
        (f,) = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
        assert ex.holdout is not None
        got[u] = (f.params["coefficient"], ex.to_dict()["holdout_gain"])
    assert got["f"][0] == pytest.approx(got["c"][0], rel=1e-6)
    assert got["f"][1] == pytest.approx(got["c"][1], rel=1e-6)
