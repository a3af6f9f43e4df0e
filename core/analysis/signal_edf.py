"""The printed OADEV's EDF from what the fit knows across τ: the noise's composition, and
the part of the AVAR its resolved deterministic terms hold.

Two things one τ cannot tell and the fit, reading every τ, can (issue 24: the printed
intervals over-cover, up to 90 %, where a sinusoid or a drift dominates):

* **The noise's composition.** With few averages the estimator cannot identify the noise
  type and takes the least EDF of every FM type (``noise_id.physical_alpha_edf``), the
  reddest type's, even where the fitted model says white and flicker noise hold most of
  the AVAR there. ``model_edf`` gives the EDF of the fitted mixture (``edf.edf_mixture``:
  Greenhall–Riley's quadratic form with the sum of the types' covariances of differences,
  which the Cauchy–Schwarz bound ``edf.edf_mixture_bound`` that it replaced took as fully
  correlated), with the composition taken the way that lowers it (each term at θ ± σ, an
  absent one at its upper limit), at the τ where the estimator could not tell the types
  apart (fewer than ``noise_id.SPREAD_LAG1`` averages).
* **A deterministic part.** A rate ramp or a sinusoid adds to the Allan variance without
  scattering: the estimate's variance is the noise part's plus the part's cross term with
  the noise, computed exactly under the fitted spectrum (``cross_term.py``), and for a
  sinusoid the spread of its own OADEV over its phase (``parts_edf``). Only terms the fit
  resolves count (present, with no "ramp or random walk" or "not yet resolved" note: a
  ramp the record cannot tell from a random walk is read as the walk), at their point
  values, the noise part the larger of the fitted noise at θ + σ and what the measured
  AVAR leaves beside the terms at their lower 1σ (``signal_parts``, ``noise_upper``). The
  strided estimators (the cascade) keep the non-central χ²'s ν/(1 − f²)
  (``edf.edf_with_signal``), whose cross term is the largest a Gaussian form allows.
* **A drift the time domain holds** (``analysis/drift.py``). Resolved apart from the AVAR
  (``fit.resolved_apart``), the split of the AVAR between ramp and noise has the fit's own
  uncertainty, and the noise part is its root mean square over it, √(N̂² + Var N̂)
  (``_noise_expected``): the estimate's variance 2N²/ν is an expectation over that split,
  and its value at the split's worst 1σ point counted the uncertainty into a 68 % interval
  twice. Not resolved (the test short of its level) but with the slope's 68 % interval
  clear of zero (``fit.drift_floor``), the ramp at that interval's near end is a part that
  does not scatter, the noise part what the AVAR leaves beside it, within the support
  (``_with_floor_edf``): no claim is made, the terms and the model stay the AVAR fit's.
  Its bounds are not that EDF's χ² about the estimate: the ramp's cross term, the slope's
  own error times Rτ², dominates the estimate's scatter at the longest τ and the verdict is
  made of the same slope, so they take the ramp's uncertainty from the slope's interval
  and the noise part's from its χ², in quadrature (``floor_bounds``).

The printed EDF is never below the estimator's own and never above what the record
supports (``noise_id.fm_support_edf``: the most any FM type gives at that m and N, the rule
every printed EDF keeps): the AVAR fit cannot split the longest τ between a ramp and a
random walk, so its parts may not take the EDF past it (``parts_edf(within_support=
False)`` is for a part known apart from the AVAR). Where neither raises it, the result is
returned unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from statistics import NormalDist
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan.edf import (
    chi2_interval,
    edf_greenhall,
    edf_mixture,
    edf_mixture_bound,
    edf_with_signal,
)
from avard.core.allan.noise_id import SPREAD_LAG1, fm_support_edf
from avard.core.analysis.cross_term import cross_term_variance
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.allan.deviations import AllanResult
    from avard.core.model.fit import NoiseFit

__all__ = ["floor_bounds", "model_edf", "noise_part_edf", "noise_psd", "parts_edf",
           "resolved_ramp_bounds", "resolved_ramp_interval", "signal_parts", "signal_share",
           "unresolved_noise_edf", "with_parts_edf", "with_share_edf", "with_signal_edf"]

#: The share of the AVAR above which a deterministic part's cross term is computed exactly.
_EXACT_SHARE = 1e-3

#: The relative gap within which a noise type's EDF is taken to tie ``model_edf``'s point
#: bound: far above the last-bit error of the bound (~1e-15), and where the other types
#: hold so little of the point bound that the type all but holds it alone.
_TIE = 1e-9

#: The estimators whose variance the fit's AVAR basis describes (Allan, not Hadamard).
_ALLAN_KINDS = ("oavar", "avar", "pavar")


def _n_phase(allan: AllanResult) -> NDArray[np.int64]:
    """Phase points each τ's differences span (the record's N + 1 for the OADEV)."""
    return np.asarray((np.maximum(allan.n, 1) - 1) * allan.stride + 2 * allan.m + 1)


def signal_parts(fit: NoiseFit, allan: AllanResult, *, lower: bool = True
                 ) -> list[tuple[NDArray[np.float64], float]]:
    """The fit's resolved deterministic terms (module docstring), each as (its AVAR at each
    τ of ``allan`` at its lower 1σ bound, or its point value with ``lower=False``, its
    frequency in cycles per sample: 0 for a ramp). Empty where none is resolved."""
    tau = np.asarray(allan.tau, dtype=float)
    cov = np.asarray(fit.theta_cov, dtype=float)
    out: list[tuple[NDArray[np.float64], float]] = []
    for j, comp in enumerate(fit.components):
        theta = float(fit.theta[j]) if j < len(fit.theta) else 0.0
        if theta <= 0 or comp.fixed_value is not None or comp.psd(fit.rate_hz) is not None:
            continue  # absent, fixed, or noise (it scatters)
        term = fit.terms.get(comp.label)
        if term is not None and (not term.present or term.note is not None):
            continue  # not resolved: read as noise
        se = math.sqrt(max(float(cov[j, j]), 0.0)) if j < len(cov) else math.inf
        low = max(theta - se, 0.0)
        if low > 0:
            f0 = float(comp.params.get("frequency_hz", 0.0)) / float(fit.rate_hz)
            out.append(((low if lower else theta) * comp.basis(tau, fit.rate_hz), f0))
    return out


def _noise_upper_levels(fit: NoiseFit) -> list[tuple[float, int]]:
    """(θ at its upper 1σ, component index) of each present noise component: θ + σ, a
    fixed one at its value. Not an absent term at its upper limit: beside a resolved ramp
    a random walk's limit is loose (the two share the longest τ), and a cross term from it
    set the steep drift's EDF at 40–50 where its estimates scatter with 1300–2400 (so did
    the most the measured AVAR allows it at any τ)."""
    cov = np.asarray(fit.theta_cov, dtype=float)
    out = []
    for j, comp in enumerate(fit.components):
        if j >= len(fit.theta) or comp.psd(fit.rate_hz) is None:
            continue
        theta = float(fit.theta[j])
        se = math.sqrt(max(float(cov[j, j]), 0.0)) if comp.fixed_value is None and \
            j < len(cov) else 0.0
        if theta > 0:
            out.append((theta + se, j))
    return out


def noise_upper(fit: NoiseFit, allan: AllanResult) -> NDArray[np.float64]:
    """The fitted noise's AVAR at each τ of ``allan`` with each noise component at its upper
    1σ (``_noise_upper_levels``): what the noise part of the estimate is at most, read from
    every τ."""
    tau = np.asarray(allan.tau, dtype=float)
    out = np.zeros(len(tau))
    for level, j in _noise_upper_levels(fit):
        out += level * fit.components[j].basis(tau, fit.rate_hz)
    return out


def _total(fit: NoiseFit, allan: AllanResult, sure: NDArray[np.float64]
           ) -> NDArray[np.float64]:
    """The expected AVAR the shares are taken of: the larger of the measured and modelled
    (and never below the deterministic part itself)."""
    var = np.asarray(allan.var, dtype=float)
    return np.fmax(np.fmax(var, fit.model_avar(np.asarray(allan.tau, dtype=float))), sure)


def signal_share(fit: NoiseFit, allan: AllanResult) -> NDArray[np.float64]:
    """The share of the AVAR at each τ of ``allan`` (one channel) that the fit's resolved
    deterministic terms hold at their lower 1σ bound (module docstring); 0 where none."""
    parts = signal_parts(fit, allan)
    sure = np.zeros(len(allan.tau))
    for s, _f0 in parts:
        sure += s
    if not np.any(sure > 0):
        return sure
    total = _total(fit, allan, sure)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total > 0, sure / total, 0.0)
    return np.nan_to_num(share, nan=0.0)


def noise_psd(fit: NoiseFit, *, upper: bool = True
              ) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """The fitted noise's two-sided PSD (cycles per sample), each present component at its
    upper 1σ (``_noise_upper_levels``), or with ``upper`` False at its value. The cross
    term weighs the record's ends, where a random walk the fit left out would scatter it:
    the steep drift's records (1 h, whose generator has a random walk below the flicker
    floor) scatter at 409.6 s with an EDF of about 1300–1550, where this gives 1800
    (docs/log/analysis.md). Beside a ramp resolved apart from the AVAR the walk is the time
    domain's own estimate (``drift.walk_beside_slope``), and the cross term, linear in the
    spectrum, is its mean over the fit's uncertainty at the point values (``upper``
    False): at the upper 1σ it counted that uncertainty into a 68 % interval once more."""
    levels = _noise_upper_levels(fit)
    if not upper:
        levels = [(float(fit.theta[j]) if fit.components[j].fixed_value is None else lv, j)
                  for lv, j in levels]
    comps = [(level, p) for level, j in levels
             if (p := fit.components[j].psd(fit.rate_hz)) is not None]

    def psd(nu: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros(len(nu))
        for level, p in comps:
            out += level * np.asarray(p(nu), dtype=float)
        return out
    return psd


#: The power-law type whose Greenhall–Riley EDF bounds each noise cause's: the fit's
#: (``fit.CAUSE_ALPHA``), except quantization, given white FM's (the most any FM type has:
#: the EDF stays within the record's support), and a Gauss–Markov process, given a random
#: walk's (what it looks like below its T, the reddest type it can be).
_CAUSE_OVERRIDES = {"quantization": 0, "gauss_markov": -2}


def model_edf(fit: NoiseFit, allan: AllanResult, *, exact: bool = True
              ) -> NDArray[np.float64]:
    """The EDF of each τ's estimate under the fitted noise model: the mixture's own
    (``edf.edf_mixture``: Greenhall–Riley's quadratic-form EDF with the sum of the
    components' covariances of differences, rate data's exact phase), or with ``exact``
    False its lower bound (``edf.edf_mixture_bound``, Cauchy–Schwarz: the types' differences
    taken as fully correlated), the fit reading the composition across every τ. The
    composition is taken the way that lowers it: the types whose own EDF is below the point
    value at their upper value (θ + σ, or the upper limit of an absent term), the others at
    their lower (θ − σ, not below 0). NaN where the fit has a noise cause it cannot type, or
    no noise at that τ."""
    from avard.core.model.fit import CAUSE_ALPHA  # (the fit module loads with the fit)

    tau = np.asarray(allan.tau, dtype=float)
    n_phase = _n_phase(allan)
    cov = np.asarray(fit.theta_cov, dtype=float)
    alphas: list[int] = []
    parts: list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                      NDArray[np.float64]]] = []
    for j, comp in enumerate(fit.components):
        if comp.psd(fit.rate_hz) is None:
            continue  # deterministic (signal_share)
        alpha = {**CAUSE_ALPHA, **_CAUSE_OVERRIDES}.get(comp.cause)
        if alpha is None:
            return np.full(len(tau), math.nan)
        theta = float(fit.theta[j])
        se = math.sqrt(max(float(cov[j, j]), 0.0)) if comp.fixed_value is None else 0.0
        upper = theta + se
        term = fit.terms.get(comp.label)
        if theta <= 0 and term is not None and term.upper is not None:
            upper = float(term.upper) ** 2
        if upper <= 0:
            continue
        b = comp.basis(tau, fit.rate_hz)
        nu = np.array([edf_greenhall(alpha, 2, int(m), int(s), int(p), rate_data=alpha <= 0)
                       for m, s, p in zip(allan.m, allan.stride, n_phase, strict=True)])
        alphas.append(int(alpha))
        parts.append((theta * b, max(theta - se, 0.0) * b, upper * b, nu))
    if not parts:
        return np.full(len(tau), math.nan)

    def mixture(levels: list[NDArray[np.float64]]) -> NDArray[np.float64]:
        lv = np.array(levels)
        if not exact:
            return edf_mixture_bound(lv, np.array([nu for _p, _l, _u, nu in parts]))
        return np.array([edf_mixture(tuple(alphas), lv[:, k], 2, int(m), int(s), int(p),
                                     rate_data=True)
                         for k, (m, s, p) in enumerate(zip(allan.m, allan.stride, n_phase,
                                                           strict=True))])

    point = mixture([p for p, _l, _u, _nu in parts])
    # the composition that lowers it: types below it at their upper value. A type whose
    # own EDF ties the point value (one α holds all of it, e.g. white FM, or white FM
    # beside an absent quantization given white FM's EDF) is not below it: the mixture
    # gives its ν back only to the last bit, and that bit differs between two sums of the
    # same AVAR (one worker's and several's, issue 29), so it is decided beyond a relative
    # _TIE. At its lower value is the side that lowers it: the others moved, the value
    # lies below the tied ν, where more of that type would raise it.
    worst = [np.where(nu < point * (1.0 - _TIE), up, lo) for _p, lo, up, nu in parts]
    return mixture(worst)


def with_signal_edf(allan: AllanResult, fit: NoiseFit) -> AllanResult:
    """``allan`` (one channel) with the EDF the fit supports: the noise's at least
    ``model_edf``, and where resolved deterministic terms hold part of the AVAR, the EDF of
    the noise's scatter plus their exact cross term with it (``with_parts_edf``); unchanged
    where the estimator's own EDF is already the larger and no resolved deterministic term
    holds part of the AVAR. Where the fit's deterministic part was resolved apart from the
    AVAR (``fit.resolved_apart``: a drift the time domain found, ``analysis/drift.py``) the
    whole EDF may pass the record's support (its noise part may not)."""
    if allan.kind not in _ALLAN_KINDS or np.asarray(allan.var).ndim != 1:
        return allan
    if allan.noise_id == "stable32":
        return allan  # Stable32's own rules, kept for row-by-row comparison (issue 24)
    noise = unresolved_noise_edf(fit, allan)
    if not signal_parts(fit, allan):  # (resolved: at its lower bound, above zero)
        if fit.drift_floor > 0:
            return _with_floor_edf(allan, fit, noise)
        return with_share_edf(allan, np.zeros(len(allan.tau)), noise)
    parts = signal_parts(fit, allan, lower=False)
    point = np.sum([s for s, _f in parts], axis=0)
    low = np.sum([s for s, _f in signal_parts(fit, allan)], axis=0)
    total = _total(fit, allan, point)
    if fit.resolved_apart:
        noise_part = _noise_expected(fit, allan, total - point)
    else:
        # the noise part: the fitted noise at its upper 1σ, or what the measured AVAR
        # leaves beside the deterministic terms at their lower 1σ, the larger
        noise_part = np.fmax(noise_upper(fit, allan), total - low)
    return with_parts_edf(allan, parts, total, noise_part,
                          noise_psd(fit, upper="rate_ramp" not in fit.resolved_apart), noise,
                          within_support=not fit.resolved_apart)


def resolved_ramp_interval(allan: AllanResult, fit: NoiseFit) -> AllanResult:
    """``with_signal_edf``'s result with, beside a ramp the time domain resolved (a fit of
    ``drift.resolve_drift``, which carries ``drift.CROSS_SCALE``), the bounds made of the
    estimate's error (``resolved_ramp_bounds``): the ramp's cross term at the slope's
    measured variance times the model's ratio (``drift.model_slope_var``), not the χ² of
    an EDF that holds the estimate's own error in the ramp's S and the fitted walk's
    cross term. Elsewhere, and where a bound is not a number, ``with_signal_edf``'s.

    Measured, not what analyze prints (docs/log/2026-11-29-cov29.md): it brings the 60 h
    ramp cells in and holds 1 h, but under-covers 12 h drift at its longest τ, where the
    slope's Δ ≤ 1 curvature is narrower than its scatter."""
    out = with_signal_edf(allan, fit)
    scale = _ramp_cross_scale(fit)
    if "rate_ramp" not in fit.resolved_apart or not math.isfinite(scale) or \
            allan.kind not in _ALLAN_KINDS or np.asarray(allan.var).ndim != 1 or \
            allan.noise_id == "stable32":
        return out
    parts = signal_parts(fit, allan, lower=False)
    if not parts:
        return out
    lo, hi = resolved_ramp_bounds(allan, parts, _noise_fitted(fit, allan),
                                  noise_psd(fit, upper=False),
                                  noise_part_edf(allan, unresolved_noise_edf(fit, allan)),
                                  scale)
    keep = np.isfinite(lo) & np.isfinite(hi) & np.isfinite(np.asarray(out.lo, dtype=float))
    return replace(out, lo=np.where(keep, lo, out.lo), hi=np.where(keep, hi, out.hi))


def _ramp_cross_scale(fit: NoiseFit) -> float:
    """The resolved ramp's cross-term scale (``drift.CROSS_SCALE``: the slope's measured
    variance over the GLS slope's under the fitted noise), NaN where the fit carries none
    (no ramp resolved from the time domain, or a fit not made by ``drift.resolve_drift``)."""
    from avard.core.analysis.drift import CROSS_SCALE

    for comp in fit.components:
        if comp.label == "rate_ramp":
            return float(comp.params.get(CROSS_SCALE, math.nan))
    return math.nan


def _noise_fitted(fit: NoiseFit, allan: AllanResult) -> NDArray[np.float64]:
    """The fitted noise's AVAR at each τ of ``allan``, every noise component at its point
    value (not ``_noise_expected``'s √(N̂² + Var N̂), which holds the ramp's own uncertainty
    once more: the bounds carry it in the cross term)."""
    tau = np.asarray(allan.tau, dtype=float)
    out = np.zeros(len(tau))
    for j, comp in enumerate(fit.components[:len(fit.theta)]):
        if comp.psd(fit.rate_hz) is not None:
            out += float(fit.theta[j]) * comp.basis(tau, fit.rate_hz)
    return out


def resolved_ramp_bounds(allan: AllanResult, parts: list[tuple[NDArray[np.float64], float]],
                         noise_avar: NDArray[np.float64],
                         psd: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                         noise_nu: NDArray[np.float64], ramp_scale: float = 1.0
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The bounds of an estimate σ̂² beside a ramp resolved apart from the AVAR (and any
    resolved sinusoid, ``parts``), made of the estimate's error, not of a χ² about it:

        σ̂² − T = (the noise's own scatter about N) + Σ_j (part j's cross term with the
        noise, and a sinusoid's spread over its phase),

    the first a χ² on the noise's EDF ``noise_nu`` scaled by the model's noise N
    (``noise_avar``), the others of variance V = Σ S_j·c_j + S_j²·p_j (``parts_edf``'s
    terms), taken as Gaussian (a deterministic part's cross term is a linear form in the
    noise) and combined with the first in quadrature:

        lo = σ̂² − √((N·(χ²_hi/ν − 1))² + z²V),  hi = σ̂² + √((N·(1 − χ²_lo/ν))² + z²V).

    Why not the χ² of ``parts_edf``'s EDF about σ̂²: that EDF, 2T²/Var, holds the ramp's
    AVAR at the estimated slope, whose error is the estimate's own (a record whose slope
    came out high has a high estimate), so the EDF rose with the estimate and the interval
    was narrow exactly where the estimate was high; and a scale family about σ̂² reaches far
    above a low estimate. Here the widths do not scale with σ̂² (V with the part's AVAR,
    which is the slope's square, and N the fitted noise). NaN where a bound is not a
    positive number, or where the ramp holds under ``_EXACT_SHARE`` of the estimate (the
    caller keeps its own).

    ``ramp_scale`` multiplies a ramp's c (``with_signal_edf`` passes the slope's measured
    variance over the GLS slope's under the fitted noise, ``drift.model_slope_var``): with
    c under the fitted spectrum alone the widths still followed the estimate, since the
    walk that sets c is read from the same long τ (docs/log/2026-11-29-cov28b.md); the
    ratio of c to the GLS slope's variance under one spectrum moves far less with that
    walk than either."""
    tau = np.asarray(allan.tau, dtype=float)
    var = np.asarray(allan.var, dtype=float)
    z = NormalDist().inv_cdf(0.5 + float(allan.ci) / 2.0)
    u_lo, u_hi = chi2_interval(np.ones(len(tau)), noise_nu, allan.ci, allan.quantiles)
    noise = np.maximum(np.asarray(noise_avar, dtype=float), 0.0)
    v = np.zeros(len(tau))
    for s, f0 in parts:
        c = np.array([cross_term_variance(psd, int(m), int(n), f0) if sk > 0 else 0.0
                      for m, n, sk in zip(allan.m, allan.n, s, strict=True)])
        if f0 <= 0:
            c = c * ramp_scale
        v += s * np.where(np.isfinite(c), c, 4.0 * noise / noise_nu) + \
            s**2 * phase_spread(allan.n, f0)
    with np.errstate(invalid="ignore", divide="ignore"):
        lo = var - np.hypot(noise * (1.0 / u_lo - 1.0), z * np.sqrt(v))
        hi = var + np.hypot(noise * (1.0 - 1.0 / u_hi), z * np.sqrt(v))
    # (where the ramp holds under 0.1 % of the estimate it changes nothing worth it: the
    # caller's χ² about the estimate, which needs no model of the noise's level, stands)
    ramp = np.sum([s for s, f0 in parts if f0 <= 0], axis=0) if parts else np.zeros(len(tau))
    ok = np.isfinite(lo) & np.isfinite(hi) & (lo > 0) & (hi > lo) & \
        (ramp >= _EXACT_SHARE * var)
    return np.where(ok, lo, np.nan), np.where(ok, hi, np.nan)


def _with_floor_edf(allan: AllanResult, fit: NoiseFit, noise_edf: NDArray[np.float64]
                    ) -> AllanResult:
    """``allan`` with the EDF of a drift the time domain found but did not resolve
    (``fit.drift_floor``): the ramp at its 68 % interval's near end holds that much of the
    AVAR without scattering; the noise part is what the AVAR leaves beside it, with the
    noise's own EDF; within the record's support (the AVAR fit read the ramp as a walk).
    The bounds, where the fit carries the test's slope (``fit.drift_slope``), are
    ``floor_bounds``': the ramp's uncertainty from the slope's interval, not a χ² about the
    estimate (the printed EDF stays this rule's, what the noise and the floor support)."""
    tau = np.asarray(allan.tau, dtype=float)
    part = fit.drift_floor**2 * tau**2 / 2.0
    total = _total(fit, allan, part)
    out = with_parts_edf(allan, [(part, 0.0)], total, total - part, noise_psd(fit),
                         noise_edf)
    if not fit.drift_slope:
        return out
    lo, hi = floor_bounds(allan, fit.drift_slope, noise_part_edf(allan, noise_edf))
    keep = np.isfinite(lo) & np.isfinite(hi) & np.isfinite(np.asarray(out.lo, dtype=float))
    return replace(out, lo=np.where(keep, lo, out.lo), hi=np.where(keep, hi, out.hi))


def floor_bounds(allan: AllanResult, slope: tuple[float, float, float],
                 noise_nu: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The bounds of an estimate beside a drift the time domain found short of its level
    (``NoiseFit.drift_slope``: the GLS slope R̂ and its 68 % profile interval, clear of
    zero), taken about the estimate σ̂² from the two things its error is made of: the ramp's
    ½R²τ², whose uncertainty is the slope's (its interval [R₋, R₊] at the bounds' level),
    and the noise part σ̂² − ½R̂²τ² with its χ² on the noise's EDF ``noise_nu``, the two
    combined in quadrature (the slope's error and the noise's scatter about its own mean are
    nearly independent):

        lo = σ̂² − √((½R̂²τ² − ½R₋²τ²)² + (N̂ − N₋)²),  hi = σ̂² + √((½R₊²τ² − ½R̂²τ²)² + (N₊ − N̂)²)

    Why not a χ² about σ̂²: at the longest τ the ramp's cross term with the noise, R·τ·D_noise
    (the noise's mean Allan difference, i.e. the slope's own error times Rτ²), dominates the
    estimate's scatter, and the drift test's verdict is made of the same slope, so the
    records it leaves short of its level are those whose estimate fell low. A χ² on the
    estimate, held within the record's support, then reaches far above a low estimate and
    over-covers those records (79–87 % at the longest τ of the coverage benchmark's drift
    rows); the slope's interval carries the same error where it is made (docs/log/
    2026-11-28-cov24h.md). Where the ramp holds nothing the bounds are the noise's χ² on σ̂².
    Never narrower than the record's support: where hi/lo falls below the χ² ratio at the
    support's EDF, the bounds are widened to it about their geometric mean. NaN where a
    bound is not a positive number, or where the ramp at the slope's upper end holds under
    ``_EXACT_SHARE`` of the estimate (the caller keeps its own)."""
    tau = np.asarray(allan.tau, dtype=float)
    var = np.asarray(allan.var, dtype=float)
    r, r_lo, r_hi = (abs(v) for v in slope)
    r_lo, r_hi = sorted((r_lo, r_hi))
    z = NormalDist().inv_cdf(0.5 + float(allan.ci) / 2.0)  # (the slope's interval is 1σ)
    r_lo = max(r - z * (r - r_lo), 0.0)
    r_hi = r + z * (r_hi - r)
    g = tau**2 / 2.0
    ramp, ramp_lo, ramp_hi = r * r * g, r_lo * r_lo * g, r_hi * r_hi * g
    noise = np.maximum(var - ramp, 0.01 * var)
    n_lo, n_hi = chi2_interval(noise, noise_nu, allan.ci, allan.quantiles)
    lo = var - np.hypot(ramp - ramp_lo, noise - n_lo)
    hi = var + np.hypot(ramp_hi - ramp, n_hi - noise)
    s_lo, s_hi = chi2_interval(np.ones(len(tau)), _support(allan), allan.ci, allan.quantiles)
    with np.errstate(invalid="ignore", divide="ignore"):
        narrow = hi / lo < s_hi / s_lo
        mid = np.sqrt(lo * hi)
        lo = np.where(narrow, mid * np.sqrt(s_lo / s_hi), lo)
        hi = np.where(narrow, mid * np.sqrt(s_hi / s_lo), hi)
    # (where even the slope's upper end holds under 0.1 % of the estimate the ramp changes
    # nothing worth it: the caller's χ², which the noise's is there, stands)
    ok = np.isfinite(lo) & np.isfinite(hi) & (lo > 0) & (hi > lo) & \
        (ramp_hi >= _EXACT_SHARE * var)
    return np.where(ok, lo, np.nan), np.where(ok, hi, np.nan)


def _noise_expected(fit: NoiseFit, allan: AllanResult, left: NDArray[np.float64]
                    ) -> NDArray[np.float64]:
    """The noise part's root mean square over the fit's uncertainty, √(N̂² + Var N̂), where
    the deterministic part was resolved apart from the AVAR (``fit.resolved_apart``), so the
    split of the AVAR between it and the noise has a known uncertainty: the estimate's
    variance 2N²/ν is an expectation over that split, E N² = N̂² + Var N̂, not its value at
    the split's worst 1σ point (which counted the split's uncertainty into a 68 % interval
    twice: the 1 h drift records the time domain resolved covered 80 % at 409.6 s). N̂ the
    larger of the fitted noise (its covariance from the fit) and what the measured AVAR
    ``left`` beside the deterministic part at its point value (the part's variance)."""
    tau = np.asarray(allan.tau, dtype=float)
    cov = np.asarray(fit.theta_cov, dtype=float)
    k = len(fit.theta)
    b = np.zeros((k, len(tau)))
    noisy = np.zeros(k, dtype=bool)
    for j, comp in enumerate(fit.components[:k]):
        b[j] = comp.basis(tau, fit.rate_hz)
        noisy[j] = comp.psd(fit.rate_hz) is not None
    theta = np.asarray(fit.theta, dtype=float)
    bn, bs = b * noisy[:, None], b * ~noisy[:, None]
    fitted = theta @ bn
    var_fitted = np.einsum("it,ij,jt->t", bn, cov, bn)
    var_part = np.einsum("it,ij,jt->t", bs, cov, bs)
    return np.asarray(np.fmax(np.sqrt(fitted**2 + np.maximum(var_fitted, 0.0)),
                              np.sqrt(np.maximum(left, 0.0)**2 + np.maximum(var_part, 0.0))))


def noise_part_edf(allan: AllanResult, noise_edf: NDArray[np.float64] | None = None
                   ) -> NDArray[np.float64]:
    """The EDF the noise part of each τ's estimate is given: the larger of the estimator's
    and ``noise_edf`` (NaN: none), within the record's support (the most any FM type gives
    at that m and N, ``noise_id.fm_support_edf``) and never below the estimator's own."""
    edf = np.asarray(allan.edf, dtype=float)
    base = edf if noise_edf is None else np.fmax(edf, noise_edf)
    return np.where(np.isfinite(edf), np.maximum(edf, np.fmin(base, _support(allan))), edf)


def _support(allan: AllanResult) -> NDArray[np.float64]:
    """The record's support at each τ: the most EDF any FM type gives (``fm_support_edf``)."""
    return np.array([fm_support_edf(2, int(m), int(s), int(p))
                     for m, s, p in zip(allan.m, allan.stride, _n_phase(allan), strict=True)])


def parts_edf(allan: AllanResult, parts: list[tuple[NDArray[np.float64], float]],
              total: NDArray[np.float64], noise_avar: NDArray[np.float64],
              psd: Callable[[NDArray[np.float64]], NDArray[np.float64]],
              noise_edf: NDArray[np.float64] | None = None, *, within_support: bool = True
              ) -> NDArray[np.float64]:
    """The EDF 2T²/Var of an OADEV estimate whose expectation T (``total``) holds the
    deterministic ``parts`` (their AVAR S_j, frequency ν_j in cycles per sample) and the
    noise's ``noise_avar`` N: the noise part scatters with ``noise_part_edf`` ν (capped at
    the support), and
    each part adds its exact cross term with the noise, S_j·``cross_term_variance`` under
    the fitted noise spectrum ``psd`` (a deterministic part does not scatter itself):

        EDF = 2T² / (2N²/ν + Σ_j S_j·c_j + Σ_j S_j²·p_j),

    p_j the spread of a sinusoid's own OADEV over its phase (``phase_spread``; 0 for a
    ramp).

    The support caps the noise's EDF, and with ``within_support`` (what analyze prints)
    the whole EDF too. Where a known deterministic part dominates the estimate scatters far
    less than any noise type's χ² says, and ``within_support=False`` says so (the coverage
    benchmark's oracle, given the true part and spectrum, covers 60–80 % with it). The
    AVAR fit's own parts cannot lift it: at the longest τ it cannot split the AVAR between
    a ramp and a random walk, and takes the walk's share for the ramp's, so the noise part
    comes out too small (12 h "steep" records: the EDF 480–570 where the estimates scatter
    with 240–300, coverage 58 %; docs/log/analysis.md). The deterministic share is held below
    0.99 (as ``edf.edf_with_signal``). For the estimators with a stride (the cascade),
    whose cross term this does not model, the non-central ν/(1 − f²) within the support."""
    nu = noise_part_edf(allan, noise_edf)
    sure = np.zeros(len(allan.tau))
    for s, _f0 in parts:
        sure += s
    noise = np.clip(noise_avar, 0.01 * total, total)
    if np.any(np.asarray(allan.stride) != 1):
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.nan_to_num(np.where((total > 0) & (sure > 0), 1.0 - noise / total, 0.0))
        return with_share_edf(allan, share, noise_edf).edf
    cross = np.zeros(len(allan.tau))
    for s, f0 in parts:
        # where the part holds under 0.1 % of the AVAR its cross term is taken at the most a
        # Gaussian quadratic form allows, 4SN/ν (under 0.2 % of the variance: not worth the
        # quadrature)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where(s < _EXACT_SHARE * total, 4.0 * noise / nu, 0.0)
        for k, (m, n, sk) in enumerate(zip(allan.m, allan.n, s, strict=True)):
            if sk >= _EXACT_SHARE * total[k]:
                c[k] = cross_term_variance(psd, int(m), int(n), f0)
        with np.errstate(invalid="ignore", divide="ignore"):
            # (a cross term that is not a number is not "no scatter": the Gaussian bound)
            c = np.where(np.isfinite(c), c, 4.0 * noise / nu)
        cross += s * c + s**2 * phase_spread(allan.n, f0)
    with np.errstate(invalid="ignore", divide="ignore"):
        edf = 2.0 * total**2 / (2.0 * noise**2 / nu + cross)
    edf = np.where(np.isfinite(edf), edf, nu)  # (no differences at a τ: the noise's)
    if within_support:
        edf = np.fmin(edf, _support(allan))
    return np.where(np.isfinite(nu) & (sure > 0), np.fmax(edf, nu), nu)


def phase_spread(n_diff: NDArray[np.int64], f0: float) -> NDArray[np.float64]:
    """The variance, per unit S², of a sinusoid's own OADEV over ``n_diff`` differences
    across its phase (the AVAR is the phase average; a record holding a fraction of a
    cycle more or less weighs one phase more): (1/M)Σ sin²(2πν₀k + φ) = ½ − the
    Dirichlet sum's cos(2φ + …) term, so Var = ½·(sin(2πν₀M)/(M sin(2πν₀)))². None for a
    ramp (ν₀ = 0)."""
    m = np.asarray(n_diff, dtype=float)
    if f0 <= 0:
        return np.zeros(len(m))
    den = m * np.sin(2 * np.pi * f0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(np.abs(den) > 0, np.sin(2 * np.pi * f0 * m) / den, 1.0)
    return 0.5 * rel**2


def with_parts_edf(allan: AllanResult, parts: list[tuple[NDArray[np.float64], float]],
                   total: NDArray[np.float64], noise_avar: NDArray[np.float64],
                   psd: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                   noise_edf: NDArray[np.float64] | None = None, *,
                   within_support: bool = True) -> AllanResult:
    """``allan`` with ``parts_edf`` and its χ² bounds (unchanged where it is the same)."""
    new = parts_edf(allan, parts, total, noise_avar, psd, noise_edf,
                    within_support=within_support)
    edf = np.asarray(allan.edf, dtype=float)
    new = np.where(np.isfinite(edf), np.maximum(new, edf), edf)
    if np.array_equal(new, edf):
        return allan
    lo, hi = chi2_interval(allan.var, new, allan.ci, allan.quantiles)
    return replace(allan, edf=new, lo=np.where(np.isfinite(new), lo, allan.lo),
                   hi=np.where(np.isfinite(new), hi, allan.hi))


def unresolved_noise_edf(fit: NoiseFit, allan: AllanResult) -> NDArray[np.float64]:
    """``model_edf`` at every τ of avard's rule: the fitted mixture's lower bound where the
    estimator took the least EDF of several types it could not tell apart (fewer than
    ``SPREAD_LAG1`` averages; ``model_edf(exact=False)``: the issue asks the least EDF the
    plausible noises allow), the mixture's own where it identified one type (the lag-1 ACF
    reads one α from a mixture's averages and rounds it: white + flicker at 16–64 s of
    the coverage benchmark's 12 h and 60 h records read as flicker FM, whose EDF is 10–20 %
    below the mixture's, which their estimates scatter with). Measured on the benchmark
    (docs/analysis.md, "Coverage of the intervals"). NaN under "powerlaw" and "stable32":
    there the estimator's identification stands, as it prints it from the API (NBS14
    through analyze: every τ)."""
    if allan.noise_id != "avard":
        return np.full(len(allan.tau), math.nan)
    n_phase = _n_phase(allan)
    few = (n_phase - 1) / allan.m < SPREAD_LAG1
    noise = np.full(len(allan.tau), math.nan)
    if np.any(few):
        # the identification uncertain: the least the mixture can have (the rule,
        # the least EDF where the types cannot be told apart)
        noise[few] = model_edf(fit, allan, exact=False)[few]
    if np.any(~few):
        # every identified τ: the fitted mixture's own (the estimator's one type is read
        # from a mixture's averages and rounded; its EDF is that type's)
        noise[~few] = model_edf(fit, allan)[~few]
    return noise


def with_share_edf(allan: AllanResult, share: NDArray[np.float64],
                   noise_edf: NDArray[np.float64] | None = None) -> AllanResult:
    """``allan`` (one channel, an Allan kind) with the EDF ν/(1 − f²) of a deterministic
    share ``f`` at each τ, ν the larger of the estimator's EDF and ``noise_edf`` (NaN: none),
    within the record's support and never below the estimator's; and its bounds."""
    edf = np.asarray(allan.edf, dtype=float)
    base = edf if noise_edf is None else np.fmax(edf, noise_edf)
    if not np.any(share > 0) and not np.any(base > edf):
        return allan
    cap = _support(allan)
    raised = edf_with_signal(base, share)
    # never above the record's support, never below the estimator's own EDF
    new = np.where(np.isfinite(edf), np.maximum(edf, np.fmin(raised, cap)), edf)
    if np.array_equal(new, edf):
        return allan
    lo, hi = chi2_interval(allan.var, new, allan.ci, allan.quantiles)
    return replace(allan, edf=new, lo=np.where(np.isfinite(new), lo, allan.lo),
                   hi=np.where(np.isfinite(new), hi, allan.hi))
