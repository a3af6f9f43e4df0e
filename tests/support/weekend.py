"""A weekend as it really is: a generator written apart from ``avard simulate``, ``core/sim``
and ``tests/support/hidden.py`` (numpy only), for ``avard explain``'s checks of issue 23.

Physics, each stage its own first-order path with its own time constant:
room (HVAC cycle, a compressor's square-ish cycle, slow wander) → plate (``plate_tau_s``) →
die (``die_tau_s``, behind the plate) and → logged DS18B20 (``sensor_tau_s`` behind the plate,
rounded to 0.0625 K, one reading every 0.75 s). The accelerometer sees the *die*:
coefficient·T_die (+ optional terms in T_die², dT_die/dt, or a hysteresis), so a logged
sensor slower than the die is a negative lag, and two paths are two time constants.
Mechanisms outside explain's candidates (x only): a cubic response above a threshold, a cycle
from an unlogged channel, a tempco that ages or switches (a sign flip mid-run), a die lag that
drifts, a humidity- or pressure-like front on the 12 h tide, a tilt following a setback room
through the building's slow time constant, and a response to (dT/dt)².

Noise: white (N), flicker (B) by Kasdin's fractional-difference filter (h_k = h_{k−1}·(k − 1
+ α/2)/k, α = 1 for 1/f in rate, applied by FFT convolution), random walk (K).

Transients: warm-ups, steps and excursions (a step up then back) at given times, a linear
drift; periodic disturbances: a fundamental with harmonics and an amplitude modulation
(sidebands), a pump whose frequency moves linearly over the record. Log faults:
85.0 °C readings, −127 °C readings, dropouts (NaN) and a stuck stretch (the reading frozen),
and acceleration glitches (a few samples far off).

``make`` returns (accel (n, 3), temperature (n, k) with NaN between readings, names, truth
dict); ``save`` writes the .npz avard reads and the truth as JSON beside it.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

AXES = ("x", "y", "z")
READ_EVERY_S = 0.75
STEP_C = 0.0625


@dataclass
class Weekend:
    """What is hidden (SI units); every list holds tuples as documented."""

    hours: float = 4.0
    rate_hz: float = 10.0
    N: float = 1.6e-4
    B: float = 2e-5
    K: float = 2e-6
    hvac_c: float = 0.5
    hvac_period_s: float = 1800.0
    compressor_c: float = 0.0
    compressor_period_s: float = 1200.0
    wander_c: float = 0.05
    plate_tau_s: float = 600.0
    die_tau_s: float = 30.0
    sensor_tau_s: float = 60.0
    logged: tuple[str, ...] = ("plate",)
    coefficient: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s²/K on T_die
    quadratic: float = 0.0  # m/s²/K² on (T_die − mean) ², x only
    rate_coupling: float = 0.0  # m/s² per K/s on dT_die/dt, x only
    hysteresis_c: float = 0.0  # m/s²: ±h by the sign of the die's last move > 0.05 K, x only
    second_path: tuple[float, float] = (0.0, 0.0)  # (coefficient, die τ) of a 2nd path, x
    # mechanisms outside explain's thermal candidates (issue 23 item 5), x only:
    #: (m/s²/K³, K): a cubic response above a threshold, c₃·max(T_die − mean − T₀, 0)³
    threshold_cubic: tuple[float, float] = (0.0, 0.0)
    #: (m/s², period s): a humidity-like third channel that is not logged: a cycle of its own
    #: period whose phase wanders (a slow random walk of ±1 rad over the record)
    unlogged: tuple[float, float] = (0.0, 0.0)
    #: fractional change of the linear coefficient over the record (a tempco that ages:
    #: c·(1 + drift·(t/record − ½)))
    tempco_drift: float = 0.0
    #: (fraction of the record, factor): from that time on the linear coefficient is
    #: factor·c (a mount that slips, a screw that loosens: −1 flips its sign)
    tempco_switch: tuple[float, float] = (0.0, 1.0)
    #: s: the die's time constant moves linearly from die_tau_s to die_tau_s + this over the
    #: record (the air flow round the board changes: a lag that drifts)
    lag_drift_s: float = 0.0
    #: (m/s², s): a humidity- or pressure-like disturbance with no logged channel: a weather
    #: front (a logistic rise of this size over the given width, at a random time in the
    #: record's middle half) on half this size of the 12 h atmospheric tide
    humidity: tuple[float, float] = (0.0, 0.0)
    #: K over the record: the room's setback, a linear fall of the room (the HVAC still
    #: cycling on it)
    room_ramp_c: float = 0.0
    #: (m/s²/K, s): a tilt that follows the *room* through the building's own slow time
    #: constant (a slab, far beyond explain's lag grid)
    slab: tuple[float, float] = (0.0, 0.0)
    #: m/s² per (K/s)²: a response to the square of the die's rate of change (a gradient's
    #: stress, of either sign of the rate)
    rate_squared: float = 0.0
    warmups: list[tuple[float, float]] = field(default_factory=list)  # (size, T), x
    steps: list[tuple[float, float]] = field(default_factory=list)  # (time, size), x
    excursions: list[tuple[float, float, float]] = field(default_factory=list)  # (t0, t1, size)
    drift: float = 0.0  # m/s³: a linear drift of x about the record's middle
    #: periodic disturbances of x: (f0 Hz, amplitudes of harmonics 1, 2, … m/s², sideband
    #: offset Hz, modulation depth): A_k·(1 + depth·sin 2π f_m t)·sin(2π k f0 t + φ_k)
    periodic: list[tuple[float, tuple[float, ...], float, float]] = field(default_factory=list)
    #: a pump whose frequency moves linearly: (f at the start Hz, f at the end Hz, amplitude)
    pump: tuple[float, float, float] | None = None
    faults_85: int = 0
    faults_127: int = 0
    dropouts_s: list[tuple[float, float]] = field(default_factory=list)  # (start, length)
    stuck_s: list[tuple[float, float]] = field(default_factory=list)  # (start, length)
    glitches: list[tuple[float, int, float]] = field(default_factory=list)  # (t, n, size)


def _lag(u: NDArray, tau: float, dt: float) -> NDArray:
    """First-order lag, exact for a held input (y_k = a·y_(k−1) + (1 − a)·u_k), from steady
    state; a plain recursion (numpy only, no filter library)."""
    if tau <= 0:
        return u.copy()
    a = math.exp(-dt / tau)
    out = np.empty_like(u)
    y = float(u[0])
    for i, v in enumerate(u.tolist()):
        y = a * y + (1 - a) * v
        out[i] = y
    return out


def _lag_varying(u: NDArray, tau: NDArray, dt: float) -> NDArray:
    """First-order lag whose time constant moves (``tau`` per sample), from steady state."""
    a = np.exp(-dt / np.maximum(tau, 1e-9))
    out = np.empty_like(u)
    y = float(u[0])
    for i, (v, ai) in enumerate(zip(u.tolist(), a.tolist(), strict=True)):
        y = ai * y + (1 - ai) * v
        out[i] = y
    return out


def _kasdin_flicker(n: int, rng: np.random.Generator) -> NDArray:
    """Flicker (1/f) noise by Kasdin's fractional-difference filter (α = 1) on unit white
    noise, the whole record long: one-sided PSD 1/(π f) at low f, i.e. AVAR 2 ln 2/π
    (the bias instability's, per unit B²)."""
    k = np.arange(1, n)
    coeff = np.concatenate([[1.0], np.cumprod((k - 1 + 0.5) / k)])
    w = rng.standard_normal(n)
    size = 1 << math.ceil(math.log2(2 * n))
    return np.fft.irfft(np.fft.rfft(w, size) * np.fft.rfft(coeff, size), size)[:n]


def make(seed: int, w: Weekend) -> tuple[NDArray, NDArray, list[str], dict[str, Any]]:
    rng = np.random.default_rng(seed)
    dt = 1.0 / w.rate_hz
    n = int(w.hours * 3600 * w.rate_hz)
    t = np.arange(n) * dt
    ph = rng.uniform(0, 2 * math.pi, 3)
    room = 21.0 + w.hvac_c * np.sin(2 * math.pi * t / w.hvac_period_s + ph[0])
    if w.compressor_c:
        room += w.compressor_c * np.tanh(4 * np.sin(2 * math.pi * t / w.compressor_period_s
                                                    + ph[1]))
    room += w.wander_c * np.cumsum(rng.standard_normal(n)) / math.sqrt(n)
    room += w.room_ramp_c * (t / (n * dt) - 0.5)
    plate = _lag(room, w.plate_tau_s, dt)
    if w.lag_drift_s:
        die = _lag_varying(plate, w.die_tau_s + w.lag_drift_s * t / (n * dt), dt)
    else:
        die = _lag(plate, w.die_tau_s, dt)
    sensor = _lag(plate, w.sensor_tau_s, dt)
    acc = w.N * math.sqrt(w.rate_hz) * rng.standard_normal((n, 3))
    for j in range(3):  # AVAR (2 ln 2/π)·B² (NIST SP 1065 Table 5's flicker floor)
        acc[:, j] += w.B * _kasdin_flicker(n, rng)
    acc += w.K * math.sqrt(dt) * np.cumsum(rng.standard_normal((n, 3)), axis=0)
    dm = die - die.mean()
    for j in range(3):
        acc[:, j] += w.coefficient[j] * dm
    acc[:, 0] += w.quadratic * (dm ** 2 - np.mean(dm ** 2))
    if w.rate_coupling:
        acc[:, 0] += w.rate_coupling * np.gradient(die, dt)
    if w.hysteresis_c:
        state, ref, hy = 1.0, die[0], np.empty(n)
        for i in range(n):
            if die[i] - ref > 0.05:
                state, ref = 1.0, die[i]
            elif ref - die[i] > 0.05:
                state, ref = -1.0, die[i]
            ref = max(ref, die[i]) if state > 0 else min(ref, die[i])
            hy[i] = state
        acc[:, 0] += w.hysteresis_c * (hy - hy.mean())
    if w.second_path[0]:
        d2 = _lag(plate, w.second_path[1], dt)
        acc[:, 0] += w.second_path[0] * (d2 - d2.mean())
    if w.threshold_cubic[0]:
        x = np.maximum(dm - w.threshold_cubic[1], 0.0) ** 3
        acc[:, 0] += w.threshold_cubic[0] * (x - x.mean())
    if w.unlogged[0]:
        wander = np.cumsum(rng.standard_normal(n)) / math.sqrt(n)
        h = np.sin(2 * math.pi * t / w.unlogged[1] + ph[2] + wander)
        acc[:, 0] += w.unlogged[0] * (h - h.mean())
    if w.tempco_drift:
        acc[:, 0] += w.coefficient[0] * w.tempco_drift * (t / (n * dt) - 0.5) * dm
    if w.tempco_switch[1] != 1.0:
        after = t >= w.tempco_switch[0] * n * dt
        acc[:, 0] += w.coefficient[0] * (w.tempco_switch[1] - 1.0) * np.where(after, dm, 0.0)
    if w.humidity[0]:
        t0 = rng.uniform(0.25, 0.75) * n * dt
        front = 1.0 / (1.0 + np.exp(-(t - t0) / max(w.humidity[1], dt)))
        tide = 0.5 * np.sin(2 * math.pi * t / 43200.0 + rng.uniform(0, 2 * math.pi))
        h = w.humidity[0] * (front + tide)
        acc[:, 0] += h - h.mean()
    if w.slab[0]:
        s = _lag(room, w.slab[1], dt)
        acc[:, 0] += w.slab[0] * (s - s.mean())
    if w.rate_squared:
        r2 = np.gradient(die, dt) ** 2
        acc[:, 0] += w.rate_squared * (r2 - r2.mean())
    for size, T in w.warmups:
        acc[:, 0] += size * np.exp(-t / T)
    for ts, size in w.steps:
        acc[:, 0] += np.where(t >= ts, size, 0.0)
    for t0, t1, size in w.excursions:
        acc[:, 0] += np.where((t >= t0) & (t < t1), size, 0.0)
    if w.drift:
        acc[:, 0] += w.drift * (t - 0.5 * n * dt)
    for f0, amps, fm, depth in w.periodic:
        env = 1.0 + depth * np.sin(2 * math.pi * fm * t) if depth else 1.0
        for k, a in enumerate(amps, start=1):
            acc[:, 0] += a * env * np.sin(2 * math.pi * k * f0 * t + rng.uniform(0, 2 * math.pi))
    if w.pump is not None:
        fa, fb, a = w.pump
        span = n * dt
        acc[:, 0] += a * np.sin(2 * math.pi * (fa * t + 0.5 * (fb - fa) / span * t**2))
    for tg, k, size in w.glitches:
        i = int(tg * w.rate_hz)
        acc[i:i + k] += size
    every = max(1, round(READ_EVERY_S * w.rate_hz))
    cols = {"plate": sensor, "ambient": room}
    temps = np.full((n, len(w.logged)), np.nan)
    for c, name in enumerate(w.logged):
        r = np.round(cols[name][::every] / STEP_C) * STEP_C
        temps[::every, c] = r
    readings = np.flatnonzero(np.isfinite(temps[:, 0]))
    for k in rng.choice(len(readings) - 20, w.faults_85, replace=False) + 10:
        temps[readings[k], 0] = 85.0
    for k in rng.choice(len(readings) - 20, w.faults_127, replace=False) + 10:
        temps[readings[k], 0] = -127.0
    for s0, ln in w.stuck_s:
        i0, i1 = int(s0 * w.rate_hz), int((s0 + ln) * w.rate_hz)
        v = temps[i0:i1, 0]
        v[np.isfinite(v)] = np.nanmean(v[:every * 2])
    for s0, ln in w.dropouts_s:
        temps[int(s0 * w.rate_hz):int((s0 + ln) * w.rate_hz), :] = np.nan
    truth = asdict(w)
    truth["seed"] = seed
    truth["lag_effective_s"] = w.die_tau_s - w.sensor_tau_s  # die vs logged plate sensor
    return acc, temps, list(w.logged), truth


def save(seed: int, w: Weekend, path: Path) -> Path:
    acc, temps, names, truth = make(seed, w)
    np.savez(path, accel=acc, rate_hz=w.rate_hz, axes=np.array(AXES), temperature_c=temps,
             temperature_names=np.array(names))
    Path(str(path) + ".truth.json").write_text(json.dumps(truth, indent=1))
    return path
