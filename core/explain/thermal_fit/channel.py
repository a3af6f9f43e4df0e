"""The choice between temperature channels (``path_distance``, the channel margin)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan.beta import t_two_sided
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.explain.thermal_paths.columns import Column
from avard.core.explain.thermal_fit.holes import Holes
from avard.core.explain.thermal_fit.lag import best_lag
from avard.core.explain.thermal_fit.scan import OPEN_END_MARGIN, ScanPoint

#: How much lower a channel's held-out −2 ln L (``holdout.channel_heldout``) must be for it
#: to drive an axis rather than another channel: at least the margin ``thermal_paths`` asks
#: of a path over one lag (``HELDOUT_MARGIN``) ...
CHANNEL_MARGIN = 6.0
#: ... or this many standard errors of the difference, from its spread over the record's
#: parts (``holdout.ChannelPath.versus``): two channels that both describe the path differ
#: in held-out −2 ln L by the record's noise on a scale that grows with the coupling, not
#: by the fixed margin a nested model's extra term is held to. Student's t with the parts'
#: 9 degrees of freedom at 5 %, two-sided. To either is added what the readings' 0.0625 K
#: rounding through the worse channel's coupling makes up of its held-out deviance beyond
#: the better one's (``ChannelPath.rounding``): an error of the regressor, not of the path,
#: which a channel seen through a long lag smooths away.
CHANNEL_T = t_two_sided(0.05, 9)


def path_distance(lag_s: float) -> float:
    """How far a channel is from the die along the heat's path, for a lag of either sign: a
    positive lag is the lag itself (the channel upstream of the die); a negative lag −a is
    the lead-lag of a logged sensor 2a and a die a behind one point (``lag_filter``), so the
    path from the channel to the die runs back through that point, 3a long."""
    return lag_s if lag_s >= 0 else 3.0 * abs(lag_s)


def _choose_channel(y: NDArray, temps: NDArray, names: list[str], rate_hz: float,
                    best: dict[int, list[ScanPoint]], holes: Holes | None,
                    floors: dict[int, float] | None,
                    columns: dict[int, dict[Column, NDArray[np.float64]]] | None = None,
                    steps: dict[int, float] | None = None
                    ) -> tuple[int, dict[str, dict[str, float]], str]:
    """The channel that drives axis ``y``, by the held-out likelihood of each channel
    through its own lag (``holdout.channel_heldout``), not by the scan's z: (its index, per
    channel name what was compared, a note when the record does not tell channels apart).

    A channel whose scan's best lag sits at the end of the lags tried (open) pays
    ``OPEN_END_MARGIN`` beside one with an interior optimum. Channels whose held-out −2 ln L
    is within ``max(CHANNEL_MARGIN, CHANNEL_T·se)`` of the best, plus what the readings'
    rounding makes up of it beyond the best's (``ChannelPath.rounding``), describe the axis
    equally:
    the room seen through the plate's long lag is the plate's own path, and on a record
    that holds nothing the plate does not pass on, the two cannot be told apart (a long lag
    also filters the readings' rounding, so the farther channel often predicts a little
    better). Among those the more direct path is reported, by one fixed order, never by
    the record's luck: an interior optimum before an open one, then the channel nearest
    the die along the heat's path (``path_distance``: a longer lag on another channel is
    that path with the lags between them added, and a lag long against the drive's period
    trades with its coefficient, which it leaves unresolved), then the lower held-out
    −2 ln L. ``columns``: per channel, the held-out regressors already built for another axis
    (``holdout.channel_heldout``)."""
    from avard.core.explain.holdout import channel_heldout

    ks = {j: int(np.argmax([s.z for s in sc])) for j, sc in best.items()}
    lags0 = {j: best_lag(sc, ks[j]) for j, sc in best.items()}
    is_open = {j: ks[j] in (0, len(sc) - 1) for j, sc in best.items()}
    interior = not all(is_open.values())
    hp = channel_heldout(y, temps, lags0, rate_hz, floors, holes, columns, steps)
    # a channel whose held-out fit gave no number (NaN) can neither win nor tie
    cost = {j: (hp[j].heldout if math.isfinite(hp[j].heldout) else math.inf)
            + (OPEN_END_MARGIN if is_open[j] and interior else 0.0) for j in best}
    dist = {j: path_distance(lags0[j]) for j in best}
    j0 = min(cost, key=lambda j: (cost[j], dist[j]))
    spread = {j: hp[j].versus(hp[j0])[1] for j in best}
    need = {j: max(CHANNEL_MARGIN, CHANNEL_T * spread[j])
            + max(0.0, hp[j].rounding - hp[j0].rounding) for j in best}
    tied = [j0, *(j for j in best if j != j0 and cost[j] <= cost[j0] + need[j])]
    jb = min(tied, key=lambda j: (is_open[j], dist[j], cost[j]))
    compared = {names[j]: {"heldout": hp[j].heldout, "heldout_lag_s": lags0[j],
                           "heldout_coefficient": hp[j].coefficient,
                           "heldout_margin_vs_best": need[j],
                           "heldout_rounding": hp[j].rounding, "scan_z": best[j][ks[j]].z,
                           "open": float(is_open[j])}
                for j in best}
    note = ""
    if len(tied) > 1:
        others = [j for j in tied if j != jb]
        who = " and ".join(f"'{names[j]}' (through {lags0[j]:.4g} s)" for j in others)
        note = (f"{who} describe{'s' if len(others) == 1 else ''} the axis as well (held-out "
                f"−2 ln L within {max(need[j] for j in tied):.3g} of the best: "
                f"{CHANNEL_MARGIN:g} or {CHANNEL_T:.3g} standard errors of the difference "
                "over the record's parts, and the readings' rounding's share): this record "
                f"cannot tell the channels apart; '{names[jb]}', the more direct path (the "
                "nearest the die, interior), is reported, the other channel being that path "
                "seen through the lags between them, whose coefficient trades with its lag")
    elif jb != max(best, key=lambda j: best[j][ks[j]].z):
        note = (f"'{names[jb]}' predicts the held-out halves better than the channel of "
                "the larger scan z, by more than the margin")
    return jb, compared, note


def _coef_slope(scan: list[ScanPoint], k: int, lo: float, hi: float) -> float:
    """dĉ/dL over the lag's interval [lo, hi]: the least-squares slope of ĉ on the lags in it
    (the neighbours of ``k`` when fewer than three): ĉ jumps with z where a negative lag's
    shortest τ drops an octave, and the neighbours' difference across such a jump, times the
    interval's half-width, made a coefficient ±150 % wide."""
    x = np.array([p.lag for p in scan if lo <= p.lag <= hi])
    if len(x) < 3 or np.ptp(x) <= 0:
        return (scan[k + 1].c - scan[k - 1].c) / (scan[k + 1].lag - scan[k - 1].lag)
    c = np.array([p.c for p in scan if lo <= p.lag <= hi])
    return float(np.polyfit(x, c, 1)[0])
