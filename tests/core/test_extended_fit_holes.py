"""The whole record's extended fit (``engine.channel._explain_channel``) leaves the holes of the log
its claimed thermal cause runs on out of its Allan variance, as the held-out halves do (issue 23
item 1: "a masked stretch is a gap to the estimators … a hole in a log is never a cause on
another channel"). Before, the thermal signal was removed from the whole record, across a
25-minute dropout where it ran on the interpolated temperature, and the compensated Allan
variance counted what that left as the model's misfit: a correct one-lag model was UNEXPLAINED
(in-sample χ²/dof 11–16 on 13 dof) on every such record. Now the hole and the lag's settling
after it are gaps (``engine.thermal._thermal_keep``, ``thermal_fit.hole_mask``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from avard.core.explain.engine.thermal import _thermal_keep
from avard.core.explain.thermal_fit.holes import HOLE_SETTLE_LAGS
from avard.core.explain.verdict import ALPHA
from avard.core.io.screen import Screened, ScreenLog

from tests.core.test_halves_holes import _explain, _record

TRUE_COEF = 3e-3


@pytest.mark.parametrize("seed", [3, 4])
@pytest.mark.parametrize("half", ["first", "second"])
def test_a_dropout_in_the_coupling_log_leaves_a_correct_model_fitting(tmp_path, seed, half):
    """A record with a 25-minute dropout and three 85 °C readings in the log of its coupling:
    the verdict says the extended model fits (in-sample p ≥ the test's level, held out not
    rejected), with the clean twin's claims and a coefficient within 2σ of the truth."""
    clean = _explain(_record(tmp_path, seed, None))
    faulty = _explain(_record(tmp_path, seed, half))
    assert faulty.to_dict()["screened"]["counts"].get("dropout") == 1
    cc, cf = clean.channels["x"], faulty.channels["x"]
    assert [f.cause for f in cf.claimed] == [f.cause for f in cc.claimed] == ["temperature"]
    v = cf.verdict
    assert v is not None and v.tested
    assert v.p_value >= ALPHA, v.line()
    assert v.explained, v.line()
    th = cf.thermal
    assert th is not None and th.passed
    assert abs(th.coefficient - TRUE_COEF) <= 2 * th.coef_se, (th.coefficient, th.coef_se)


class _Th:
    """The parts of a ThermalFit ``_thermal_keep`` reads."""

    def __init__(self, channel: str, lag_s: float) -> None:
        self.channel, self.lag_s, self.path = channel, lag_s, None


def _log(channel: str, start_s: float, end_s: float) -> ScreenLog:
    log = ScreenLog(rate_hz=1.0)
    log.stretches.append(Screened(channel, "dropout", int(start_s), int(end_s), start_s,
                                  end_s, int(end_s - start_s)))
    return log


def test_only_the_claimed_cause_log_holes_and_their_settling_are_gaps():
    """Blocks of a hole in the claimed cause's log and ``HOLE_SETTLE_LAGS`` lags after it are
    left out; a hole in another log, no claimed thermal cause or no screen leaves all in."""
    rate_b, lag = 0.5, 20.0
    keep = _thermal_keep(_Th("ambient", lag), _log("ambient", 100.0, 200.0), 400, rate_b)
    assert keep is not None
    out = np.flatnonzero(~keep)
    settle = math.ceil(HOLE_SETTLE_LAGS * lag * rate_b)
    assert out[0] == 50 and out[-1] == 100 + settle
    assert len(out) == 100 + settle - 50 + 1
    # a negative lag (the logged sensor lagging the die) settles as long
    keep_neg = _thermal_keep(_Th("ambient", -lag), _log("ambient", 100.0, 200.0), 400, rate_b)
    assert keep_neg is not None and np.array_equal(keep_neg, keep)
    assert _thermal_keep(_Th("board", lag), _log("ambient", 100.0, 200.0), 400, rate_b) is None
    assert _thermal_keep(None, _log("ambient", 100.0, 200.0), 400, rate_b) is None
    assert _thermal_keep(_Th("ambient", lag), None, 400, rate_b) is None
    # a single masked reading (under a second) is interpolated exactly enough: no gap
    short = _log("ambient", 100.0, 100.5)
    assert _thermal_keep(_Th("ambient", lag), short, 400, rate_b) is None
