"""The DS18B20 readings' rounding seen through a path, and the EDF at a candidate's τ."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from avard.core.explain.thermal_fit.rounding import DS18B20_STEP_K, rounding_correlation_s
from avard.core.explain.thermal_paths.columns import Column
from avard.core.explain.thermal_paths.settings import RATE_SMOOTH_S
from numpy.typing import NDArray


def sawtooth_avar(T: NDArray, rate_hz: float, tau: NDArray, lag_s: float = 0.0,
                  gain2: Callable[[NDArray], NDArray] | None = None,
                  step: float | None = None) -> NDArray[np.float64]:
    """The readings' rounding AVAR (K²) at ``tau`` seen through ``lag_filter`` of ``lag_s``:
    the rounding as a sawtooth (``thermal_fit.rounding_correlation_s``), white at τ above
    its correlation time t_c with AVAR q²/12·t_c/τ (white FM, h₀ = q²t_c/6), the filter's
    |H(f)|² applied in the AVAR's integral ∫ h₀|H|²·2 sin⁴(πfτ)/(πfτ)² df (NIST SP 1065
    eq. 10's transfer function); a long lag passes little of it at τ below the lag.
    ``gain2``: |H(f)|² of another linear path instead (``_path_gain2``; then in (m/s²)²,
    its coefficients in it, and not capped at the readings' own 2q²/12). ``step``: the
    readings' step q (K), None the 12-bit 0.0625 (``choose_path`` passes its channel's)."""
    T = np.asarray(T, dtype=float)
    tau = np.asarray(tau, dtype=float)
    if len(T) < 16:
        return np.zeros(len(tau))
    step = DS18B20_STEP_K if step is None else step
    tc = rounding_correlation_s(T, rate_hz, step)
    if not (math.isfinite(tc) and tc > 0):
        # a channel that never crosses a step (constant, or stuck): no sawtooth to see
        return np.zeros(len(tau))
    q2 = step**2 / 12.0
    h0 = 2.0 * q2 * tc
    # f up to the correlation time's 1/(2 t_c), where the white model ends
    f = np.geomspace(1e-7, 0.5 / tc, 4000)
    w2 = (2 * np.pi * f) ** 2
    a = abs(lag_s)
    H2 = (gain2(f) if gain2 is not None else np.ones_like(f) if lag_s == 0
          else 1.0 / (1.0 + w2 * a * a) if lag_s > 0
          else (1.0 + 4.0 * w2 * a * a) / (1.0 + w2 * a * a))
    out = np.empty(len(tau))
    for i, t in enumerate(tau.tolist()):
        x = np.pi * f * t
        out[i] = np.trapezoid(h0 * H2 * 2.0 * np.sin(x) ** 4 / x**2, f) if t > 0 else 0.0
    if gain2 is not None:
        return np.asarray(out, dtype=float)
    return np.asarray(np.minimum(out, 2.0 * q2), dtype=float)


def _path_gain2(cols: tuple[Column, ...], beta: NDArray) -> Callable[[NDArray], NDArray]:
    """|H(f)|² of a linear path's couplings (m/s²/K)²: Σ β_i·H_i(f) over its "u" columns
    (a lag 1/(1 + jωL), a negative one's lead-lag (1 + 2jωa)/(1 + jωa)) and its "rate"
    column (jω/(1 + ω²s²), ``path_columns``); the start states carry no rounding."""
    terms = [(c, float(b)) for c, b in zip(cols, beta, strict=False) if c.kind in ("u", "rate")]

    def g(f: NDArray) -> NDArray:
        w = 2j * np.pi * np.asarray(f, dtype=float)
        H = np.zeros(len(w), dtype=complex)
        for c, b in terms:
            a = abs(c.lag)
            if c.kind == "rate":
                H += b * w / (1 - (w * RATE_SMOOTH_S) ** 2)
            elif c.lag > 0:
                H += b / (1 + w * a)
            elif c.lag < 0:
                H += b * (1 + 2 * w * a) / (1 + w * a)
            else:
                H += b
        return np.abs(H) ** 2

    return g


def _edf_at(tau: NDArray, tau_ref: NDArray, edf_ref: NDArray) -> NDArray[np.float64]:
    """The axis's EDF at ``tau``, interpolated in ln τ from the whole slow view's (the EDF
    at a τ does not depend on how finely the record was averaged below it)."""
    tr = np.asarray(tau_ref, float)
    er = np.asarray(edf_ref, float)
    ok = np.isfinite(er) & (er > 0) & (tr > 0)
    if not np.any(ok):
        return np.zeros(len(tau))
    return np.asarray(np.exp(np.interp(np.log(tau), np.log(tr[ok]), np.log(er[ok]),
                                       right=-np.inf)), dtype=float)
