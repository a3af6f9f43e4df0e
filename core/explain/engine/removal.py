"""Claimed signals taken out of an axis: the Allan variance left and its covariance."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from avard.core.explain import causes as cz
from avard.core.explain.thermal_fit import (
    ThermalFit,
    compensated_avar,
)
from avard.core.explain.thermal_fit.holes import feed
from avard.core.model.fit import NoiseFit
from numpy.typing import NDArray


def _noise_levels(fit: NoiseFit) -> dict[str, float]:
    """N, B, K for the time-domain GLS of the transients (their covariance and their floor):
    a term the fit calls present at its value, an absent one at its upper limit (0 when it
    has none). Absent means the data cannot show the term, not that it is zero; a covariance
    without it pretends the noise is whiter than the data allow. With K read as 0 where the
    fit left it out (26 of 150 axes of warm-up + step records at 3× their minima), the
    warm-up size's 68 % interval held the truth on 6 of those 26 (82 of the other 124);
    the upper limit is the largest K the data allow, so there the intervals err wide."""
    out = {}
    for key, term in (("N", "velocity_random_walk"), ("B", "bias_instability"),
                      ("K", "rate_random_walk")):
        t = fit.terms.get(term)
        v = None if t is None else (t.value if t.present else t.upper)
        out[key] = float(v) if v is not None and math.isfinite(v) else 0.0
    return out


def _thermal_signal(thermal: ThermalFit, temps: NDArray, y: NDArray, rate_b: float,
                    settled: NDArray | None = None) -> tuple[NDArray[np.float64], bool]:
    """The thermal signal to remove, and whether it includes the fitted start state. The lag
    filter's start state is unknown: a start-up settling with the lag's own time constant is
    part of the thermal model (fitted). When a warm-up still shows after that, it is a cause
    of its own: the start state is then not fitted, so the warm-up test sees the transient
    whole. ``settled``: a warm-up found beyond the start state (``_thermal_fits``), taken out
    of ``y`` before the start state is fitted, which would otherwise take it over."""
    if thermal.lag_s == 0:
        return thermal.signal(temps), False
    if settled is not None:
        # the start state and a warm-up found beyond it trade with each other (fitted on the
        # axis less the warm-up's first estimate, β took the estimate's error and the claim
        # kept it: T 650 s for 900 on 3 of 6 records); the warm-up is fitted whole
        return thermal.signal(temps), False
    with_start = thermal.signal(temps, y)
    if cz.detect_warmup(y - with_start, rate_b).passed:
        return thermal.signal(temps), False
    return with_start, True


def _signal_variations(thermal: ThermalFit | None, temps: NDArray | None, y: NDArray,
                       with_start: bool, cands: list[cz.Candidate], rate_b: float
                       ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """For each uncertain parameter of the removed signals, the change of the removed signal
    when that parameter moves one standard error up and down (68 % half-widths): the thermal
    coefficient and lag, each transient's size and time constant or time."""
    out: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    if thermal is not None and temps is not None and thermal.passed:
        base = thermal.signal(temps, y if with_start else None)
        moves = [("coefficient", thermal.coef_se)]
        if math.isfinite(thermal.lag_hi) and thermal.lag_hi > thermal.lag_lo:
            moves.append(("lag_s", 0.5 * (thermal.lag_hi - thermal.lag_lo)))
        for key, se in moves:
            if not (math.isfinite(se) and se > 0):
                continue
            v = getattr(thermal, key)
            # either sign: a coefficient may be negative, a lag negative (the logged sensor
            # lagging the die)
            sig = [replace(thermal, **{key: v + sgn * se}).signal(
                temps, y if with_start else None) - base for sgn in (1, -1)]
            out.append((sig[0], sig[1]))
    for c in cands:
        base = cz.cause_signal(c, len(y), rate_b)
        for key, (lo, hi) in c.intervals.items():
            se = 0.5 * (hi - lo)
            if key not in c.params or not (math.isfinite(se) and se > 0):
                continue
            sig = [cz.cause_signal(replace(c, params={**c.params, key: c.params[key] + sgn * se}),
                                   len(y), rate_b) - base for sgn in (1, -1)]
            out.append((sig[0], sig[1]))
    return out


def removed_avar(var: NDArray, tau: NDArray, y: NDArray, d: NDArray, rate_b: float,
                 keep: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """``var`` (the axis's AVAR at ``tau``) with the signal ``d`` removed from the slow view
    ``y`` (``compensated_avar`` at coefficient 1), from the Allan covariance of (y, d) alone:
    ``StreamingAllan.covariance``, ``thermal_fit.allan2``'s τ and covariance to the bit
    without the noise identification and EDF it computes and this never reads (an Allan
    pass per removed signal: every transient tried, every parameter moved). ``keep``: the
    blocks the covariance reads (None: all); the others are gaps (``thermal_fit.feed``), so
    ``var`` is scaled by what the removal takes off where ``d`` is known."""
    sa = StreamingAllan(2, rate_b)
    feed(sa, np.column_stack([y, d]), keep)
    return compensated_avar(var, tau, sa.covariance(), 1.0)


def removal_covariance(var: NDArray, tau: NDArray, y: NDArray, total: NDArray, rate_b: float,
                       variations: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
                       keep: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """Covariance of the compensated AVAR at ``tau`` that the removed signal's parameters
    carry, by the delta method: for each parameter, J = [AVAR_c(θ + s) − AVAR_c(θ − s)]/2 (s
    its standard error; the central difference is exact for the thermal coefficient, on which
    the compensated AVAR is quadratic), summed as Σ J Jᵀ with the parameters taken
    independent. ``fit_noise(added_cov=…)`` adds it to the noise model's covariance, so the
    extended fit's intervals carry the uncertainty of what was removed."""
    k = len(tau)
    cov = np.zeros((k, k))
    for up, down in variations:
        hi = removed_avar(var, tau, y, total + up, rate_b, keep)
        lo = removed_avar(var, tau, y, total + down, rate_b, keep)
        j = np.where(np.isfinite(hi - lo), 0.5 * (hi - lo), 0.0)
        cov += np.outer(j, j)
    return cov
