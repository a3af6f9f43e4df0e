"""Which logged temperature channel drives an axis (issue 23, item 4: "chosen by held-out
likelihood, not by the in-sample χ²"; chan23c).

With the plate and the ambient both logged, the ambient seen through the plate's own lag is a
second description of a coupling through the plate; ranked by the lag scan's z, explain blamed
the axis on the ambient through a long lag (the adversary's generator: 12 of 19 records; a
`quiet-lab` record: ambient through 3600 s at 3.4× the true coefficient). The channels are now
compared by each one's held-out −2 ln L through its own lag (``holdout.channel_heldout``);
where the record cannot tell them apart, the shorter interior path is reported and the other
named beside it."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.holdout import channel_heldout
from avard.core.explain.options import ExplainOptions
from avard.core.explain.thermal_fit import min_detectable_tempco
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record
from tests.support.hidden import save as save_hidden
from tests.support.weekend import Weekend, make
from tests.support.weekend import save as save_weekend

HOURS, PERIOD, PLATE_TAU = 4.0, 1800.0, 600.0


def _plate_at_lag_0(hours: float = HOURS, rate_hz: float = 10.0) -> tuple[Weekend, float]:
    """The weekend generator with both channels logged, the die and the plate's sensor 30 s
    behind the plate (lag 0 from the plate channel), the coupling on x at 3× its stated
    minimum on that sensor's swing (the benchmark row "two channels, plate at lag 0")."""
    w = 2 * math.pi / PERIOD
    swing = 0.5 / math.hypot(1.0, w * PLATE_TAU) / math.hypot(1.0, w * 30.0)
    c = 3 * min_detectable_tempco(1.6e-4, 2e-5, 2e-6, hours * 3600.0, swing, PERIOD, 0.0)
    base = Weekend(hours=hours, rate_hz=rate_hz, N=1.6e-4, B=2e-5, K=2e-6)
    return replace(base, die_tau_s=30.0, sensor_tau_s=30.0, logged=("plate", "ambient"),
                   coefficient=(c, 0.0, 0.0)), c


def test_the_parts_held_out_deviances_add_up_to_the_channels():
    """The spread the choice reads (``ChannelPath.versus``) is of a true decomposition: each
    held-out half's −2 ln L is the sum of its parts' (the Allan difference sums add, ν ∝
    their count), so a channel's ``parts`` add up to its ``heldout``; and the difference of
    two channels' is the difference of their sums."""
    w, _c = _plate_at_lag_0(hours=2.0, rate_hz=1.0)
    acc, temps, _names, _truth = make(5, w)
    # (a reading every 0.75 s: at 1 Hz one on every sample, no fault)
    assert np.all(np.isfinite(temps))
    got = channel_heldout(acc[:, 0], temps, {0: 0.0, 1: 600.0}, 1.0)
    for ch in got.values():
        assert len(ch.parts) == 10
        assert sum(ch.parts) == pytest.approx(ch.heldout, rel=1e-9)
    d, se = got[0].versus(got[1])
    assert d == pytest.approx(got[0].heldout - got[1].heldout)
    diff = np.subtract(got[0].parts, got[1].parts)
    assert se == pytest.approx(math.sqrt(10 / 9 * np.sum((diff - diff.mean()) ** 2)))


@pytest.mark.parametrize("seed", [90000, 90001])
def test_the_plate_at_lag_0_is_chosen_over_the_room_through_the_plates_lag(tmp_path, seed):
    """A coupling through the plate at 3× its stated minimum with the ambient logged too
    (the room through the plate's 600 s is the die too, up to the die's 30 s and the
    readings' rounding, which the long lag smooths away): claimed on the plate, one lag near
    0, coefficient within 20 %; the evidence compares both channels by the same held-out
    −2 ln L. Ranked by the scan's z (before), seed 90001 went to the ambient (z 24.6 against
    the plate's 23.4) through 804 s at 1.24× the coefficient."""
    w, c = _plate_at_lag_0()
    ex = explain_file(open_record(str(save_weekend(seed, w, tmp_path / "w.npz"))),
                      ExplainOptions(channels=("x",), heldout=False))
    x = ex.channels["x"]
    temp = [f for f in x.claimed if f.cause == "temperature"]
    assert len(temp) == 1
    f = temp[0]
    assert f.channel == "plate" and f.mechanism == "one_lag"
    assert abs(f.params["lag_s"]) <= 30.0
    assert f.params["coefficient"] == pytest.approx(c, rel=0.2)
    th = x.thermal
    assert th is not None
    for name in ("plate", "ambient"):
        row = th.channel_choice if name == th.channel else th.others[name]
        assert math.isfinite(row["heldout"]) and math.isfinite(row["scan_z"])
        assert f"'{name}'" in f.evidence
    assert "held-out −2 ln L" in f.evidence


def test_an_open_ambient_is_not_preferred_over_an_interior_plate(tmp_path):
    """The plate drives through 120 s (2e-3 m/s²/K, 4 h): the ambient's best lag is the
    longest tried (3600 s, open), which a channel with an interior optimum must beat by
    ``OPEN_END_MARGIN`` in held-out −2 ln L; the plate is chosen, its lag within 20 %."""
    rec, _ = make_record(11, truth=Truth(coefficient=(2e-3, 0.0, 0.0), lag_s=120.0,
                                         drive="plate"), hours=4.0)
    path = save_hidden(rec, tmp_path / "h.npz")
    th = explain_file(open_record(str(path)),
                      ExplainOptions(channels=("x",), heldout=False)).channels["x"].thermal
    assert th is not None and th.passed
    assert th.others["ambient"]["open"] == 1.0 and th.channel_choice["open"] == 0.0
    assert th.channel == "plate"
    assert th.lag_s == pytest.approx(120.0, rel=0.2)
    assert th.coefficient == pytest.approx(2e-3, rel=0.2)


def test_quiet_lab_blames_the_plate_not_the_ambient_through_the_end_of_the_grid(tmp_path):
    """The issue's own example: a 4 h `quiet-lab` record (seed 1), the die the plate through
    60 s at 1.96e-4 m/s²/K on x. Before, x was blamed on the ambient through 3600 s (the end of
    the lag grid, not flagged) at 6.7e-4. Now the plate is reported with its coefficient
    within 20 %, an interior lag, and the ambient named beside it when the held-out halves do
    not tell them apart."""
    rec = tmp_path / "ql.npz"
    subprocess.run([sys.executable, "-m", "avard.daemon.cli", "simulate", "--preset",
                    "quiet-lab", "--hours", "4", "--seed", "1", "--out", str(rec)],
                   capture_output=True, text=True, check=True, timeout=600)
    th = explain_file(open_record(str(rec)),
                      ExplainOptions(channels=("x",), heldout=False)).channels["x"].thermal
    assert th is not None and th.passed
    assert th.channel == "plate"
    assert th.coefficient == pytest.approx(1.96133e-4, rel=0.2)
    assert not th.lag_open and 0.0 < th.lag_s < 300.0
    if th.channel_note:
        assert "'ambient'" in th.channel_note


def test_the_room_through_its_own_lag_stays_the_ambient(tmp_path):
    """The converse: the die follows the room through 300 s (2e-3 m/s²/K) and the plate is
    the room through 600 s, so the plate describes the die only through a lead (exactly:
    die = plate·(1 + 600s)/(1 + 300s), ``lag_filter``'s lead-lag of −300 s), and predicts
    the held-out halves worse mostly by its readings' rounding, which the lead amplifies.
    Where the record does not tell them apart, the nearer path along the heat's flow is the
    ambient's 300 s, not the plate's lead (``path_distance``: 3|L|); the ambient is
    reported with its lag, and a tie, if said, names the plate."""
    rec, _ = make_record(11, truth=Truth(coefficient=(2e-3, 0.0, 0.0), lag_s=300.0,
                                         drive="ambient"), hours=4.0)
    path = save_hidden(rec, Path(tmp_path) / "h.npz")
    th = explain_file(open_record(str(path)),
                      ExplainOptions(channels=("x",), heldout=False)).channels["x"].thermal
    assert th is not None and th.passed and th.channel == "ambient"
    assert th.lag_s == pytest.approx(300.0, rel=0.2)
    assert th.coefficient == pytest.approx(2e-3, rel=0.2)
    assert not th.channel_note or "'plate'" in th.channel_note


def test_a_channel_that_never_moves_is_compared_without_a_traceback():
    """Two channels, one of them constant (a sensor stuck from the start): its readings have
    no rounding sawtooth to model, and the choice keeps the channel that moves."""
    from avard.core.explain.thermal_fit import fit_thermal_axes

    rng = np.random.default_rng(4)
    rate, n = 1.0, 4 * 3600
    t = np.arange(n) / rate
    room = 21.0 + 0.6 * np.sin(2 * math.pi * t / 1800.0)
    y = 3e-3 * (room - 21.0) + 2e-4 * rng.standard_normal(n)
    temps = np.column_stack([np.round(room / 0.0625) * 0.0625, np.full(n, 21.0)])
    (th,) = fit_thermal_axes(y[:, None], temps, ["plate", "stuck"], rate)
    assert th is not None and th.channel == "plate" and th.passed


def test_a_channel_below_its_own_rounding_at_every_tau_cannot_drive(tmp_path):
    """The adversary's compound record 305 (4 h): its plate log barely moves, so the
    readings never stand above their rounding (the rounding floor is infinite) and both
    channels' held-out scores are 0. The tie went to the plate by its path distance and the
    coupling test then had no τ to start from (an OverflowError, a traceback); a channel
    with no τ to regress on is no candidate. (Since chan23g the floor is the first octave
    above the rounding, not the first of two in a row: this plate's 1800 s cycle of about
    one step stands 20× above it at 655 s alone, so it has a τ and may drive; the record
    holds no coupling, and none is claimed. A channel with no τ at all:
    ``test_a_channel_that_never_moves_is_compared_without_a_traceback``.)"""
    from tests.support.adversary_gen import make_record as adversary

    rec = tmp_path / "c305.npz"
    adversary("compound", 305, rec, 4.0)
    ex = explain_file(open_record(str(rec)), ExplainOptions(heldout=False))
    assert "warmup" in {f.cause for f in ex.channels["x"].claimed}
    for ch in ex.channels.values():
        assert "temperature" not in {f.cause for f in ch.claimed}


def test_the_channels_held_out_regressors_are_built_once_for_every_axis(monkeypatch):
    """``channel_heldout``'s ``columns`` (chan23g): the regressors of a channel at one lag,
    built for one axis, are read by the next axis scored at that lag, and give the same
    held-out −2 ln L as built afresh; ``fit_thermal_axes`` hands one cache to every axis it
    picks a channel for."""
    import avard.core.explain.holdout as ho
    from avard.core.explain.thermal_fit import fit_thermal_axes
    from avard.core.explain.thermal_paths import columns as tp_columns

    w, _c = _plate_at_lag_0(hours=2.0, rate_hz=1.0)
    acc, temps, names, _truth = make(5, w)
    lags = {0: 0.0, 1: 600.0}
    fresh = [channel_heldout(acc[:, a], temps, lags, 1.0) for a in range(2)]
    built = []
    real = tp_columns.path_columns

    def counting(T, cols, rate_hz, done=None):
        built.append(sum(c not in (done or {}) for c in cols))
        return real(T, cols, rate_hz, done)

    monkeypatch.setattr(tp_columns, "path_columns", counting)
    cache: dict = {}
    cached = [channel_heldout(acc[:, a], temps, lags, 1.0, columns=cache) for a in range(2)]
    assert sum(built[:2]) > 0 and sum(built[2:]) == 0  # the second axis builds nothing
    for a in range(2):
        for j in lags:
            assert cached[a][j].heldout == pytest.approx(fresh[a][j].heldout, rel=1e-12)
    seen = []
    real_ch = ho.channel_heldout

    def spy(*args, **kw):
        seen.append(kw.get("columns", args[6] if len(args) > 6 else None))
        return real_ch(*args, **kw)

    monkeypatch.setattr(ho, "channel_heldout", spy)
    fit_thermal_axes(acc[:, :2], temps, list(names), 1.0)
    assert len(seen) == 2 and seen[0] is not None and seen[0] is seen[1]
