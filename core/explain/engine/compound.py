"""The compound transient search on one axis, beside its thermal coupling and its log's holes."""

from __future__ import annotations

import math
from dataclasses import replace

from avard.core.explain import causes as cz
from avard.core.explain import transients as tr
from avard.core.explain.thermal_fit import (
    ThermalFit,
)
from avard.core.explain.thermal_fit.holes import HOLE_SETTLE_LAGS, near_hole
from avard.core.io.screen import ScreenLog
from numpy.typing import NDArray


def _label(c: cz.Candidate, i: int, cands: list[cz.Candidate]) -> str:
    """The name of a removed signal's AVAR curve: its cause, numbered when the axis has
    several of that cause (two steps: "bias_step 1", "bias_step 2")."""
    same = [j for j, o in enumerate(cands) if o.cause == c.cause]
    return c.cause if len(same) == 1 else f"{c.cause} {same.index(i) + 1}"


def _compound(work: NDArray, rate_b: float, noise_of: tr.NoiseOf, thermal: ThermalFit | None,
              screen: ScreenLog | None, start_span: float = 0.0
              ) -> tuple[list[cz.Candidate], list[cz.Candidate]]:
    """(claimed, not claimed) transients and drift of one axis (:mod:`transients`). Where a
    thermal signal was removed, a transient the logged temperature's rounding can make
    (``causes.transient_floor``), one in a hole of the driving log (``_not_in_hole``), or a
    warm-up the lag filter's fitted start state can make (T within a factor 3 of the lag,
    size within ``start_span``, the removed signal's swing over its first three lags) is not
    claimed, and the others are refitted and tested again without it."""
    found, missed = tr.find_compound(work, rate_b, noise_of)
    if found and thermal is not None and thermal.passed:
        record_s = len(work) / rate_b
        lag = abs(thermal.lag_s)
        checked = []
        for c in found:
            floor, why = cz.transient_floor(c, {}, record_s, _rounding_gain(thermal),
                                            thermal.grid[0])
            T = c.params.get("time_constant_s", math.nan)
            if (c.cause == "warmup" and lag > 0 and lag / 3 <= T <= 3 * lag
                    and abs(c.params["size"]) <= start_span):
                c = replace(c, passed=False, intervals={}, evidence=c.evidence + (
                    f"; not claimed: a settling with the thermal lag's time scale ({lag:.4g} s)"
                    f" and within the swing the removed thermal signal makes over its first "
                    f"three lags ({start_span:.3g} m/s²) is what the lag filter's unknown "
                    "start state can leave"))
            elif abs(c.params["size"]) < floor:
                c = replace(c, passed=False, intervals={}, evidence=c.evidence + (
                    f"; not claimed: size {abs(c.params['size']):.3g} m/s² is below {why}"))
            elif screen is not None:
                c = _not_in_hole(c, screen, thermal, record_s)
            checked.append(c)
        kept = [c for c in checked if c.passed]
        if len(kept) < len(found):
            # the others refitted without it, and tested again in that fit (each claim's
            # statistic and sentence are those of the fit it is reported with)
            found, lost = tr.confirm_compound(work, rate_b, noise_of, kept)
            missed = [c for c in checked if not c.passed] + lost + missed
    drift = tr.test_drift(work, rate_b, noise_of(tr.signal_of(found, len(work), rate_b)),
                          found, noise_of=noise_of)
    return ([*found, drift], missed) if drift.passed else (found, [*missed, drift])


def _rounding_gain(thermal: ThermalFit) -> float:
    """The coefficient through which the logged readings' rounding reaches the residual: ĉ
    times the L1 norm of the path's impulse response, the largest factor it can put on a
    bounded error: 1 for a lag, 3 for a negative lag's lead-lag 2δ − h_lag (a 2× factor, its
    high-frequency gain, left Gauss–Markov claims of 1.02× the floor on 3 of 3 records); for
    a thermal path beyond one lag, the L1 norm of all its linear terms
    (``PathFit.rounding_gain``: a two-path fit's second coefficient counts as much as its
    first)."""
    if thermal.path is not None and thermal.path.kind != "one_lag":
        return thermal.path.rounding_gain()
    return abs(thermal.coefficient) * (3.0 if thermal.lag_s < 0 else 1.0)


def _not_in_hole(c: cz.Candidate, screen: ScreenLog, thermal: ThermalFit,
                 record_s: float) -> cz.Candidate:
    """``c`` unless it is a passed transient inside a hole of the driving temperature log (a
    masked reading, a dropout, a stuck run) or within ``HOLE_SETTLE_LAGS`` lags after it:
    there the removed thermal signal is made of interpolated temperature, and what it leaves
    in the axis is the hole, not a cause of the axis (a 25-minute dropout read as a bias step
    of 4–5e-4 m/s²). Such a transient is not claimed, and says why."""
    span = cz.transient_span(c.cause, c.params) if c.passed else None
    if span is None:
        return c
    for h0, h1 in screen.holes(thermal.channel):
        if near_hole(span, (h0, h1), thermal.lag_s):
            return replace(c, passed=False, intervals={}, evidence=c.evidence + (
                f"; not claimed: it falls in a hole of the temperature log {thermal.channel!r}"
                f" ({h0:.6g}–{h1:.6g} s, or the {HOLE_SETTLE_LAGS:g} lags after it), where "
                "the removed thermal signal is interpolated: a hole in a log is not a cause"))
    return c
