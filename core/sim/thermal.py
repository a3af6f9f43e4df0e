"""Room, plate and die temperatures, their coupling into the acceleration, and DS18B20 readings.

The room air follows a set point, an HVAC cycle (sinusoid), a linear drift and a slow
Gauss–Markov wander. The sensor plate follows the room through a first-order thermal lag and the
ADXL355 die follows the plate through a second, shorter one, plus a self-heating warm-up after
power-on. The die temperature moves the output by a bias temperature coefficient (m/s²/K) and a
sensitivity coefficient (1/K) times the gravity component on that axis (datasheet: ±0.01 %/°C,
about 1e-3 m/s²/K on the 1 g axis).

Everything here is slow, so it runs on the simulator's coarsest grid (about one point per
second) and reaches the samples by linear interpolation.
"""

from __future__ import annotations

import math

import numpy as np
from avard.core.sim.linear_filter import ModalFilter, first_order_scan
from avard.core.sim.presets import SimConfig
from numpy.typing import NDArray

#: DS18B20 12-bit resolution (°C).
DS18B20_STEP_C = 0.0625


def lag_coefficients(tau_s: float, step_s: float) -> tuple[list[float], list[float]]:
    """Exact discretisation of dp/dt = (u − p)/τ for u linear between grid points
    (first-order hold): p[j] = a·p[j−1] + b0·u[j] + b1·u[j−1], a = e^(−Δ/τ),
    b0 = 1 − (τ/Δ)(1 − a), b1 = (τ/Δ)(1 − a) − a. DC gain 1, no lag bias on a ramp."""
    a = math.exp(-step_s / tau_s)
    k = (tau_s / step_s) * (-math.expm1(-step_s / tau_s))
    return [1.0 - k, k - a], [1.0, -a]


def _lagged_sine(amplitude: float, omega: float, taus: list[float]) -> tuple[float, float]:
    """Amplitude and phase of A·sin(ωt) after the first-order lags ``taus`` (steady state)."""
    amp, phase = amplitude, 0.0
    for tau in taus:
        amp /= math.hypot(1.0, omega * tau)
        phase -= math.atan(omega * tau)
    return amp, phase


class ThermalSource:
    """Slow-grid source, layout (3, m): the temperature coupling, warm-up bias transient and
    rate ramp (m/s²). The plate, ambient and die temperatures (°C) it computes on the way are
    kept for :meth:`temps`."""

    def __init__(self, cfg: SimConfig, step_s: float, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.step_s = step_s
        self.rng = rng
        self.j = 0
        self.omega = 2.0 * math.pi / cfg.hvac_period_s
        self.b_plate, self.a_plate = lag_coefficients(cfg.plate_tau_s, step_s)
        self.b_chip, self.a_chip = lag_coefficients(cfg.chip_tau_s, step_s)
        self.plate_lag = ModalFilter.first_order(*self.b_plate, -self.a_plate[1])
        self.chip_lag = ModalFilter.first_order(*self.b_chip, -self.a_chip[1])
        self._started = False
        self.phi_w = math.exp(-step_s / cfg.room_wander_tau_s)
        self.wander = cfg.room_wander_c * rng.standard_normal()
        gravity = np.asarray(cfg.gravity_mps2)
        self.k_temp = np.asarray(cfg.bias_tempco_mps2_per_k) + gravity * np.asarray(
            cfg.sensitivity_tempco_per_k)
        self.t_ref = cfg.room_temp_c if cfg.tempco_ref_c is None else cfg.tempco_ref_c
        self._tbuf = np.zeros((3, 0))        # plate, ambient, die for grid points from _tbuf_j0
        self._tbuf_j0 = 0

    def _initial_state(self, u0: float) -> tuple[float, float]:
        """Plate and die start in the steady state of the room's cycle and drift, so the record
        has no artificial settling transient (the warm-up is modelled on purpose). Returns the
        lags' states: y[0] = b0·u[0] + state."""
        c = self.cfg
        drift = c.room_drift_c_per_h / 3600.0
        amp_p, ph_p = _lagged_sine(c.hvac_amplitude_c, self.omega, [c.plate_tau_s])
        amp_c, ph_c = _lagged_sine(c.hvac_amplitude_c, self.omega, [c.plate_tau_s, c.chip_tau_s])
        base = c.room_temp_c + self.wander
        p0 = base + amp_p * math.sin(ph_p) - drift * c.plate_tau_s
        c0 = base + amp_c * math.sin(ph_c) - drift * (c.plate_tau_s + c.chip_tau_s)
        # y[0] = b0·u[0] + z  ⇒  z = y[0] − b0·u[0]
        return p0 - self.b_plate[0] * u0, c0 - self.b_chip[0] * p0

    def next_values(self, m: int) -> NDArray[np.float64]:
        c = self.cfg
        j = np.arange(self.j, self.j + m)
        self.j += m
        t = j * self.step_s
        # slow room wander: AR(1) on this grid (Gauss–Markov, σ = room_wander_c)
        w = self.rng.standard_normal(m)
        gain = c.room_wander_c * math.sqrt(-math.expm1(-2.0 * self.step_s / c.room_wander_tau_s))
        wander = first_order_scan(gain * w, self.phi_w, self.wander)
        ambient = (c.room_temp_c + c.hvac_amplitude_c * np.sin(self.omega * t)
                   + c.room_drift_c_per_h * t / 3600.0 + wander)
        if not self._started and m:
            self._started = True
            z_plate, z_chip = self._initial_state(float(ambient[0]))
            self.plate_lag.state[:] = z_plate
            self.chip_lag.state[:] = z_chip
        if m:
            self.wander = float(wander[-1])
        plate = self.plate_lag.run(ambient[None, :])[0]
        die = self.chip_lag.run(plate[None, :])[0]
        chip = die + c.warmup_chip_c * -np.expm1(-t / c.warmup_tau_s)
        self._tbuf = np.concatenate([self._tbuf, np.stack([plate, ambient, chip])], axis=1)
        return (np.outer(self.k_temp, chip - self.t_ref)
                + np.outer(c.warmup_bias_mps2, np.exp(-t / c.warmup_tau_s))
                + np.outer(c.rate_ramp, t))

    def temps(self, j0: int, j1: int) -> NDArray[np.float64]:
        """Plate, ambient and die temperature (3, j1−j0+1) at grid points j0..j1, which must
        have been generated; points before j1 − 1 are then dropped (requests move forward)."""
        if j0 < self._tbuf_j0 or j1 >= self._tbuf_j0 + self._tbuf.shape[1]:
            raise RuntimeError("temperature grid asked outside what was generated")  # a bug
        out = self._tbuf[:, j0 - self._tbuf_j0 : j1 - self._tbuf_j0 + 1]
        keep = max(self._tbuf_j0, j1 - 1)
        self._tbuf = self._tbuf[:, keep - self._tbuf_j0 :].copy()
        self._tbuf_j0 = keep
        return out


def ds18b20_schedule(index0: int, n: int, rate_hz: float, conversion_s: float) -> NDArray:
    """Sample indices in [index0, index0+n) at which a DS18B20 conversion completes: the k-th
    (k ≥ 1) at the first sample at or after k·conversion_s. A function of the index only, so
    chunks see the same schedule as a whole record."""
    per = conversion_s * rate_hz
    k0 = max(1, math.ceil((index0 - 1) / per))
    k1 = math.floor((index0 + n) / per) + 1
    k = np.arange(k0, k1 + 1)
    idx = np.ceil(k * per - 1e-9).astype(np.int64)
    return idx[(idx >= index0) & (idx < index0 + n)]


def ds18b20_readings(
    temp_c: NDArray, rate_hz: float, conversion_s: float = 0.75, *, index0: int = 0,
    offset_c: float | NDArray = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """DS18B20 readings of the true temperatures ``temp_c`` ((n,) or (n, k), one row per
    sample): one reading per conversion time, quantised to 0.0625 °C (12-bit), plus a fixed
    sensor offset. Returns (t_s, values): times in s from sample 0 and the readings (°C)."""
    temp = np.asarray(temp_c, dtype=float)
    idx = ds18b20_schedule(index0, len(temp), rate_hz, conversion_s)
    vals = temp[idx - index0] + np.asarray(offset_c, dtype=float)
    return idx / rate_hz, np.round(vals / DS18B20_STEP_C) * DS18B20_STEP_C


def ds18b20_aligned(temp_c: NDArray, rate_hz: float, conversion_s: float = 0.75, *,
                    index0: int = 0, offset_c: float | NDArray = 0.0) -> NDArray[np.float64]:
    """The readings of :func:`ds18b20_readings` placed on the sample grid: same shape as
    ``temp_c``, NaN where no reading completed (the .npz ``temperature_c`` layout)."""
    temp = np.asarray(temp_c, dtype=float)
    out = np.full(temp.shape, np.nan)
    idx = ds18b20_schedule(index0, len(temp), rate_hz, conversion_s)
    vals = temp[idx - index0] + np.asarray(offset_c, dtype=float)
    out[idx - index0] = np.round(vals / DS18B20_STEP_C) * DS18B20_STEP_C
    return out
