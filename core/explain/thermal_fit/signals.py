"""The temperature signal through a first-order lag, the de-rounded readings, and the Allan
differences and regression terms built from them."""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core.allan import kernels
from avard.core.allan.streaming import StreamingAllan
from avard.core.sim.thermal import lag_coefficients
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.holes import feed
from avard.core.explain.thermal_fit.settings import _RHO, DS18B20_CONVERSION_S


def lag_filter(T: NDArray, lag_s: float, rate_hz: float) -> NDArray[np.float64]:
    """T seen through a first-order lag of time constant ``lag_s`` (s), starting in steady
    state at T[0]; ``lag_s`` = 0 returns T.

    A negative ``lag_s`` is the logged sensor lagging the die: with a = |lag_s|, the lead-lag
    (1 + 2as)/(1 + as) = 2 − 1/(1 + as), i.e. 2T − lag(T, a): at the slow frequencies where
    the coupling acts it is T + a·dT/dt (the die a ahead of the log, continuous through 0
    with the lag, T − a·dT/dt), and its gain at high frequencies stays 2 where the pure
    inverse T + a·dT/dt would amplify the 0.0625 K rounding of the readings without bound
    (which buried a true −90 s lag under its own noise: found at +12 s). It is the model of a
    sensor lag 2a against a die lag a; other ratios differ from it at periods near a."""
    T = np.asarray(T, dtype=float)
    if lag_s < 0:
        return np.asarray(2.0 * T - lag_filter(T, -lag_s, rate_hz), dtype=float)
    if lag_s == 0:
        return T.copy()
    b, a = lag_coefficients(lag_s, 1.0 / rate_hz)
    c = kernels.compiled()
    if c is None or len(T) == 0:  # the general path
        from scipy import signal as sps

        zi = sps.lfilter_zi(b, a) * T[0]
        out, _ = sps.lfilter(b, a, T, zi=zi)
        return np.asarray(out, dtype=float)
    # the compiled loop (lfilter's operations, bit for bit: tests/core/test_kernels.py), from
    # the steady state lfilter_zi solves for, by the same solve: importing scipy.signal for
    # it cost explain more CPU than all its filtering
    zi = np.linalg.solve(np.eye(1) - np.array([[-a[1]]]), np.array([b[1] - a[1] * b[0]]))
    y = np.empty(len(T))
    c.first_order(np.ascontiguousarray(T), b[0], b[1], a[1], float(zi[0] * T[0]), y)
    return y


def allan2(y: NDArray, u: NDArray, rate_hz: float,
           keep: NDArray[np.bool_] | None = None) -> Any:
    """Allan variances and covariance of (y, u) with the streaming estimator (rows outside
    ``keep`` left out as gaps)."""
    sa = StreamingAllan(2, rate_hz)
    feed(sa, np.column_stack([y, u]), keep)
    return sa.result()


def _kept(res: Any, min_tau_s: float) -> NDArray[np.bool_]:
    """The rows (τ) of a two-channel Allan result the regression uses."""
    cov = np.asarray(res.cov, dtype=float)
    tau = np.asarray(res.tau, dtype=float)
    edf = np.asarray(res.edf, dtype=float)
    edf_y = edf[:, 0] if edf.ndim == 2 else edf
    vy, vu = cov[:, 0, 0], cov[:, 1, 1]
    return np.asarray(np.isfinite(vy) & np.isfinite(vu) & (vu > 0) & (tau >= min_tau_s)
                      & np.isfinite(edf_y) & (edf_y >= 3))


def regression_terms(res: Any, min_tau_s: float = 2 * DS18B20_CONVERSION_S
                     ) -> tuple[NDArray[np.float64], ...]:
    """(τ, Cov_A(y, u), AVAR_u, AVAR_y, ν_y) at the τ the regression uses, from a
    two-channel Allan result (axis, temperature)."""
    cov = np.asarray(res.cov, dtype=float)
    edf = np.asarray(res.edf, dtype=float)
    edf_y = edf[:, 0] if edf.ndim == 2 else edf
    ok = _kept(res, min_tau_s)
    return (np.asarray(res.tau, dtype=float)[ok], cov[ok, 0, 1], cov[ok, 1, 1],
            cov[ok, 0, 0], edf_y[ok])


@functools.lru_cache(maxsize=64)
def _rho(k: int) -> NDArray[np.float64]:
    """The correlation of neighbouring octaves' c_k for a white regressor and white noise,
    ``_RHO``^|i − j| (k, k): where no regressor's ``octave_spectra`` is at hand; the same
    few sizes every time, so made once each (read-only)."""
    idx = np.arange(k)
    rho = _RHO ** np.abs(np.subtract.outer(idx, idx))
    rho.flags.writeable = False
    return rho


def without_start(cols: NDArray, lag_s: float, rate_hz: float) -> NDArray[np.float64]:
    """``cols`` (M, k) with the lag filter's start-up settling e^(−t/τ_L) projected out of
    every column (least squares, with an offset).

    The sensor's temperature when the record starts is unknown; ``lag_filter`` starts in
    steady state at T[0], so the lagged channel differs from the sensor's by β·e^(−t/τ_L).
    With both the axis and the lagged temperature residualised on that shape, their
    regression gives the coefficient of the model y = c·u + β'·e^(−t/τ_L) (Frisch–Waugh).
    Without it, a plate-logged channel with a 20-minute lag (the start-up difference
    three times the lagged swing) gave the coefficient and the lag at 0.75× the truth even
    without noise."""
    X = np.asarray(cols, dtype=float)
    if lag_s == 0:
        return X.copy()
    # e^(−t/τ_L) is below 1e-16 after 37 lags: its products are taken where it lives (the
    # whole-record products cost most of a lag scan), the mean's share added in closed form
    # (Xc has zero mean, so vᵀXc = eᵀXc)
    M = len(X)
    n_e = min(M, math.ceil(37.0 * abs(lag_s) * rate_hz) + 1)
    e = np.exp(-np.arange(n_e) / (rate_hz * abs(lag_s)))
    mean_e = float(e.sum()) / M
    # einsum, not e @ e: OpenBLAS's threaded ddot spent ~100× the arithmetic's CPU time on a
    # shared machine
    vv = float(np.einsum("i,i->", e, e)) - M * mean_e**2
    if not vv > 0:
        return X.copy()
    Xc = X - X.mean(axis=0)
    w = (e @ Xc[:n_e]) / vv
    Xc += mean_e * w
    Xc[:n_e] -= np.outer(e, w)
    return Xc
