"""Equivalent degrees of freedom and chi-squared confidence intervals of difference variances.

The EDF follows C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on
finite differences", Proc. 35th PTTI (2003), referred to as GR below, and NIST SP 1065 §5.3.
GR write a variance estimator as the mean of M squared d-th differences of the phase, taken
every ``stride`` samples (``S = m / stride`` estimates per averaging time τ = m·τ0). For a
Gaussian process the estimate is a quadratic form, so its EDF is

    edf = 2 E[V]² / Var[V] = M² R(0)² / Σ_{|j|<M} (M − |j|) R(j)²,

with R(j) the covariance of two differences j strides apart. GR express R through the
generalised autocovariance ``sw`` of power-law noise (their eq. 7), filtered by the averaging
(eq. 8) and by the d-th difference (eq. 9), and give the truncated sum (eq. 10) plus
asymptotic forms (their tables 1–3) for long records. The stride enters only through S and
M, which is why the same algorithm covers non-, partially and fully overlapping estimators.

Noise exponents ``alpha`` are those of fractional frequency, S_y(f) ∝ f^alpha:
+2 white PM, +1 flicker PM, 0 white FM, −1 flicker FM, −2 random-walk FM, −3, −4 (Hadamard
only). In accelerometer language "frequency" is the measured acceleration: white FM is
velocity random walk, flicker FM is bias instability, random-walk FM is rate random walk.
"""

from __future__ import annotations

import math
from functools import lru_cache
from math import comb

import numpy as np
from avard.core.allan.chi2 import chi2_ppf, chi2_ppf_stable32
from avard.core.errors import DataError
from numpy.typing import ArrayLike, NDArray

__all__ = ["QUANTILES", "chi2_interval", "edf_greenhall", "edf_mixture", "edf_mixture_bound",
           "edf_simple", "edf_with_signal"]

# GR switch to the asymptotic forms beyond this many terms of the basic sum.
_J_MAX = 100

# GR table 1 (modified variances) is not needed: avard has no modified estimators.
# GR table 2: asymptotic (a0, a1) for unmodified variances, rows alpha = +2 … −4,
# columns d = 1, 2, 3; NaN where alpha + 2d ≤ 1 (variance does not converge).
_NAN = (math.nan, math.nan)
_TABLE2: dict[int, tuple[tuple[float, float], ...]] = {
    2: ((3 / 2, 1 / 2), (35 / 18, 1.0), (231 / 100, 3 / 2)),
    1: ((78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)),
    0: ((2 / 3, 1 / 6), (2 / 3, 1 / 3), (7 / 9, 1 / 2)),
    -1: (_NAN, (0.852, 0.375), (0.997, 0.617)),
    -2: (_NAN, (1.079, 0.368), (1.033, 0.607)),
    -3: (_NAN, _NAN, (1.053, 0.553)),
    -4: (_NAN, _NAN, (1.302, 0.535)),
}
# GR table 3: (b0, b1) for flicker PM (alpha = +1), columns d = 1, 2, 3.
_TABLE3 = ((6.0, 4.0), (15.23, 12.0), (47.8, 40.0))


def _sw(t: NDArray[np.float64], alpha: int) -> NDArray[np.float64]:
    """GR eq. 7: generalised autocovariance of the power-law 'w' process, up to a constant."""
    # The overall sign of sw is irrelevant here: the EDF only uses ratios of squares of it.
    at = np.abs(t)
    p = 3 - alpha
    if alpha % 2 == 0:  # even alpha: |t|^(3 − alpha)
        return at**p
    # odd alpha: |t|^(3 − alpha) · ln|t|, continuous with value 0 at t = 0
    with np.errstate(divide="ignore", invalid="ignore"):
        val = np.where(at > 0, at**p * np.log(np.where(at > 0, at, 1.0)), 0.0)
    return val


def _sx(t: NDArray[np.float64], f: float, alpha: int) -> NDArray[np.float64]:
    """GR eq. 8: the averaging filter applied to sw; f = ∞ is the continuous-time limit."""
    if math.isinf(f):
        return _sw(t, alpha + 2)
    return f * f * (2 * _sw(t, alpha) - _sw(t - 1 / f, alpha) - _sw(t + 1 / f, alpha))


def _sz(t: NDArray[np.float64], f: float, alpha: int, d: int) -> NDArray[np.float64]:
    """GR eq. 9: the d-th difference filter, Σ_k (−1)^k C(2d, d+k) sx(t + k)."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros_like(t)
    for k in range(-d, d + 1):
        out += (-1) ** abs(k) * comb(2 * d, d + k) * _sx(t + k, f, alpha)
    return out


def _basic_sum(j_terms: int, m_count: float, s: float, f: float, alpha: int, d: int) -> float:
    """GR eq. 10: sz(0)² + 2 Σ_{j=1}^{J−1} (1 − j/M) sz(j/S)² + (1 − J/M) sz(J/S)².

    Written as A − B/M with A, B depending only on (J, S, F, alpha, d), which are cached: a
    snapshot every few seconds then costs no sz evaluations, only the new M.
    """
    a_sum, b_sum = _basic_terms(int(j_terms), float(s), float(f), int(alpha), int(d))
    return a_sum - b_sum / m_count


@lru_cache(maxsize=4096)
def _basic_terms(j_terms: int, s: float, f: float, alpha: int, d: int) -> tuple[float, float]:
    j = np.arange(1, j_terms, dtype=np.float64)
    sz_j = _sz(j / s, f, alpha, d) ** 2
    sz_0 = float(_sz(np.zeros(1), f, alpha, d)[0]) ** 2
    sz_last = float(_sz(np.array([j_terms / s]), f, alpha, d)[0]) ** 2
    a_sum = sz_0 + 2.0 * float(np.sum(sz_j)) + sz_last
    b_sum = 2.0 * float(np.sum(j * sz_j)) + j_terms * sz_last
    return a_sum, b_sum


@lru_cache(maxsize=256)
def _sz0_squared(f: float, alpha: int, d: int) -> float:
    return float(_sz(np.zeros(1), f, alpha, d)[0]) ** 2


def edf_greenhall(alpha: int, d: int, m: int, stride: int, n_phase: int, *,
                  rate_data: bool = False) -> float:
    """Equivalent degrees of freedom of an unmodified d-th difference variance (GR 2003).

    Parameters
    ----------
    alpha : int
        Power-law exponent of the rate (fractional-frequency) noise, +2 … −4; must satisfy
        alpha + 2d > 1 for the variance to exist.
    d : int
        Order of the phase difference: 1, 2 (Allan variance), 3 (Hadamard variance).
    m : int
        Averaging factor, τ = m·τ0.
    stride : int
        Distance in samples between successive differences: 1 fully overlapping
        (NIST SP 1065 eq. 12), m non-overlapping (eq. 11), anything between partially
        overlapping. GR's stride factor is S = m / stride.
    n_phase : int
        Number of phase points (rate samples + 1) of the segment the differences come from.
    rate_data : bool
        The phase is the exact running sum of rate samples (an accelerometer's record), not
        phase read through a measurement bandwidth: for the FM types (α ≤ 0) GR's averaging
        filter is then the identity (F = ∞, their continuous-time sx), which is the exact
        EDF of the sampled process. GR's (and Stable32's) F = m for short τ averages the
        phase over one sample: at m = 1–33 of an OADEV it misstates white FM's EDF by up to
        17 % (m = 1: 28 173 against the exact 2M/3 = 24 000 on 36 000 samples; m = 8 of
        216 000: 36 250 against 39 722, the difference covariance 2m − 3l, l − 2m summed
        directly). Off (the default) for Stable32's rows.

    Returns
    -------
    float
        The EDF, or NaN when no difference fits in the record.
    """
    alpha, d, m, stride, n_phase = int(alpha), int(d), int(m), int(stride), int(n_phase)
    if d not in (1, 2, 3):
        raise DataError(f"difference order d={d} is not supported; use 1, 2 or 3")
    if not -4 <= alpha <= 2 or alpha + 2 * d <= 1:
        raise DataError(
            f"noise exponent alpha={alpha} is outside the range where a d={d} difference "
            f"variance converges (need -4 <= alpha <= 2 and alpha + 2d > 1)"
        )
    if m < 1 or stride < 1:
        raise DataError(f"averaging factor m={m} and stride={stride} must both be >= 1")
    s_factor = m / stride  # GR's S
    length = 1 + m * d  # GR's L for unmodified variances (F = m)
    if n_phase < length:
        return math.nan
    m_count = 1 + (n_phase - length) // stride  # GR's M: number of differences
    j_terms = int(min(m_count, math.ceil((d + 1) * s_factor)))  # GR's J
    r = m_count / s_factor

    if alpha <= 0:  # GR case 2: unmodified, alpha <= 0
        if j_terms <= _J_MAX:
            f = float(m) if m * (d + 1) <= _J_MAX and not rate_data else math.inf
            return _sz0_squared(f, alpha, d) * m_count / _basic_sum(
                j_terms, m_count, s_factor, f, alpha, d)
        if r > d + 1:
            a0, a1 = _TABLE2[alpha][d - 1]
            return 1.0 / ((a0 - a1 / r) / r)
        m_prime = _J_MAX / r
        return _sz0_squared(math.inf, alpha, d) * _J_MAX / _basic_sum(
            _J_MAX, _J_MAX, m_prime, math.inf, alpha, d)

    if alpha == 1:  # GR case 3: flicker PM, the averaging factor enters through ln m
        if j_terms <= _J_MAX:
            return _sz0_squared(float(m), 1, d) * m_count / _basic_sum(
                j_terms, m_count, s_factor, float(m), 1, d)
        b0, b1 = _TABLE3[d - 1]
        if r > d + 1:
            a0, a1 = _TABLE2[1][d - 1]
            return (b0 + b1 * math.log(m)) ** 2 * r / (a0 - a1 / r)
        m_prime = _J_MAX / r
        return (b0 + b1 * math.log(m)) ** 2 * _J_MAX / _basic_sum(
            _J_MAX, _J_MAX, m_prime, m_prime, 1, d
        )

    # GR case 4: white PM (alpha = +2). Differences further apart than d·m are uncorrelated,
    # so the basic sum is exact whenever it is short; otherwise GR's asymptotic form.
    if j_terms <= _J_MAX:
        return _sz0_squared(float(m), 2, d) * m_count / _basic_sum(
            j_terms, m_count, s_factor, float(m), 2, d)
    a0 = comb(4 * d, 2 * d) / comb(2 * d, d) ** 2
    a1 = d / 2.0
    return 1.0 / ((a0 - a1 / r) / m_count)


def edf_simple(n_diff: int) -> float:
    """Crude EDF = number of differences; only for comparison with the GR value."""
    return float(n_diff)


def edf_with_signal(edf: ArrayLike, share: ArrayLike) -> NDArray[np.float64]:
    """EDF of a variance estimate a known share of whose expectation is deterministic.

    An estimate V = S + V_n of a deterministic part S (a rate ramp, a sinusoid) and a noise
    part V_n with EDF ν (ν·V_n/E[V_n] ~ χ²_ν) is, with the noise's cross term with the
    signal taken as large as a Gaussian quadratic form allows, a non-central χ²:
    ν·V/E[V_n] ~ χ'²(ν, λ), λ = ν·S/E[V_n]. Matched in its first two moments to a scaled
    central χ² (NIST SP 1065 eq. 40 then applies unchanged), its EDF is

        2 E[V]²/Var[V] = (ν + λ)²/(ν + 2λ) = ν / (1 − f²),   f = S/(S + E[V_n]),

    the share ``f`` of the expected variance that does not scatter. It is ν at f = 0 (noise
    alone: the interval is exactly the noise's), grows without bound as f → 1, and is never
    below ν. The cross term of a smooth signal is smaller than the non-central χ²'s (its
    differences weigh the noise nearly evenly, and their sum telescopes), so the estimate
    scatters less still: the interval this EDF gives is never narrower than the data
    support, as long as ``f`` is not overstated (the caller takes the part it is sure of).
    Entries with a non-finite EDF stay as they are; ``share`` is clipped to [0, 0.99].
    """
    e = np.asarray(edf, dtype=np.float64)
    f = np.clip(np.nan_to_num(np.asarray(share, dtype=np.float64), nan=0.0), 0.0, 0.99)
    return e / (1.0 - f * f)


def edf_mixture_bound(levels: ArrayLike, edfs: ArrayLike) -> NDArray[np.float64]:
    """A lower bound on the EDF of a variance estimate of a sum of independent Gaussian
    noises, from each one's part of the variance (``levels``, shape (J, K)) and its own EDF
    (``edfs``, (J, K): the Greenhall–Riley EDF of its pure type at the same m and N).

    Each noise's estimate is a quadratic form yᵀAy of its own covariance C_j, and Var of the
    sum is Σ_ij 2 tr(C_i A C_j A) ≤ (Σ_j √(2 tr((C_j A)²)))² = (Σ_j N_j √(2/ν_j))² by
    Cauchy–Schwarz, so

        EDF ≥ (Σ_j N_j)² / (Σ_j N_j/√ν_j)²,

    which lies between the least and the largest ν_j (equal to ν when one noise holds it
    all). NaN where no level is positive."""
    lv = np.atleast_2d(np.asarray(levels, dtype=np.float64))
    nu = np.atleast_2d(np.asarray(edfs, dtype=np.float64))
    num = np.sum(lv, axis=0)
    den = np.sum(np.where(lv > 0, lv / np.sqrt(nu), 0.0), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num**2 / den**2, np.nan)


def edf_mixture(alphas: tuple[int, ...], levels: ArrayLike, d: int, m: int, stride: int,
                n_phase: int, *, rate_data: bool = False) -> float:
    """The EDF of a d-th difference variance estimate of a *sum* of independent power-law
    noises (types ``alphas``, each holding ``levels[j]`` of the variance at this τ): GR's
    quadratic-form EDF with the mixture's own covariance of differences, R = Σ_j N_j r_j
    (r_j the type's covariance normalised to 1 at lag 0), so

        EDF = (Σ_j N_j)² / Σ_ij N_i N_j ρ_ij / √(ν_i ν_j),

    ν_j = ``edf_greenhall`` of type j alone and ρ_ij = Σ c_l r_i(l) r_j(l) / √(…ii …jj) the
    correlation of the two types' difference covariances over GR's lags l (their weights
    c_l = 1, 2(1 − l/M), …, eq. 10). One type alone gives its ν exactly; ρ = 1 everywhere is
    ``edf_mixture_bound`` (Cauchy–Schwarz), the least the mixture can have. The types'
    differences are correlated over different spans (white FM's within two τ, a random
    walk's far beyond), so ρ < 1 and the mixture's estimate scatters less than the bound
    says, and can scatter less than any of its types alone (the coverage generator's
    white + flicker at 8 s of a 60 h record: 44 000 simulated, white FM's own 36 000).
    ``rate_data`` as ``edf_greenhall``. NaN where no difference fits or no level is
    positive."""
    lv = np.asarray(levels, dtype=np.float64).reshape(-1)
    keep = [j for j in range(len(lv)) if lv[j] > 0]
    if not keep:
        return math.nan
    al = tuple(int(alphas[j]) for j in keep)
    w = lv[keep]
    nu = np.array([edf_greenhall(a, d, m, stride, n_phase, rate_data=rate_data) for a in al])
    if not np.all(np.isfinite(nu)) or np.any(nu <= 0):
        return math.nan
    rho = _mixture_rho(al, int(d), int(m), int(stride), int(n_phase), bool(rate_data))
    x = rho / np.sqrt(np.outer(nu, nu))
    den = float(w @ x @ w)
    return float(np.sum(w)) ** 2 / den if den > 0 else math.nan


@lru_cache(maxsize=4096)
def _mixture_rho(alphas: tuple[int, ...], d: int, m: int, stride: int, n_phase: int,
                 rate_data: bool) -> NDArray[np.float64]:
    """ρ_ij of ``edf_mixture``: on GR's lag grid where their basic sum is exact (J ≤
    ``_J_MAX``, the averaging filter F as ``edf_greenhall`` takes it), else on the
    continuous-time grid GR use past it (``_J_MAX`` lags, S' = ``_J_MAX``/min(r, d + 1),
    M' = r·S')."""
    s_factor = m / stride
    m_count = 1 + (n_phase - (1 + m * d)) // stride
    j_terms = int(min(m_count, math.ceil((d + 1) * s_factor)))
    if j_terms <= _J_MAX:
        s_eff, m_eff, j_eff = s_factor, float(m_count), j_terms
        f_fm = float(m) if m * (d + 1) <= _J_MAX and not rate_data else math.inf
    else:
        r = m_count / s_factor
        s_eff = _J_MAX / min(r, d + 1.0)
        m_eff, j_eff, f_fm = r * s_eff, _J_MAX, math.inf
    lag = np.arange(j_eff + 1, dtype=np.float64)
    c = np.where(lag == 0, 1.0, 2.0 * (1.0 - lag / m_eff))
    if j_eff >= 1:
        c[-1] = 1.0 - j_eff / m_eff
    rows = []
    for a in alphas:
        sz = _sz(lag / s_eff, f_fm if a <= 0 else float(m), a, d)
        rows.append(sz / sz[0])
    r_ = np.array(rows)
    t = (r_ * c) @ r_.T
    diag = np.sqrt(np.clip(np.diag(t), 1e-300, None))
    return np.asarray(np.clip(t / np.outer(diag, diag), -1.0, 1.0))


QUANTILES = ("exact", "stable32")


def chi2_interval(
    var: ArrayLike, edf: ArrayLike, ci: float = 0.683, quantiles: str = "exact"
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two-sided chi-squared confidence interval of a variance estimate (NIST SP 1065 eq. 40).

    ``lo = edf·var / χ²_{edf}((1+ci)/2)``, ``hi = edf·var / χ²_{edf}((1−ci)/2)``. Entries
    with a non-finite or non-positive EDF get NaN bounds. ``quantiles="stable32"`` takes the
    χ² quantiles as Stable32 computes them (``chi2.chi2_ppf_stable32``: an approximation
    above 100 degrees of freedom), to reproduce its printed bounds; the default is exact.
    """
    if not 0.0 < ci < 1.0:
        raise DataError(f"confidence level ci={ci} must lie strictly between 0 and 1")
    if quantiles not in QUANTILES:
        raise DataError(f"quantiles={quantiles!r} is unknown; use one of {QUANTILES}")
    v = np.asarray(var, dtype=np.float64)
    e = np.broadcast_to(np.asarray(edf, dtype=np.float64), v.shape)
    ok = np.isfinite(e) & (e > 0)
    e_safe = np.where(ok, e, 1.0)
    # (core/allan/chi2.py, numpy only: the service computes intervals with every snapshot and
    # must not import scipy, ~30 MB of resident memory on a 512 MB Raspberry Pi.)
    lo = np.where(ok, e_safe * v / _quantiles(quantiles, 0.5 + ci / 2, e_safe), np.nan)
    hi = np.where(ok, e_safe * v / _quantiles(quantiles, 0.5 - ci / 2, e_safe), np.nan)
    return lo, hi


# χ² quantiles already computed, by (method, p, EDF): a snapshot needs one per τ and channel,
# channels at a τ mostly share their EDF, and the long-τ levels' EDF does not change between
# snapshots. Bounded: cleared when full.
_PPF_CACHE: dict[tuple[str, float, float], float] = {}
_PPF_CACHE_MAX = 1 << 14


def _quantiles(method: str, p: float, k: NDArray[np.float64]) -> NDArray[np.float64]:
    """χ²_k(p) for every entry of k, each distinct value computed once (and remembered)."""
    flat = k.ravel()
    uniq, inverse = np.unique(flat, return_inverse=True)
    vals = np.array([_PPF_CACHE.get((method, p, float(u)), math.nan) for u in uniq])
    todo = np.isnan(vals)
    if todo.any():
        ppf = chi2_ppf if method == "exact" else chi2_ppf_stable32
        vals[todo] = ppf(p, uniq[todo])
        if len(_PPF_CACHE) > _PPF_CACHE_MAX:
            _PPF_CACHE.clear()
        for u, v in zip(uniq[todo].tolist(), vals[todo].tolist(), strict=True):
            _PPF_CACHE[(method, p, u)] = v
    return vals[inverse].reshape(k.shape)


# ----------------------------------------------------------------------------------------------
# The long-τ statistics (core/allan/longtau.py). New functions only: the estimators above keep
# their EDF exactly.

# GR table 1: asymptotic (a0, a1) for the modified variances (F = 1), rows alpha = +2 … −4,
# columns d = 1, 2, 3; NaN where the variance does not converge.
_TABLE1: dict[int, tuple[tuple[float, float], ...]] = {
    2: ((2 / 3, 1 / 3), (7 / 9, 1 / 2), (22 / 25, 2 / 3)),
    1: ((0.840, 0.345), (0.997, 0.616), (1.141, 0.843)),
    0: ((1.079, 0.368), (1.033, 0.607), (1.184, 0.848)),
    -1: (_NAN, (1.048, 0.534), (1.180, 0.816)),
    -2: (_NAN, (1.302, 0.535), (1.175, 0.777)),
    -3: (_NAN, _NAN, (1.194, 0.703)),
    -4: (_NAN, _NAN, (1.489, 0.702)),
}


def edf_greenhall_modified(alpha: int, d: int, m: int, n_phase: int) -> float:
    """EDF of a fully overlapping *modified* d-th difference variance (MVAR and TVAR for d = 2;
    GR 2003 case 1, F = 1, S = m; NIST SP 1065 §5.3), for ``n_phase`` phase points. NaN when
    no difference fits."""
    alpha, d, m, n_phase = int(alpha), int(d), int(m), int(n_phase)
    if d not in (1, 2, 3) or not -4 <= alpha <= 2 or alpha + 2 * d <= 1:
        raise DataError(f"alpha={alpha}, d={d}: a modified variance needs -4 <= alpha <= 2, "
                        "d in 1..3 and alpha + 2d > 1")
    if m < 1:
        raise DataError(f"averaging factor m={m} must be >= 1")
    length = m + m * d  # GR's L = m/F + m·d with F = 1
    if n_phase < length:
        return math.nan
    s_factor = float(m)  # fully overlapping: stride 1
    m_count = 1 + (n_phase - length)  # GR's M = 1 + ⌊S (N − L)/m⌋
    j_terms = int(min(m_count, (d + 1) * s_factor))
    r = m_count / s_factor
    if j_terms <= _J_MAX:
        return _sz0_squared(1.0, alpha, d) * m_count / _basic_sum(
            j_terms, m_count, s_factor, 1.0, alpha, d)
    if r > d + 1:
        a0, a1 = _TABLE1[alpha][d - 1]
        return 1.0 / ((a0 - a1 / r) / r)
    m_prime = _J_MAX / r
    return _sz0_squared(1.0, alpha, d) * _J_MAX / _basic_sum(
        _J_MAX, _J_MAX, m_prime, 1.0, alpha, d)


# SP 1065 Table 7 (TOTVAR) and Table 8 (MTOT, TTOT): edf = b·(T/τ) − c, by alpha.
TOTVAR_EDF = {0: (1.50, 0.0), -1: (1.17, 0.22), -2: (0.93, 0.36)}
MTOT_EDF = {2: (1.90, 2.10), 1: (1.20, 1.40), 0: (1.10, 1.20), -1: (0.85, 0.50),
            -2: (0.75, 0.31)}
# SP 1065 Table 9 (HTOT): edf = (T/τ) / (b0 + b1·τ/T), FM types alpha 0 … −4.
HTOT_EDF = {0: (0.559, 1.004), -1: (0.868, 1.006), -2: (0.938, 1.000), -3: (0.974, 1.000),
            -4: (1.276, 0.792)}


def edf_total(kind: str, alpha: int, m: int, n_phase: int) -> float:
    """EDF of a total variance from SP 1065's tables, with T/τ = (N − 1)/m for N phase points
    (the record's length over τ); NaN where the table has no row for ``alpha`` (the caller
    takes the corresponding non-total EDF there, ``longtau``) or the formula gives ≤ 0."""
    ratio = (int(n_phase) - 1) / int(m)
    table = {"totvar": TOTVAR_EDF, "mtotvar": MTOT_EDF, "ttotvar": MTOT_EDF}.get(kind)
    if table is not None:
        if int(alpha) not in table:
            return math.nan
        b, c = table[int(alpha)]
        e = b * ratio - c
    elif kind == "htotvar":
        if int(alpha) not in HTOT_EDF:
            return math.nan
        b0, b1 = HTOT_EDF[int(alpha)]
        e = ratio / (b0 + b1 / ratio)
    else:
        raise DataError(f"{kind!r} is not a total variance")
    return e if e > 0 else math.nan


def edf_theo1(alpha: int, m: int, n_phase: int) -> float:
    """EDF of Theo1 at the averaging factor m (τ = 0.75·m·τ0) for ``n_phase`` phase points,
    by the fitted forms of NIST SP 1065 §5.2.14 (Howe and Tasset; W. Riley's "CI2"), with
    r = 0.75·m and N = ``n_phase``:

    * white PM (α = 2):   0.86 (N + 1)(N − 4r/3) / (N − r) · r / (r + 1.14)
    * flicker PM (α = 1): (4.798 N² − 6.374 N r + 12.387 r) / (√(r + 36.6) (N − r)) · r / (r + 0.3)
    * white FM (α = 0):   [(4.1 N + 0.8)/r − (3.1 N + 6.5)/N] · r^1.5 / (r^1.5 + 5.2)
    * flicker FM (α = −1): (2 N² − 1.3 N r − 3.5 r) / (N r) · r³ / (r³ + 2.3)
    * random-walk FM (α = −2): (4.4 N − 2)/(2.9 r) · [(4.4 N − 1)² − 8.6 r (4.4 N − 1)
      + 11.4 r²] / (4.4 N − 3)²

    These are what Stable32 prints (its Theo1 bounds on a 1253-point record, α = −1, are
    reproduced within 3.2e-4: tests/core/test_stable32_longtau.py). NaN where no form applies:
    α outside +2 … −2, or a form that gives EDF < 1 (random-walk FM towards r ≈ 0.63 N, where
    its quadratic changes sign: an EDF of 0.1 there puts the whole χ² interval above the
    estimate, and its simulated coverage fell to 45 %); the caller then says what it takes
    instead (``longtau``)."""
    a, n = int(alpha), float(n_phase)
    r = 0.75 * int(m)
    if r <= 0 or r >= n:
        return math.nan
    if a == 2:
        e = 0.86 * (n + 1) * (n - 4 * r / 3) / (n - r) * r / (r + 1.14)
    elif a == 1:
        e = (4.798 * n * n - 6.374 * n * r + 12.387 * r) / (math.sqrt(r + 36.6) * (n - r)) \
            * r / (r + 0.3)
    elif a == 0:
        e = ((4.1 * n + 0.8) / r - (3.1 * n + 6.5) / n) * r**1.5 / (r**1.5 + 5.2)
    elif a == -1:
        e = (2 * n * n - 1.3 * n * r - 3.5 * r) / (n * r) * r**3 / (r**3 + 2.3)
    elif a == -2:
        q = 4.4 * n - 1
        e = (4.4 * n - 2) / (2.9 * r) * (q * q - 8.6 * r * q + 11.4 * r * r) / (4.4 * n - 3) ** 2
    else:
        return math.nan
    return e if e >= 1 else math.nan


def edf_table5(alpha: int, m: int, n_phase: int) -> float:
    """The "simple" EDF of NIST SP 1065 Table 5 (Stein's approximations for the overlapping
    AVAR), for N = ``n_phase`` phase points at the averaging factor m:

    * white PM (α = 2):   (N + 1)(N − 2m) / (2 (N − m))
    * flicker PM (α = 1): exp(√(ln((N − 1)/2m) · ln((2m + 1)(N − 1)/4)))
    * white FM (α = 0):   [3(N − 1)/2m − 2(N − 2)/N] · 4m² / (4m² + 5)
    * flicker FM (α = −1): 2(N − 2)/(2.3 N − 4.9) at m = 1, 5N² / (4m (N + 3m)) from m = 2
    * random-walk FM (α = −2): (N − 2)/(m (N − 3)²) · [(N − 1)² − 3m(N − 1) + 4m²]

    Stable32 prints HTOT's bounds with these below AF 16 and at white PM (``longtau``). NaN
    for another α or an EDF ≤ 0."""
    a, n, mm = int(alpha), float(n_phase), float(m)
    if mm < 1 or n <= 2 * mm:
        return math.nan
    if a == 2:
        e = (n + 1) * (n - 2 * mm) / (2 * (n - mm))
    elif a == 1:
        u, v = (n - 1) / (2 * mm), (2 * mm + 1) * (n - 1) / 4
        e = math.exp(math.sqrt(math.log(u) * math.log(v))) if u > 1 else math.nan
    elif a == 0:
        e = (3 * (n - 1) / (2 * mm) - 2 * (n - 2) / n) * 4 * mm * mm / (4 * mm * mm + 5)
    elif a == -1:
        e = 2 * (n - 2) / (2.3 * n - 4.9) if mm == 1 else 5 * n * n / (4 * mm * (n + 3 * mm))
    elif a == -2:
        e = (n - 2) / (mm * (n - 3) ** 2) * ((n - 1) ** 2 - 3 * mm * (n - 1) + 4 * mm * mm)
    else:
        return math.nan
    return e if e > 0 else math.nan
