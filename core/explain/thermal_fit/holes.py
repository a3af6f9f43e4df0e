"""Holes in a temperature log: the mask that keeps Allan differences off them and the runs kept
between them."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass


#: Lags after a hole in the temperature log that stay out of the regression (the lag filter
#: still carries the interpolated stretch: e^(−3) ≈ 5 % of it).
HOLE_SETTLE_LAGS = 3.0
#: Holes: per temperature channel, (first, last) slow-view blocks the log says nothing about.
Holes = dict[int, list[tuple[int, int]]]


def near_hole(span: tuple[float, float], hole: tuple[float, float], lag_s: float) -> bool:
    """Whether ``span`` (s) lies in ``hole`` (s, a second or more: across a shorter one the
    interpolation is exact enough) or within ``HOLE_SETTLE_LAGS`` lags after it, with a
    second's slack either side: where the removed thermal signal is made of interpolated
    temperature."""
    h0, h1 = hole
    return (h1 - h0 >= 1.0 and span[0] <= h1 + HOLE_SETTLE_LAGS * abs(lag_s) + 1.0
            and span[1] >= h0 - 1.0)


def hole_mask(n: int, holes: list[tuple[int, int]], lag_s: float, rate_hz: float
              ) -> NDArray[np.bool_] | None:
    """Blocks kept by the regression (None: all): each hole and ``HOLE_SETTLE_LAGS`` lags
    after it are left out, so the interpolation across a hole is never taken for the axis's
    response (a 25-minute dropout put the lag at +34…47 s against a true 0)."""
    if not holes:
        return None
    keep = np.ones(n, dtype=bool)
    settle = math.ceil(HOLE_SETTLE_LAGS * abs(lag_s) * rate_hz)
    for a, b in holes:
        keep[max(0, a):min(n, b + 1 + settle)] = False
    return keep


def feed(sa: StreamingAllan, X: NDArray, keep: NDArray[np.bool_] | None) -> None:
    """``sa.update`` with the rows of ``X`` where ``keep`` is False left out as gaps (no Allan
    difference spans them)."""
    if keep is None:
        sa.update(X)
        return
    m = np.concatenate([[False], keep, [False]]).astype(np.int8)
    d = np.diff(m)
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        sa.update(X[a:b])
        sa.gap()


def kept_runs(n: int, keep: NDArray[np.bool_] | None) -> list[tuple[int, int]]:
    """(start, end) of the runs of rows ``keep`` holds (all rows when None): the segments
    ``feed`` gives the accumulator."""
    if keep is None:
        return [(0, n)]
    m = np.concatenate([[False], keep, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                    strict=True))
