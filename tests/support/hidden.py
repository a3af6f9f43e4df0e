"""A hidden-effect record generator for testing ``avard explain``, written apart from the
simulator (``avard simulate`` / ``core/sim/simulate.py`` / ``core/sim/thermal.py``).

Noise: white (per-sample σ = N·√fs), bias instability from ``noise_gen``'s flicker ladder
(the end-corrected one), rate random walk as a cumulative sum. Temperatures: an ambient
channel (HVAC sinusoid plus a slow AR(1) wander) and a plate that follows it through a
first-order lag; the sinusoid's lagged response is the closed form A/√(1+ω²τ²) at phase
−atan(ωτ), the wander's the zero-order-hold recursion: a different discretisation from the
one the fit uses (first-order hold). The sensor sees the *driving* channel through its own
first-order lag. Logged like a DS18B20: one reading every 0.75 s, 0.0625 °C steps, NaN in
between. Transients: a warm-up size·e^(−t/T) and a bias step; a Gauss–Markov process (AR(1));
a sinusoid (random phase per axis).

``make_record`` returns the record (``readers.Record``) and the truth separately, so a test
hands only the record (or its file) to explain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from avard.core.io.readers import Record
from avard.core.sim import noise_gen
from numpy.typing import NDArray

AXES = ("x", "y", "z")
DS18B20_STEP_C = 0.0625
DS18B20_CONVERSION_S = 0.75


@dataclass
class Truth:
    """What was hidden (SI units)."""

    coefficient: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s²/K per axis
    lag_s: float = 0.0
    drive: str = "ambient"  # which channel the sensor follows: "ambient" or "plate"
    warmup: tuple[float, float] | None = None  # (size m/s², time constant s), all axes
    step: tuple[float, float] | None = None  # (time s, size m/s²), all axes
    gauss_markov: tuple[float, float] | None = None  # (σ m/s², correlation time s), all axes
    sinusoid: tuple[float, float] | None = None  # (amplitude m/s², frequency Hz), all axes
    noise: dict[str, float] = field(default_factory=dict)


def _lagged_sine(t: NDArray, amp: float, omega: float, taus: list[float]) -> NDArray:
    a, ph = amp, 0.0
    for tau in taus:
        a /= math.hypot(1.0, omega * tau)
        ph -= math.atan(omega * tau)
    return a * np.sin(omega * t + ph)


def _zoh_lag(u: NDArray, tau: float, dt: float) -> NDArray:
    if tau <= 0:
        return u.copy()
    a = math.exp(-dt / tau)
    out = np.empty_like(u)
    x = u[0]
    # vectorised with lfilter would be the fit's tool; a plain recursion in blocks via
    # cumulative products is not needed at these sizes: use numpy's ufunc accumulate
    from scipy.signal import lfilter

    out = lfilter([1.0 - a], [1.0, -a], u, zi=[a * x])[0]
    return out


def make_record(seed: int, *, hours: float = 4.0, rate_hz: float = 10.0,
                N: float = 1.6e-4, B: float = 2e-5, K: float = 2e-6,
                truth: Truth | None = None, logged: tuple[str, ...] = ("plate", "ambient"),
                hvac_amp_c: float = 0.5, hvac_period_s: float = 1800.0,
                plate_tau_s: float = 600.0, wander_c: float = 0.05) -> tuple[Record, Truth]:
    """A 3-axis static record with the effects of ``truth`` (default: none)."""
    truth = truth or Truth()
    truth.noise = {"N": N, "B": B, "K": K}
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * rate_hz)
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    acc = N * math.sqrt(rate_hz) * rng.standard_normal((n, 3))
    acc += np.cumsum(K * math.sqrt(dt) * rng.standard_normal((n, 3)), axis=0)
    if B > 0:
        ladder = noise_gen.flicker_ladder([B] * 3, dt, 10 * n * dt, 2.0, dt_s=dt)
        bank = noise_gen.AR1Bank(ladder, dt, np.random.SeedSequence(seed + 17))
        acc += bank.next_values(n).T
    # temperatures: the sinusoid in closed form, the wander by a zero-order-hold recursion
    omega = 2 * math.pi / hvac_period_s
    wt = 7200.0
    phi = math.exp(-dt / wt)
    w = rng.standard_normal(n) * wander_c * math.sqrt(1 - phi * phi)
    from scipy.signal import lfilter

    wander = lfilter([1.0], [1.0, -phi], w, zi=[phi * wander_c * rng.standard_normal()])[0]
    ambient = 22.0 + hvac_amp_c * np.sin(omega * t) + wander
    plate = (22.0 + _lagged_sine(t, hvac_amp_c, omega, [plate_tau_s])
             + _zoh_lag(wander, plate_tau_s, dt))
    base = {"ambient": (0.0, [], wander), "plate": (0.0, [plate_tau_s], None)}
    if any(truth.coefficient):
        if truth.drive == "ambient":
            sensor = (_lagged_sine(t, hvac_amp_c, omega, [truth.lag_s])
                      + _zoh_lag(wander, truth.lag_s, dt))
        else:
            sensor = (_lagged_sine(t, hvac_amp_c, omega, [plate_tau_s, truth.lag_s])
                      + _zoh_lag(_zoh_lag(wander, plate_tau_s, dt), truth.lag_s, dt))
        acc += np.outer(sensor, np.asarray(truth.coefficient))
    del base
    if truth.warmup is not None:
        size, tc = truth.warmup
        acc += size * np.exp(-t / tc)[:, None]
    if truth.step is not None:
        ts, size = truth.step
        acc += np.where(t >= ts, size, 0.0)[:, None]
    if truth.gauss_markov is not None:
        sg, tg = truth.gauss_markov
        phi_g = math.exp(-dt / tg)
        wg = rng.standard_normal((n, 3)) * sg * math.sqrt(1 - phi_g * phi_g)
        x0 = sg * rng.standard_normal(3)
        acc += lfilter([1.0], [1.0, -phi_g], wg, axis=0, zi=(phi_g * x0)[None, :])[0]
    if truth.sinusoid is not None:
        amp_s, f_s = truth.sinusoid
        acc += amp_s * np.sin(2 * math.pi * f_s * t[:, None] + rng.uniform(0, 2 * math.pi, 3))
    chans = {"plate": plate, "ambient": ambient}
    temps = np.full((n, len(logged)), np.nan)
    idx = np.arange(1, int(n * dt / DS18B20_CONVERSION_S)) * DS18B20_CONVERSION_S * rate_hz
    idx = np.ceil(idx - 1e-9).astype(np.int64)
    idx = idx[idx < n]
    for j, name in enumerate(logged):
        temps[idx, j] = np.round(chans[name][idx] / DS18B20_STEP_C) * DS18B20_STEP_C
    rec = Record(acc, rate_hz, list(AXES), temps, list(logged), f"hidden seed {seed}")
    return rec, truth


def save(rec: Record, path: Path) -> Path:
    """The record as an .npz that ``avard analyze`` / ``avard explain`` read."""
    np.savez(path, accel=rec.accel, rate_hz=rec.rate_hz, axes=np.array(rec.names),
             temperature_c=rec.temperature_c,
             temperature_names=np.array(rec.temperature_names))
    return path
