"""One fit's problem: the usable τ, the model's columns on them, and the GLS with non-negative
terms under the model's own covariance, reweighted until it settles."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from avard.core.model.nnls import nnls
from numpy.typing import NDArray


def _n_samples(result: Any) -> NDArray[np.float64]:
    """Samples spanned by the differences of each τ: (n − 1)·stride + 2m (≈ N for every τ)."""
    stride = np.asarray(getattr(result, "stride", np.ones_like(result.m)), dtype=float)
    return (np.asarray(result.n, float) - 1.0) * stride + 2.0 * np.asarray(result.m, float)


def _usable(result: Any, min_edf: float, min_averages: float,
            tau_range: tuple[float, float] | None) -> NDArray[np.intp]:
    """Indices of the τ points a fit may use: a finite positive AVAR, enough independent
    averages (≥ ``min_averages``) and EDF (≥ ``min_edf``) for a usable weight, inside
    ``tau_range`` (s). One cut for ``fit_noise`` and ``model_chi2``."""
    var = np.asarray(result.var, dtype=float)
    tau = np.asarray(result.tau, dtype=float)
    m = np.asarray(result.m, dtype=float)
    n = np.asarray(result.n, dtype=float)
    M = _n_samples(result)
    n_total = float(np.nanmax(M)) if len(M) else 0.0
    edf = np.asarray(getattr(result, "edf", np.full_like(var, np.nan)), dtype=float)
    ok = np.isfinite(var) & (var > 0) & (n > 0)
    # long-τ cut: too few independent averages, or too few EDF for a usable weight
    ok &= n_total / m >= min_averages
    ok &= ~(np.isfinite(edf) & (edf < min_edf))
    if tau_range is not None:
        ok &= (tau >= tau_range[0] * (1 - 1e-9)) & (tau <= tau_range[1] * (1 + 1e-9))
    return np.flatnonzero(ok)


#: ``_fit_active``'s result: θ, Cov θ[active], the AVAR covariance C and the χ² of the fit.
_ActiveFit = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]


@dataclass
class _Problem:
    """The fixed ingredients of one channel's fit over the τ points kept."""

    y: NDArray[np.float64]  # measured AVAR minus fixed components
    X: NDArray[np.float64]  # (K, A) basis of fitted components
    fixed: NDArray[np.float64]  # (K,) AVAR of fixed components
    G: NDArray[np.float64]  # (K, K, A+F, A+F) covariance kernels
    theta_fixed: NDArray[np.float64]
    M: NDArray[np.float64]  # (K,) number of difference positions
    edf_floor: NDArray[np.float64]
    m_tau: NDArray[np.float64]  # (K,) τ of the points (s)
    # (K, K) covariance from outside the noise model (the uncertainty of a removed signal)
    added: NDArray[np.float64] | None = None
    # ``_fit_active``'s results by (points, components, iterations): the selection, its
    # ramp/walk comparison, the long-τ check and the final fit ask for the same ones
    fits: dict[tuple[bytes, tuple[int, ...], int], _ActiveFit] = field(default_factory=dict)
    # ``_at``'s slices by points: every iteration of every fit on the same points takes them
    subsets: dict[bytes, _Subset] = field(default_factory=dict)


@dataclass(frozen=True)
class _Subset:
    """The fixed ingredients of ``_avar_cov`` at some points ``idx`` of a ``_Problem``: G's
    block, max(M_k, M_l), the basis, the fixed components' AVAR, the EDF floor, the added
    covariance (the same arrays every call would slice)."""

    G: NDArray[np.float64]
    MM: NDArray[np.float64]
    X: NDArray[np.float64]
    fixed: NDArray[np.float64]
    edf_floor: NDArray[np.float64]
    added: NDArray[np.float64] | None


def _at(p: _Problem, idx: NDArray) -> _Subset:
    """``p``'s ingredients at points ``idx``, sliced once per problem and points."""
    key = np.asarray(idx, dtype=np.intp).tobytes()
    got = p.subsets.get(key)
    if got is None:
        M = p.M[idx]
        got = _Subset(p.G[np.ix_(idx, idx)], np.maximum.outer(M, M), p.X[idx], p.fixed[idx],
                      p.edf_floor[idx],
                      None if p.added is None else p.added[np.ix_(idx, idx)])
        for arr in (got.G, got.MM, got.X, got.fixed, got.edf_floor, got.added):
            if arr is not None:
                arr.flags.writeable = False
        p.subsets[key] = got
    return got


def _theta_full(p: _Problem, theta: NDArray) -> NDArray:
    return np.concatenate([theta, p.theta_fixed])


def _avar_cov(p: _Problem, theta: NDArray, idx: NDArray) -> NDArray[np.float64]:
    """Modelled covariance matrix of the AVAR estimates at points ``idx`` (Whittle form),
    with a floor so that deterministic-only models keep finite weights."""
    th = _theta_full(p, theta)
    sub = _at(p, idx)
    q = np.einsum("klab,a,b->kl", sub.G, th, th)
    C = 2.0 * q / sub.MM
    model = sub.X @ theta + sub.fixed
    floor = 2.0 * model**2 / sub.edf_floor
    d = np.diag(C).copy()
    bump = np.maximum(floor - d, 0.0)
    C.flat[:: len(C) + 1] = d + bump  # the diagonal
    if sub.added is not None:
        C += sub.added
    return C


def _whitener(C: NDArray) -> NDArray[np.float64]:
    """T with T·C·Tᵀ = I on C's numerically non-null subspace (eigen-decomposition of the
    correlation matrix; directions below 1e-10 of the largest eigenvalue are dropped)."""
    d = np.sqrt(np.diag(C))
    R = C / (d[:, None] * d[None, :])  # np.outer's product
    w, V = np.linalg.eigh(R)
    keep = w > 1e-10 * w.max()
    return (V[:, keep] / np.sqrt(w[keep])).T / d


def _param_cov(A: NDArray) -> NDArray[np.float64]:
    """(AᵀA)⁻¹ of a whitened design A, its columns scaled to unit norm first. The basis spans
    many decades (1/τ², 1/τ, τ, τ² over 0.01 s to 10⁴ s), and the pseudo-inverse of the
    unscaled normal matrix cut its smallest directions as numerically null, which set their
    variance to zero: a 60 h record without a filter read a 0.04 % shortfall at one sample
    as a bend at z = −9700 and left out its 5 shortest τ as "filter-bent" (issue 24)."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    As = A / scale
    return np.linalg.pinv(As.T @ As) / np.outer(scale, scale)


def _gls_scaled(A: NDArray, b: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least squares of the whitened system A·θ ≈ b: (θ, Cov θ), columns scaled as in
    ``_param_cov``."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    coef, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    return coef / scale, _param_cov(A)


def _gls_nnls(X: NDArray, y: NDArray, T: NDArray, Ty: NDArray | None = None
              ) -> tuple[NDArray[np.float64], float]:
    """Non-negative generalised least squares: min ‖T(y − Xθ)‖², θ ≥ 0; returns (θ, χ²).
    Columns are scaled to unit norm first because the basis spans many decades. ``Ty``:
    T·y when the caller has it (the selection's subsets share one T)."""
    A = T @ X
    b = T @ y if Ty is None else Ty
    scale = np.sqrt(np.add.reduce(A * A, axis=0))  # np.linalg.norm(A, axis=0), as it sums
    scale[scale == 0] = 1.0
    sol, rnorm = nnls(A / scale, b, maxiter=50 * X.shape[1] + 100)
    return sol / scale, float(rnorm**2)


def _fit_active(p: _Problem, idx: NDArray, active: list[int], iterations: int = 8
                ) -> _ActiveFit:
    """``_fit_once``, computed once per problem for each (points, components): a pure
    function of them, so the cached result is the one a new call would give bit for bit
    (its arrays are read-only, so no caller can change what another one reads)."""
    key = (np.asarray(idx, dtype=np.intp).tobytes(), tuple(active), iterations)
    got = p.fits.get(key)
    if got is None:
        got = _fit_once(p, idx, active, iterations)
        for arr in got[:3]:
            arr.flags.writeable = False
        p.fits[key] = got
    return got


def _fit_once(p: _Problem, idx: NDArray, active: list[int], iterations: int
              ) -> _ActiveFit:
    """Iterated GLS fit, θ ≥ 0, on points ``idx`` with components ``active``: the covariance
    of the AVAR estimates is recomputed from the current model until θ settles.

    Returns θ (zeros for inactive components), Cov(θ[active]) = (XᵀC⁻¹X)⁻¹, the AVAR
    covariance C and the generalised χ² of the residuals."""
    A = p.X.shape[1]
    X = p.X[np.ix_(idx, np.asarray(active, dtype=np.intp))]
    y = p.y[idx]
    theta = np.zeros(A)
    # start: relative weights from the measured values, no correlation
    v = 2.0 * np.maximum(y + p.fixed[idx], 1e-300) ** 2 / p.M[idx]
    theta[active], _ = _gls_nnls(X, y, np.diag(1.0 / np.sqrt(v)))
    for _ in range(iterations):
        C = _avar_cov(p, theta, idx)
        new = np.zeros(A)
        new[active], _ = _gls_nnls(X, y, _whitener(C))
        done = _settled(new, theta)
        theta = new
        if done:
            break
    C = _avar_cov(p, theta, idx)
    T = _whitener(C)
    TX = T @ X
    cov = _param_cov(TX)
    r = T @ (y - X @ theta[active])
    return theta, cov, C, float(r @ r)


def _settled(new: NDArray, old: NDArray) -> bool:
    """``np.allclose(new, old, rtol=1e-5, atol=0)``, the iteration's stop: |new − old| ≤
    1e-5·|old| everywhere, the same comparison without allclose's per-call overhead where
    both are finite (allclose itself otherwise: its rules for infinities and NaN)."""
    if not (np.isfinite(new).all() and np.isfinite(old).all()):
        return bool(np.allclose(new, old, rtol=1e-5, atol=0))
    return bool((np.abs(new - old) <= 1e-5 * np.abs(old)).all())


def _neg_log_lik(p: _Problem, idx: NDArray, active: list[int]) -> float:
    """−2 ln L (up to a constant) of the AVAR points under the fitted model ``active`` with
    the model's own covariance: χ² + ln det C."""
    _, _, C, c2 = _fit_active(p, idx, active)
    sign, logdet = np.linalg.slogdet(C)
    return c2 + logdet if sign > 0 else math.inf
