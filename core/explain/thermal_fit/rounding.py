"""The DS18B20 readings' rounding: its correlation time and the τ below which it floors the fit."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass
from avard.core.explain.thermal_fit.settings import DS18B20_CONVERSION_S

#: DS18B20 resolution (K) and the white-noise variance of its rounding, q²/12 (K²).
DS18B20_STEP_K = 0.0625
#: A log's own (step K, origin) (``screen.log_step``: a DS18B20 at 9–11 bits, a °F log
#: taken as °C) reaches every rounding term as an argument (``fit_thermal_axes``' ``grids``,
#: ``ThermalFit.grid``, ``choose_path``'s ``grid``, ``PathFit.grid``): each log is modelled
#: on its own step, and a coarse log leaves a finer one's model as it is. The default of
#: every such argument is the 12-bit (0.0625, 0).


#: How far a channel's AVAR must stand above its readings' rounding for a τ to enter the
#: regression: at 10 the rounding is ≤ 1/11 of the regressor's variance there.
ROUNDING_SNR = 10.0


def rounding_correlation_s(T: NDArray, rate_hz: float, step: float | None = None) -> float:
    """How long (s) the logged channel ``T`` (slow view) keeps one rounding error: a
    temperature moving at |dT/dt| crosses a 0.0625 K step every q/|dT/dt| s, and between
    crossings its rounding error is one slowly moving value of the sawtooth, not a new draw
    per reading; never less than the read interval (the rounding as white noise). |dT/dt|
    from 1-minute means (the differences of a rounded series are mostly its steps)."""
    T = np.asarray(T, dtype=float)
    if len(T) < 2:
        return DS18B20_CONVERSION_S
    slope = float(np.sqrt(np.mean(np.diff(T) ** 2))) * rate_hz
    k = max(1, round(60.0 * rate_hz))
    if len(T) > 4 * k:
        Tm = T[:len(T) // k * k].reshape(-1, k).mean(axis=1)
        slope = float(np.sqrt(np.mean(np.diff(Tm) ** 2))) * rate_hz / k
    q = DS18B20_STEP_K if step is None else step
    return max(DS18B20_CONVERSION_S, q / slope if slope > 0 else math.inf)


def rounding_floor_tau(T: NDArray, rate_hz: float, snr: float = ROUNDING_SNR,
                       step: float | None = None) -> float:
    """The shortest octave τ (s) from which the logged channel ``T`` (slow view) varies at
    least ``snr`` times more than its readings' rounding, the rounding taken as a sawtooth:
    AVAR_T(τ) ≥ snr·(q²/12)·t_c/τ at that τ, t_c the time one rounding
    error lasts (``rounding_correlation_s``). Below it the regressor is mostly rounding: an
    error in the variable that pulls ĉ towards 0 and, as a longer trial lag smooths the
    steps away, favours positive lags.

    The rounding taken as white at the read interval (t_c = 0.75 s) put the floor of a
    slowly turning room ≈ 3 octaves too low: on the faulty-log benchmark records (a true lag
    of 0) the best lag came out +7 s on average with a spread of 15 s, the rounding-free
    log's 0.6 ± 10.6; with the sawtooth 1.2 ± 10.2 (12 seeds). ``thermal_paths`` found the
    same for the per-τ coefficients (0.2–0.9× the truth at τ 16–64 s)."""
    T = np.asarray(T, dtype=float)
    if len(T) < 16:
        return 0.0
    step = DS18B20_STEP_K if step is None else step
    tc = rounding_correlation_s(T, rate_hz, step)
    sa = StreamingAllan(1, rate_hz)
    sa.update(T[:, None])
    res = sa.result()
    tau = np.asarray(res.tau, dtype=float)
    var = np.asarray(res.var, dtype=float)
    q = step**2 / 12.0 * tc / tau
    ok = np.isfinite(var) & (var >= snr * q)
    for i in range(len(tau)):
        # the first τ above the rounding, whatever the octaves after it: a cycle's AVAR
        # peaks below its period and dips towards its multiples, and for a drive of a step
        # or two's swing the next octave can sit in that dip under the bar; asked to pass
        # too, it put the floor past the cycle (or at ∞), leaving the coupling no τ (docs,
        # chan23g). Octaves in such a dip stay in the regression as they do beyond any
        # floor: their small AVAR_u weighs them little. (The rounding's model overstates
        # it below t_c, where the sawtooth's AVAR rises as τ²: an octave does not pass by
        # the model's error.)
        if ok[i]:
            return float(tau[i]) if i > 0 else 0.0
    return math.inf
