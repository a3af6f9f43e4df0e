"""The scatter a deterministic part of the signal adds to an OADEV estimate: its cross term
with the noise, exactly, under the fitted noise spectrum (issue 24).

An overlapping AVAR estimate at averaging factor m over M differences is
σ̂² = (1/M)·Σ_k u_k², u_k = (ȳ_{k+m} − ȳ_k)/√2. With y = s + n (s deterministic: a rate ramp,
a sinusoid) u_k = a_k + v_k and

    σ̂² = S + (1/M)Σ v_k² + (2/M)Σ a_k v_k,     S = (1/M)Σ a_k²,

so beside the noise's own scatter the estimate has the cross term's,

    Var[(2/M)Σ a_k v_k] = (4/M²)·∫_{−½}^{½} S_n(ν)·|A(ν)|²·|H_m(ν)|² dν,

A(ν) = Σ_k a_k e^{−2πiνk}, H_m the response of u_k (|H_m|² = 2 sin⁴(πνm)/(m² sin²(πν)),
the convention of ``model.terms``: AVAR = ∫ S|H_m|²), S_n the noise's two-sided PSD in
cycles per sample. A ramp's a_k is one constant, √S: |A|² = S·|D_M(ν)|², the Dirichlet
kernel sin²(πMν)/sin²(πν) (the sum telescopes: only the record's two ends weigh). A
sinusoid of frequency ν₀ has a_k = √(2S)·sin(2πν₀k + φ): averaged over its phase,
|A|² = (S/2)·(|D_M(ν − ν₀)|² + |D_M(ν + ν₀)|²). So the cross term's variance is S times
``cross_term_variance`` (the kernel per unit S), whatever the noise.

The non-central χ² (``edf.edf_with_signal``) is this with the signal's differences spread
like the noise's own, the largest a Gaussian quadratic form allows: a smooth signal's
Dirichlet kernel weighs only the noise near its own frequency, and the exact term is far
smaller (the estimate of a record dominated by a ramp scatters little more than the ramp's
own AVAR, which does not scatter).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["cross_term_variance"]

PsdFn = Callable[[NDArray[np.float64]], NDArray[np.float64]]

#: half-width of the Dirichlet kernel's main region, in 1/M: resolved exactly there, its
#: mean 1/(2 sin²) outside (the tail's oscillation averages out against a smooth spectrum)
_NEAR = 32
#: above c/m the response |H_m|²'s sin⁴ oscillates faster than the rest varies: its mean 3/8
_C_FAST = 4.0


def _dirichlet2(x: NDArray[np.float64], n: int, near: NDArray[np.bool_]) -> NDArray[np.float64]:
    """|D_n(x)|² = sin²(πnx)/sin²(πx); its mean over the fast oscillation off ``near``."""
    s2 = np.sin(np.pi * x) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        exact = np.where(s2 > 0, np.sin(np.pi * n * x) ** 2 / s2, float(n) ** 2)
        mean = 0.5 / s2
    return np.where(near, exact, mean)


def _nodes(m: int, n_diff: int, f0: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Midpoints and widths on [0, ½]: fine (1/(16M)) within _NEAR/M of ±ν₀, fine in the
    response's oscillation (1/(32m)) below c/m, geometric in the distance from ν₀ and from 0
    elsewhere."""
    w = _NEAR / n_diff
    parts = [np.linspace(max(f0 - w, 0.0), min(f0 + w, 0.5), 2 * 16 * _NEAR + 1),
             np.geomspace(1.0 / (16 * n_diff), 0.5, 512),
             np.clip(f0 + np.geomspace(w, 0.5, 512), 0.0, 0.5),
             np.clip(f0 - np.geomspace(w, 0.5, 512), 0.0, 0.5),
             np.linspace(0.0, min(0.5, _C_FAST / m), 129 if _C_FAST / m < 0.5 else 33)]
    edges = np.unique(np.concatenate([[0.0, 0.5], *parts]))
    return 0.5 * (edges[1:] + edges[:-1]), np.diff(edges)


def cross_term_variance(noise_psd: PsdFn, m: int, n_diff: int, f0: float = 0.0) -> float:
    """Var of the cross term of an OADEV estimate at averaging factor ``m`` over ``n_diff``
    differences with a deterministic part whose own AVAR there is 1: a ramp (``f0`` = 0) or
    a sinusoid of frequency ``f0`` (cycles per sample, phase averaged), under the two-sided
    noise PSD ``noise_psd`` (cycles per sample; module docstring). Multiply by the part's
    AVAR S."""
    if n_diff < 1 or m < 1:
        return float("nan")
    nu, width = _nodes(m, n_diff, float(f0))
    s = np.asarray(noise_psd(nu), dtype=float)
    sin2 = np.sin(np.pi * nu) ** 2
    fast = 3.0 / 8.0 if m > 1 else 1.0  # (m = 1: sin⁴(πν)/sin²(πν) is smooth)
    sin4 = np.where(nu * m < _C_FAST, np.sin(np.pi * nu * m) ** 4, fast)
    if m == 1:
        sin4 = np.sin(np.pi * nu) ** 4
    h2 = 2.0 * sin4 / (m * m * sin2)
    w = _NEAR / n_diff
    lower, upper = nu - f0, nu + f0
    kern = 0.5 * (_dirichlet2(lower, n_diff, np.abs(lower) < w)
                  + _dirichlet2(upper, n_diff, np.abs(upper) < w))
    # two-sided: twice the integral over [0, ½] of an even integrand
    integral = 2.0 * float(np.sum(width * s * h2 * kern))
    return 4.0 * integral / float(n_diff) ** 2
