"""The regularised incomplete beta function, its inverse, and the F distribution's quantiles,
without scipy.

``avard analyze`` needs one F quantile after its pass over the data, the line finder's
threshold (core/analysis/spectrum.py ``line_threshold``: F(ν, ν_bg) with ν up to ~6000, ν_bg up to
~3·10⁵ and tail probabilities down to ~1e-7). Importing scipy.special for it cost every
analyze 0.1–0.2 CPU-s on a PC and about a second on a Raspberry Pi; the χ² quantiles and tail
(core/allan/chi2.py) are here for the same reason. tests/core/test_beta.py holds these values
to scipy.special's (``betainc``, ``betaincinv``, ``fdtri``).

Definitions (DLMF §8.17): I_x(a, b) = B_x(a, b)/B(a, b), B_x(a, b) = ∫₀ˣ tᵃ⁻¹(1 − t)ᵇ⁻¹ dt
(8.17.1, 8.17.2), and I_x(a, b) = 1 − I_{1−x}(b, a) (8.17.4). The F distribution with
(ν₁, ν₂) degrees of freedom has the upper tail Pr(F > f) = I_y(ν₂/2, ν₁/2) = 1 − I_x(ν₁/2,
ν₂/2) with x = ν₁f/(ν₁f + ν₂), y = 1 − x (Abramowitz & Stegun 26.6.2).

How, and why so:

- Everything is carried in the logit t = ln(x/(1 − x)), with ln x and ln(1 − x) computed from
  t: both x and 1 − x keep full relative precision (a tail near x = 1 is a tail in 1 − x), and
  an F value is (ν₂/ν₁)·eᵗ exactly, with no 1 − x lost to rounding.
- I_x by the continued fraction DLMF 8.17.22–23, evaluated by the modified Lentz method,
  on the side where it converges fast (x < (a + 1)/(a + b + 2); else 8.17.4 and the fraction
  for I_{1−x}(b, a)). The fraction gives the smaller tail directly, so tails far below 1e-300
  still have a finite logarithm and full relative precision.
- The prefactor xᵃ(1 − x)ᵇ/B(a, b) is written around the mean x₀ = a/(a + b) with Stirling's
  series for ln Γ (DLMF 5.11.1): a·ln(x/x₀) + b·ln((1 − x)/(1 − x₀)) + ½·ln(ab/(2π(a + b)))
  − s(a) − s(b) + s(a + b), s(z) = ln Γ(z) − [(z − ½)ln z − z + ½ln 2π]. ln Γ(a + b) itself is
  ~10⁶ for the line finder's degrees of freedom; subtracting three such numbers would leave
  ~1e-10 of relative error in the tail.
- The inverse is Newton's method on ln(tail) as a function of t. The density of t,
  xᵃ(1 − x)ᵇ/B(a, b), is log-concave for every a, b > 0, so both tails are log-concave in t
  and Newton's iteration on their logarithm converges from any start (at most one overshoot,
  then monotonically); a bracket kept from the residual's sign bisects should a step leave
  it. The derivative comes free from the fraction: d ln I_x/dt = xᵃ(1 − x)ᵇ/(B(a, b)·I_x).
"""

from __future__ import annotations

import math
from functools import lru_cache
from statistics import NormalDist

import numpy as np
from avard.core.allan.chi2 import _stirling_err
from numpy.typing import ArrayLike, NDArray

_EPS = 1e-16            # the fraction stops when a factor is within this of 1
_TINY = 1e-300          # Lentz's guard against a zero denominator
_MAX_TERMS = 100_000    # ~√(ab/(a+b))·few terms are needed; this is only a runaway guard
_T_MAX = 1500.0         # |t| beyond this: x or 1 − x is below the smallest double
_HALF_LN_2PI = 0.5 * math.log(2.0 * math.pi)


def _stirling_remainder(z: float) -> float:
    """s(z) = ln Γ(z) − [(z − ½)ln z − z + ½ln 2π]: the series (chi2.py's) for z ≥ 15, where
    it is exact to rounding, else directly (there ln Γ(z) is small and nothing cancels)."""
    if z >= 15.0:
        return float(_stirling_err(np.asarray(z, dtype=np.float64)))
    return math.lgamma(z) - ((z - 0.5) * math.log(z) - z + _HALF_LN_2PI)


def _log_x_y(t: float) -> tuple[float, float]:
    """(ln x, ln(1 − x)) for x = 1/(1 + e⁻ᵗ), neither rounded through x or 1 − x."""
    if t >= 0.0:
        e = math.log1p(math.exp(-t))
        return -e, -t - e
    e = math.log1p(math.exp(t))
    return t - e, -e


def _log_front(a: float, b: float, ln_x: float, ln_y: float) -> float:
    """ln[xᵃ(1 − x)ᵇ/B(a, b)], written around x₀ = a/(a + b) (see the module docstring)."""
    ab = a + b
    # ln x₀ = −ln(1 + b/a), ln(1 − x₀) = −ln(1 + a/b): log(b/(a + b)) would round b/(a + b),
    # an error that b multiplies
    return (a * (ln_x + math.log1p(b / a)) + b * (ln_y + math.log1p(a / b))
            + 0.5 * math.log(a * b / ab) - _HALF_LN_2PI
            - _stirling_remainder(a) - _stirling_remainder(b) + _stirling_remainder(ab))


def _fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of DLMF 8.17.22, 1 + d₁/(1 + d₂/(1 + …)), with (8.17.23)
    d₂ₘ = m(b − m)x/((a + 2m − 1)(a + 2m)), d₂ₘ₊₁ = −(a + m)(a + b + m)x/((a + 2m)(a + 2m + 1)),
    by the modified Lentz method (all partial denominators 1). I_x(a, b) = xᵃ(1 − x)ᵇ/(a·B(a, b)
    ·this); it converges fast for x < (a + 1)/(a + b + 2)."""
    f = 1.0
    c = 1.0
    d = 0.0
    for j in range(1, _MAX_TERMS):
        m = j // 2
        if j % 2:
            dj = -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))
        else:
            dj = m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m))
        d = 1.0 + dj * d
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = 1.0 + dj / c
        c = c if abs(c) > _TINY else _TINY
        step = c * d
        f *= step
        if abs(step - 1.0) < _EPS:
            return f
    raise ArithmeticError(f"incomplete beta: the continued fraction did not converge "
                          f"(a = {a}, b = {b}, x = {x})")


def _log_tail(a: float, b: float, t: float, upper: bool) -> tuple[float, float]:
    """(ln T, d ln T/dt) with T = I_x(a, b) (``upper`` False) or 1 − I_x(a, b) (True) at
    x = 1/(1 + e⁻ᵗ)."""
    ln_x, ln_y = _log_x_y(t)
    ln_front = _log_front(a, b, ln_x, ln_y)
    x = math.exp(ln_x)
    lower_direct = x < (a + 1.0) / (a + b + 2.0)
    if lower_direct:      # I_x(a, b) = front/(a·fraction)
        ln_direct = ln_front - math.log(a * _fraction(a, b, x))
    else:                 # 1 − I_x(a, b) = I_{1−x}(b, a) (8.17.4)
        ln_direct = ln_front - math.log(b * _fraction(b, a, math.exp(ln_y)))
    # the tail that decreases with t (the upper one) has a negative slope
    sign = -1.0 if upper else 1.0
    if lower_direct != upper:
        ln_tail = ln_direct
    else:                 # the complement of the fraction's tail
        ln_tail = math.log1p(-math.exp(ln_direct)) if ln_direct < 0.0 else -math.inf
    return ln_tail, sign * math.exp(ln_front - ln_tail)


def _check_shape(a: float, b: float) -> None:
    if not (0.0 < a < math.inf and 0.0 < b < math.inf):
        raise ValueError(f"incomplete beta: a = {a} and b = {b} must be positive and finite")


def betainc_pair(a: float, b: float, x: float) -> tuple[float, float]:
    """(I_x(a, b), 1 − I_x(a, b)), each to full relative precision (0 ≤ x ≤ 1, a, b > 0)."""
    _check_shape(a, b)
    if not 0.0 <= x <= 1.0:
        raise ValueError(f"incomplete beta: x = {x} must lie in [0, 1]")
    if x == 0.0:
        return 0.0, 1.0
    if x == 1.0:
        return 1.0, 0.0
    t = math.log(x) - math.log1p(-x)
    ln_p, _ = _log_tail(a, b, t, upper=False)
    ln_q, _ = _log_tail(a, b, t, upper=True)
    return math.exp(ln_p), math.exp(ln_q)


def betainc(a: float, b: float, x: float) -> float:
    """I_x(a, b), the regularised incomplete beta function (DLMF 8.17.2)."""
    return betainc_pair(a, b, x)[0]


def _logit_quantile(a: float, b: float, target: float, upper: bool) -> float:
    """t = ln(x/(1 − x)) at which I_x(a, b) (or 1 − I_x(a, b), ``upper``) equals ``target``
    (0 < target ≤ ½: the tail that is given is the one solved for, at full precision)."""
    # start: ln F ≈ normal with mean 1/ν₂ − 1/ν₁ and variance 2/ν₁ + 2/ν₂ (Fisher's z), ν = 2a,
    # 2b; in t = ln(x/(1 − x)) = ln F + ln(a/b). Newton corrects any start (log-concavity).
    z = NormalDist().inv_cdf(target)
    t = math.log(a / b) + 0.5 / b - 0.5 / a + (-z if upper else z) * math.sqrt(1 / a + 1 / b)
    t = min(max(t, -_T_MAX), _T_MAX)
    lo, hi = -_T_MAX, _T_MAX
    ln_target = math.log(target)
    for _ in range(200):
        ln_tail, slope = _log_tail(a, b, t, upper)
        g = ln_tail - ln_target
        if g == 0.0:
            return t
        # the root lies where the tail is smaller (g > 0) or larger (g < 0)
        if (g > 0.0) == upper:
            lo = t
        else:
            hi = t
        new = t - g / slope if slope != 0.0 and math.isfinite(slope) else math.nan
        # converged: the tail equals the target to rounding, or the step is rounding
        if abs(g) <= 1e-14 * max(1.0, abs(ln_target)) or abs(new - t) <= 1e-15 * max(1.0, abs(t)):
            return new
        if not lo < new < hi:        # a step out of the bracket: bisect instead
            new = 0.5 * (lo + hi)
        if hi - lo <= 1e-15 * max(1.0, abs(t)):
            return new
        t = new
    raise ArithmeticError(f"incomplete beta inverse did not converge (a = {a}, b = {b}, "
                          f"target = {target})")


def _check_probability(p: float, name: str) -> None:
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"{name}: probability {p} must lie in [0, 1]")


def betaincinv(a: float, b: float, p: float) -> float:
    """x with I_x(a, b) = p (0 ≤ p ≤ 1, a, b > 0)."""
    _check_shape(a, b)
    _check_probability(p, "betaincinv")
    if p == 0.0:
        return 0.0
    if p == 1.0:
        return 1.0
    t = _logit_quantile(a, b, p, upper=False) if p <= 0.5 else \
        _logit_quantile(a, b, 1.0 - p, upper=True)
    return math.exp(_log_x_y(t)[0])


def _f_from_logit(t: float, dfn: float, dfd: float) -> float:
    # x = ν₁f/(ν₁f + ν₂) ⇒ t = ln(x/(1 − x)) = ln(ν₁f/ν₂)
    return dfd / dfn * math.exp(t) if t < 709.0 else math.inf


@lru_cache(maxsize=256)
def f_isf(q: float, dfn: float, dfd: float) -> float:
    """The F(ν₁ = dfn, ν₂ = dfd) upper quantile: f with Pr(F > f) = q (0 ≤ q ≤ 1), i.e.
    scipy's ``fdtri(dfn, dfd, 1 − q)`` without rounding 1 − q (A&S 26.6.2)."""
    _check_shape(dfn, dfd)
    _check_probability(q, "f_isf")
    if q == 0.0:
        return math.inf
    if q == 1.0:
        return 0.0
    a, b = 0.5 * dfn, 0.5 * dfd
    t = _logit_quantile(a, b, q, upper=True) if q <= 0.5 else \
        _logit_quantile(a, b, 1.0 - q, upper=False)
    return _f_from_logit(t, dfn, dfd)


def t_two_sided(q: float, dof: float) -> float:
    """|t| with Pr(|T| > t) = q for Student's t with ``dof`` degrees of freedom: T² is
    F(1, dof), so t = √(F(1, dof) upper quantile at q) (A&S 26.7.8 via 26.6.2)."""
    return math.sqrt(f_isf(q, 1.0, dof))


def f_ppf(p: float, dfn: float, dfd: float) -> float:
    """The F(ν₁ = dfn, ν₂ = dfd) lower quantile: f with Pr(F ≤ f) = p (scipy's ``fdtri``)."""
    _check_probability(p, "f_ppf")
    return f_isf(1.0 - p, dfn, dfd) if p > 0.5 else _f_lower(p, dfn, dfd)


def _f_lower(p: float, dfn: float, dfd: float) -> float:
    _check_shape(dfn, dfd)
    if p == 0.0:
        return 0.0
    return _f_from_logit(_logit_quantile(0.5 * dfn, 0.5 * dfd, p, upper=False), dfn, dfd)


def f_isf_array(q: float, dfn: float, dfd: ArrayLike) -> NDArray[np.float64]:
    """``f_isf`` over an array of ν₂ (the line finder's background degrees of freedom take a
    few dozen distinct values over thousands of bins: each is solved once)."""
    d = np.asarray(dfd, dtype=np.float64)
    values, where = np.unique(d, return_inverse=True)
    out = np.array([f_isf(q, float(dfn), float(v)) for v in values], dtype=np.float64)
    return out[where].reshape(d.shape)
