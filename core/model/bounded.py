"""Bounded minimisation of a function of one variable: Brent's method (golden section with
parabolic steps) on [a, b], in plain Python.

Brent (*Algorithms for Minimization without Derivatives*, 1973, ch. 5, procedure fmin), in
the form of ``scipy.optimize.minimize_scalar(method="bounded")`` (scipy's
``_minimize_scalar_bounded``, BSD-3), step for step: the same trial points in the same
order, so the same minimum to the last bit (``tests/core/test_bounded.py`` holds it equal to
scipy's). Why here and not scipy: importing scipy.optimize cost `avard explain` about 0.4
CPU-s of its own for this one function (the Gauss–Markov scan's refinement of T), as
``nnls`` did for the noise fit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

__all__ = ["Minimum", "minimize_bounded"]

_SQRT_EPS = math.sqrt(2.2e-16)
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))


class Minimum(NamedTuple):
    """The point found, the function there, the evaluations made, and whether it met the
    tolerance within ``maxiter`` evaluations."""

    x: float
    fun: float
    nfev: int
    converged: bool


def _sign1(v: float) -> float:
    """sign(v), with +1 at 0 (scipy's ``np.sign(v) + (v == 0)``)."""
    return 1.0 if v >= 0 else -1.0


def minimize_bounded(func: Callable[[float], float], a: float, b: float,
                     xatol: float = 1e-5, maxiter: int = 500) -> Minimum:
    """The minimum of ``func`` on [a, b] to within ``xatol`` (plus √ε·|x|), at most
    ``maxiter`` evaluations."""
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ValueError("the bounds must be finite")
    if a > b:
        raise ValueError("the lower bound exceeds the upper bound")
    fulc = a + _GOLDEN * (b - a)
    nfc = xf = fulc
    rat = e = 0.0
    fx = func(xf)
    num = 1
    fu = math.inf
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    converged = True
    while abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = True
        if abs(e) > tol1:  # a parabola through the three best points
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r = e
            e = rat
            if abs(p) < abs(0.5 * q * r) and p > q * (a - xf) and p < q * (b - xf):
                rat = (p + 0.0) / q
                x = xf + rat
                if (x - a) < tol2 or (b - x) < tol2:
                    rat = tol1 * _sign1(xm - xf)
            else:
                golden = True
        if golden:
            e = (a - xf) if xf >= xm else (b - xf)
            rat = _GOLDEN * e
        x = xf + _sign1(rat) * max(abs(rat), tol1)
        fu = func(x)
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fnfc or nfc == xf:
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif fu <= ffulc or fulc == xf or fulc == nfc:
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxiter:
            converged = False
            break
    if math.isnan(xf) or math.isnan(fx) or math.isnan(fu):
        converged = False
    return Minimum(xf, fx, num, converged)
