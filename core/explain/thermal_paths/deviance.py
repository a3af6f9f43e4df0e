"""The pooled Allan-covariance fit of a regressor subset: its coefficients and its deviance (−2
ln L) on the octave sums."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from avard.core.explain.thermal_fit.sums import OctaveSums, covariance_block
from avard.core.model.nnls import _lstsq
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class _View:
    """Allan covariance (K, C, C) of (y, regressors…), the axis's EDF ν (K,) and the noise
    AVAR s (K,) the residual is weighed against, at the τ used."""

    cov: NDArray[np.float64]
    nu: NDArray[np.float64]
    s: NDArray[np.float64]
    #: the logged readings' rounding AVAR (K²) at these τ (``sawtooth_avar``), or zeros
    rounding: NDArray[np.float64] | None = None
    #: per regressor subset (``_blocks``): its covariance blocks and its fit, kept because
    #: every candidate's grid is fitted (``_fit``) and then scored (``_dev``) on the same
    #: views, and the jackknife fits the best point again on views that fitted it already
    _memo: dict[tuple[int, ...], _Blocks] = field(default_factory=dict, init=False,
                                                  compare=False, repr=False)

    @cached_property
    def weights(self) -> NDArray[np.float64]:
        """ν/s, each τ's weight in the normal equations (``_fit``)."""
        return np.asarray(self.nu / self.s, dtype=np.float64)

    def rounding_share(self, coefficient: float) -> float:
        """Σ_k ν_k·min(1, c²R_k/s_k): the part of this view's deviance the readings'
        rounding passed through a coupling ``coefficient`` makes up. A model that passes
        less of it (two lags of opposite sign smooth the 0.0625 K steps more than one) gains
        up to this much without any physics."""
        if self.rounding is None or not len(self.nu):
            return 0.0
        share = np.minimum(1.0, coefficient**2 * self.rounding / self.s)
        return float(np.sum(self.nu * share))


def _view(sums: OctaveSums, edf_ref: NDArray, n_ref: NDArray, ok_tau: NDArray[np.bool_],
          s_ref: NDArray | None = None, r_ref: NDArray | None = None) -> _View:
    k = min(len(sums.ms), len(edf_ref), len(ok_tau))
    cov = sums.cov()[:k]
    with np.errstate(invalid="ignore", divide="ignore"):
        nu = np.asarray(edf_ref[:k], float) * sums.n[:k] / np.asarray(n_ref[:k], float)
    s = cov[:, 0, 0] if s_ref is None else np.asarray(s_ref[:k], float)
    good = (ok_tau[:k] & np.isfinite(nu) & (nu >= 3) & np.all(np.isfinite(cov), axis=(1, 2))
            & np.isfinite(s) & (s > 0))
    return _View(cov[good], nu[good], s[good],
                 None if r_ref is None else np.asarray(r_ref[:k], float)[good])


#: the view of some sums on an axis's weights (``_view`` with its EDF, τ and s bound)
_Weights = Callable[[OctaveSums], _View]

class _Blocks:
    """The covariance blocks of one regressor subset ``idx`` of a view: V_uy (K, n) and
    V_uu (K, n, n), gathered once (``thermal_fit.covariance_block``: the same numbers in the
    same memory order as the plain indexing,
    ``test_the_paths_fit_reads_its_blocks_as_the_plain_indexing_does``), and its fit β once
    computed (``_fit``, a pure function of the view and ``idx``)."""

    __slots__ = ("beta", "vuu", "vuy")

    def __init__(self, c: NDArray[np.float64], idx: list[int]) -> None:
        self.vuy: NDArray[np.float64] = c[:, idx, 0]
        self.vuu: NDArray[np.float64] = covariance_block(c, idx)
        self.beta: NDArray[np.float64] | None = None


def _blocks(v: _View, idx: list[int]) -> _Blocks:
    key = tuple(idx)
    got = v._memo.get(key)
    if got is None:
        got = v._memo[key] = _Blocks(v.cov, idx)
    return got


def _resid(v: _View, idx: list[int], beta: NDArray) -> NDArray[np.float64]:
    """The residual AVAR r_k(β) = V_yy − 2βᵀV_uy + βᵀV_uuβ."""
    c = v.cov
    vy = c[:, 0, 0]
    if not idx:
        return np.asarray(vy, dtype=float)
    bl = _blocks(v, idx)
    r = vy - 2 * bl.vuy @ beta + np.einsum("i,kij,j->k", beta, bl.vuu, beta)
    return np.asarray(r, dtype=float)


def _fit(v: _View, idx: list[int]) -> NDArray[np.float64]:
    """β minimising Σ_k ν_k r_k(β)/s_k (weighted normal equations)."""
    if not len(v.nu) or not idx:
        return np.zeros(len(idx))
    bl = _blocks(v, idx)
    if bl.beta is None:
        bl.beta = _solve(v, bl)
        bl.beta.flags.writeable = False
    return bl.beta.copy()


def _solve(v: _View, bl: _Blocks, vuy: NDArray | None = None) -> NDArray[np.float64]:
    # (the same operations as np.diag, np.max, np.outer and np.ix_ make, without their
    # wrappers' per-call cost: thousands of these small solves per axis; the weights ν/s
    # divided once per view); ``vuy``: another column's V_u· in y's place
    w = v.weights
    A = np.einsum("k,kij->ij", w, bl.vuu)
    b = w @ (bl.vuy if vuy is None else vuy)
    d = A.diagonal()
    # a regressor this view does not see (a start state in a part after the start) stays 0
    live = np.flatnonzero(d > 1e-14 * max(float(np.maximum.reduce(d)), 1e-300))
    out = np.zeros(len(d))
    if len(live) == len(d):
        sc = np.sqrt(d)
        out[:] = np.array(_lstsq(A / (sc[:, None] * sc[None, :]), b / sc, rcond=1e-10)) / sc
    elif len(live):
        sc = np.sqrt(d[live])
        # (numpy's lstsq to the bit, without its per-call checks)
        out[live] = np.array(_lstsq(A[live[:, None], live] / (sc[:, None] * sc[None, :]),
                                    b[live] / sc, rcond=1e-10)) / sc
    return out


def _ungained(v: _View, idx: list[int], beta: NDArray, ref: int) -> NDArray[np.float64]:
    """A dT/dt fit's coefficients ``beta`` (columns ``idx``: the static lag's, the smoothed
    rate column's, nuisance) read back through the smoothing's gain: the fit is linear in y
    (``_fit``), so a response r·x to the true rate x (column ``ref``, ``Column("slope")``)
    comes out as r·γ, γ = x's own fit on the same columns and weights; the smoothing's
    1/(1 + ω²s²) on whatever lines the drive has (a compressor's harmonics: 0.82 at its
    third) puts γ_rate above 1 and γ_lag beside it. r = β_rate/γ_rate and c = β_lag −
    r·γ_lag. The fit itself (θ, the deviance, the choice) stays on the smoothed column: the
    reference only calibrates it, on the record's own drive. A γ_rate that is not positive
    (a reference that does not follow the column) leaves ``beta`` as it is."""
    if not len(v.nu):
        return np.array(beta, dtype=float)
    return _through(beta, _solve(v, _blocks(v, idx), v.cov[:, idx, ref]))


def _through(beta: NDArray, gain: ArrayLike) -> NDArray[np.float64]:
    """``beta`` (c, r, …) read through a dT/dt column's gain γ (``_ungained``)."""
    out = np.array(beta, dtype=float)
    g = np.asarray(gain, dtype=float)
    if len(g) < 2 or not (math.isfinite(g[1]) and g[1] > 0):
        return out
    out[1] = beta[1] / g[1]
    out[0] = beta[0] - out[1] * g[0]
    return out


def _held_dev(v: _View, idx: list[int], beta: NDArray, n: int) -> float:
    """The deviance on held-out data of a model whose first ``n`` coefficients (the
    couplings) are ``beta[:n]``, fitted elsewhere; the rest (the lag filter's start states,
    which belong to the record's start and not to the sensor) are refitted here."""
    if not len(v.nu):
        return 0.0
    # the view of (y − Σ β_i u_i, nuisance…) by the linear map of the channels
    C = v.cov.shape[1]
    A = np.zeros((1 + len(idx) - n, C))
    A[0, 0] = 1.0
    A[0, idx[:n]] -= beta[:n]
    for r, j in enumerate(idx[n:], start=1):
        A[r, j] = 1.0
    w = _View(np.einsum("ri,kij,sj->krs", A, v.cov, A), v.nu, v.s)
    rest = list(range(1, A.shape[0]))
    return _dev(w, rest, _fit(w, rest))


def _dev(v: _View, idx: list[int], beta: NDArray) -> float:
    """Σ_k ν_k r_k(β)/s_k: −2 ln L up to a constant, the Allan differences Gaussian with the
    noise AVAR s_k (the one-lag model's residual on the whole record, the same weights for
    every candidate), ν_k of them independent at τ_k. A noise level free at each τ instead
    (Σ ν ln r) let three regressors cancel the few differences of the longest τ exactly and
    ran to −∞ there."""
    if not len(v.nu):
        return 0.0
    return float(np.sum(v.nu * _resid(v, idx, beta) / v.s))
