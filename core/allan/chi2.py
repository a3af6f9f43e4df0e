"""Chi-squared quantiles in numpy alone, for the confidence intervals of core/allan/edf.py.

The intervals of an Allan deviation with ν equivalent degrees of freedom are
ν·σ²/χ²_ν(p) (NIST SP 1065 eq. 42); χ²_ν(p) = 2·P⁻¹(ν/2, p) with P the regularised lower
incomplete gamma function. scipy.special has P⁻¹, but importing scipy costs ~30 MB of resident
memory and ~0.2 s, which the acquisition service (it publishes intervals with every snapshot)
must not pay on a 512 MB Raspberry Pi. tests/core/test_chi2.py holds these values equal to
scipy's ``gammaincinv`` (relative 1e-10 over ν = 0.2 … 10⁹ and p = 0.001 … 0.999).

P(a, x) is evaluated by its power series (x < a + 1) or Legendre's continued fraction for the
upper tail Q (x ≥ a + 1) while a < ``_QUAD_A``; for larger a, where both need O(√a) terms,
the tail beyond x (Q above the mode, P below it) of the density tᵃ⁻¹e⁻ᵗ/Γ(a) by composite
Gauss–Legendre quadrature over 16 σ (σ = √a) away from x, the density written around t = a
with Stirling's series so that 10⁹-sized terms never cancel. The quantile is Newton's
iteration from the Wilson–Hilferty start.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

_QUAD_A = 50.0          # above this shape, Q by quadrature
_SPAN = 16.0            # σ integrated away from x: beyond, < 1e-30 of the mass for a ≥ 50
_PANELS = 16            # quadrature panels of width σ
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(16)
_ITER_SERIES = 600
_TINY = 1e-300


def _lgamma(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([math.lgamma(v) for v in a.ravel()], dtype=np.float64).reshape(a.shape)


def _log_prefactor(a: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """ln(xᵃ e⁻ˣ / Γ(a))."""
    return a * np.log(x) - x - _lgamma(a)


def _p_series(a: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """P(a, x) = xᵃe⁻ˣ/Γ(a+1) · Σₙ xⁿ/((a+1)…(a+n)); fast for x < a + 1."""
    term = np.ones_like(x)
    total = np.ones_like(x)
    live = np.ones(x.shape, dtype=bool)  # converged entries stop changing: each value is
    for n in range(1, _ITER_SERIES):     # then the same whatever else is in the vector
        term = term * x / (a + n)
        total = np.where(live, total + term, total)
        live &= ~(term <= total * 1e-16)
        if not live.any():
            break
    return np.exp(_log_prefactor(a, x) - np.log(a)) * total


def _q_fraction(a: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Q(a, x) by the continued fraction (modified Lentz); fast for x ≥ a + 1."""
    b = x + 1.0 - a
    c = np.full_like(x, 1.0 / _TINY)
    d = 1.0 / b
    h = d.copy()
    live = np.ones(x.shape, dtype=bool)
    for i in range(1, _ITER_SERIES):
        an = -i * (i - a)
        b = b + 2.0
        d = an * d + b
        d = np.where(np.abs(d) < _TINY, _TINY, d)
        c = b + an / c
        c = np.where(np.abs(c) < _TINY, _TINY, c)
        d = 1.0 / d
        delta = d * c
        h = np.where(live, h * delta, h)  # converged entries stop changing (see _p_series)
        live &= ~(np.abs(delta - 1.0) < 1e-15)
        if not live.any():
            break
    return np.exp(_log_prefactor(a, x)) * h


def _stirling_err(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """ln Γ(a) − [(a − ½) ln a − a + ½ ln 2π], by its asymptotic series (a ≥ 15)."""
    r = 1.0 / a
    r2 = r * r
    return r * (1 / 12 - r2 * (1 / 360 - r2 * (1 / 1260 - r2 * (1 / 1680 - r2 / 1188))))


def _log_density(a: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """ln(tᵃ⁻¹e⁻ᵗ/Γ(a)) for large a, with t = a(1 + u): the O(a) parts cancel analytically."""
    u = np.maximum(t / a - 1.0, -1.0 + 1e-16)     # t → 0: a density of 0, not a log(0)
    l1p = np.log1p(u)
    return (a * (l1p - u) - l1p - 0.5 * np.log(2 * math.pi * a) - _stirling_err(a))


def _tail_quadrature(a: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """The tail on x's side of the mode, integrated away from the mode over 16 σ (the rest is
    below 1e-30 for a ≥ 50): ∫ₓ^{x+16σ} (x ≥ a, Q) or ∫_{x−16σ}^x (x < a, P)."""
    sigma = np.sqrt(a)
    upper = x >= a
    width = np.where(upper, _SPAN, -_SPAN) * sigma / _PANELS
    k = np.arange(_PANELS, dtype=np.float64)
    # t[..., panel, node], panels going away from x
    mid = x[..., None, None] + (k[:, None] + 0.5) * width[..., None, None]
    t = np.maximum(mid + 0.5 * width[..., None, None] * _NODES, _TINY)
    dens = np.exp(_log_density(a[..., None, None], t))
    return 0.5 * np.abs(width) * np.einsum("...pn,n->...", dens, _WEIGHTS)


def _density(a: NDArray[np.float64], x: NDArray[np.float64]) -> NDArray[np.float64]:
    big = a >= _QUAD_A
    out = np.empty_like(x)
    if big.any():
        out[big] = np.exp(_log_density(a[big], x[big]))
    if (~big).any():
        out[~big] = np.exp(_log_prefactor(a[~big], x[~big]) - np.log(x[~big]))
    return out


def gammainc_pq(a: ArrayLike, x: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(P(a, x), Q(a, x)), the regularised lower and upper incomplete gamma functions."""
    a_arr, x_arr = np.broadcast_arrays(np.asarray(a, dtype=np.float64),
                                       np.asarray(x, dtype=np.float64))
    a_arr, x_arr = a_arr.ravel().copy(), np.maximum(x_arr.ravel(), _TINY)
    p = np.empty_like(x_arr)
    q = np.empty_like(x_arr)
    big = a_arr >= _QUAD_A
    series = ~big & (x_arr < a_arr + 1.0)
    frac = ~big & ~series
    if big.any():
        ab, xb = a_arr[big], x_arr[big]
        tail = _tail_quadrature(ab, xb)
        upper = xb >= ab
        q[big] = np.where(upper, tail, 1.0 - tail)
        p[big] = np.where(upper, 1.0 - tail, tail)
    if series.any():
        p[series] = _p_series(a_arr[series], x_arr[series])
        q[series] = 1.0 - p[series]
    if frac.any():
        q[frac] = _q_fraction(a_arr[frac], x_arr[frac])
        p[frac] = 1.0 - q[frac]
    shape = np.broadcast_shapes(np.shape(a), np.shape(x))
    return p.reshape(shape), q.reshape(shape)


def chi2_sf(x: ArrayLike, k: ArrayLike) -> NDArray[np.float64]:
    """Pr(χ²_k > x), the chi-squared upper tail (a fit's p-value): Q(k/2, x/2), Q the
    regularised upper incomplete gamma function (DLMF 8.2.4; x ≥ 0, k > 0)."""
    return gammainc_pq(np.asarray(k, dtype=np.float64) / 2.0,
                       np.asarray(x, dtype=np.float64) / 2.0)[1]


def chi2_ppf(p: float, k: ArrayLike) -> NDArray[np.float64]:
    """χ²_k(p): the p-quantile of the chi-squared distribution with k degrees of freedom
    (k > 0 and finite, 0 < p < 1), as 2·P⁻¹(k/2, p)."""
    return chi2_ppf_grid([p], k)[0]


#: Quantile columns already computed, by (the probabilities, k): each entry is computed on its
#: own, so a stored column is the very one a new call would give. A live separation asks for
#: the same 64 probabilities on each axis with mostly the same EDFs; a bounded store, emptied
#: when full (a long run's EDFs grow with its samples and are not asked again).
_COLUMNS: dict[tuple[tuple[float, ...], float], NDArray[np.float64]] = {}
_COLUMNS_MAX = 1024


def chi2_ppf_grid(ps: Sequence[float], k: ArrayLike) -> NDArray[np.float64]:
    """χ²_k(p) for every p of ``ps`` and every k: shape (len(ps), *k.shape), row j the
    ``chi2_ppf(ps[j], k)``. One Newton iteration over all of them at once (an interval over a
    grid of probabilities costs one call, not one per probability); each entry stops changing
    once it has converged, so it is the same whatever else is in the call, and equal k
    (the separation's parts share their EDF) are computed once, as are those an earlier call
    computed for the same probabilities (tests/core/test_chi2.py holds the rows equal to
    ``chi2_ppf`` one p, and one k, at a time, and a stored column to a fresh one)."""
    p_list = [float(p) for p in ps]
    for p in p_list:
        if not 0.0 < p < 1.0:
            raise ValueError(f"chi2_ppf: p = {p} must lie strictly between 0 and 1")
    k_arr = np.asarray(k, dtype=np.float64)
    out_shape = (len(p_list), *k_arr.shape)
    if not p_list or k_arr.size == 0:
        return np.empty(out_shape)
    # Equal k have equal quantiles (each entry is computed on its own): compute each once.
    k_unique, where = np.unique(k_arr.ravel(), return_inverse=True)
    key = tuple(p_list)
    cols = [_COLUMNS.get((key, float(kv))) for kv in k_unique]
    missing = [i for i, c in enumerate(cols) if c is None]
    if missing:
        fresh = _ppf_columns(p_list, k_unique[missing])
        if len(_COLUMNS) + len(missing) > _COLUMNS_MAX:
            _COLUMNS.clear()
        for j, i in enumerate(missing):
            cols[i] = col = fresh[:, j].copy()
            _COLUMNS[(key, float(k_unique[i]))] = col
    table = np.stack([c for c in cols if c is not None], axis=1)      # (len(ps), unique k)
    return table[:, where.ravel()].reshape(out_shape)


def _ppf_columns(p_list: list[float], k_unique: NDArray[np.float64]) -> NDArray[np.float64]:
    """χ²_k(p), (len(p_list), len(k_unique)): the Newton iteration of chi2_ppf_grid."""
    a1 = k_unique / 2.0
    a = np.tile(a1, len(p_list))
    p_col = np.repeat(np.array(p_list), a1.size)
    # Wilson–Hilferty start: (χ²/k)^(1/3) is nearly normal with mean 1 − 2/(9k), var 2/(9k).
    z = np.repeat(np.array([math.sqrt(2.0) * _erfinv(2.0 * p - 1.0) for p in p_list]), a1.size)
    kk = 2.0 * a
    h = 2.0 / (9.0 * kk)
    x = np.maximum(0.5 * kk * (1.0 - h + z * np.sqrt(h)) ** 3, 1e-3 * a)
    # For small shapes the lower tail behaves as P ≈ xᵃ/Γ(a+1): start from its inverse.
    small = a < 1.0
    if small.any():
        log_p = np.repeat(np.array([math.log(p) for p in p_list]), a1.size)[small]
        x0 = np.exp((log_p + _lgamma(a[small] + 1.0)) / a[small])
        x[small] = np.minimum(x[small], x0)
    todo = np.ones(a.shape, dtype=bool)
    for _ in range(60):
        at, xt, pt = a[todo], x[todo], p_col[todo]
        lower, upper = gammainc_pq(at, xt)
        # Newton on whichever tail is the smaller number (its relative error is the least).
        step = np.where(lower < 0.5, lower - pt, (1.0 - pt) - upper) / _density(at, xt)
        new = np.where(xt - step <= 0.0, 0.5 * xt, xt - step)   # never step through zero
        x[todo] = new
        todo[todo] = np.abs(new - xt) > 1e-13 * np.abs(xt)
        if not todo.any():
            break
    out: NDArray[np.float64] = (2.0 * x).reshape(len(p_list), a1.size)
    return out


def _erfinv(y: float) -> float:
    """Inverse error function by Newton on math.erf (only the start of chi2_ppf needs it)."""
    if y == 0.0:
        return 0.0
    x = math.copysign(math.sqrt(-math.log((1.0 - abs(y)) / 2.0)), y) * 0.9
    for _ in range(60):
        err = math.erf(x) - y
        x -= err / (2.0 / math.sqrt(math.pi) * math.exp(-x * x))
        if abs(err) < 1e-16:
            break
    return x


# --------------------------------------------------------------------------------------------
# Stable32's quantiles, to reproduce its printed intervals digit for digit

# Abramowitz & Stegun 26.2.22, the normal upper-tail quantile x_p ≈ t − (c0 + c1 t)/(1 + d1 t +
# d2 t²), t = √(ln 1/p²), |error| < 3e-3: A&S print c1 = 0.27061; Stable32's source has 0.27601
# (two digits swapped), which is what its bounds carry (A. Wallin, allantools' maintainer,
# reading Stable32's source: "Fun with chi-squared", 2020; checked here on NBS14's bounds).
STABLE32_AS_26_2_22 = (2.30753, 0.27601, 0.99229, 0.04481)
# Stable32 uses the approximation above this EDF, and iterates on the distribution below.
STABLE32_APPROX_EDF = 100.0


def _normal_upper_quantile_as(p: float) -> float:
    """x with Q_normal(x) = p by A&S 26.2.22 with Stable32's coefficients (0 < p < 1)."""
    q = p if p <= 0.5 else 1.0 - p
    t = math.sqrt(math.log(1.0 / (q * q)))
    c0, c1, d1, d2 = STABLE32_AS_26_2_22
    x = t - (c0 + c1 * t) / (1.0 + d1 * t + d2 * t * t)
    return x if p <= 0.5 else -x


def chi2_ppf_stable32(p: float, k: ArrayLike) -> NDArray[np.float64]:
    """χ²_k(p) as Stable32 computes it, for reproducing its printed intervals (not for new
    results: it is off by up to ~1e-3 relative near k = 100).

    For k > 100, Abramowitz & Stegun 26.4.17 (Wilson–Hilferty),
    χ² ≈ k (1 − 2/(9k) + x √(2/(9k)))³, with x the normal quantile of upper-tail probability
    1 − p from A&S 26.2.22 as Stable32 has it (``STABLE32_AS_26_2_22``). For k ≤ 100 Stable32
    iterates on the distribution function, to about four digits; the exact quantile is used.
    """
    if not 0.0 < p < 1.0:
        raise ValueError(f"chi2_ppf_stable32: p = {p} must lie strictly between 0 and 1")
    k_arr = np.asarray(k, dtype=np.float64)
    out = chi2_ppf(p, k_arr)
    big = k_arr > STABLE32_APPROX_EDF
    if np.any(big):
        x = _normal_upper_quantile_as(1.0 - p)
        kb = k_arr[big]
        h = 2.0 / (9.0 * kb)
        out[big] = kb * (1.0 - h + x * np.sqrt(h)) ** 3
    return out
