"""A thermal path whose extension is the whole claim is tested beside the transients the axis
holds (docs/log/2026-11-28-paths24h.md; ``engine._beside_transients``): on a 1 h record with
nothing coupled, a relay's few switches can take a warm-up and a bias step."""

from __future__ import annotations

import pytest
from avard.core.explain.causes import min_detectable_step, min_detectable_warmup
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.transients.minima import min_detectable_excursion
from avard.core.io.source import open_record

from tests.support.weekend import Weekend, save

N, B, K = 1.6e-4, 2e-5, 2e-6


def _compound_1h() -> Weekend:
    """The weekend benchmark's "compound 1 h" row: on x a warm-up (T 300 s), two bias steps
    of one sign (at 30 and 80 % of the record) and an excursion (450 s, in the middle), each
    at 3× its stated minimum; x couples nothing (the HVAC's 30-minute cycle is logged)."""
    rec = 3600.0
    tw, dur = rec / 12, rec / 8
    w = 3 * min_detectable_warmup(N, B, K, tw)
    st = 3 * min_detectable_step(N, B, K, rec)
    ex = 3 * min_detectable_excursion(N, B, K, rec, dur)
    t0 = 0.5 * rec - dur / 2
    return Weekend(hours=1.0, rate_hz=10.0, N=N, B=B, K=K, warmups=[(w, tw)],
                   steps=[(0.3 * rec, st), (0.8 * rec, st)], excursions=[(t0, t0 + dur, ex)])


@pytest.mark.parametrize("seed", [23504, 23510, 23534])
def test_a_relay_is_not_claimed_where_it_takes_the_transients_of_an_uncoupled_axis(
        tmp_path, seed):
    """Seeds of that row where, on main, x (coupling nothing) claimed a temperature coupling
    with a hysteresis relay (coefficient −2 to −4e-4 m/s²/K, width 0.02–0.1 K, a lead of
    65–165 s): the one lag failed its own test, and the relay's two or three switches on 1 h
    took the warm-up and the first step (on 23510 nothing else was claimed). With the
    transients the compound search finds beside every candidate, no extension passes: no
    temperature claim, and the warm-up and both steps are claimed as what they are."""
    path = save(seed, _compound_1h(), tmp_path / "w.npz")
    ex = explain_file(open_record(str(path)), ExplainOptions(heldout=False))
    x = ex.channels["x"]
    causes = [f.cause for f in x.claimed]
    assert "temperature" not in causes
    assert causes.count("warmup") == 1
    assert causes.count("bias_step") == 2


def test_a_true_relay_is_kept_beside_the_excursion_its_own_switches_make(tmp_path):
    """The adversary's hysteresis 415 (plate only, tests/support/adversary_gen.py): the one
    lag fails its own test (a lag of 648 s for a coupling at 0 s), the relay is chosen, and
    the compound search on the axis as recorded reads one of the relay's half-cycles as an
    excursion (−2.2e-4 m/s², 863 s). Beside it the relay still predicts the held-out halves
    better than one lag and than the excursion alone by far more than the margin, so it is
    kept (a test that asked the relay's extra-term z again beside that excursion dropped it
    under its threshold, and the excursion was then claimed in its place)."""
    from tests.support.adversary_gen import make_record

    path = tmp_path / "hysteresis415.npz"
    make_record("hysteresis", 415, path, logged=("plate",))
    ex = explain_file(open_record(str(path)), ExplainOptions(channels=("x",)))
    x = ex.channels["x"]
    th = [f for f in x.claimed if f.cause == "temperature"]
    assert th and x.thermal is not None and x.thermal.mechanism == "hysteresis"
    assert not [f for f in x.claimed if f.cause == "excursion"]
