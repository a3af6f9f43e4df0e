"""The z an extension's extra term is held to (``thermal_paths.z_thresholds``): the search's
Bonferroni over every grid point of every extension where the extension would be the axis's
whole claim; one test at the paths' share where the one lag passed its own test, since the
temperature claim is then made at the temperature's share and the extension changes only
the mechanism (docs/log/2026-11-28-cand25.md)."""

from __future__ import annotations

import pytest
from avard.core.allan.beta import t_two_sided
from avard.core.explain import alarm
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.thermal_paths import LEAN_MARGIN, LEAN_T, PARTS, z_thresholds
from avard.core.io.source import open_record

from tests.support.adversary_gen import make_record as adversary_record


def test_the_search_threshold_stays_where_the_extension_is_the_whole_claim():
    """An axis whose one lag failed its own test: its extension's term is a search over
    every grid point of every extension at the paths' share (10.95 over the 150 grid points
    of a 4 h record); coupled, one test at that share (t₉ at 2.5e-4: 5.83)."""
    search, uncoupled = z_thresholds(150, coupled=False)
    assert uncoupled == search == pytest.approx(
        t_two_sided(alarm.THERMAL_PATHS / 150, PARTS - 1))
    assert search > 10.0
    search_c, coupled = z_thresholds(150, coupled=True)
    assert search_c == search
    assert coupled == pytest.approx(t_two_sided(alarm.THERMAL_PATHS, PARTS - 1))
    assert 5.0 < coupled < 6.5


def _x(tmp_path, kind: str, seed: int):  # type: ignore[no-untyped-def]
    path = tmp_path / f"{kind}{seed}.npz"
    truth = adversary_record(kind, seed, path, logged=("plate",))
    ex = explain_file(open_record(str(path)), ExplainOptions(channels=("x",)))
    return truth["axes"]["x"], ex.channels["x"]


def test_a_dt_term_that_predicts_better_on_a_coupled_axis_is_chosen(tmp_path):
    """dtdt 413 (the adversary's generator, plate logged): the one lag passes its own test,
    and the dT/dt term predicts the held-out halves 13 better than one lag with the same
    nuisance columns (beyond the margin 6), its term at z 6.6. On main the search threshold
    (10.95: the relay's 78 grid points are most of it) kept one lag and only named the term
    beside it; the axis's claim is one lag's either way, so the term is one test at the
    paths' share, and the dT/dt term is chosen with r − c·L near the truth."""
    truth, ch = _x(tmp_path, "dtdt", 413)
    th = [f for f in ch.claimed if f.cause == "temperature"]
    assert th and ch.thermal is not None and ch.thermal.passed
    pf = ch.thermal.path
    assert pf is not None
    assert pf.z_threshold < pf.scores["rate"].z_extra < pf.z_search
    assert pf.scores["rate"].matched < -pf.margin
    assert pf.kind == "rate" and th[0].mechanism == "rate"
    assert pf.params()[0]["rate_coupling"] == pytest.approx(
        truth["r_mps2_per_k_per_s"], rel=0.2)
    d = pf.to_dict()
    assert d["z_threshold"] < d["z_threshold_search"]


@pytest.mark.parametrize("seed", [401, 405])
def test_a_lead_whose_dt_term_passes_any_threshold_stays_one_lag(tmp_path, seed):
    """neglag 401 and 405 (the logged sensor 100 s behind the die: one lag with a lead): the
    dT/dt term's jackknife z is 16–18, past even the search threshold (a lead is a dT/dt
    term at the drive, so against a one-lag truth that z is no centred t), and it predicts
    the held-out halves no better than one lag with the same nuisance columns. What keeps
    one lag is that comparison, whatever threshold the term is held to: one lag with a
    negative lag is chosen, and the dT/dt term is not."""
    _truth, ch = _x(tmp_path, "neglag", seed)
    th = [f for f in ch.claimed if f.cause == "temperature"]
    assert th and ch.thermal is not None and ch.thermal.path is not None
    pf = ch.thermal.path
    assert pf.scores["rate"].z_extra > pf.z_search
    assert pf.scores["rate"].matched > -pf.margin
    assert pf.kind == "one_lag" and th[0].mechanism in (None, "one_lag")
    assert "rate" not in pf.alternatives
    assert th[0].params["lag_s"] < 0


def test_one_lag_kept_beside_a_relay_that_predicts_better_short_of_choosing_has_no_interval(
        tmp_path):
    """hysteresis 405 (the adversary's, plate logged): the relay predicts the held-out halves
    ≈ 4.5 better than one lag (beyond ``LEAN_MARGIN``, short of the margin choosing needs)
    with its term at z ≈ 17: one lag is kept whatever the term's threshold, and its
    coefficient and lag are a linear model's reading of a response no linear path has,
    printed with no interval (``PathFit.leaning``)."""
    _truth, ch = _x(tmp_path, "hysteresis", 405)
    th = [f for f in ch.claimed if f.cause == "temperature"]
    assert th and ch.thermal is not None and ch.thermal.path is not None
    pf = ch.thermal.path
    h = pf.scores["hysteresis"]
    assert -pf.margin < h.matched < -LEAN_MARGIN and h.z_extra >= LEAN_T
    assert pf.kind == "one_lag" and pf.leaning == ("hysteresis",)
    f = th[0]
    assert f.model_dependent and f.intervals == {}
    assert f.intervals_if_model_held and "coefficient" in f.intervals_if_model_held
    assert "one lag kept, but hysteresis" in f.evidence
