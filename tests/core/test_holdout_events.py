"""held29: a claimed event (a step, an excursion, a warm-up) beside a predictive cause is
handled alike on both halves of the held-out comparison (``holdout._signals``,
``_fit_events``, ``_held_events``): where a half holds it, it is neither counted against the
extended model nor for it. Before held29 the half that held a step or an excursion was
predicted with it left in, by a model fitted where it was removed (adv29 D1: the correct
mechanism called rejected, its intervals withheld). Records from
tests/support/adversary_gen4.py (truth known: the extended model is the truth)."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.explain import holdout as ho
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

from tests.support import adversary_gen4 as gen


def _explain(path):
    return explain_file(open_record(path), ExplainOptions(channels=("ch0",))).to_dict()


def _fits_and_keeps_intervals(d, events):
    ch = d["channels"]["ch0"]
    claimed = {f["cause"]: f for f in ch["findings"] if f["claimed"]}
    assert "temperature" in claimed, sorted(claimed)
    assert abs(claimed["temperature"]["params"]["coefficient"] / 1e-3 - 1) < 0.2
    # the event is claimed (as the truth, or as its edges): the case is the one asked for
    assert set(claimed) & events, sorted(claimed)
    v = ch["verdict"]
    assert v["explained"], v["line"]
    assert v["heldout_p"] is not None and v["heldout_p"] >= 0.01, v["line"]
    assert claimed["temperature"]["intervals"], "a correct mechanism lost its intervals"
    assert d["holdout_gain"] is not None and d["holdout_gain"] > 0.5, d["holdout_gain"]


@pytest.mark.parametrize("lo,hi", [(0.35, 0.65), (0.6, 0.85)],
                         ids=["across-the-split", "inside-the-second-half"])
def test_an_excursion_beside_a_coupling_is_not_rejected_by_the_held_out_test(tmp_path, lo, hi):
    arrays, truth = gen.coupling_step(hours=2.0, seed=3, lag_s=120.0, at_frac=lo)
    acc = arrays["accel"]
    acc[int(hi * acc.shape[0]):, 0] -= 4e-4  # back where it was: an excursion lo…hi
    d = _explain(gen.save(tmp_path / "ce.npz", arrays, truth))
    _fits_and_keeps_intervals(d, {"excursion", "bias_step"})


def test_a_warm_up_whose_tail_crosses_the_split_is_not_rejected(tmp_path):
    arrays, truth = gen.coupling_step(hours=2.0, seed=4, lag_s=120.0, step=0.0)
    acc = arrays["accel"]
    t = np.arange(acc.shape[0]) / 10.0
    acc[:, 0] += 6e-4 * np.exp(-t / 1500.0)  # still 5 % of its size at the split
    d = _explain(gen.save(tmp_path / "cw.npz", arrays, truth))
    _fits_and_keeps_intervals(d, {"warmup"})


def _part(y, t0, first, rate):
    return ho.Part(np.asarray(y, float), t0, "p", first, rate)


def test_an_event_in_the_held_out_half_is_cut_from_both_models_and_one_in_the_fit_half_removed():
    """The mechanics, on white noise with two steps: the fit half's step sizes come from the
    fit half (not the whole record's), the held-out half is cut at its own step's edge (both
    models alike) and nothing else of it is touched; a second record (``refit`` False)
    holds none of the record's events."""
    rate = 1.0
    rng = np.random.default_rng(0)
    n = 2048
    y = rng.standard_normal(2 * n) * 1e-4
    y[500:] += 3e-3          # in the first half
    y[n + 700:] += -2e-3     # in the second half
    c = ho.Claims(step_time_s=500.0)
    # the whole record's sizes deliberately wrong: split must not use them
    c.events = [("bias_step", {"time_s": 500.0, "size": 1.0}, {"time_s": [499.0, 501.0]}),
                ("bias_step", {"time_s": n + 700.0, "size": 1.0}, {})]
    A, B = _part(y[:n], 0.0, True, rate), _part(y[n:], float(n), False, rate)
    d_fit, d_held, _s, _l, _sp, w_held, gaps = ho._signals(A, B, c, rate, True, None, None)
    assert abs(np.ptp(d_fit) - 3e-3) < 1e-4          # the first half's own step, its own size
    assert not d_held.any() and not w_held.any()      # no event predicted into the other half
    assert gaps is not None
    cut = np.flatnonzero(~gaps)
    assert cut.min() >= 690 and cut.max() <= 710 and cut.min() <= 700 <= cut.max()
    # the other fold: the second half's step removed from it, the first half cut at 500 ±3σ
    d_fit, d_held, _s, _l, _sp, w_held, gaps = ho._signals(B, A, c, rate, True, None, None)
    assert abs(np.ptp(d_fit) - 2e-3) < 1e-4 and not d_held.any()
    assert gaps is not None and set(np.flatnonzero(~gaps)) == set(range(496, 505))
    # a second record: the fit record's events removed with their own sizes, none cut there
    d_fit, d_held, *_r, w_held, gaps = ho._signals(A, _part(y[n:], 0.0, True, rate), c, rate,
                                                   False, None, None)
    assert gaps is None and not d_held.any()
