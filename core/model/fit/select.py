"""Which terms are present: stepwise likelihood-ratio selection, the rescue of a term hidden by
its neighbours, upper limits for terms not found, and a term that rests on the longest τ alone."""

from __future__ import annotations

import math

import numpy as np
from avard.core.allan.chi2 import chi2_sf
from avard.core.model.fit.problem import (
    _at,
    _avar_cov,
    _fit_active,
    _gls_nnls,
    _neg_log_lik,
    _param_cov,
    _Problem,
    _whitener,
)
from numpy.typing import NDArray


def _select_terms(p: _Problem, idx: NDArray, A: int, z_present: float,
                  ramp: int | None = None, walk: int | None = None,
                  upper_limits: bool = True
                  ) -> tuple[list[int], NDArray[np.float64], NDArray[np.float64], bool]:
    """Stepwise selection by the likelihood-ratio test on the correlated, EDF-weighted
    residuals: a component is kept when removing it raises χ² by at least z_present²
    (2.33² = 5.4: one-sided 1 % for a coefficient on the boundary θ = 0).

    All candidate models are compared with one covariance, the one of the full model (every
    candidate term fitted), so that a deterministic term (rate ramp, which adds no estimator
    variance of its own) cannot look significant merely by shrinking its own error bars.
    Forward steps add the candidate that lowers χ² most while the drop passes the test; then
    backward steps remove any term that no longer passes. Returns the selected components,
    √Δχ² of each (the z of its test) and, for the terms left out, the one-sided upper limit
    θ̂ + z_present·se of θ when fitted with the selected ones (a "not detected, below" bound).

    Rate ramp (index ``ramp``) against rate random walk (``walk``): a random walk's
    realisation over a record looks like a trend, and a ramp fitted with the covariance of a
    model in which it has taken the random walk's place has tight error bars it did not earn.
    So the common covariance is that of the model *without* the ramp (the long-τ excess read
    as a random walk): the ramp must beat what a random walk would do. When exactly one of
    the two is selected, the two readings are compared by their Gaussian likelihood, each
    with its own covariance; when neither is better by the test's margin the record cannot
    tell them apart: the random walk is kept (the stochastic reading, whose interval includes
    the realisation's scatter) and the last value returned is True ("ramp or random walk").
    """
    base = [a for a in range(A) if a != ramp] if walk is not None else list(range(A))
    _, _, C_star, _ = _fit_active(p, idx, base)
    T = _whitener(C_star)
    y = p.y[idx]
    Ty = T @ y
    Xi = _at(p, idx).X
    crit = z_present**2

    done: dict[tuple[int, ...], tuple[float, NDArray]] = {}

    def chi2(active: list[int]) -> tuple[float, NDArray]:
        # the forward, backward and upper-limit passes ask for the same subsets again: one
        # fit each (a pure function of the subset under the one covariance T)
        key = tuple(active)
        if key not in done:
            if not active:
                r = T @ y
                done[key] = float(r @ r), np.zeros(0)
            else:
                th, c2 = _gls_nnls(np.ascontiguousarray(Xi[:, np.asarray(active, dtype=np.intp)]),
                                   y, T, Ty)
                done[key] = c2, th
        return done[key]

    z_all = np.full(A, np.nan)
    active: list[int] = []
    cur, _ = chi2(active)
    while len(active) < A:
        trials = []
        for a in range(A):
            if a not in active:
                cand = sorted([*active, a])
                c2, th = chi2(cand)
                trials.append((c2, a, cand, th))
        c2, a, cand, th = min(trials, key=lambda t: t[0])
        gain = cur - c2
        if gain < crit or th[cand.index(a)] <= 0:
            break
        active, cur = cand, c2
    while active:
        drops = []
        for a in active:
            rest = [b for b in active if b != a]
            c2, _ = chi2(rest)
            drops.append((c2 - cur, a))
            z_all[a] = math.sqrt(max(c2 - cur, 0.0))
        gain, a = min(drops)
        if gain >= crit:
            break
        active.remove(a)
        cur, _ = chi2(active)
    ambiguous = False
    if ramp is not None and walk is not None and ramp in active and walk in active:
        # both chosen: the ramp stays only if it also wins on likelihood with the models'
        # own covariances; else the random walk alone reads the long-τ excess
        without = [b for b in active if b != ramp]
        if not _neg_log_lik(p, idx, active) + crit < _neg_log_lik(p, idx, without):
            active = without
            ambiguous = True
    if ramp is not None and walk is not None and (ramp in active) != (walk in active):
        # One of the two was chosen: compare the two readings by their Gaussian likelihood,
        # each with its own covariance (χ² + ln det C), so that a random walk's wide scatter
        # and a ramp's tight one both count. Clearly better (by the test's margin) wins;
        # otherwise the record cannot tell them apart and the random walk is reported.
        there, other = (ramp, walk) if ramp in active else (walk, ramp)
        swapped = sorted([b for b in active if b != there] + [other])
        nll_there, nll_other = _neg_log_lik(p, idx, active), _neg_log_lik(p, idx, swapped)
        if nll_other + crit < nll_there:
            active = swapped
        elif not nll_there + crit < nll_other:
            ambiguous = True
            if there == ramp:  # the random walk reading
                active = swapped
        cur, _ = chi2(active)
        if walk in active:
            c2_no_walk, _ = chi2([b for b in active if b != walk])
            z_all[walk] = math.sqrt(max(c2_no_walk - cur, 0.0))
    rescued = _rescue_hidden_terms(p, idx, A, active, crit, ramp)
    if rescued:
        for a, z in rescued.items():
            z_all[a] = z
        active = sorted([*active, *rescued])
        cur, _ = chi2(active)
    upper = np.full(A, np.nan)
    for a in range(A):
        if a not in active:
            cand = sorted([*active, a])
            c2, th = chi2(cand)
            z_all[a] = math.sqrt(max(cur - c2, 0.0))
            if upper_limits:
                upper[a] = _upper_limit(p, idx, cand, a, z_present, T)
    return active, z_all, upper, ambiguous


#: The own-covariance χ² upper tail below which the selection looks again for a noise term
#: the common covariance hid (``_rescue_hidden_terms``): the level of explain's misfit test.
RESCUE_P = 0.01


def _rescue_hidden_terms(p: _Problem, idx: NDArray, A: int, active: list[int], crit: float,
                         ramp: int | None) -> dict[int, float]:
    """Noise terms the selection's common covariance hid: {component: z} to add.

    The selection compares subsets under the full model's covariance, in which every term
    carries the variance it has when fitted. Beside a bias instability that took up the long-τ
    rise, the full model's random walk scatters the longest τ so widely that they weigh little,
    and the random walk that rise is made of passed at z 2.2–2.3 (or not at all, its NNLS
    coefficient 0 beside the flicker) on 4 h records of white + flicker + random walk, where
    the model left without it misfits its own covariance at χ²/dof 4–34 (p 1e-7 to 1e-85) and
    explain said "unexplained" on 8 % of null axes. So where the selected model fails its own
    χ² test at ``RESCUE_P``, each absent stochastic term (never the ramp, which adds no
    variance and is tested against the random walk above) is tried by the Gaussian
    likelihood with each model's own covariance (χ² + ln det C, as the ramp against the walk)
    and the best one that lowers it by the test's margin (``crit``) with a positive
    coefficient is added, until the model passes or none does. Its z is √ of that drop."""
    out: dict[int, float] = {}
    cur = list(active)
    while cur:  # (an empty selection keeps its own χ²: nothing was seen at all)
        _, _, _, c2 = _fit_active(p, idx, cur)
        dof = len(idx) - len(cur)
        if dof <= 1 or not math.isfinite(c2) or float(chi2_sf(c2, dof)) >= RESCUE_P:
            return out
        here = _neg_log_lik(p, idx, cur)
        best: tuple[float, int] | None = None
        for a in range(A):
            if a in cur or a == ramp:
                continue
            cand = sorted([*cur, a])
            th, _, _, _ = _fit_active(p, idx, cand)
            if not th[a] > 0:
                continue
            gain = here - _neg_log_lik(p, idx, cand)
            if gain >= crit and (best is None or gain > best[0]):
                best = (gain, a)
        if best is None:
            return out
        out[best[1]] = math.sqrt(best[0])
        cur = sorted([*cur, best[1]])
    return out


def _upper_limit(p: _Problem, idx: NDArray, cand: list[int], a: int, z: float,
                 T0: NDArray, iterations: int = 6) -> float:
    """One-sided upper limit θ_u = θ̂ + z·se of an absent component's θ, with the AVAR
    covariance evaluated *at* θ_u (the hypothesis the limit excludes), iterated to a fixed
    point. With the covariance of the fitted model instead, a random walk whose realisation
    fell low also had small error bars, and the limit came out below the truth in 1 of 8
    absent-K records (issue 12); a term as large as θ_u scatters the AVAR as much as it
    would if it were there."""
    X = p.X[np.ix_(idx, np.asarray(cand, dtype=np.intp))]
    y = p.y[idx]
    j = cand.index(a)
    theta = np.zeros(p.X.shape[1])
    T = T0  # first round: the common covariance of the selection
    up = 0.0
    for _ in range(iterations):
        th, _ = _gls_nnls(X, y, T)
        TX = T @ X
        se = math.sqrt(max(_param_cov(TX)[j, j], 0.0))
        new = th[j] + z * se
        done = up > 0 and abs(new - up) <= 1e-3 * up
        up = new
        theta[cand] = th
        theta[a] = up  # the covariance of the next round: the term at its limit
        if done:
            break
        T = _whitener(_avar_cov(p, theta, idx))
    return up


def _rests_on_longest(p: _Problem, idx: NDArray, active: list[int], a: int, crit: float,
                      ramp: int | None, walk: int | None) -> bool:
    """Whether component ``a``'s presence hangs on the longest τ of the fit alone: with that
    point left out its likelihood-ratio gain falls below the test's ``crit``.

    A rate ramp (AVAR ∝ τ²) and a rate random walk (∝ τ) are read at the long end of the
    curve, where the last point holds a handful of averages, and a slow periodic signal (a
    30-minute air-conditioning cycle) rises as τ² below a quarter of its period: on 40 min of
    such a record the fit read a ramp from its one last point, which the longer τ beyond
    the fit (too few averages to fit) refuted (issue 24). As in ``_select_terms``, the test
    uses one covariance for both models, that of the active model with the ramp read as a
    random walk, so the ramp must beat what a random walk would do."""
    sub = idx[:-1]
    if len(sub) < len(active) + 2:
        return True
    cov_model = list(active)
    if ramp is not None and walk is not None and ramp in cov_model:
        cov_model = sorted({b for b in cov_model if b != ramp} | {walk})
    _, _, C, _ = _fit_active(p, sub, cov_model)
    T = _whitener(C)
    y = p.y[sub]
    _, with_a = _gls_nnls(p.X[np.ix_(sub, np.asarray(active, dtype=np.intp))], y, T)
    rest = [b for b in active if b != a]
    if rest:
        _, without = _gls_nnls(p.X[np.ix_(sub, np.asarray(rest, dtype=np.intp))], y, T)
    else:
        r = T @ y
        without = float(r @ r)
    return without - with_a < crit
