"""A deterministic drift told from a rate random walk in the time domain: the one test
``avard analyze`` (the printed EDF, issue 24) and ``avard explain`` (a drift cause, issue 23)
share.

The Allan variance cannot tell a rate ramp R (AVAR R²τ²/2) from a rate random walk K (K²τ/3)
on one record: both rise at the longest τ, and the AVAR fit reads such a rise as the walk
("ramp or random walk", ``fit.RAMP_OR_WALK``). The time domain can: a drift's increments are
all of one sign and size, a walk's are not. So on the record's block means ȳ_i (at most
``DRIFT_BLOCKS`` of them) the Gaussian likelihood of an offset alone (H0) and of an offset
and a slope (H1) is computed under white, flicker and random-walk noise N, B, K
(``block_noise_cov``), with K *profiled*, free over a range that reaches ``K_SPAN`` times
beyond the AVAR fit's upper value for it (its 68 % upper bound where present, its one-sided
upper limit where absent) and four decades below; N and B, which the short and middle τ pin
down, at the fit's values. Λ = −2 ln L0 + 2 ln L1 is divided by a Bartlett factor β
(``bartlett``), and z = ±√(Λ/β) (the slope's sign) is N(0, 1) under a random walk with no
drift.

**Why the Bartlett factor.** Where the walk holds only a few of the means' directions (12 h
of the benchmark's noise: the walk meets the flicker floor at a fifteenth of the record),
K's profile is fitted on those few and the slope takes what the walk left: Λ is then more
like the square of a t of few degrees of freedom than a χ²(1), and its 1 % point is 1.4
times χ²(1)'s even on means drawn from the covariance itself, N and B exact (3 % past the
1 % level). β is that ratio, measured once by simulation from the model (``BARTLETT``) and
looked up by the walk's directions at the offset-only K (``walk_directions``), never
below 1. The point-form covariance used before hid part of this (``block_noise_cov``).

**Why not a least-squares slope against the AVAR fit's K.** That test was measured and not
kept: on 12 h white + flicker + random-walk records whose walk meets the flicker floor at a
fifteenth of the record, the AVAR fit finds no K on 36 of 40 (the τ it fits stop at T/8),
and a slope tested against the noise it does find passed the 0.1 % level on 13 % of records
with no drift, its z spread 2.4 times too wide; explain's likelihood, whose K grid was
centred on the fit's K (or, with none, on N/T), could not reach the true walk either (12 of
40 records past 2.58, z spread 2.6). With K profiled over a range reaching past what the
AVAR allows, and the Bartlett factor, the benchmark's plain records pass in 0.0 %, 1.8 % and
1.0 % at 1 h, 12 h and 60 h (400 each, z spread 0.99–1.09; ``python -m benchmarks
drift_null``, docs/log/analysis.md).

The profile is cheap: with C₀ = L Lᵀ the white and flicker covariance and M = min(t_i, t_j)
the walk's, L⁻¹ M L⁻ᵀ = V Λ Vᵀ once, every K's covariance is diagonal in the rotated basis
(1 + K²λ_i), so a fine K grid costs one Cholesky factor and one eigen-decomposition.

**A step is not a drift.** A level step inside the record has a slope too, and a random
walk can make either; a drift's slope is the same in both halves of the record. A passed
drift is refuted when one line per half (offset and slope each, K profiled) fits better
than one line by χ²(2) at ``HALVES_LEVEL``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial
from statistics import NormalDist
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.allan.deviations import AllanResult
    from avard.core.model.fit import NoiseFit

__all__ = [
    "CROSS_SCALE",
    "DRIFT_BLOCKS",
    "LEVEL",
    "MIN_BLOCKS",
    "BlockMeans",
    "BlockSums",
    "BlockSumsPart",
    "DriftLikelihood",
    "block_noise_cov",
    "channel_drift",
    "drift_block",
    "drift_likelihood",
    "interval_rise",
    "mean_difference",
    "model_slope_var",
    "resolve_drift",
    "two_sided_z",
]

#: Most block means the likelihood uses (its question lives at the longest scales).
DRIFT_BLOCKS = 256
#: K's profile reaches this factor beyond the larger of the fit's upper K and N/T ...
K_SPAN = 30.0
#: ... and this many decades below it (and K = 0), on ``K_POINTS`` log-spaced points.
K_DECADES, K_POINTS = 4.0, 121
#: Fewest blocks a drift is tested on.
MIN_BLOCKS = 32
#: χ²(2)'s level at which one line per half refutes a drift (a step, not a drift).
HALVES_LEVEL = 0.01

#: The noise the slope's interval is computed under (``DriftLikelihood.interval_noise``,
#: said in analyze's JSON and text where a drift is reported): the N and B of the AVAR
#: refitted less the fitted line (``channel_drift`` given the AVAR); the AVAR fit's own
#: (no AVAR given: explain's call, the model-draw benchmarks); and the two fallbacks to
#: the fit's N and B where the refit was asked for and could not be used: it raised or
#: found no white N, or the means' covariance under its N and B did not factor. A
#: fallback interval is wider on drift records (the drift lowers the fit's B, cov27),
#: so it is recorded rather than passed off as the refit's.
IntervalNoise = Literal["refit_less_line", "fit", "fit_refit_failed", "fit_not_factored"]
INTERVAL_NOISE: dict[IntervalNoise, str] = {
    "refit_less_line": "the noise refitted on the AVAR less the fitted line",
    "fit": "the AVAR fit's N and B",
    "fit_refit_failed": "the AVAR fit's N and B: the refit less the line failed or found "
                        "no white N",
    "fit_not_factored": "the AVAR fit's N and B: the means' covariance under the refit's "
                        "N and B did not factor",
}
#: The Bartlett table (``bartlett``): the likelihood ratio's 99 % point under the null over
#: χ²(1)'s, by the walk's directions at the offset-only K, never below 1 (where the walk is
#: absent the ratio is below χ²(1), and the test stays as conservative as that). Made by
#: ``python -m benchmarks drift_null --table --draws 1500`` (10 500 draws a length, 1 h, 12 h
#: and 60 h geometries, K from 0.1 to 10 times the benchmark's), 2026-11-28. Where the
#: walk holds a few directions the ratio is 1.4 times χ²(1) at its 1 % point: K's profile
#: is fitted on those few and the slope takes what the walk left (a t of few degrees of
#: freedom, not a z); where it holds many, the K grid's steps keep it a few % above.
BARTLETT_DOF = (0.0, 0.63, 1.48, 2.73, 4.63, 7.97, 14.3, 27.5, 65.7, 90.1, 170.0)
BARTLETT = (1.0, 1.0, 1.101, 1.402, 1.436, 1.308, 1.033, 1.002, 1.0, 1.105, 1.077)
#: The interval's rise (``interval_rise``): the same ratio's 68.3 % point over χ²(1)'s (1),
#: by the same ν, never below 1; where the slope's 68 % interval ends on its profile −2 ln L
#: (each slope b at the ν of the means less b·t, its own null's: ``drift_likelihood``).
#: Made by the same run as ``BARTLETT`` (same draws, same bins), 2026-11-28. Why not β:
#: β is the ratio's 1 % tail, and where the walk holds a few directions the ratio's centre
#: is inflated more than its tail (K's profile takes a share of the slope's scatter on
#: every draw, not only on the rare large ones), so an interval at Δ ≤ β held the true
#: slope in well under 68 %. The test (z, its level) stays on β.
INTERVAL_RISE_DOF = BARTLETT_DOF
INTERVAL_RISE = (1.0, 2.886, 2.756, 1.705, 1.249, 1.193, 1.013, 1.12, 1.0, 1.021, 1.024)


def block_noise_cov(t: NDArray, block_s: float, n_white: float, b_inst: float,
                    k_rrw: float) -> NDArray[np.float64]:
    """Covariance ((m/s²)²) of block means (length ``block_s``, centres ``t``) of white,
    flicker and random-walk rate noise, as block means hold them: N²/block on the diagonal;
    flicker as noise_gen's ladder of Gauss–Markov processes (Σ σ_k² e^(−|Δt|/T_k)) from
    ``FLICKER_BELOW`` below the block up, each member's covariance block-averaged
    (``_gm_block_cov``); random walk K²·min(t_i, t_j) off the diagonal (its start value is
    the offset column) and K²·(t_i − block/6) on it, the mean of min(s, u) over one block's
    s and u. The one covariance of the drift test, the slow-sinusoid search
    (``slow_sine.py``) and explain's transients.

    Why not the point form (a member's e^(−|Δt|/T) from the block up, the walk's diagonal
    K²t), which the drift test used until issue 24's sixth session: without the averaged
    ladder the flicker's 1/f above the block's rate is missing from the means' spectrum (at
    12 h it is above the white there) and the walk's diagonal adds white noise of K²·block/6
    (ten times N²/block where the walk holds the block scale). The slow search read both as
    slow sinusoids; the drift test's false rate at 12 h looked right with it (3.0 % at a
    1 % level) only because that error offset part of the small-sample inflation its
    likelihood ratio has where the walk holds few directions (``bartlett``)."""
    from avard.core.sim.noise_gen import flicker_ladder

    c = np.diag(np.full(len(t), n_white**2 / block_s))
    if b_inst > 0:
        lag = np.abs(np.subtract.outer(t, t))
        steps = np.rint(lag / block_s)
        even = bool(np.allclose(lag, steps * block_s, rtol=0.0, atol=1e-9 * block_s))
        # evenly spaced centres: the covariance is a function of the lag in blocks,
        # added up over the ladder on one vector and spread over the matrix once
        at = np.arange(len(t)) * block_s if even else lag
        total = np.zeros(at.shape)
        for T, s in flicker_ladder([b_inst], block_s / FLICKER_BELOW,
                                   10 * float(t[-1] + block_s), 2.0):
            total += float(np.asarray(s)[0]) ** 2 * _gm_block_cov(at, block_s, T)
        c += total[steps.astype(int)] if even else total
    if k_rrw > 0:
        c += k_rrw**2 * _walk_cov(t, block_s)
    return np.asarray(c, dtype=np.float64)


#: The flicker ladder of ``block_noise_cov`` starts this factor below the block length.
FLICKER_BELOW = 64.0


def _gm_block_cov(lag: NDArray, block_s: float, T: float) -> NDArray[np.float64]:
    """The covariance of the means over ``block_s`` of a unit-variance Gauss–Markov process
    of time constant ``T``, at centre distances ``lag`` (0 or at least one block):
    (2T/b)(1 − (T/b)(1 − e^(−b/T))) at 0, e^(−lag/T)·(2T²/b²)(cosh(b/T) − 1) beyond."""
    x = block_s / T
    if x < 1e-3:  # a member far slower than the block: its point covariance
        return np.asarray(np.exp(-lag / T))
    with np.errstate(over="ignore", under="ignore"):
        far = (0.5 * (np.exp((block_s - lag) / T) + np.exp(-(block_s + lag) / T))
               - np.exp(-lag / T)) * (2.0 / (x * x))
    same = (2.0 / x) * (1.0 - (1.0 - math.exp(-x)) / x)
    return np.asarray(np.where(lag < 0.5 * block_s, same, far))


def _walk_cov(t: NDArray, block_s: float) -> NDArray[np.float64]:
    """The covariance of a unit random walk's block means (``block_noise_cov``)."""
    return np.asarray(np.minimum.outer(t, t) - np.eye(len(t)) * (block_s / 6.0))


class _Profile:
    """The block means and columns whitened once for every K (module docstring)."""

    def __init__(self, yb: NDArray, t: NDArray, block_s: float, n_white: float,
                 b_inst: float, gm: tuple[float, float] | None = None) -> None:
        # numpy and the project's triangular solver, not scipy.linalg: analyze imports no
        # scipy (its import would cost more than every solve here)
        from avard.core.model.triangular import LowerSolver

        c0 = block_noise_cov(t, block_s, n_white, b_inst, 0.0)
        if gm is not None and gm[0] > 0 and gm[1] > 0:
            # a Gauss–Markov process (σ, T) claimed beside the noise (explain): its block
            # means' covariance in the fixed part, so that its variance is not taken by the
            # profiled walk, whose red spectrum would then hide a slow sinusoid
            lag = np.abs(np.subtract.outer(t, t))
            c0 = c0 + float(gm[0]) ** 2 * _gm_block_cov(lag, block_s, float(gm[1]))
        L = np.linalg.cholesky(c0)  # LinAlgError: the caller says "would not factor"
        low = LowerSolver(L)
        walk = _walk_cov(t, block_s)
        a = low.solve(walk)
        a = low.solve(np.ascontiguousarray(a.T))
        lam, V = np.linalg.eigh(0.5 * (a + a.T))
        self.lam = np.maximum(lam, 0.0)
        self.logdet0 = 2.0 * float(np.sum(np.log(np.diag(L))))
        self._white = lambda x: V.T @ low.solve(x)
        self.wy = self._white(np.asarray(yb, dtype=float))

    def white(self, cols: NDArray) -> NDArray[np.float64]:
        return np.asarray(self._white(cols))

    def fit(self, k: float, wx: NDArray) -> tuple[float, NDArray, NDArray, float]:
        """(−2 ln L up to a constant, GLS coefficients, their covariance, χ²) at walk K
        of the whitened columns ``wx``."""
        s = 1.0 + k * k * self.lam
        d = 1.0 / np.sqrt(s)
        a, b = wx * d[:, None], self.wy * d
        coef, *_ = np.linalg.lstsq(a, b, rcond=None)
        r = b - a @ coef
        chi2 = float(r @ r)
        return (self.logdet0 + float(np.sum(np.log(s))) + chi2, coef,
                np.linalg.pinv(a.T @ a), chi2)

    def best(self, ks: NDArray, wx: NDArray) -> tuple[int, float]:
        """(index in ``ks``, −2 ln L) of the K that fits ``wx`` best."""
        j, nll = self.k_profile(ks, wx)
        return j, float(nll[j])

    def k_profile(self, ks: NDArray, wx: NDArray) -> tuple[int, NDArray[np.float64]]:
        """(index of the best K in ``ks``, −2 ln L at each K) of the columns ``wx``."""
        # every K at once (the rotated basis makes each K's covariance diagonal): the same
        # −2 ln L as ``fit`` per K, held equal by tests/core/test_drift.py
        nll = self._nll_each_k(self._over_k(ks, wx), self.wy, _solve_each)
        return int(np.argmin(nll)), nll

    def k_profile_reml(self, ks: NDArray, wx: NDArray) -> NDArray[np.float64]:
        """−2 ln of K's restricted likelihood at each K of ``ks`` beside the columns ``wx``
        (``k_profile`` plus ln det of the columns' GLS normal matrix): the likelihood of
        the residuals the columns leave, which is what K's variance is read from where the
        columns take part of the walk (a fitted slope takes the walk's own linear part, and
        K's ordinary profile beside it is biased low by that much)."""
        k = self._over_k(ks, wx)
        nll = self._nll_each_k(k, self.wy, _solve_each)
        sign, logdet = np.linalg.slogdet(k.xtx)
        return np.asarray(np.where(sign > 0, nll + logdet, np.inf))

    def slope_profile(self, ks: NDArray, w0: NDArray, wt: NDArray, slopes: NDArray
                      ) -> NDArray[np.float64]:
        """−2 ln L at each of ``slopes`` (the slope column ``wt`` fixed, the columns ``w0``
        fitted), K profiled over ``ks``: the slope's profile likelihood."""
        return self.slope_profile_k(ks, w0, wt, slopes)[0]

    def slope_profile_k(self, ks: NDArray, w0: NDArray, wt: NDArray, slopes: NDArray
                        ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``slope_profile`` and, at each slope b, the K it is profiled at: the K the
        means less the line b·t want under ``w0``'s columns alone (with ``w0`` the offset,
        the drift test's offset-only K of those means)."""
        basis = self._over_k(ks, w0)  # the columns' side is the same at every slope
        out = np.full(len(slopes), np.inf)
        at = np.zeros(len(slopes))
        for i, b in enumerate(slopes):
            nll = self._nll_each_k(basis, self.wy - b * wt, _solve_strict)
            j = int(np.argmin(nll))
            out[i], at[i] = float(nll[j]), float(ks[j])
        return out, at

    def _over_k(self, ks: NDArray, wx: NDArray) -> _OverK:
        """The columns ``wx`` weighted for every K of ``ks`` and their normal matrices."""
        s = 1.0 + np.outer(ks * ks, self.lam)  # (K, blocks)
        d = 1.0 / np.sqrt(s)
        x = wx[None, :, :] * d[:, :, None]  # (K, blocks, p)
        return _OverK(d, self.logdet0 + np.sum(np.log(s), axis=1), x,
                      np.einsum("kbp,kbq->kpq", x, x))

    @staticmethod
    def _nll_each_k(k: _OverK, wy: NDArray,
                    solve: Callable[[NDArray, NDArray], NDArray[np.float64]]
                    ) -> NDArray[np.float64]:
        """−2 ln L at each K of the whitened data ``wy`` on ``k``'s columns."""
        r = wy[None, :] * k.d  # (K, blocks)
        coef = solve(k.xtx, np.einsum("kbp,kb->kp", k.x, r))
        res = r - np.einsum("kbp,kp->kb", k.x, coef)
        return np.asarray(k.logdet + np.einsum("kb,kb->k", res, res))


@dataclass(frozen=True)
class _OverK:
    """Columns weighted for each K of a grid (``_Profile._over_k``): the weights ``d``
    (K, blocks), each K's ln det, the weighted columns ``x`` (K, blocks, p), ``xtx``."""

    d: NDArray[np.float64]
    logdet: NDArray[np.float64]
    x: NDArray[np.float64]
    xtx: NDArray[np.float64]


def _solve_strict(xtx: NDArray, xtr: NDArray) -> NDArray[np.float64]:
    """Each K's normal equations solved (``LinAlgError`` where one is singular)."""
    return np.asarray(np.linalg.solve(xtx, xtr[:, :, None])[:, :, 0])


def _solve_each(xtx: NDArray, xtr: NDArray) -> NDArray[np.float64]:
    """Each K's normal equations solved (least squares where one is singular)."""
    try:
        return _solve_strict(xtx, xtr)
    except np.linalg.LinAlgError:
        return np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(xtx, xtr,
                                                                            strict=True)])


@dataclass(frozen=True)
class DriftLikelihood:
    """``drift_likelihood``'s answer. ``z``: ±√Δ(−2 ln L) of a slope against a random walk
    with K profiled (the slope's sign); ``slope`` the GLS slope (input unit per s) at
    ``k_drift``, the K the likelihood picks beside it (``k_walk``: the K the walk alone
    wants; ``k_drift_hi`` the top of its Δ(−2 ln L) ≤ 1 range beside the slope, the most
    walk the time domain allows), ``slope_lo``/``slope_hi`` its 68 % profile-likelihood
    interval (K profiled at every slope: the walk's uncertainty is in it): the slopes b
    whose profile stands above its minimum by at most the ratio's 68.3 % point under the
    null b (``interval_rise`` at the walk directions of the means less b·t; not 1, nor the
    test's ``bartlett`` β, nor the rise at the record's own ``walk_dof``, which a true drift
    raises), from the lowest such b to the highest; ``end_rises`` the rise at each end and
    ``interval_rise`` the one at the record's ν (the null of no drift); ``slope_se`` its
    half-width; ``slope_sd`` the slope's standard error, the half-width of the profile's
    Δ ≤ 1 interval, what a resolved ramp's uncertainty is propagated with
    (``resolve_drift``); ``k_top`` the K grid's top; ``halves_gain``: Δ(−2 ln L) of one
    line per half over one line (a step, not a drift, past χ²(2) at ``HALVES_LEVEL``);
    ``blocks`` used, ``record_s`` they span."""

    z: float
    slope: float
    slope_lo: float
    slope_hi: float
    k_walk: float
    k_drift: float
    k_drift_hi: float
    k_top: float
    halves_gain: float
    blocks: int
    record_s: float
    walk_dof: float = 0.0
    bartlett: float = 1.0
    interval_rise: float = 1.0
    end_rises: tuple[float, float] = (1.0, 1.0)
    slope_sd: float = math.nan
    #: the noise ``slope_lo``/``slope_hi`` and ``slope_sd`` were computed under: a key of
    #: ``INTERVAL_NOISE``
    interval_noise: IntervalNoise = "fit"

    @property
    def slope_se(self) -> float:
        return 0.5 * (self.slope_hi - self.slope_lo)

    @property
    def floor(self) -> float:
        """The least |slope| of its 68 % interval: 0 where the interval holds zero, or where
        the test cannot speak (a step, or K at its grid's top)."""
        if self.slope_lo * self.slope_hi <= 0 or self.step_like or self.at_edge:
            return 0.0
        return min(abs(self.slope_lo), abs(self.slope_hi))

    @property
    def at_edge(self) -> bool:
        """K at its grid's top under either hypothesis (the walk may be larger still)."""
        return max(self.k_walk, self.k_drift) >= self.k_top * (1 - 1e-9)

    @property
    def step_like(self) -> bool:
        """One line per half fits better than one line by χ²(2) at ``HALVES_LEVEL``."""
        return self.halves_gain > -2.0 * math.log(HALVES_LEVEL)

    def passes(self, z_threshold: float) -> bool:
        """|z| at or past ``z_threshold`` (the slope's profile likelihood at zero that far
        above its minimum), not a step, and K inside its grid (at the top, a larger walk
        was not tried: no claim)."""
        return abs(self.z) >= z_threshold and not self.step_like and not self.at_edge


def two_sided_z(level: float) -> float:
    """|z| of a two-sided test at ``level`` (a slope's sign is free)."""
    return NormalDist().inv_cdf(1.0 - 0.5 * level)


def drift_likelihood(yb: NDArray, t: NDArray, block_s: float, n_white: float, b_inst: float,
                     k_scale: float, base: Sequence[NDArray] = (),
                     beside: Callable[[float], tuple[float, float] | None] | None = None
                     ) -> DriftLikelihood:
    """The time-domain likelihood ratio of a drift against a random walk (module docstring)
    on block means ``yb`` (centres ``t``, s; length ``block_s``) with white N and flicker B
    at the given values and K profiled up to ``K_SPAN``·max(``k_scale``, N/T); ``base``:
    further columns fitted under both hypotheses (the offset is always there: explain's
    transients). The slope's interval is its profile likelihood's, K profiled at every
    slope: the GLS error at the K picked beside the slope alone was a sixth of the true
    scatter where that K fell to 0 (explain's drift records). ``beside``: given the GLS
    slope, the white N and flicker B of the noise beside that line (``channel_drift``: the
    AVAR refitted less the fitted line), which the slope's interval and standard error are
    computed under; None (or ``beside`` absent) keeps the test's N and B. The test itself
    (z, β) is always at ``n_white`` and ``b_inst``: its null is no drift. Raises
    ``np.linalg.LinAlgError`` when the noise covariance does not factor."""
    t = np.asarray(t, dtype=float)
    record_s = len(t) * block_s
    top = K_SPAN * max(float(k_scale), n_white / record_s)
    ks = np.concatenate([[0.0], np.geomspace(top * 10.0**-K_DECADES, top, K_POINTS)])
    prof = _Profile(yb, t, block_s, n_white, b_inst)
    one = np.ones_like(t)
    tc = t - t.mean()
    w0 = prof.white(np.column_stack([one, *base]))
    w1 = np.column_stack([w0, prof.white(tc)])
    i, h0 = prof.best(ks, w0)
    j, nll1 = prof.k_profile(ks, w1)
    h1 = float(nll1[j])
    # the K range beside the slope: up to the first grid point past Δ = 1 (or the top)
    past = np.flatnonzero((np.arange(len(ks)) > j) & (nll1 > h1 + 1.0))
    k_hi = float(ks[past[0]] if past.size else ks[-1])
    # ν at the offset-only K. (At the K beside the slope, or its REML value, a true drift
    # would not raise it, but the 12 h plain records then passed in 3.5–4 %: that K is low
    # exactly where the slope has taken the walk.) The price: a true drift raises it (1 h
    # drift records: ν about 4 where plain ones have 0), and the test loses power there
    nu = walk_directions(prof.lam, float(ks[i]))
    beta = bartlett(nu)
    lr = max(0.0, h0 - h1) / beta
    _nll, coef, _cov, _chi2 = prof.fit(float(ks[j]), w1)
    slope = float(coef[-1])
    # The interval is the test inverted: a slope b is judged as the null "the means less
    # b·t are noise", and that noise's N and B are those of the record less a line, not of
    # the record: a true drift lowers the AVAR fit's B (the fit's long-τ terms take the
    # drift's rise and the flicker floor gives way), and under a B too low the walk takes
    # more of the means' directions, so each slope is judged at a rise its noise does not
    # have and the interval over-covers (cov27). The test's z stays at the record's N and B
    # (its null is b = 0, whose noise is the record itself).
    noise_at = beside(slope) if beside is not None else None
    iprof = prof
    used: IntervalNoise = "fit"
    if beside is not None:
        # (a refit asked for and not usable falls back to the test's N and B, and says so)
        used = "refit_less_line"
        if noise_at is None or not noise_at[0] > 0:
            used = "fit_refit_failed"
        elif (noise_at[0], noise_at[1]) != (n_white, b_inst):
            try:
                iprof = _Profile(yb, t, block_s, float(noise_at[0]), float(noise_at[1]))
            except np.linalg.LinAlgError:
                used = "fit_not_factored"
    if iprof is not prof:
        iw0 = iprof.white(np.column_stack([one, *base]))
        iw1 = np.column_stack([iw0, iprof.white(tc)])
        ii, _h = iprof.best(ks, iw0)
    else:
        iw0, iw1, ii = w0, w1, i
    # the profile over slopes: a first span from the GLS error at the walk's own K (the
    # widest of the two), then the Δ = 1 crossings on a finer one
    wide = math.sqrt(max(float(iprof.fit(float(ks[ii]), iw1)[2][-1, -1]), 0.0))
    # the interval at the ratio's own 68.3 % point (``interval_rise``), not at Δ ≤ 1 nor
    # at Δ ≤ β: where the walk holds a few directions the ratio's centre is inflated more
    # than its 1 % tail β, and an interval at Δ ≤ β under-covered (drift25, slope25). Each
    # slope b is judged at the rise of its own null, ν of the means less b·t (the test
    # inverted), not at the record's ν: a true drift raises the record's (the offset-only K
    # takes the drift), which put drift records on a rise of about 1 and their interval
    # held the true slope far less often than a driftless record's (slope26)
    rise = interval_rise(nu)
    lo, hi, end_rises = _crossings(
        iprof, ks, iw0, iw1[:, -1], slope,
        max(wide * math.sqrt(max(rise, max(INTERVAL_RISE))), abs(slope) * 1e-6),
        lambda k: interval_rise(walk_directions(iprof.lam, float(k))))
    # the slope's standard error, what a resolved ramp's uncertainty is propagated with:
    # the profile's Δ ≤ 1 half-width (its curvature), not the 68 % interval's, which is
    # set for coverage under the ratio's inflated centre and is wider than the slope's
    # scatter (a drift moves neither)
    lo1, hi1, _r = _crossings(iprof, ks, iw0, iw1[:, -1], slope,
                              max(wide, abs(slope) * 1e-6), 1.0)
    # one line per half (a step makes two flat halves, a drift one slope)
    half = (t >= np.median(t)).astype(float)
    w2 = np.column_stack([w0, prof.white(np.column_stack([half, tc, tc * half]))])
    _k2, h2 = prof.best(ks, w2)
    return DriftLikelihood(math.copysign(math.sqrt(lr), slope), slope, lo, hi, float(ks[i]),
                           float(ks[j]), k_hi, float(top), max(0.0, h1 - h2), len(t),
                           record_s, nu, beta, rise, end_rises, 0.5 * (hi1 - lo1), used)


def _reml_range(ks: NDArray, nll: NDArray) -> tuple[float, float, float]:
    """(the K of least ``nll``, and where ``nll`` rises by 1 below and above it): the least
    from a parabola in K² through the grid's lowest point and its neighbours, each crossing
    interpolated linearly in K² between the grid's points (0 where the profile has not
    risen by 1 at K = 0; the grid's top where it has not at the top)."""
    ks = np.asarray(ks, dtype=float)
    nll = np.asarray(nll, dtype=float)
    if not np.any(np.isfinite(nll)):
        return math.nan, math.nan, math.nan
    j = int(np.argmin(nll))
    k2 = ks * ks
    best, least = float(ks[j]), float(nll[j])
    if 0 < j < len(ks) - 1 and np.all(np.isfinite(nll[j - 1:j + 2])):
        a, b, c = np.polyfit(k2[j - 1:j + 2], nll[j - 1:j + 2], 2)
        if a > 0 and k2[j - 1] < -b / (2 * a) < k2[j + 1]:
            best = math.sqrt(-b / (2 * a))
            least = min(least, float(c - b * b / (4 * a)))
    lim = least + 1.0

    def cross(a: int, b: int) -> float:  # between a (≤ lim) and b (> lim)
        return math.sqrt(float(np.interp(lim, [nll[a], nll[b]], [k2[a], k2[b]])))

    below = np.flatnonzero((np.arange(len(ks)) < j) & (nll > lim))
    lo = cross(int(below[-1]) + 1, int(below[-1])) if below.size else 0.0
    above = np.flatnonzero((np.arange(len(ks)) > j) & (nll > lim))
    hi = cross(int(above[0]) - 1, int(above[0])) if above.size else float(ks[-1])
    return best, min(lo, best), max(hi, best)


#: B's grid for K's profile beside a slope (``walk_beside_slope``): 0 and this many points
#: from a sixteenth of the largest B the AVAR fit allows to twice it.
B_POINTS = 25


def walk_beside_slope(fit: NoiseFit, means: NDArray, block_s: float,
                      refit: NoiseFit | None = None) -> tuple[float, float, float] | None:
    """The walk K beside a fitted slope from the block means: (K, and its Δ(−2 ln L) ≤ 1
    range below and above), None where it cannot be computed.

    K's *restricted* likelihood (``_Profile.k_profile_reml``): the slope, fitted, takes the
    walk's own linear part, and K's ordinary profile beside it is biased low by that much
    (on means drawn from the model itself; tests/core/test_drift.py). N at the fit's value
    (the short τ pin it); B *profiled* under what the AVAR fit knows of it, a Gaussian in
    B² at the fit's θ and standard error (an absent B at 0, its upper limit z_present
    standard errors above): B and K trade at the block means' scales, and a B held at a
    value the fit got wrong (absent, on some of the adversary's drift records) moved K by
    more than its range. Where ``fit`` has no B and ``refit`` (the noise refitted on the
    AVAR less the fitted line) has one, B is profiled under the refit's: a steep ramp holds
    the AVAR from the flicker floor on, the first fit then finds no B, and B held near 0
    gave K the block means' flicker (a walk below the flicker floor read far above its own
    K, and the ramp's cross term with it). Costs one factorisation per B; run only beside
    a resolved ramp."""
    yb = np.asarray(means, dtype=float).reshape(-1)
    if len(yb) < MIN_BLOCKS or not np.all(np.isfinite(yb)):
        return None
    t = (np.arange(len(yb)) + 0.5) * block_s
    n_w = float(fit.terms["velocity_random_walk"].value or 0.0)
    if not n_w > 0:
        return None
    if refit is not None and not fit.terms["bias_instability"].present and \
            refit.terms["bias_instability"].present:
        b_fit = refit  # (N and K's range stay the first fit's: the short τ pin N)
    else:
        b_fit = fit
    b_term = b_fit.terms["bias_instability"]
    j = next((i for i, c in enumerate(b_fit.components) if c.cause == "bias_instability"),
             None)
    theta = float(b_fit.theta[j]) if j is not None and j < len(b_fit.theta) else 0.0
    if b_term.present and theta > 0 and j is not None:
        se = math.sqrt(max(float(b_fit.theta_cov[j, j]), 0.0))
    else:
        theta, se = 0.0, float(b_term.upper or 0.0) ** 2 / b_fit.z_present
    b_top = max(math.sqrt(theta + se), float(b_term.hi or 0.0), float(b_term.upper or 0.0))
    grid = (np.concatenate([[0.0], np.geomspace(b_top / 16.0, 2.0 * b_top, B_POINTS)])
            if se > 0 and b_top > 0 else np.array([math.sqrt(theta)]))
    top = K_SPAN * max(_k_upper(fit), n_w / (len(t) * block_s))
    ks = np.concatenate([[0.0], np.geomspace(top * 10.0**-K_DECADES, top, K_POINTS)])
    tc = t - t.mean()
    nll = np.full(len(ks), np.inf)
    for b in grid:
        try:
            prof = _Profile(yb, t, block_s, n_w, float(b))
        except np.linalg.LinAlgError:
            continue
        w1 = np.column_stack([prof.white(np.ones_like(t)), prof.white(tc)])
        pen = ((b * b - theta) / se) ** 2 if se > 0 else 0.0
        nll = np.fmin(nll, prof.k_profile_reml(ks, w1) + pen)
    k, lo, hi = _reml_range(ks, nll)
    return (k, lo, hi) if math.isfinite(k) else None


def walk_directions(lam: NDArray, k: float) -> float:
    """How many directions of the means the walk K holds: Σ w_i² with w_i = K²λ_i/(1 + K²λ_i)
    its share of the whitened, rotated direction i (``_Profile``), 2θ²·I(θ) with I the
    Fisher information of θ = K² (the χ² degrees of freedom K² is measured with)."""
    th = k * k * np.asarray(lam, dtype=float)
    return float(np.sum((th / (1.0 + th)) ** 2))


def bartlett(walk_dof: float) -> float:
    """The factor the slope's likelihood ratio (K profiled) exceeds χ²(1) by at its 1 %
    point under the null, as a function of ``walk_directions`` at the offset-only K: a
    table (``BARTLETT_DOF``, ``BARTLETT``) measured once by simulation from the model
    itself (``python -m benchmarks drift_null --table``), interpolated in ln(1 + ν)."""
    x = np.log1p(np.asarray(BARTLETT_DOF, dtype=float))
    return float(np.interp(math.log1p(max(walk_dof, 0.0)), x, np.asarray(BARTLETT)))


def interval_rise(walk_dof: float) -> float:
    """Where the slope's 68 % interval ends: the rise of its profile −2 ln L (K profiled)
    that the likelihood ratio stays below on 68.3 % of null draws, as a function of
    ``walk_directions`` at the offset-only K (``INTERVAL_RISE_DOF``, ``INTERVAL_RISE``,
    measured with ``bartlett``'s table by ``python -m benchmarks drift_null --table``),
    interpolated in ln(1 + ν), never below 1."""
    x = np.log1p(np.asarray(INTERVAL_RISE_DOF, dtype=float))
    r = float(np.interp(math.log1p(max(walk_dof, 0.0)), x, np.asarray(INTERVAL_RISE)))
    return max(1.0, r)


def _crossings(prof: _Profile, ks: NDArray, w0: NDArray, wt: NDArray, slope: float,
               span: float, rise: float | Callable[[float], float] = 1.0
               ) -> tuple[float, float, tuple[float, float]]:
    """The slopes b whose profile −2 ln L stands at most ``rise`` above its minimum
    (searched over ±4·``span`` about ``slope``, widened while the ends are still inside):
    (lowest, highest, the rise at each). ``rise`` is a number (1 for a χ²(1) ratio) or a
    function of the K each b is profiled at, the offset-only K of the means less b·t
    (``_Profile.slope_profile_k``): each b tested at the rise of its own null
    (``drift_likelihood``)."""
    rise_of = rise if callable(rise) else (lambda _k, r=float(rise): r)
    for _ in range(4):
        grid = slope + span * np.linspace(-4.0, 4.0, 161)
        prof_, at = prof.slope_profile_k(ks, w0, wt, grid)
        least = float(np.min(prof_))
        over = prof_ - least - np.array([rise_of(k) for k in at])  # ≤ 0 inside
        if over[0] > 0 and over[-1] > 0:
            inside = np.flatnonzero(over <= 0)
            a, b = int(inside[0]), int(inside[-1])
            lo, r_lo = _edge(prof, ks, w0, wt, least, rise_of, grid[a], grid[a - 1])
            hi, r_hi = _edge(prof, ks, w0, wt, least, rise_of, grid[b], grid[b + 1])
            return lo, hi, (r_lo, r_hi)
        span *= 3.0
    return -math.inf, math.inf, (math.nan, math.nan)


def _edge(prof: _Profile, ks: NDArray, w0: NDArray, wt: NDArray, least: float,
          rise_of: Callable[[float], float], inside: float, outside: float
          ) -> tuple[float, float]:
    """The end of the slopes ``_crossings`` keeps between ``inside`` (kept) and
    ``outside`` (not), by bisection on the profile itself (the rise of a slope's own null
    steps where its K does, so interpolating between grid points would not find it), and
    the rise there."""
    r_in = math.nan
    for _ in range(30):
        mid = 0.5 * (inside + outside)
        p, k = prof.slope_profile_k(ks, w0, wt, np.array([mid]))
        r = rise_of(float(k[0]))
        if float(p[0]) - least <= r:
            inside, r_in = mid, r
        else:
            outside = mid
    if math.isnan(r_in):
        k = prof.slope_profile_k(ks, w0, wt, np.array([inside]))[1]
        r_in = rise_of(float(k[0]))
    return float(inside), float(r_in)


def _block_sums(a: NDArray, b: int) -> NDArray[np.float64]:
    """Sums of consecutive ``b``-row blocks of ``a`` (its length a multiple of ``b``), each
    one sequential reduction; a block the stream hands in pieces is the sum of its pieces'
    sums (equal to one reduction to rounding). ``reduceat`` along the rows, not a mean over
    the middle axis of (blocks, b, C), which strides over C columns and cost the pass more
    than its Allan sums."""
    return np.asarray(np.add.reduceat(a, np.arange(0, len(a), b), axis=0))


class BlockSums:
    """The drift test's block sums over the rows [``own_from``, ``own_until``) of a record
    (a chunk of a parallel pass, ``analysis/parallel.py``; every row for ``BlockMeans``):
    fed the record from its start (the stretches between gaps, and so the blocks, are
    counted from where each stretch starts), it keeps the sums and row counts of the blocks
    it owns rows of, keyed by (stretch start, block). The chunks' parts add up
    (``BlockSumsPart.__add__``) to the one pass's blocks; a block a cut splits is summed in
    two pieces, so its mean equals the one pass's to rounding, not to the bit."""

    def __init__(self, n_channels: int, block: int, own_from: int = 0,
                 own_until: int | None = None) -> None:
        self.block = max(1, int(block))
        self._c = int(n_channels)
        self._own = (int(own_from), own_until)
        self._pos = 0
        self._start = 0  # where the current stretch began
        self._sums: dict[tuple[int, int], NDArray[np.float64]] = {}
        self._counts: dict[tuple[int, int], int] = {}
        # the sum and rows of one block not yet complete
        self._pend_sum: NDArray[np.float64] = np.zeros(self._c)
        self._pend_n = 0
        self._key: tuple[int, int] | None = None

    def update(self, a: NDArray) -> None:
        a = np.asarray(a, dtype=float)
        if a.ndim == 1:
            a = a[:, None]
        lo = self._pos
        self._pos += len(a)
        own_from, own_until = self._own
        s, e = max(lo, own_from), min(self._pos, self._pos if own_until is None else own_until)
        if s >= e:
            return
        x, b, st = a[s - lo:e - lo], self.block, self._start
        first = (s - st) // b
        cuts = st + np.arange(first + 1, (e - 1 - st) // b + 1) * b - s
        for k, piece in enumerate(np.split(x, cuts)):
            key = (st, first + k)
            if key != self._key:
                self._flush()
                self._key = key
            # summed piece by piece, as ``BlockMeans`` sums a block the pass hands in pieces
            total = _block_sums(piece, len(piece))[0]
            self._pend_sum = total if self._pend_n == 0 else self._pend_sum + total
            self._pend_n += len(piece)
            if self._pend_n >= b:
                self._flush()

    def _flush(self) -> None:
        if self._key is None or not self._pend_n:
            return
        self._sums[self._key] = (self._sums[self._key] + self._pend_sum
                                 if self._key in self._sums else self._pend_sum)
        self._counts[self._key] = self._counts.get(self._key, 0) + self._pend_n
        self._pend_n, self._key = 0, None

    def gap(self) -> None:
        self._flush()
        self._start = self._pos

    def part(self) -> BlockSumsPart:
        self._flush()
        return BlockSumsPart(self.block, self._c, dict(self._sums), dict(self._counts))


@dataclass(frozen=True)
class BlockSumsPart:
    """A chunk's ``BlockSums``: added up over a pass's chunks, ``longest`` gives what one
    ``BlockMeans`` over the record gives (to rounding in the blocks a cut splits)."""

    block: int
    n_channels: int
    sums: dict[tuple[int, int], NDArray[np.float64]]
    counts: dict[tuple[int, int], int]

    def __add__(self, other: BlockSumsPart) -> BlockSumsPart:
        sums, counts = dict(self.sums), dict(self.counts)
        for key, v in other.sums.items():
            sums[key] = sums[key] + v if key in sums else v
            counts[key] = counts.get(key, 0) + other.counts[key]
        return BlockSumsPart(self.block, self.n_channels, sums, counts)

    def longest(self) -> NDArray[np.float64]:
        """(blocks, C) means of the longest stretch's whole blocks (the first of equal
        ones, as ``BlockMeans``)."""
        full: dict[int, list[int]] = {}
        for (st, k), c in self.counts.items():
            if c == self.block:
                full.setdefault(st, []).append(k)
        best: tuple[int, int] | None = None  # (blocks, stretch start)
        for st in sorted(full):
            if best is None or len(full[st]) > best[0]:
                best = (len(full[st]), st)
        if best is None:
            return np.zeros((0, self.n_channels))
        st = best[1]
        return np.stack([self.sums[(st, k)] / self.block for k in sorted(full[st])])


class BlockMeans(BlockSums):
    """Block means of C channels, ``block`` samples each, kept for the longest stretch
    without a gap (no block straddles one): what the drift test reads, carried by the pass
    that computes the OADEV, so a one-shot stream needs no second read. ``BlockSums`` owning
    every row: one piece of code for the one pass and the parallel chunks."""

    def __init__(self, n_channels: int, block: int) -> None:
        super().__init__(n_channels, block)

    def longest(self) -> NDArray[np.float64]:
        """(blocks, C) means of the longest stretch so far (the current one included)."""
        return self.part().longest()


def drift_block(n_samples: int) -> int:
    """Samples per block for a record of ``n_samples``: at most ``DRIFT_BLOCKS`` blocks."""
    return max(1, -(-int(n_samples) // DRIFT_BLOCKS))


# --------------------------------------------------------------------------------------------
# analyze: a detected drift made a resolved ramp


#: analyze's level for a drift: two-sided 1 % (the slope's sign is free).
LEVEL = 0.01


def _k_upper(fit: NoiseFit) -> float:
    """The most K the AVAR fit allows: its 68 % upper bound where present, its one-sided
    upper limit where absent (0 where it has neither)."""
    k = fit.terms.get("rate_random_walk")
    if k is None:
        return 0.0
    return float((k.hi if k.present else k.upper) or 0.0)


def channel_drift(fit: NoiseFit, means: NDArray, block_s: float,
                  allan: AllanResult | None = None, refit: Callable[..., NoiseFit] | None = None
                  ) -> DriftLikelihood | None:
    """``drift_likelihood`` of one channel's block means (``BlockMeans.longest``) with the
    fit's N and B and K's profile reaching past the fit's upper K; None where the record has
    fewer than ``MIN_BLOCKS`` blocks or the covariance does not factor. With ``allan`` (the
    channel's AVAR, which ``fit`` was fitted on) the slope's interval is computed under the
    N and B of the AVAR less the fitted line, refitted by ``refit`` (the channel's own
    ``fit_noise`` arguments; ``fit_noise`` itself by default) without a ramp: the noise of
    the slopes the interval tests (``drift_likelihood``'s ``beside``). Where that refit
    fails, the fit's N and B, recorded (``DriftLikelihood.interval_noise``)."""
    yb = np.asarray(means, dtype=float).reshape(-1)
    if len(yb) < MIN_BLOCKS or not np.all(np.isfinite(yb)):
        return None
    t = (np.arange(len(yb)) + 0.5) * block_s
    n_w = float(fit.terms["velocity_random_walk"].value or 0.0)
    b_i = float(fit.terms["bias_instability"].value or 0.0)
    if not n_w > 0:
        return None
    beside = None
    if allan is not None:
        beside = partial(_noise_beside_line, allan, yb, block_s, refit)
    try:
        return drift_likelihood(yb, t, block_s, n_w, b_i, _k_upper(fit), beside=beside)
    except np.linalg.LinAlgError:
        return None


def _noise_beside_line(allan: AllanResult, means: NDArray, block_s: float,
                       refit: Callable[..., NoiseFit] | None, slope: float
                       ) -> tuple[float, float] | None:
    """(N, B) of the AVAR less the line ``slope``·t (``_line_removed``), refitted without a
    ramp; None where the refit fails or finds no white N."""
    from avard.core.errors import FitError
    from avard.core.model.fit import fit_noise
    from avard.core.model.terms import TERMS

    fitter = refit if refit is not None else fit_noise
    tau = np.asarray(allan.tau, dtype=float)
    removed, _d, _known = _line_removed(means, block_s, tau, slope)
    less = replace(allan, var=np.asarray(allan.var, dtype=float) - removed)
    try:
        noise = fitter(less, terms=[t for t in TERMS if t != "rate_ramp"])
    except (FitError, np.linalg.LinAlgError, ValueError):
        return None
    n_w = float(noise.terms["velocity_random_walk"].value or 0.0)
    if not n_w > 0:
        return None
    return n_w, float(noise.terms["bias_instability"].value or 0.0)


def _line_removed(means: NDArray, block_s: float, tau: NDArray, slope: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """What the AVAR at ``tau`` loses when the line ``slope``·t is taken from the record
    (``resolve_drift``), and the mean difference D at each τ (``mean_difference``; 0 where
    not known) with where it is known."""
    g = tau**2 / 2.0
    d = mean_difference(np.asarray(means, dtype=float).reshape(-1), block_s, tau)
    known = np.isfinite(d)
    d0 = np.where(known, d, 0.0)
    removed = np.where(known, slope * tau * d0 - slope**2 * g, slope * slope * g)
    return np.asarray(removed, dtype=np.float64), np.asarray(d0, dtype=np.float64), known


def resolve_drift(fit: NoiseFit, allan: AllanResult, means: NDArray, block_s: float,
                  refit: Callable[..., NoiseFit], level: float = LEVEL
                  ) -> tuple[NoiseFit, DriftLikelihood | None]:
    """``fit`` with a drift the time domain finds (``channel_drift`` past ``level``) as a
    resolved rate ramp: R the GLS slope, its interval the slope's profile-likelihood one
    (K profiled), and the noise terms refitted (``refit(allan, terms=..., added_cov=...)``,
    the channel's own ``fit_noise`` arguments) on the AVAR of the record less the fitted
    line (``mean_difference``), what is left uncertain added to the AVAR's covariance, so K
    is no longer made of the drift. Where no drift passes, a ramp the AVAR fit claimed is
    not (``_no_ramp``); ``fit`` unchanged (and the test, or None) where the refit fails."""
    from avard.core.errors import FitError
    from avard.core.model.fit import Component, TermEstimate
    from avard.core.model.terms import TERMS, UNITS

    lik = channel_drift(fit, means, block_s, allan, refit)
    if lik is None:
        return fit, lik
    if not lik.passes(two_sided_z(level)):
        return _no_ramp(fit, allan, lik, refit, level), lik
    tau = np.asarray(allan.tau, dtype=float)
    g = tau**2 / 2.0
    # the ramp's uncertainty propagated with the slope's standard error (its scatter), not
    # the 68 % interval's half-width (slope26: that made the AVAR intervals beside a
    # resolved ramp wider than their estimates scatter at the longest τ)
    r, se = abs(lik.slope), lik.slope_sd if math.isfinite(lik.slope_sd) else lik.slope_se
    var_r2 = 4.0 * r * r * se**2 + 2.0 * se**4
    # The AVAR of the record less the fitted line, not the AVAR less R̂²τ²/2: each Allan
    # difference loses R̂τ, so the variance loses R̂τ·D(τ) − R̂²τ²/2 with D the mean
    # difference at τ. D holds the noise's own mean difference, which the ramp multiplies
    # (a cross term R·τ·D_noise the size of the walk's whole AVAR at the longest τ when the
    # ramp is a few times its detectable minimum, and no model of it): subtracting R̂²τ²/2
    # left it in, and K beside a resolved ramp scattered far beyond its interval.
    removed, d0, known = _line_removed(means, block_s, tau, lik.slope)
    # what is left uncertain: (R − R̂)·τ·D_noise and (R − R̂)²τ²/2, both of the slope's
    # error, not of the ramp's size (R̂²'s own variance where D is not known)
    dn = np.where(known, tau * (d0 - lik.slope * tau), 0.0)
    added = se**2 * np.outer(dn, dn) + 2.0 * se**4 * np.outer(g, g)
    added[np.ix_(~known, ~known)] = var_r2 * np.outer(g[~known], g[~known])
    less = replace(allan, var=np.asarray(allan.var, dtype=float) - removed)
    try:
        noise = refit(less, terms=[t for t in TERMS if t != "rate_ramp"], added_cov=added)
    except FitError:
        return fit, lik
    noise = _walk_from_time_domain(noise, lik, walk_beside_slope(fit, means, block_s, noise))
    # the slope's measured variance (the profile's Δ ≤ 1 curvature, what the ramp's θ
    # covariance holds) over the GLS slope's under the fitted noise: the scale the ramp's
    # cross term is taken at by ``signal_edf.resolved_ramp_interval`` (measured, not what
    # analyze prints: at 12 h the curvature is narrower than the slope's scatter, and the
    # 68 % interval's half-width is wider than it at 1 h; docs/log/2026-11-29-cov29.md)
    ratio = se**2 / model_slope_var(noise, means, block_s)
    params = {CROSS_SCALE: ratio} if math.isfinite(ratio) and ratio > 0 else {}
    ramp = Component("rate_ramp", "rate_ramp", params, "value", UNITS["rate_ramp"])
    k = len(noise.theta)
    cov = np.zeros((k + 1, k + 1))
    cov[:k, :k] = noise.theta_cov
    cov[k, k] = var_r2
    lo, hi = sorted((abs(lik.slope_lo), abs(lik.slope_hi)))
    if lik.slope_lo * lik.slope_hi <= 0:
        lo = 0.0
    terms = {**noise.terms, "rate_ramp": TermEstimate(r, lo, hi, UNITS["rate_ramp"], True,
                                                      abs(lik.z))}
    return replace(noise, terms=terms, components=[*noise.components, ramp],
                   theta=np.append(noise.theta, r * r), theta_cov=cov,
                   resolved_apart=("rate_ramp",), drift_interval_noise=lik.interval_noise), lik


#: The key, in a resolved ramp's ``Component.params``, of the slope's measured variance over
#: the GLS slope's under the fitted noise (``resolve_drift``, ``model_slope_var``).
CROSS_SCALE = "cross_scale"


def model_slope_var(noise: NoiseFit, means: NDArray, block_s: float) -> float:
    """The GLS slope's variance on the block ``means`` (an offset beside it) under the
    noise ``noise`` holds at its point values (white N, flicker B, walk K: the covariance
    ``block_noise_cov`` of the drift test), NaN where it has no white N or does not factor.

    Why: beside a resolved ramp the estimate's error holds the ramp's cross term with the
    noise, R·τ·D_noise (D_noise the noise's mean Allan difference), of variance S·c under
    the fitted spectrum (``cross_term.cross_term_variance``). c read alone follows the
    estimate: its walk is read from the same long τ, and a record whose noise rose at the
    ends has a high estimate, a high fitted walk and a wide interval (docs/log/
    2026-11-29-cov28b.md). D_noise/τ is a linear slope estimator on the same noise, so c is
    the GLS slope's variance times a ratio that both share the walk of: the ratio is taken
    from the model, the slope's variance from the time domain's own profile, where the
    drift test measured it."""
    yb = np.asarray(means, dtype=float).reshape(-1)
    n_w = float(noise.terms["velocity_random_walk"].value or 0.0)
    if len(yb) < 3 or not n_w > 0:
        return math.nan
    b_i = float(noise.terms["bias_instability"].value or 0.0)
    j = next((i for i, c in enumerate(noise.components) if c.cause == "rate_random_walk"),
             None)
    k2 = float(noise.theta[j]) if j is not None and j < len(noise.theta) else 0.0
    t = (np.arange(len(yb)) + 0.5) * block_s
    c = block_noise_cov(t, block_s, n_w, b_i, math.sqrt(max(k2, 0.0)))
    x = np.column_stack([np.ones_like(t), t - t.mean()])
    try:
        L = np.linalg.cholesky(c)
        w = np.linalg.solve(L, x)
        return float(np.linalg.inv(w.T @ w)[1, 1])
    except np.linalg.LinAlgError:
        return math.nan


def mean_difference(means: NDArray, block_s: float, tau: NDArray) -> NDArray[np.float64]:
    """The mean of the overlapping Allan differences ȳ(t+τ) − ȳ(t) at each ``tau`` (the
    averages over τ, every start t in the record), from the block means ``means`` (each
    ``block_s`` long, the record read as piecewise constant): with S the running integral
    and I its integral, (1/τ(T−2τ))·∫₀^{T−2τ} S(t+2τ) − 2S(t+τ) + S(t) dt, exact in I. NaN
    where 2τ ≥ T (no difference fits)."""
    y = np.asarray(means, dtype=float)
    tau = np.asarray(tau, dtype=float)
    nb = len(y)
    T = nb * block_s
    out = np.full(tau.shape, np.nan)
    if nb == 0:
        return out
    S = np.concatenate([[0.0], np.cumsum(y) * block_s])
    I_edges = np.concatenate([[0.0], np.cumsum(0.5 * (S[:-1] + S[1:]) * block_s)])

    def integral(t: NDArray) -> NDArray[np.float64]:
        k = np.clip(np.floor(t / block_s).astype(int), 0, nb - 1)
        u = t - k * block_s
        return I_edges[k] + S[k] * u + y[k] * u * u / 2.0

    ok = (tau > 0) & (2.0 * tau < T)
    tk = tau[ok]
    full = I_edges[-1]
    num = (full - integral(2.0 * tk) - 2.0 * (integral(T - tk) - integral(tk))
           + integral(T - 2.0 * tk))
    out[ok] = num / (tk * (T - 2.0 * tk))
    return out


def _no_ramp(fit: NoiseFit, allan: AllanResult, lik: DriftLikelihood,
             refit: Callable[..., NoiseFit], level: float) -> NoiseFit:
    """``fit`` where the time domain finds no drift past ``level``: its floor kept, and a
    rate ramp the AVAR fit claimed there not claimed. The AVAR fit's ramp test weighs the
    ramp against a walk through the long-τ points alone, which a walk's realisation that
    happens to curve like τ² passes (a no-ramp record of the adversary's drift class, seed
    305: R present, K absent); the block means, which tell a drift's one-signed increments
    from a walk's, did not find it. The AVAR is then refitted without R (K takes the rise,
    as the fit reads "ramp or random walk"), and R is absent with the time domain's upper
    limit at the test's level: |slope| + z·(its 68 % half-width)."""
    from avard.core.errors import FitError
    from avard.core.model.fit import TermEstimate
    from avard.core.model.terms import TERMS, UNITS

    r = fit.terms.get("rate_ramp")
    if r is None or not r.present or "rate_ramp" in fit.resolved_apart:
        return replace(fit, drift_floor=lik.floor, drift_slope=_slope(lik),
                       drift_interval_noise=lik.interval_noise)
    try:
        noise = refit(allan, terms=[t for t in TERMS if t != "rate_ramp"])
    except FitError:
        return replace(fit, drift_floor=lik.floor, drift_slope=_slope(lik),
                       drift_interval_noise=lik.interval_noise)
    upper = abs(lik.slope) + two_sided_z(level) * lik.slope_se
    absent = TermEstimate(None, None, None, UNITS["rate_ramp"], False, abs(lik.z),
                          upper if math.isfinite(upper) else None)
    return replace(noise, terms={**noise.terms, "rate_ramp": absent}, drift_floor=lik.floor,
                   drift_slope=_slope(lik), drift_interval_noise=lik.interval_noise)


def _slope(lik: DriftLikelihood) -> tuple[float, float, float] | tuple[()]:
    """(slope, lo, hi) of the test where it carries a floor (``NoiseFit.drift_slope``), ()
    where it carries none."""
    if not lik.floor > 0:
        return ()
    return (float(lik.slope), float(lik.slope_lo), float(lik.slope_hi))


def _walk_from_time_domain(noise: NoiseFit, lik: DriftLikelihood,
                           walk: tuple[float, float, float] | None = None) -> NoiseFit:
    """``noise`` (the AVAR fit less the ramp) with its walk K reaching what the time domain
    finds beside the drift, ``walk`` (``walk_beside_slope``: K and its range; without it,
    the ordinary profile's K beside the slope, ``lik.k_drift``, its upper 1σ
    ``lik.k_drift_hi`` mirrored below). Where the AVAR finds K, its value is kept and its
    interval covers both estimates; where it finds none, the time domain's K stands. The
    AVAR fit's τ stop at T/8 and, with the fitted line taking the walk's own linear part,
    often find no K; a ramp's cross term with the noise weighs the record's ends, where the
    walk dominates, so without it the printed EDF of the 12 h "steep" records was 2–3 times
    what their estimates scatter with (coverage 50–53 % at 1024–4096 s)."""
    from avard.core.model.fit import TermEstimate

    j = next((i for i, c in enumerate(noise.components) if c.cause == "rate_random_walk"),
             None)
    if walk is None:
        k_hi = lik.k_drift_hi
        k = max(lik.k_drift, math.sqrt(0.5) * k_hi)  # (noise_psd drops a θ of 0)
        walk = (k, math.sqrt(max(2.0 * k * k - k_hi * k_hi, 0.0)), k_hi)
    k, k_lo, k_hi = walk
    up = k_hi**2
    if j is None or not up > 0:
        return noise
    theta = float(noise.theta[j])
    se = math.sqrt(max(float(noise.theta_cov[j, j]), 0.0))
    old = noise.terms["rate_random_walk"]
    if theta > 0 and old.present:
        # Two estimates of one walk, the AVAR's and the block means': the interval covers
        # both, the value stays the AVAR's. (Taking the time domain's value whenever it was
        # the higher kept the larger of two scattered estimates, and the interval beside a
        # resolved ramp held the generator's K on under half of the adversary's drift
        # records.)
        lo = min(float(old.lo if old.lo is not None else 0.0), k_lo)
        hi = max(float(old.hi if old.hi is not None else 0.0), k_hi)
        if lo >= (old.lo or 0.0) and hi <= (old.hi or 0.0):
            return noise
        wide = max(hi * hi - theta, se)  # θ's upper 1σ reaches the top (noise_psd)
        cov = np.array(noise.theta_cov, dtype=float)
        grow = wide / se if se > 0 else 0.0
        if grow > 0:
            cov[j, :] *= grow
            cov[:, j] *= grow
        else:
            cov[j, :] = 0.0
            cov[:, j] = 0.0
            cov[j, j] = wide * wide
        term = replace(old, lo=lo, hi=hi)
        return replace(noise, theta_cov=cov, terms={**noise.terms, "rate_random_walk": term})
    point = k * k if k > 0 else 0.5 * up  # (noise_psd drops a θ of 0)
    new_theta = np.array(noise.theta, dtype=float)
    new_theta[j] = point
    cov = np.array(noise.theta_cov, dtype=float)
    cov[j, :] = 0.0
    cov[:, j] = 0.0
    cov[j, j] = max(up - point, 0.0) ** 2
    term = TermEstimate(math.sqrt(point), min(k_lo, k), max(k_hi, k), old.unit, True, old.z)
    return replace(noise, theta=new_theta, theta_cov=cov,
                   terms={**noise.terms, "rate_random_walk": term})
