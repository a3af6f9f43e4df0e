"""The coefficient's jackknife and analytic standard errors (``coefficient_se``)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.octaves import tempco_from_cov
from avard.core.explain.thermal_fit.settings import DS18B20_CONVERSION_S, JACKKNIFE_GROUPS
from avard.core.explain.thermal_fit.signals import _kept, allan2
from avard.core.explain.thermal_fit.sums import CovView, cov_view, octave_sums_by_part


def jackknife_tempco(y: NDArray, u: NDArray, rate_hz: float,
                     groups: int = JACKKNIFE_GROUPS,
                     min_tau_s: float = 2 * DS18B20_CONVERSION_S,
                     keep: NDArray[np.bool_] | None = None,
                     ref: Any | None = None,
                     weights: tuple[float, ...] = ()) -> tuple[float, float]:
    """(ĉ, se) of the Allan-covariance regression with a delete-a-group jackknife standard
    error: the record in ``groups`` contiguous parts, each its own segment (their difference
    sums add exactly, ``OctaveSums``); ĉ_(−g) from all parts but g;
    se² = (G−1)/G·Σ(ĉ_(−g) − mean)². The analytic se of :func:`tempco_from_cov` treats the
    Allan differences of the noise as independent across a slow regressor, which red noise
    (random walk, flicker at the HVAC period) violates; the jackknife does not assume it.
    ``ref``: the axis's Allan result on the whole record (its EDF, scaled to each
    leave-one-out count; computed here when not given). ``weights``: fixed weights of the
    octaves the whole record's regression uses (``CouplingTest.weights``, in τ order): ĉ
    and each ĉ_(−g) are then that combination of their octaves' Cov_A/AVAR_u, the test's
    statistic, not the inverse-variance one."""
    whole, rest = _jackknife_views(y, u, rate_hz, groups, keep, ref)
    return _jackknife_se(whole, rest, min_tau_s, weights)


def _jackknife_views(y: NDArray, u: NDArray, rate_hz: float, groups: int,
                     keep: NDArray[np.bool_] | None, ref: Any | None
                     ) -> tuple[CovView, list[CovView]]:
    """The whole record's covariance view and each delete-a-part one (one pass over the
    record: ``octave_sums_by_part``), for :func:`jackknife_tempco`."""
    M = len(y)
    X = np.column_stack([y, u])
    if ref is None:
        ref = allan2(y, u, rate_hz, keep)
    edf_ref = np.asarray(ref.edf, dtype=float)
    edf_ref = edf_ref[:, 0] if edf_ref.ndim == 2 else edf_ref
    n_ref = np.asarray(ref.n, dtype=float)
    edges = np.linspace(0, M, groups + 1).astype(int)
    parts = octave_sums_by_part(X, edges, keep)
    full = sum(parts[1:], start=parts[0])
    return (cov_view(full, rate_hz, edf_ref, n_ref),
            [cov_view(full - ps, rate_hz, edf_ref, n_ref) for ps in parts])


def _jackknife_se(whole: CovView, rest: list[CovView], min_tau_s: float,
                  weights: tuple[float, ...] = ()) -> tuple[float, float]:
    """(ĉ, its delete-a-group jackknife se) from :func:`_jackknife_views`, ĉ the
    inverse-variance combination or, with ``weights``, that fixed combination."""
    rows = np.flatnonzero(_kept(whole, min_tau_s))
    fixed = len(weights) == len(rows) and len(rows) > 0

    def one(view: CovView) -> float:
        if not fixed:
            return tempco_from_cov(view, min_tau_s)[0]
        cov = np.asarray(view.cov, dtype=float)[rows]
        with np.errstate(invalid="ignore", divide="ignore"):
            ck = cov[:, 0, 1] / cov[:, 1, 1]
        ok = np.isfinite(ck)
        w = np.asarray(weights, dtype=float)[ok]
        return float(w @ ck[ok] / np.sum(w)) if np.sum(w) > 0 else math.nan

    c_all = one(whole)
    c = np.asarray([one(v) for v in rest])
    if not np.all(np.isfinite(c)):
        return c_all, math.inf
    g = len(rest)
    return c_all, math.sqrt((g - 1) / g * float(np.sum((c - c.mean()) ** 2)))


def coefficient_se(se_jk: float, se_analytic: float) -> float:
    """The standard error of ĉ for its 68 % interval from its two estimates, the
    delete-a-group jackknife ``se_jk`` and the regressor's analytic ``se_analytic``
    (``CouplingTest.se_interval``): the larger.

    The jackknife's parts can be shorter than the noise's correlation at the regressor's
    period (its se then too small), the analytic model can miss a noise. Where both are
    right the larger of the two scattered estimates is above the deviation (by about half
    their spread), but the interval is ± one se on an error whose se is itself estimated,
    and the lag's share (delta method) falls short where the coefficient trades with a long
    lag: the root mean square of the two in its place lowered the coverage on every regime
    of the adversary's generator and further below 68 % where it was short
    (docs/log/2026-11-28-coef26.md). Infinite where either is."""
    return max(se_jk, se_analytic)
