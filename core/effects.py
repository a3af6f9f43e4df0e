"""Seeded hidden-effect generator for testing `avard explain`.

:func:`make_case` draws one cause (or none) and its parameters from a seeded random choice,
hides it in a simulated static record and returns the record and the truth *separately*, so
that a test hands only the record to the pipeline.

The base record is the ADXL355-like noise of allan.md: white noise (per-sample σ = N·√fs),
bias instability as a sum of first-order Gauss–Markov processes two per decade of correlation
time (scaled so the AVAR floor is (2 ln2/π)B²), and rate random walk (b[k] = b[k−1] + K√dt·w).
Every record carries two temperature channels ("plate", "ambient") read like a DS18B20
(0.0625 °C steps, a new value every second): ambient wanders as low-pass filtered noise plus
a slow drift, the plate follows it through a thermal time constant. Without a temperature
effect the acceleration does not depend on them, so they are a fair null witness.

Effect sizes are drawn relative to the base noise at the averaging time where the effect
shows, so each one is visible in the Allan deviation but not trivially large:
see ``_draw`` for the ranges (they are part of the test's statement).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from . import model
from .causes import CAUSES, oavar
from .errors import DataError

#: Cases cycle through these so that every cause (and the null record) appears.
CASE_KINDS = ("none", *CAUSES)


@dataclass
class HiddenRecord:
    """A simulated record as `explain` sees it (accel (n, 1) m/s², temperatures (n, 2) °C)."""

    accel: NDArray
    rate_hz: float
    names: list[str]
    temperature_c: NDArray
    temperature_names: list[str]
    source: str = "effects.make_case"
    meta: dict = field(default_factory=dict)


@dataclass
class Truth:
    """What was hidden: the cause (None for a null record), its parameters in SI units, and
    the base noise coefficients."""

    cause: str | None
    params: dict[str, float]
    noise: dict[str, float]
    record_s: float


def _flicker(rng: np.random.Generator, n: int, rate_hz: float, B: float) -> NDArray:
    """Bias instability as Σ Gauss–Markov processes, T spaced 2 per decade from 2τ0 to 10×
    the record (allan.md); the common σ is scaled so the mean AVAR over the covered τ range
    equals (2 ln2/π)B²."""
    dt = 1.0 / rate_hz
    Ts = 10.0 ** np.arange(math.log10(2 * dt), math.log10(10 * n * dt), 0.5)
    tau = np.geomspace(10 * dt, n * dt / 10, 24)
    floor = sum(model.gauss_markov_avar(tau, 1.0, T) for T in Ts)
    s2 = (model.BI_FACTOR * B) ** 2 / float(np.mean(floor))
    out = np.zeros(n)
    for T in Ts:
        a = math.exp(-dt / T)
        w = rng.standard_normal(n) * math.sqrt(s2 * (1 - a * a))
        x = signal.lfilter([1.0], [1.0, -a], w)
        x += rng.standard_normal() * math.sqrt(s2) * a ** np.arange(n)  # stationary start
        out += x
    return out


def _temperatures(rng: np.random.Generator, n: int, rate_hz: float) -> NDArray:
    """True ambient and plate temperatures (°C) at the sample rate."""
    dt = 1.0 / rate_hz
    # work at 1 Hz and interpolate: temperatures are slow
    n1 = int(n * dt) + 2
    corner_s = rng.uniform(150.0, 400.0)
    a = math.exp(-1.0 / corner_s)
    w = rng.standard_normal(n1) * math.sqrt(1 - a * a)
    x = signal.lfilter([1.0], [1.0, -a], w)
    x = signal.lfilter([1.0], [1.0, -a], x)
    x *= rng.uniform(0.3, 0.6) / max(np.std(x), 1e-12)
    t1 = np.arange(n1)
    drift = rng.uniform(-0.4, 0.4) / 3600.0 * t1
    ambient = 22.0 + x + drift
    tc = rng.uniform(200.0, 600.0)
    b = math.exp(-1.0 / tc)
    plate = signal.lfilter([1 - b], [1.0, -b], ambient - ambient[0]) + ambient[0]
    t = np.arange(n) * dt
    return np.column_stack([np.interp(t, t1, plate), np.interp(t, t1, ambient)])


def _ds18b20(temp_true: NDArray, rate_hz: float) -> NDArray:
    """What a DS18B20 reports: 0.0625 °C steps, a new conversion every second, held between."""
    n = len(temp_true)
    hold = max(1, round(rate_hz))
    idx = (np.arange(n) // hold) * hold
    return np.round(temp_true[idx] / 0.0625) * 0.0625


def base_adev(tau: NDArray, noise: dict[str, float]) -> NDArray:
    """ADEV of the base noise (closed forms, allan.md)."""
    v = (model.term_avar("velocity_random_walk", tau, noise["N"])
         + model.term_avar("bias_instability", tau, noise["B"])
         + model.term_avar("rate_random_walk", tau, noise["K"]))
    return np.sqrt(v)


def _draw(rng: np.random.Generator, cause: str | None, n: int, rate_hz: float,
          noise: dict[str, float], temps_true: NDArray) -> dict[str, float]:
    """Parameters of the hidden effect, scaled to the base noise where it shows."""
    T = n / rate_hz

    def adev(tau: float) -> float:
        return float(base_adev(np.array([tau]), noise)[0])

    sign = rng.choice([-1.0, 1.0])
    if cause is None:
        return {}
    if cause == "temperature":
        ch = int(rng.integers(0, 2))
        lag = float(rng.uniform(60.0, 300.0))
        # the coupled ADEV c·ADEV_T(τ) is 2–6× the base ADEV at τ = T/32 (where the Allan
        # covariance regression still has ~30 independent differences)
        tau = T / 32.0
        m = np.array([max(1, round(tau * rate_hz))])
        adev_t = math.sqrt(float(oavar(temps_true[:, ch], rate_hz, m)[0]))
        c = sign * rng.uniform(2.0, 6.0) * adev(tau) / adev_t
        return {"coefficient": c, "lag_s": lag, "channel": ch}
    if cause == "sinusoid":
        f0 = float(math.exp(rng.uniform(math.log(40.0 / T), math.log(rate_hz / 20.0))))
        snr = rng.uniform(2.0, 6.0)  # peak ADEV / base ADEV at τ = 0.371/f0
        amp = snr * adev(0.371 / f0) / 0.7246
        return {"frequency_hz": f0, "amplitude": float(amp)}
    if cause == "bias_step":
        t_s = float(rng.uniform(0.1, 0.9) * T)
        w = 0.01 * T
        size = sign * rng.uniform(12.0, 30.0) * math.sqrt(2.0) * adev(w)
        return {"time_s": t_s, "size": float(size)}
    if cause == "warmup":
        tc = float(rng.uniform(0.01, 0.06) * T)
        size = sign * rng.uniform(20.0, 50.0) * math.sqrt(2.0) * adev(tc) / 0.4
        return {"time_constant_s": tc, "size": float(size)}
    if cause == "rate_ramp":
        tau = T / 32.0
        slope = sign * rng.uniform(4.0, 10.0) * adev(tau) * math.sqrt(2.0) / tau
        return {"slope": float(slope)}
    if cause == "gauss_markov":
        tc = float(math.exp(rng.uniform(math.log(1.0), math.log(T / 100.0))))
        sigma = rng.uniform(2.5, 6.0) * adev(1.893 * tc) / 0.6174
        return {"sigma": float(sigma), "time_constant_s": tc}
    if cause == "quantization":
        sd = noise["N"] * math.sqrt(rate_hz)
        return {"lsb": float(rng.uniform(0.5, 2.0) * sd)}
    if cause == "filter":
        return {"bandwidth_hz": float(rng.uniform(rate_hz / 12.0, rate_hz / 4.0))}
    raise DataError(f"unknown cause {cause!r}; choose one of {', '.join(CAUSES)}")


def make_case(seed: int, cause: str | None = "random", *, n: int = 1 << 18,
              rate_hz: float = 50.0) -> tuple[HiddenRecord, Truth]:
    """Draw (with ``seed``) a cause — ``"random"`` picks one of :data:`CASE_KINDS` — and its
    parameters, hide it in a simulated record of ``n`` samples at ``rate_hz``, and return
    ``(record, truth)``. ``cause=None`` or ``"none"`` gives a null record."""
    if n < 1 << 14:
        raise DataError(f"n={n} samples is too short for a hidden-effect case; use >= 16384")
    rng = np.random.default_rng(seed)
    if cause == "random":
        cause = str(rng.choice(CASE_KINDS))
    if cause == "none":
        cause = None
    noise = {"N": 1.6e-4 * rng.uniform(0.7, 1.4), "B": 2.0e-5 * rng.uniform(0.7, 1.4),
             "K": 5.0e-7 * rng.uniform(0.5, 2.0)}
    dt = 1.0 / rate_hz
    white = rng.standard_normal(n) * noise["N"] * math.sqrt(rate_hz)
    temps_true = _temperatures(rng, n, rate_hz)
    params = _draw(rng, cause, n, rate_hz, noise, temps_true)
    if cause == "filter":
        b, a = signal.butter(2, params["bandwidth_hz"] / (rate_hz / 2))
        white = signal.lfilter(b, a, white) / (np.sum(b) / np.sum(a))
    y = white + _flicker(rng, n, rate_hz, noise["B"])
    y += np.cumsum(rng.standard_normal(n)) * noise["K"] * math.sqrt(dt)
    t = np.arange(n) * dt
    if cause == "temperature":
        ch = int(params.pop("channel"))
        k = round(params["lag_s"] * rate_hz)
        Tt = temps_true[:, ch]
        Td = np.concatenate((np.full(k, Tt[0]), Tt[: n - k]))
        y += params["coefficient"] * (Td - Td.mean())
        params["channel"] = ch  # kept for the reader of the truth; not an explain parameter
    elif cause == "sinusoid":
        y += params["amplitude"] * np.sin(2 * np.pi * params["frequency_hz"] * t
                                          + rng.uniform(0, 2 * np.pi))
    elif cause == "bias_step":
        y += np.where(t >= params["time_s"], params["size"], 0.0)
    elif cause == "warmup":
        y += params["size"] * np.exp(-t / params["time_constant_s"])
    elif cause == "rate_ramp":
        y += params["slope"] * (t - t.mean())
    elif cause == "gauss_markov":
        a = math.exp(-dt / params["time_constant_s"])
        w = rng.standard_normal(n) * params["sigma"] * math.sqrt(1 - a * a)
        gm = signal.lfilter([1.0], [1.0, -a], w)
        y += gm + rng.standard_normal() * params["sigma"] * a ** np.arange(n)
    elif cause == "quantization":
        y = np.round(y / params["lsb"]) * params["lsb"]
    temps = np.column_stack([_ds18b20(temps_true[:, 0], rate_hz),
                             _ds18b20(temps_true[:, 1], rate_hz)])
    rec = HiddenRecord(y.reshape(n, 1), float(rate_hz), ["x"], temps, ["plate", "ambient"],
                       meta={"seed": seed})
    return rec, Truth(cause, params, noise, n / rate_hz)


#: Tolerances of the hidden-effect tests (relative unless noted). Issue 6 fixes frequency 2 %,
#: temperature coefficient 20 %, step time 2 % of the record and time constants 30 %; the
#: sizes are held to 30 %, the slope to 20 % and the LSB to 1 %.
TOLERANCE = {
    "frequency_hz": 0.02,
    "coefficient": 0.20,
    "time_s": 0.02,  # of the record length
    "lag_s": 0.30,
    "time_constant_s": 0.30,
    "bandwidth_hz": 0.30,
    "amplitude": 0.30,
    "size": 0.30,
    "slope": 0.20,
    "sigma": 0.30,
    "lsb": 0.01,
}


def check_case(truth: Truth, findings: list[dict]) -> tuple[bool, str]:
    """Did `explain` name the hidden cause (and only it) with parameters within
    :data:`TOLERANCE`? Returns (passed, reason)."""
    causes = [f["cause"] for f in findings]
    if truth.cause is None:
        return (not findings, "null record: no finding" if not findings
                else f"null record, but claimed {causes}")
    if causes != [truth.cause]:
        return False, f"hid {truth.cause}, explain claimed {causes}"
    got = findings[0]["params"]
    bad = []
    for k, v in truth.params.items():
        if k == "channel":
            continue
        tol = TOLERANCE[k]
        err = abs(got[k] - v) / (truth.record_s if k == "time_s" else abs(v))
        if not err <= tol:
            bad.append(f"{k} {got[k]:.4g} vs {v:.4g} (error {err:.3g} > {tol:g})")
    if bad:
        return False, f"{truth.cause}: " + "; ".join(bad)
    return True, f"{truth.cause} found within tolerance"
