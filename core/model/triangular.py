"""Solves with a lower-triangular matrix L (a Cholesky factor), L·X = B, in numpy.

Why here and not ``scipy.linalg.solve_triangular``: importing scipy.linalg cost `avard
explain` about 0.2 CPU-s (and ~30 MB), more than all of its triangular solves, which whiten
the block means of the time-domain tests (``causes``, ``transients``) by the noise
covariance's Cholesky factor. ``avard analyze`` imports no scipy, and explain no longer
does either (as for ``nnls`` and ``bounded``).

Method: blocked forward substitution. L is cut into diagonal blocks of ``BLOCK`` rows; each
diagonal block's inverse is computed once per factor (``LowerSolver``: one factor whitens
many columns), and a solve is, block by block, X_i = L_ii⁻¹·(B_i − L_i,<i·X_<i): matrix
products only. The inverse of a diagonal block (LU with partial pivoting, ``numpy.linalg.inv``)
is as accurate as that block's condition, smaller than the whole factor's; the result agrees
with LAPACK's dtrsm to rounding (``tests/core/test_triangular.py`` holds it to scipy's).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["BLOCK", "LowerSolver", "solve_lower"]

#: Rows per diagonal block: the products dominate above it, the per-block calls below.
BLOCK = 64


class LowerSolver:
    """Solves L·X = B for one lower-triangular ``L`` (n, n) with nonzero diagonal, its
    diagonal blocks inverted once for every right-hand side."""

    def __init__(self, L: NDArray) -> None:
        L = np.asarray(L, dtype=np.float64)
        if L.ndim != 2 or L.shape[0] != L.shape[1]:
            raise ValueError(f"L must be a square matrix, got shape {L.shape}")
        self.n = L.shape[0]
        self._L = L
        self._edges = [*range(0, self.n, BLOCK), self.n]
        # np.tril: the inverse of a lower-triangular block is lower triangular; LU's
        # rounding leaves tiny values above the diagonal, which would mix rows in
        self._inv = [np.tril(np.linalg.inv(L[a:b, a:b]))
                     for a, b in zip(self._edges[:-1], self._edges[1:], strict=True)]

    def solve(self, B: NDArray) -> NDArray[np.float64]:
        """X with L·X = B, B (n,) or (n, k)."""
        B = np.asarray(B, dtype=np.float64)
        if B.shape[:1] != (self.n,) or B.ndim > 2:
            raise ValueError(f"B must have {self.n} rows (a vector or a matrix), got shape "
                             f"{B.shape}")
        X = np.empty_like(B)
        for i, (a, b) in enumerate(zip(self._edges[:-1], self._edges[1:], strict=True)):
            rhs = B[a:b] - self._L[a:b, :a] @ X[:a] if a else B[a:b]
            X[a:b] = self._inv[i] @ rhs
        return X


def solve_lower(L: NDArray, B: NDArray) -> NDArray[np.float64]:
    """X with L·X = B for a lower-triangular ``L`` (n, n) and B (n,) or (n, k): one solve
    (``LowerSolver`` when the same L solves several)."""
    return LowerSolver(L).solve(B)
