"""Start-up glitches and isolated shocks in the acceleration: each sample against its neighbours'
running median, on a scale the block's own fast noise (or its LSB grid) sets."""

from __future__ import annotations

import math

import numpy as np
from avard.core.allan import kernels
from numpy.typing import NDArray

#: Robust σ of the sample scale an acceleration outlier must exceed.
SHOCK_Z = 12.0
#: Half-window of the running median (samples): stretches up to this long stand out.
SHOCK_HALF = 8
#: Samples around an outlier that go with it (and that join two outliers into one stretch).
SHOCK_MARGIN = 2
#: Seconds after a record's start where an outlier is a start-up glitch.
STARTUP_S = 1.0


# --------------------------------------------------------------------------------------------
# acceleration


def _running_median(a: NDArray[np.float64], idx: NDArray[np.intp], half: int
                    ) -> NDArray[np.float64]:
    """Median of a[i − half … i + half] (clipped to the array) at the indices ``idx``."""
    out = np.empty(len(idx))
    for k, i in enumerate(idx):
        out[k] = np.median(a[max(0, i - half):i + half + 1])
    return out


def _local_residual(col: NDArray[np.float64], half: int) -> NDArray[np.float64]:
    """col minus the mean of its 2·half + 1 neighbours (reflected at the ends, so a glitch in
    the first samples still stands out), by one cumulative sum: the high-pass statistic whose
    robust spread scales the outlier test."""
    x = np.pad(col - col[0], half, mode="reflect")
    c = np.empty(len(x) + 1)
    c[0] = 0.0
    np.cumsum(x, out=c[1:])
    w = 2 * half + 1
    return np.asarray(col - col[0] - (c[w:] - c[:-w]) / w, dtype=float)


#: ``_median_floor``'s guess: this share of the median of every ``FLOOR_STRIDE``-th value, far
#: enough below the median that the count proves it (the guess's spread on a block's 1024
#: values is ~4 %), near enough that a block without outliers stays below the test.
FLOOR_SHARE, FLOOR_STRIDE = 0.85, 16


def _median_floor(x: NDArray[np.float64]) -> float:
    """A number proven ≤ ``np.median(x)``, or 0.0 when the cheap guess cannot be proven.

    The guess v is ``FLOOR_SHARE`` of the median of a subsample; it is a floor when at most
    (n − 1) // 2 values lie below it, for then the middle order statistic(s), and their
    mean, are ≥ v. A count and a subsample's median cost a fraction of the median of all
    values (a partition whose time depends on the data: 60–220 µs a block's axis)."""
    n = len(x)
    if n < 2 * FLOOR_STRIDE:
        return 0.0
    v = FLOOR_SHARE * float(np.median(x[::FLOOR_STRIDE]))
    if not v > 0 or int(np.count_nonzero(x < v)) > (n - 1) // 2:
        return 0.0
    return v


#: |N(0, 1)| below its 98th percentile (2.326): the RMS there is this share of σ
#: (√(1 − 2·2.326·φ(2.326)/0.98)); the top 2 % hold any shock and are left out of the RMS.
TRIM_Q, TRIM_RMS = 0.98, 0.9346
#: the quantisation's share of a sample's distance from its 17 neighbours' mean: the grid
#: step q rounds each sample by up to q/2 (RMS q/√12), and that distance keeps 16/17 of it.
GRID_SHARE = math.sqrt(16.0 / 17.0 / 12.0)
#: the trimmed RMS (used where the median collapsed below the quantisation) is capped at this
#: many times the quantisation: it restores the spread of noise of ~1/3 LSB the median lost
#: (≈ 1.3× the quantisation), and no more; a block a third of it in vibration bursts would
#: raise it above a 20 LSB shock
GRID_RMS_CAP = 2.0
#: changes between samples a block's axis needs before its smallest one is taken as its grid
GRID_MIN_CHANGES = 16


def grid_step(col: NDArray[np.float64]) -> float:
    """The column's grid step (its smallest non-zero change between samples, above the
    floating rounding of its values), 0.0 where it changes fewer than ``GRID_MIN_CHANGES``
    times."""
    d = np.abs(np.diff(col))
    tiny = 64.0 * np.finfo(float).eps * float(np.max(np.abs(col))) if len(col) else 0.0
    d = d[d > tiny]
    # a column that changes a few times shows no grid (one shock on a dead axis is no step)
    return float(d.min()) if len(d) >= GRID_MIN_CHANGES else 0.0


def grid_scale(col: NDArray[np.float64], dist: NDArray[np.float64], scale: float) -> float:
    """A floor of the robust scale on a record whose grid is coarse against its noise (the
    grid step above a quarter of ``scale``, or a scale of 0): the grid's own quantisation
    (q/√12, its share in the distance), and, only where the median's ``scale`` is below that
    (a discrete distribution's median collapsed to 0 or a fraction of a step), the distances'
    RMS below their 98th percentile, at most ``GRID_RMS_CAP`` times the quantisation. Not
    above it: where the median stands at or over the
    quantisation it measures the noise, robust to bursts of vibration holding up to half the
    block, which the RMS is not (20–30 % of a block in ±30 LSB bursts raised the RMS above
    a 40–80 LSB shock's distance, and the shock stayed in). On a record finer than its noise,
    0.0 (the median's scale stands)."""
    q = grid_step(col)
    if not q > 0 or (scale > 0 and q < 0.25 * scale):
        return 0.0
    floor = GRID_SHARE * q
    d = dist[np.isfinite(dist)]
    if not len(d) or scale >= floor:
        return floor
    top = float(np.quantile(d, TRIM_Q))
    low = d[d <= top]
    rms = float(np.sqrt(np.mean(low * low))) / TRIM_RMS if len(low) else 0.0
    return min(max(floor, rms), GRID_RMS_CAP * floor)


def screen_accel(a: NDArray[np.float64], held: NDArray[np.bool_] | None = None
                 ) -> NDArray[np.bool_]:
    """Rows of ``a`` (n, C) that are outliers on some axis (the rule in the module's doc),
    with their margin. The scale is the robust spread of the sample's distance from its
    neighbours' mean (the same statistic, so a chip filter's correlated samples, whose first
    differences are small against their spread, are not taken for shocks); the median of the
    neighbours is taken only where that distance already stands out. ``held``: rows cut as
    held acceleration, left out of the scale (their distances are 0: a block half held had
    its scale collapse, and its live samples cut as shocks) and never shocks."""
    n = len(a)
    bad = np.zeros(n, dtype=bool)
    if n < 2 * SHOCK_HALF + 2:
        return bad
    kern = kernels.compiled()
    dist = np.empty(n)
    for j in range(a.shape[1]):
        col = np.asarray(a[:, j], dtype=float)
        if kern is not None:  # the compiled pass (general path: _local_residual)
            kern.local_residual(col, SHOCK_HALF, dist)
        else:
            np.abs(_local_residual(col, SHOCK_HALF), out=dist)
        if held is not None and held.any():
            dist[held] = 0.0
            live = dist[~held]
            if len(live) < 2 * SHOCK_HALF + 2:
                continue
        else:
            live = dist
        # every 4th sample gives the median to a few % on a block (and a quarter the work)
        sub = live[::4]
        low = _median_floor(sub)
        if low > 0 and float(dist.max()) <= 0.5 * SHOCK_Z * (low / 0.6745):
            # no candidate under the exact scale either: it is ≥ low / 0.6745 (division and
            # product by positive constants keep the order), so the block's median, the
            # costliest step of the screen, is taken only where a sample could stand out
            continue
        scale = float(np.median(sub)) / 0.6745
        # a moving window sum leaves a rounding residue where the exact distance is 0: on a
        # record on its LSB grid most samples equal their neighbours' mean, and a scale made
        # of that residue (1e-21 of a 4e-5 m/s² step) cut every step as a shock; below the
        # sum's own rounding the scale is 0, as the exact median is
        if not scale > 4.0 * len(col) * np.finfo(float).eps * float(np.ptp(col)):
            scale = 0.0
        # (a scale of 0: every sample whose distance is not 0 is a candidate)
        cand = np.flatnonzero(dist > 0.5 * SHOCK_Z * scale)
        if not len(cand):
            continue
        # on a coarse grid the median of a few discrete distances is no scale: never below
        # what the grid's quantisation and the distances' own spread support
        scale = max(scale, grid_scale(col, sub, scale))
        if not scale > 0:
            continue
        # an outlier of k ≤ SHOCK_HALF samples stands at least half out of the mean too
        cand = cand[dist[cand] > 0.5 * SHOCK_Z * scale]
        if not len(cand):
            continue
        med = _running_median(col, cand, SHOCK_HALF)
        out = cand[np.abs(col[cand] - med) > SHOCK_Z * scale]
        bad[out] = True
    if bad.any():
        idx = np.flatnonzero(bad)
        for m in range(1, SHOCK_MARGIN + 1):
            bad[np.clip(idx - m, 0, n - 1)] = True
            bad[np.clip(idx + m, 0, n - 1)] = True
    return bad


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """[first, last] of each run of True."""
    if not mask.any():
        return []
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), (np.flatnonzero(d == -1) - 1).tolist(),
                    strict=True))
