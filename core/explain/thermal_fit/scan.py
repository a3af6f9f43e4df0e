"""The lag scan on a grid of lags (``ScanPoint``, the grid of either sign, the refinement between
its points)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.holes import hole_mask
from avard.core.explain.thermal_fit.octaves import tempco_from_cov
from avard.core.explain.thermal_fit.settings import JACKKNIFE_GROUPS
from avard.core.explain.thermal_fit.signals import lag_filter, without_start
from avard.core.explain.thermal_fit.sums import (
    CovView,
    axes_differences,
    cov_view,
    lag_octave_sums,
    min_tau_for,
    octave_sums,
    octave_sums_by_part,
)

#: The longest negative lag tried (s): a DS18B20 in its TO-92 package on a plate lags the die
#: by its own thermal time constant, tens of seconds to a few minutes, never hours.
NEG_LAG_MAX_S = 1800.0
#: How much larger z² a channel whose best lag is at the end of the search (open) must reach
#: to be preferred over one with an interior optimum (Δ(−2 ln L) = Δz²: 9 is 3 σ).
OPEN_END_MARGIN = 9.0


def _lag_grid(record_s: float, rate_hz: float) -> NDArray[np.float64]:
    """Lags tried: negative (the logged sensor lags the die) from −``NEG_LAG_MAX_S`` (at most
    record/16), 0, and positive to record/4, log-spaced either side."""
    lo = max(4.0 / rate_hz, 4.0)
    hi = max(record_s / 4.0, 2 * lo)
    neg_hi = min(NEG_LAG_MAX_S, record_s / 16.0)
    neg = -np.geomspace(neg_hi, lo, 12) if neg_hi > 2 * lo else np.zeros(0)
    return np.concatenate([neg, [0.0], np.geomspace(lo, hi, 28)])


def _between(a: float, b: float) -> float:
    """The point between two neighbouring lags of the grid (geometric on one side of 0,
    arithmetic across it)."""
    return math.copysign(math.sqrt(a * b), a) if a * b > 0 else 0.5 * (a + b)


class ScanPoint(NamedTuple):
    """One trial lag of one axis: (lag s, ĉ, analytic se, z), and ``zg`` (G,) the z with
    each of the record's ``JACKKNIFE_GROUPS`` contiguous parts left out in turn (the lag's
    jackknife)."""

    lag: float
    c: float
    se: float
    z: float
    zg: NDArray[np.float64]


def _z(view: CovView, mt: float) -> tuple[float, float, float]:
    c, se, _n = tempco_from_cov(view, mt)
    return c, se, (abs(c) / se if se > 0 and math.isfinite(se) else 0.0)


def _scan(Y: NDArray, T: NDArray, lags: Any, rate_hz: float,
          holes: list[tuple[int, int]] | None = None, ref: Any | None = None,
          floor_s: float = 0.0, parts: bool = False) -> list[list[ScanPoint]]:
    """Per axis, a ``ScanPoint`` for every lag: one set of Allan difference sums of
    (axes…, lagged T) per lag serves all axes (``octave_sums``: the covariance alone; the
    axes' EDF, which does not depend on the lag, from ``ref``, their Allan result, computed
    once), and with ``parts`` one per contiguous part for the lag's jackknife; ``holes``
    (blocks at this rate) and their settling left out; τ from ``min_tau_for(lag, floor_s)``."""
    C = Y.shape[1]
    if ref is None:
        ref = _axes_reference(Y, rate_hz)
    edf = np.asarray(ref.edf, dtype=float).reshape(len(ref.tau), -1)
    n_ref = np.asarray(ref.n, dtype=float)
    edges = np.linspace(0, len(Y), JACKKNIFE_GROUPS + 1).astype(int)
    out: list[list[ScanPoint]] = [[] for _ in range(C)]
    # without holes the axes' differences are the same at every lag: taken once
    axes = None if holes else axes_differences(
        Y, edges if parts else np.array([0, len(Y)]))
    for L in lags:
        u = lag_filter(T, float(L), rate_hz)
        if axes is not None:
            got = lag_octave_sums(axes, u, float(L), rate_hz)
            pieces = got if parts else []
            whole = sum(got[1:], start=got[0]) if parts else got[0]
        else:
            X = without_start(np.column_stack([Y, u]), float(L), rate_hz)
            keep = hole_mask(len(Y), holes or [], float(L), rate_hz)
            # with parts, the whole record's sums are theirs added up (every difference
            # goes to one part): one pass over the record, not two
            pieces = octave_sums_by_part(X, edges, keep) if parts else []
            whole = sum(pieces[1:], start=pieces[0]) if pieces else octave_sums(X, keep)
        sums = whole
        mt = min_tau_for(float(L), floor_s)
        # the leave-one-out sums once per lag, for every axis (their covariance is cached)
        rests = [whole - ps for ps in pieces]
        for j in range(C):
            c, se, z = _z(cov_view(sums, rate_hz, edf[:, j], n_ref, (j, C)), mt)
            zg = np.array([_z(cov_view(rest, rate_hz, edf[:, j], n_ref, (j, C)), mt)[2]
                           for rest in rests])
            out[j].append(ScanPoint(float(L), c, se, z, zg))
    return out


def _merge(a: list[ScanPoint], b: list[ScanPoint]) -> list[ScanPoint]:
    """Two scans of one axis as one, sorted by lag, each lag once (a refinement's end points
    are grid points: counted twice they made the lag's interval end at the estimate)."""
    return sorted({p.lag: p for p in [*a, *b]}.values(), key=lambda p: p.lag)


def _refine(lags: list[float], best: float, n: int) -> list[float]:
    """``n`` lags between the neighbours of ``best`` in the sorted ``lags`` (geometric on
    one side of 0, linear across it)."""
    i = lags.index(best)
    if i == 0 or i == len(lags) - 1:
        return []
    a, b = lags[i - 1], lags[i + 1]
    if a * b > 0:
        return (math.copysign(1.0, a) * np.geomspace(abs(a), abs(b), n)).tolist()
    return np.linspace(a, b, n).tolist()


def _axes_reference(Y: NDArray, rate_hz: float) -> Any:
    """The axes' Allan result (analyze's estimator, its EDF) that the lag scan's regressions
    weight by."""
    sa = StreamingAllan(Y.shape[1], rate_hz)
    sa.update(Y)
    return sa.result()
