"""The held-out record of ``avard explain RECORD --holdout OTHER`` goes through the same input
screen as the record (issue 23 item 1, "screen the inputs ... by analyze and explain alike").
Before, only ``--temperature-units`` reached it: its DS18B20 85.0 °C power-on values, −127 °C
read errors, spikes and dropouts went straight into the held-out gain (a held-out record with
three 85 °C readings and a 25-minute dropout gave a gain of −55 where the same record clean
gives 0.99, and the axis was called UNEXPLAINED). Now its readings are masked by the same
rules, its acceleration shocks cut out, its log's holes (and the lag's settling after them)
are gaps of the held-out Allan variance, and what was screened is said in the text and the
JSON, labelled as the held-out record's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.explain.engine import Explanation, explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.report import summary
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save

HOURS = 2.0


def _truth() -> Truth:
    return Truth(coefficient=(3e-3, 0, 0), lag_s=300.0)


def _with_faults(rec, faults: str) -> dict[str, int]:
    """Put ``faults`` into ``rec`` (in place): "readings" (three 85.0 °C power-on values, a
    −127 °C read error, a 1 K one-reading spike), "dropout" (25 minutes without a reading),
    "accel" (a start-up glitch and an isolated shock), or "all"; the counts the screen must
    list."""
    t = rec.temperature_c
    a = rec.accel
    want: dict[str, int] = {}
    if faults in ("dropout", "all"):
        i0 = int(0.4 * len(t))
        t[i0:i0 + int(1500 * rec.rate_hz)] = np.nan
        want["dropout"] = 1
    ok = np.flatnonzero(np.isfinite(t[:, 0]))
    if faults in ("readings", "all"):
        for k in (100, 3000, 6000):
            t[ok[k], 0] = 85.0
        t[ok[4000], 0] = -127.0
        t[ok[5000], 0] = t[ok[4999], 0] + 1.0
        want.update(power_on_85=3, read_error=1, spike=1)
    if faults in ("accel", "all"):
        a[2:5] += 0.5          # the first samples of a start-up, far off
        a[len(a) // 3, :] += 0.2  # one knock on the table
        want.update(startup_glitch=1, shock=1)
    return want


def _explain(tmp_path, held_seed: int, faults: str | None, units: str = "auto"
             ) -> Explanation:
    rec, _ = make_record(3, hours=HOURS, logged=("ambient",), truth=_truth())
    base = save(rec, tmp_path / "base.npz")
    held, _ = make_record(held_seed, hours=HOURS, logged=("ambient",), truth=_truth())
    name = "clean"
    if faults is not None:
        _with_faults(held, faults)
        name = faults
    other = save(held, tmp_path / f"{name}{held_seed}.npz")
    return explain_file(open_record(base),
                        ExplainOptions(channels=("x",), temperature_units=units),
                        holdout=open_record(other))


def _held(ex: Explanation) -> tuple[float, float, float, int]:
    """(gain, χ²_base, χ²_ext, n) of axis x on the held-out record."""
    assert ex.holdout is not None
    c = ex.holdout.channels["x"]
    assert c.reason is None and c.gain is not None
    return c.gain, c.chi2_base, c.chi2_ext, c.n_points


@pytest.mark.parametrize("held_seed", [4, 6])
@pytest.mark.parametrize("faults", ["readings", "dropout", "accel", "all"])
def test_a_faulty_held_out_record_predicts_as_the_same_record_clean(tmp_path, held_seed,
                                                                    faults):
    """The same held-out record, clean and with a weekend's faults: its held-out gain agrees
    within its interval (a model that predicts the data gives χ²_ext ≈ n ± √(2n), so the gain
    1 − χ²_ext/χ²_base is known to ±√(2n)/χ²_base), the extended model predicts it (χ²_ext
    within χ²(n)'s 1 % tail either way) and the claims and the verdict are the same."""
    clean = _explain(tmp_path, held_seed, None)
    faulty = _explain(tmp_path, held_seed, faults)
    g_c, _b_c, _e_c, n_c = _held(clean)
    g_f, b_f, e_f, n_f = _held(faulty)
    assert n_f == n_c
    assert abs(g_f - g_c) <= 2 * math.sqrt(2 * n_f) / b_f, (g_f, g_c)
    assert e_f < n_f + 4 * math.sqrt(2 * n_f), e_f
    assert g_f > 0.9
    for ex in (clean, faulty):
        assert [f.cause for f in ex.channels["x"].claimed] == ["temperature"]
    vc, vf = clean.channels["x"].verdict, faulty.channels["x"].verdict
    assert vc is not None and vf is not None
    assert vf.explained == vc.explained and vf.explained
    assert not vf.heldout_rejects


def test_what_was_screened_in_the_held_out_record_is_said_in_the_json_and_the_text(tmp_path):
    """The held-out record's screen is in the JSON beside the record's (``holdout_screened``,
    the same shape, named as the held-out record's) and in the text (its own line, labelled),
    every fault listed with its time; the record's own screen stays its own."""
    rec, _ = make_record(3, hours=HOURS, logged=("ambient",), truth=_truth())
    base = save(rec, tmp_path / "base.npz")
    held, _ = make_record(4, hours=HOURS, logged=("ambient",), truth=_truth())
    want = _with_faults(held, "all")
    other = save(held, tmp_path / "weekend_faulty.npz")
    ex = explain_file(open_record(base), ExplainOptions(channels=("x",)),
                      holdout=open_record(other))
    d = ex.to_dict()
    assert d["screened"]["counts"] == {}
    hs = d["holdout_screened"]
    assert hs["record"] == "held-out" and hs["source"].endswith("weekend_faulty.npz")
    assert hs["counts"] == want
    assert set(hs) >= set(d["screened"])
    (drop,) = [s for s in hs["stretches"] if s["kind"] == "dropout"]
    assert drop["end_s"] - drop["start_s"] == pytest.approx(1500.0, abs=2.0)
    assert hs["samples_masked"] > 0
    text = summary(ex)
    lines = text.splitlines()
    (head,) = [ln for ln in lines if ln.startswith("held-out record ")]
    assert "weekend_faulty.npz: screened:" in head
    assert "3 85.0 °C power-on values" in head and "1 dropout (no reading)" in head
    assert "1 start-up glitch" in head and "1 isolated shock" in head
    # the record's own screen line says nothing was masked in the record
    assert any(ln.startswith("screened: nothing masked") for ln in lines)


def test_without_holdout_there_is_no_held_out_screen(tmp_path):
    """The record's own halves: no held-out record, so ``holdout_screened`` is null and the
    text has no held-out screen line."""
    rec, _ = make_record(3, hours=HOURS, logged=("ambient",), truth=_truth())
    ex = explain_file(open_record(save(rec, tmp_path / "base.npz")),
                      ExplainOptions(channels=("x",)))
    assert ex.to_dict()["holdout_screened"] is None
    assert not any(ln.startswith("held-out record ") for ln in summary(ex).splitlines())


def test_a_held_out_log_refused_as_fahrenheit_predicts_nothing(tmp_path):
    """A held-out record whose log is in °F (its readings on a DS18B20's °F grid) is refused
    by the same units rule as the record's log (``--temperature-units`` auto): the held-out
    test of the coupling says why it could not run, instead of a gain measured on °F read as
    °C (−1.6e4); ``--temperature-units F`` is not asked, so nothing is converted."""
    rec, _ = make_record(3, hours=HOURS, logged=("ambient",), truth=_truth())
    base = save(rec, tmp_path / "base.npz")
    held, _ = make_record(4, hours=HOURS, logged=("ambient",), truth=_truth())
    held.temperature_c[:, 0] = held.temperature_c[:, 0] * 1.8 + 32.0
    other = save(held, tmp_path / "held_f.npz")
    ex = explain_file(open_record(base), ExplainOptions(channels=("x",)),
                      holdout=open_record(other))
    assert ex.holdout is not None
    c = ex.holdout.channels["x"]
    assert c.gain is None and c.reason is not None
    assert "held-out record's temperature log ambient is not used" in c.reason
    assert "°F" in c.reason
    assert "ambient" in ex.to_dict()["holdout_screened"]["refused"]
    assert ex.to_dict()["holdout_gain"] is None


def test_a_held_out_log_held_at_each_reading_is_read_as_its_readings(tmp_path):
    """A held-out log written on every sample (each reading held until the next), with the
    weekend's faults in it: the same rule as the record's reads it as its readings (said in
    the held-out screen's notes), and its gain agrees with the same record clean."""
    clean = _explain(tmp_path, 4, None)
    rec, _ = make_record(3, hours=HOURS, logged=("ambient",), truth=_truth())
    base = save(rec, tmp_path / "base.npz")
    held, _ = make_record(4, hours=HOURS, logged=("ambient",), truth=_truth())
    _with_faults(held, "all")
    t = held.temperature_c[:, 0]
    fin = np.isfinite(t)
    last = np.maximum.accumulate(np.where(fin, np.arange(len(t)), 0))
    hold = t[last]
    hold[:int(np.argmax(fin))] = np.nan
    i0 = int(0.4 * len(t))  # the dropout of ``_with_faults``: the logger writes nothing
    hold[i0:i0 + int(1500 * held.rate_hz)] = np.nan
    held.temperature_c[:, 0] = hold
    ex = explain_file(open_record(base), ExplainOptions(channels=("x",)),
                      holdout=open_record(save(held, tmp_path / "held_log.npz")))
    hs = ex.to_dict()["holdout_screened"]
    assert hs["notes"]["ambient"]["kind"] == "held"
    assert hs["counts"]["power_on_85"] == 3 and hs["counts"]["dropout"] == 1
    g_c, *_ = _held(clean)
    g_f, b_f, _e, n_f = _held(ex)
    assert abs(g_f - g_c) <= 2 * math.sqrt(2 * n_f) / b_f, (g_f, g_c)
