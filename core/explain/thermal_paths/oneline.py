"""Two paths and the dT/dt term on a drive of one line: named beside each other.

At one drive frequency ω a dT/dt term beside one lag, c/(1 + jωL) + jωr, and two paths,
c₁/(1 + jωL₁) + c₂/(1 + jωL₂), each reach any complex gain: the line holds one complex number
and the two readings four parameters and three, so the line cannot tell them apart. Two
paths of opposite sign whose coefficients nearly cancel (``readings._derivative_limit``) are
a static coupling plus a difference of two lags, a derivative of the temperature smoothed
over their lags: the dT/dt term's own reading with a parameter more. What is left to tell
them apart is the record's start and slow wander, and there the held-out comparison weighs
how each *column* is built (the rate column is the derivative of 0.0625 K readings smoothed
over ``RATE_SMOOTH_S``; a difference of two lags smooths over hundreds of seconds and passes
less of that staircase), not a mechanism: on the weekend benchmark's dT/dt record at 3× the
fit's minimum (cand26b) such two paths predicted the held-out halves better than a dT/dt
term of the right size by more than the margin, and the term was not named.

So where the drive is one line (``ONE_LINE_SHARE``), two paths in the dT/dt term's limit are
chosen and the dT/dt term passes every test choosing needs on its own (held out better than
one lag and than no coupling by the margin, or by the margin and ``OPEN_MARGIN`` where its
θ sits at its grid's end, its extra term's z at the search threshold), the term is named
beside them whatever the held-out gap between the two (``PathFit.alternatives``): the
parameters of either are model-dependent, with no interval, and the note says the response
at the drive, which both readings share, with its 68 % interval. Two paths that do not
cancel are a response of their own and keep the margin rule."""

from __future__ import annotations

import math

from avard.core.explain.thermal_paths.readings import _derivative_limit
from avard.core.explain.thermal_paths.scores import PathScore
from avard.core.explain.thermal_paths.settings import ONE_LINE_SHARE


def _rate_on_one_line(best: PathScore, share: float) -> bool:
    """Whether ``best`` (the chosen candidate) is two paths in the dT/dt term's limit on a
    drive of one line (``share``: the channel's variance in its strongest line)."""
    return (best.kind == "two_path" and math.isfinite(share) and share >= ONE_LINE_SHARE
            and _derivative_limit(best))


def _one_line_note(best: PathScore, rate: PathScore, period: float, share: float) -> str:
    """The note naming the dT/dt term beside two paths in its limit on one drive line."""
    c1, c2 = float(best.beta[0]), float(best.beta[1])
    d = rate.heldout - best.heldout
    resp = ""
    if best.drive:
        per, gain, g_lo, g_hi, phi, p_lo, p_hi, _ = best.drive
        resp = (f"; resolved: the response at the drive's {per:.4g} s, gain {gain:.4g} "
                f"m/s²/K [{g_lo:.4g}, {g_hi:.4g}] and phase {phi:+.3g} rad [{p_lo:+.3g}, "
                f"{p_hi:+.3g}] (a lead when positive; 68 %), the same for either reading")
    return (f"two paths or one lag plus a dT/dt term: this record cannot tell them apart "
            f"(the drive is one line, {share:.0%} of the channel's variance at {period:.4g} s, "
            f"and the two paths, {c1:.3g} and {c2:.3g} m/s²/K through {best.theta[0]:.4g} and "
            f"{best.theta[1]:.4g} s, nearly cancel: a static coupling and a smoothed "
            f"derivative, the dT/dt term's reading with a parameter more; the dT/dt term "
            f"passes every test choosing needs and predicts the held-out halves "
            f"{'worse' if d > 0 else 'better'} by {abs(d):.3g}, which on one line weighs how "
            f"the two columns smooth the readings, not a mechanism); parameters "
            f"model-dependent, no interval" + resp)
