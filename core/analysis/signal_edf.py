"""The printed OADEV's EDF from what the fit knows across τ: the noise's composition, and
the part of the AVAR its resolved deterministic terms hold.

Two things one τ cannot tell and the fit, reading every τ, can (issue 24: the printed
intervals over-cover, up to 90 %, where a sinusoid or a drift dominates):

* **The noise's composition.** With few averages the estimator cannot identify the noise
  type and takes the least EDF of every FM type (``noise_id.physical_alpha_edf``), the
  reddest type's, even where the fitted model says white and flicker noise hold most of
  the AVAR there. ``model_edf`` bounds the EDF of the fitted mixture from below
  (``edf.edf_mixture_bound``, Cauchy–Schwarz over the types' own Greenhall–Riley EDFs),
  with the composition taken the way that lowers the bound (each term at θ ± σ, an absent
  one at its upper limit), at the τ where the estimator could not tell the types apart
  (fewer than ``noise_id.SPREAD_LAG1`` averages).
* **A deterministic share.** A rate ramp or a sinusoid adds to the Allan variance without
  scattering: the estimate at a τ where such a term holds a share f of the expectation is a
  non-central χ², and ``edf.edf_with_signal`` gives the moment-matched EDF ν/(1 − f²).
  Only terms the fit resolves count (present, with no "ramp or random walk" or "not yet
  resolved" note: a ramp the record cannot tell from a random walk is read as the walk),
  each at its lower 1σ bound, over the larger of the measured and modelled AVAR
  (``signal_share``).

The printed EDF is never below the estimator's own and never above what the record
supports (``noise_id.fm_support_edf``: the most any FM type gives at that m and N, the rule
every printed EDF keeps). Where neither raises it, the result is returned unchanged.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan.edf import (
    chi2_interval,
    edf_greenhall,
    edf_mixture_bound,
    edf_with_signal,
)
from avard.core.allan.noise_id import SPREAD_LAG1, fm_support_edf
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.allan.deviations import AllanResult
    from avard.core.model.fit import NoiseFit

__all__ = ["model_edf", "signal_share", "unresolved_noise_edf", "with_share_edf",
           "with_signal_edf"]

#: The estimators whose variance the fit's AVAR basis describes (Allan, not Hadamard).
_ALLAN_KINDS = ("oavar", "avar", "pavar")


def _n_phase(allan: AllanResult) -> NDArray[np.int64]:
    """Phase points each τ's differences span (the record's N + 1 for the OADEV)."""
    return np.asarray((np.maximum(allan.n, 1) - 1) * allan.stride + 2 * allan.m + 1)


def signal_share(fit: NoiseFit, allan: AllanResult) -> NDArray[np.float64]:
    """The share of the AVAR at each τ of ``allan`` (one channel) that the fit's resolved
    deterministic terms hold at their lower 1σ bound (module docstring); 0 where none."""
    tau = np.asarray(allan.tau, dtype=float)
    sure = np.zeros(len(tau))
    cov = np.asarray(fit.theta_cov, dtype=float)
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
            sure += low * comp.basis(tau, fit.rate_hz)
    if not np.any(sure > 0):
        return sure
    var = np.asarray(allan.var, dtype=float)
    total = np.fmax(np.fmax(var, fit.model_avar(tau)), sure)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total > 0, sure / total, 0.0)
    return np.nan_to_num(share, nan=0.0)


#: The power-law type whose Greenhall–Riley EDF bounds each noise cause's: the fit's
#: (``fit.CAUSE_ALPHA``), except quantization, given white FM's (the most any FM type has:
#: the EDF stays within the record's support), and a Gauss–Markov process, given a random
#: walk's (what it looks like below its T, the reddest type it can be).
_CAUSE_OVERRIDES = {"quantization": 0, "gauss_markov": -2}


def model_edf(fit: NoiseFit, allan: AllanResult) -> NDArray[np.float64]:
    """A lower bound on the EDF of each τ's estimate under the fitted noise model
    (``edf.edf_mixture_bound`` over the fit's noise components, each with the Greenhall–Riley
    EDF of its type). The fit reads the composition across every τ, which one τ of few
    averages cannot (there the estimator's own rule takes the least EDF of every FM type).
    The composition is taken the way that lowers the bound: the types whose own EDF is below
    the point bound at their upper value (θ + σ, or the upper limit of an absent term), the
    others at their lower (θ − σ, not below 0). NaN where the fit has a noise cause it
    cannot type, or no noise at that τ."""
    from avard.core.model.fit import CAUSE_ALPHA  # (the fit module loads with the fit)

    tau = np.asarray(allan.tau, dtype=float)
    n_phase = _n_phase(allan)
    cov = np.asarray(fit.theta_cov, dtype=float)
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
        nu = np.array([edf_greenhall(alpha, 2, int(m), int(s), int(p))
                       for m, s, p in zip(allan.m, allan.stride, n_phase, strict=True)])
        parts.append((theta * b, max(theta - se, 0.0) * b, upper * b, nu))
    if not parts:
        return np.full(len(tau), math.nan)
    nus = np.array([nu for _p, _l, _u, nu in parts])
    point = edf_mixture_bound([p for p, _l, _u, _nu in parts], nus)
    # the composition that lowers the bound: types below it at their upper value
    worst = [np.where(nu < point, up, lo) for _p, lo, up, nu in parts]
    return edf_mixture_bound(worst, nus)


def with_signal_edf(allan: AllanResult, fit: NoiseFit) -> AllanResult:
    """``allan`` (one channel) with the EDF the fit supports: the noise's at least
    ``model_edf`` and raised by ``signal_share`` (module docstring); unchanged where the
    estimator's own EDF is already the larger and no resolved deterministic term holds part
    of the AVAR."""
    if allan.kind not in _ALLAN_KINDS or np.asarray(allan.var).ndim != 1:
        return allan
    if allan.noise_id == "stable32":
        return allan  # Stable32's own rules, kept for row-by-row comparison (issue 24)
    return with_share_edf(allan, signal_share(fit, allan), unresolved_noise_edf(fit, allan))


def unresolved_noise_edf(fit: NoiseFit, allan: AllanResult) -> NDArray[np.float64]:
    """``model_edf`` where the estimator took the least EDF of several types it could not
    tell apart (fewer than ``SPREAD_LAG1`` averages), NaN elsewhere: with more averages its
    identification stands (the model bound there read the generator's flicker above what
    it scatters with, and the 60 h drift records fell to 60.5 % coverage at 64 s)."""
    noise = model_edf(fit, allan)
    n_phase = _n_phase(allan)
    noise[(n_phase - 1) / allan.m >= SPREAD_LAG1] = math.nan
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
    n_phase = _n_phase(allan)
    cap = np.array([fm_support_edf(2, int(m), int(s), int(p))
                    for m, s, p in zip(allan.m, allan.stride, n_phase, strict=True)])
    raised = edf_with_signal(base, share)
    # never above the record's support, never below the estimator's own EDF
    new = np.where(np.isfinite(edf), np.maximum(edf, np.fmin(raised, cap)), edf)
    if np.array_equal(new, edf):
        return allan
    lo, hi = chi2_interval(allan.var, new, allan.ci, allan.quantiles)
    return replace(allan, edf=new, lo=np.where(np.isfinite(new), lo, allan.lo),
                   hi=np.where(np.isfinite(new), hi, allan.hi))
