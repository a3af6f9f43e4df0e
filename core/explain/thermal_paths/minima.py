"""The stated minimum detectable effect of each thermal path (docs/explain.md)."""

from __future__ import annotations

import math

import numpy as np
from avard.core.explain.causes import noise_psd
from numpy.typing import NDArray


def _response_derivatives(kind: str, w: float, lag_s: float, lag2_s: float,
                          lags_known: bool) -> NDArray[np.complex128]:
    """∂G/∂p of a linear path's complex response G(ω) at ``w`` (rad/s), one row per
    parameter p the GLS fit estimates: two_path (c₁, c₂ and, with the lags unknown, c₁·L1
    and c₂·L2); rate (c, r and c·L). A lag enters as its coefficient times it (∂G/∂L_i
    divided by c_i): the other parameters' standard errors do not depend on how a nuisance
    column is scaled, so the minimum holds for any non-zero c_i."""
    h1, h2 = 1.0 / (1 + 1j * w * lag_s), 1.0 / (1 + 1j * w * lag2_s)
    if kind == "two_path":
        rows = [h1, h2] + ([] if lags_known else [-1j * w * h1**2, -1j * w * h2**2])
    else:
        rows = [h1, 1j * w] + ([] if lags_known else [-1j * w * h1**2])
    return np.array(rows, dtype=complex)


def min_detectable_path(kind: str, n_white: float, b_inst: float, k_rrw: float,
                        record_s: float, amplitude_c: float, period_s: float,
                        lag_s: float = 0.0, lag2_s: float = 0.0,
                        z: float = 5.0, lines: tuple[tuple[float, float], ...] = (),
                        lags_known: bool = False) -> float:
    """The smallest extra term of candidate ``kind`` the GLS fit detects at ``z`` on average,
    for a ±``amplitude_c`` sinusoid of ``period_s`` at the die (after the first path
    ``lag_s``) and the further drive ``lines`` ((amplitude at the die K, period s) each), with
    the linear coupling fitted beside it: the Fisher information of the fit's parameters on
    the noise PSD S(f) (N, B, K, NIST SP 1065 Table 5), one sinusoidal component of
    amplitude a known to σ_a(f) = √(2 S(f)/T) per quadrature.

    - two_path (m/s²/K, the second coefficient), rate (m/s² per K/s): every parameter the
      fit estimates unknown, the lags too (``lags_known``: only the coefficients, the
      minimum before, optimistic): with ∂G/∂p the response's derivatives at each line
      (``_response_derivatives``), I = Σ_lines (a/σ_a(f))²·Re(∂G ∂Gᴴ), e_min =
      z·√((I⁻¹)_ee). On one drive line the response is one complex number, 2 real ones,
      and two paths (c₁, c₂, L1, L2) or a dT/dt term (c, r, L: r − c·L and c(1 + ω²L²) are
      all one line tells) have more: I is singular and the minimum infinite (``math.inf``):
      there is no finite minimum with the lags unknown, the record's other content (its
      wander, its start) is all that tells them;
    - quadratic (m/s²/K²): (u − ū)² is −(a²/2)·cos 2ω t, e_min = z·σ_a(2f0)·2/a²;
    - hysteresis (m/s²): a ±h square wave switching a phase φ after each turn of the drive,
      odd harmonics 4h/(πk)·e^(−ikφ): h_min = z/√(Σ_k odd ≥ 3 (4/(πk))²/σ_a(k f0)²). The
      fundamental tells nothing of h: the fit estimates the linear coupling's gain and phase
      (c, L) and the switch's phase (L, w) beside h, and at f0 the relay's fundamental and
      the coupling are one sinusoid with a free gain and phase (2 numbers, 4 unknowns); only
      the harmonics fix h (and φ, orthogonal to it at each harmonic), and with them the
      coupling. The fundamental in the sum, as before, made the minimum 1/1.26 of this on the
      benchmark's drive: the minimum of a fit that knew the switch and the coupling.
    """
    f0 = 1.0 / period_s

    def sig(f: float) -> float:
        return math.sqrt(2 * noise_psd(f, n_white, b_inst, k_rrw) / record_s)

    a = amplitude_c
    if kind in ("two_path", "rate"):
        info: NDArray[np.float64] | None = None
        for amp, period in ((a, period_s), *lines):
            d = _response_derivatives(kind, 2 * math.pi / period, lag_s, lag2_s, lags_known)
            add = (amp / sig(1.0 / period)) ** 2 * np.real(np.outer(d, d.conj()))
            info = add if info is None else info + add
        assert info is not None
        ev = np.linalg.eigvalsh(info)
        if ev[0] <= 1e-10 * ev[-1]:
            return math.inf
        return z * math.sqrt(float(np.linalg.inv(info)[1, 1]))
    if kind == "quadratic":
        return z * sig(2 * f0) * 2 / a**2
    if kind == "hysteresis":
        s = sum((4 / (math.pi * k)) ** 2 / sig(k * f0) ** 2 for k in range(3, 40, 2))
        return z / math.sqrt(s)
    raise ValueError(kind)
