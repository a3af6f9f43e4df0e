"""Non-negative least squares, min ‖A·x − b‖ subject to x ≥ 0, in numpy.

The Lawson–Hanson active-set method (Lawson & Hanson, *Solving Least Squares Problems*, 1974,
ch. 23, algorithm NNLS): unknowns enter the passive (free) set one at a time, the one whose
gradient −Aᵀ(A·x − b) is largest; each step solves the unconstrained problem on the passive
set, and where that would make a passive unknown negative it moves only as far as the
feasible region allows and drops the unknowns that reach 0. At the end the solution is the
least-squares one on its positive set and no dropped unknown could lower the residual
(the Kuhn–Tucker conditions).

Why here and not ``scipy.optimize.nnls``: importing scipy.optimize costs `avard analyze`
0.3 CPU-s on a PC (seconds on a Pi) for this one function, and the simulator, whose start-up
must not load scipy, needs it too. The subproblems are solved by ``numpy.linalg.lstsq`` on
the columns of A, not the normal equations, so the conditioning is A's, not its square's
(the noise fit's basis spans many decades). ``tests/core/test_nnls.py`` holds it equal to
scipy's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from avard.core.errors import FitError
from numpy.typing import NDArray

__all__ = ["nnls"]

_GELSD: Any = None
try:  # the gufunc behind numpy.linalg.lstsq (LAPACK's gelsd), called without its checks
    from numpy.linalg import _umath_linalg

    _GELSD = _umath_linalg.lstsq
except (ImportError, AttributeError):  # pragma: no cover - a numpy without it: lstsq itself
    pass
_EPS = float(np.finfo(np.float64).eps)


def _svd_failed(_err: str, _flag: int) -> None:
    raise np.linalg.LinAlgError("SVD did not converge in Linear Least Squares")


def _lstsq(a: NDArray[np.float64], b: NDArray[np.float64],
           rcond: float | None = None) -> list[float]:
    """``numpy.linalg.lstsq(a, b, rcond)[0]`` for float64 a (m, n) and b (m,): the same
    gufunc on the same arrays with the same rcond (None: eps·max(m, n)), so the same numbers
    to the bit (``tests/core/test_nnls.py``), without lstsq's per-call conversions and
    checks, a third of its cost on the noise fit's (≈ 20 × ≤ 10) problems."""
    m, n = a.shape
    if _GELSD is None or m == 0:
        return list(np.linalg.lstsq(a, b, rcond=rcond)[0].tolist())
    with np.errstate(call=_svd_failed, invalid="call", over="ignore", divide="ignore",
                     under="ignore"):
        x = _GELSD(a, b[:, None], _EPS * max(m, n) if rcond is None else rcond,
                   signature="ddd->ddid")[0]
    return list(x[:, 0].tolist())


def nnls(a: NDArray, b: NDArray, maxiter: int | None = None
         ) -> tuple[NDArray[np.float64], float]:
    """(x ≥ 0 minimising ‖a·x − b‖, the residual norm ‖a·x − b‖) for a (m, n), b (m,).

    ``maxiter`` bounds the inner (backtracking) steps, 3·n by default; reaching it raises
    ``FitError`` (it only happens for degenerate problems).

    The noise fit solves thousands of these with n ≤ 10 unknowns, where numpy's per-call
    overhead on n-vectors was most of the cost: the bookkeeping on the unknowns is done on
    Python floats and lists, with the same IEEE operations in the same order (the same
    answer to the bit: ``tests/core/test_nnls.py``); the products with ``a`` and the
    subproblems' least squares stay numpy's."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.shape != (a.shape[0],):
        raise FitError(f"nnls needs a (m, n) matrix and a (m,) vector, got {a.shape} and "
                       f"{b.shape}")
    m, n = a.shape
    if n == 0:
        return np.zeros(0), float(np.linalg.norm(b))
    limit = 3 * n if maxiter is None else int(maxiter)
    x = [0.0] * n
    passive = [False] * n
    # gradients below this are rounding (Lawson & Hanson's tolerance, as scipy's)
    tol = 10.0 * _EPS * max(m, n) * max(1.0, float(np.abs(a).sum(axis=0).max()))
    w = (a.T @ b).tolist()
    # unknowns whose entry rounding undid (their own solution came out ≤ 0 at once, which
    # exact arithmetic rules out): not tried again, or the loop would pick them forever
    stuck = [False] * n
    steps = 0
    while True:
        # the free unknown of largest gradient (the first of equal ones, as argmax)
        j, best = -1, -math.inf
        for i in range(n):
            if not (passive[i] or stuck[i]) and (j < 0 or w[i] > best):
                j, best = i, w[i]
        if j < 0 or best <= tol:
            break
        passive[j] = True
        first = True
        while True:
            cols = [i for i in range(n) if passive[i]]
            sol = _lstsq(a[:, cols], b)
            z = [0.0] * n
            for i, v in zip(cols, sol, strict=True):
                z[i] = v
            if all(v > 0 for v in sol):
                break
            if first and z[j] <= 0:
                passive[j] = False
                stuck[j] = True
                z = x
                break
            first = False
            steps += 1
            if steps > limit:
                raise FitError(f"nnls did not converge in {limit} steps")
            # go from x towards z only as far as every passive unknown stays ≥ 0
            step = min(x[i] / (x[i] - z[i]) for i in cols if z[i] <= 0)
            x = [xi + step * (zi - xi) for xi, zi in zip(x, z, strict=True)]
            for i in range(n):
                passive[i] = passive[i] and x[i] > tol
                if not passive[i]:
                    x[i] = 0.0
        x = z
        xa = np.array(x)
        w = (a.T @ (b - a @ xa)).tolist()
    xa = np.array(x)
    r = a @ xa - b
    return xa, math.sqrt(float(r.dot(r)))  # numpy's norm of a vector, as it computes it
