"""adv29's record generator: numpy only, written from the docs alone (not from core/sim,
tests/support/hidden.py or the earlier adversary generators), with the truth beside each record.

Each builder returns ``(arrays, truth)``: ``arrays`` is what goes into an ``.npz`` as
docs/analysis.md *What it reads* describes it (``accel`` (N, C) in m/s², ``rate_hz``,
``temperature_c`` (N, k) with NaN between readings, ``temperature_names``), ``truth`` a dict of
the generated parameters. ``save(path, arrays, truth)`` writes the record and ``PATH.truth.json``.

The physics is deliberately simple and known exactly: white noise of density N (m/s/√s), a
random walk of K (m/s²/√s), a bias step or a warm-up of known size and time, a temperature
coupling c (m/s²/K) through a first-order lag of L seconds, and a DS18B20 log read every
``period_s`` on a ``step_k`` grid.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

G_NOISE_N = 1.56e-4  # the ADXL355's datasheet white level, m/s/√s


def white(n: int, rate_hz: float, density: float, rng: np.random.Generator) -> np.ndarray:
    """White acceleration noise whose ADEV is density/√τ."""
    return rng.standard_normal(n) * density * np.sqrt(rate_hz)


def random_walk(n: int, rate_hz: float, k: float, rng: np.random.Generator) -> np.ndarray:
    """Rate random walk whose AVAR is K²τ/3."""
    return np.cumsum(rng.standard_normal(n)) * k / np.sqrt(rate_hz)


def lag(x: np.ndarray, rate_hz: float, tau_s: float) -> np.ndarray:
    """First-order lag (exact discretisation), starting settled at x[0]."""
    if tau_s <= 0:
        return x.copy()
    a = np.exp(-1.0 / (rate_hz * tau_s))
    y = np.empty_like(x)
    acc = x[0]
    # block-free loop in numpy: scipy-free IIR by cumulative trick is unstable for long
    # records, so run it in chunks of python (records here are ≤ 150 k samples)
    for i, v in enumerate(x):
        acc = a * acc + (1.0 - a) * v
        y[i] = acc
    return y


def ds18b20(
    temp: np.ndarray, rate_hz: float, period_s: float = 1.0, step_k: float = 0.0625, phase: int = 0
) -> np.ndarray:
    """A DS18B20 log on the sample grid: a reading every period_s, rounded to step_k, NaN
    between readings (the shape docs/explain.md says avard's own records hold)."""
    out = np.full(temp.shape, np.nan)
    every = max(1, round(period_s * rate_hz))
    idx = np.arange(phase, temp.size, every)
    out[idx] = np.round(temp[idx] / step_k) * step_k
    return out


def room(
    n: int,
    rate_hz: float,
    mean_c: float,
    amp_k: float,
    period_s: float,
    rng: np.random.Generator,
    wander_k: float = 0.0,
) -> np.ndarray:
    t = np.arange(n) / rate_hz
    r = mean_c + amp_k * np.sin(2 * np.pi * t / period_s + rng.uniform(0, 2 * np.pi))
    if wander_k:
        w = np.cumsum(rng.standard_normal(n))
        w = w / np.max(np.abs(w)) * wander_k
        r = r + w
    return r


def base(
    hours: float,
    rate_hz: float,
    channels: int,
    seed: int,
    n_density: float = G_NOISE_N,
    k: float = 0.0,
) -> tuple[np.ndarray, np.random.Generator]:
    rng = np.random.default_rng(seed)
    n = round(hours * 3600 * rate_hz)
    acc = np.empty((n, channels))
    for c in range(channels):
        acc[:, c] = white(n, rate_hz, n_density, rng)
        if k:
            acc[:, c] += random_walk(n, rate_hz, k, rng)
    return acc, rng


def pack(acc: np.ndarray, rate_hz: float, temps: dict[str, np.ndarray] | None = None) -> dict:
    arrays: dict = {"accel": acc, "rate_hz": np.float64(rate_hz)}
    if temps:
        names = list(temps)
        arrays["temperature_c"] = np.column_stack([temps[k] for k in names])
        arrays["temperature_names"] = np.array(names)
    return arrays


def save(path: str | Path, arrays: dict, truth: dict) -> Path:
    path = Path(path)
    np.savez(path, **arrays)
    Path(str(path) + ".truth.json").write_text(json.dumps(truth, indent=1, default=float))
    return path


# ---- the cases ------------------------------------------------------------------------


def coupled(
    hours: float = 2.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    c: float = 2e-3,
    lag_s: float = 300.0,
    room_amp: float = 1.0,
    room_period: float = 1800.0,
    period_s: float = 1.0,
    step_k: float = 0.0625,
    channels: int = 2,
) -> tuple[dict, dict, np.ndarray]:
    """Axis x coupled to the plate through a lag, y not; the plate is logged. Returns also the
    true plate temperature (for faulty-log variants)."""
    acc, rng = base(hours, rate_hz, channels, seed)
    n = acc.shape[0]
    plate = room(n, rate_hz, 22.0, room_amp, room_period, rng)
    acc[:, 0] += c * (lag(plate, rate_hz, lag_s) - 22.0)
    truth = {
        "rate_hz": rate_hz,
        "hours": hours,
        "N": G_NOISE_N,
        "x": {"coupling": c, "lag_s": lag_s, "channel": "plate"},
        "y": {"coupling": 0.0},
    }
    return pack(acc, rate_hz, {"plate": ds18b20(plate, rate_hz, period_s, step_k)}), truth, plate


def step_record(
    hours: float = 2.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    size: float = 3e-4,
    at_frac: float = 0.5,
) -> tuple[dict, dict]:
    acc, _rng = base(hours, rate_hz, 2, seed)
    i = int(at_frac * acc.shape[0])
    acc[i:, 0] += size
    return pack(acc, rate_hz), {"x": {"bias_step": size, "t_s": i / rate_hz}, "N": G_NOISE_N}


def gauss_markov(
    n: int, rate_hz: float, sigma: float, t_s: float, rng: np.random.Generator
) -> np.ndarray:
    """First-order Gauss–Markov (OU) process of stationary SD sigma and correlation time t_s."""
    a = np.exp(-1.0 / (rate_hz * t_s))
    w = rng.standard_normal(n) * sigma * np.sqrt(1 - a * a)
    y = np.empty(n)
    acc = rng.standard_normal() * sigma
    for i in range(n):
        acc = a * acc + w[i]
        y[i] = acc
    return y


def gm_plus_slow_sine(
    hours: float = 4.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    sigma: float = 1.5e-4,
    t_s: float = 120.0,
    amp: float = 1e-4,
    period_s: float = 5400.0,
) -> tuple[dict, dict]:
    """Axis x: a Gauss–Markov process and a slow sinusoid (below a line finder's band);
    axis y: a null axis. No temperature."""
    acc, rng = base(hours, rate_hz, 2, seed)
    n = acc.shape[0]
    t = np.arange(n) / rate_hz
    acc[:, 0] += gauss_markov(n, rate_hz, sigma, t_s, rng)
    ph = rng.uniform(0, 2 * np.pi)
    acc[:, 0] += amp * np.sin(2 * np.pi * t / period_s + ph)
    truth = {
        "x": {
            "gauss_markov": {"sigma": sigma, "T_s": t_s},
            "sine": {"amp": amp, "f_hz": 1 / period_s},
        },
        "y": {},
        "N": G_NOISE_N,
    }
    return pack(acc, rate_hz), truth


def negative_lag_coarse(
    hours: float = 4.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    c: float = 2e-3,
    die_lag_s: float = 30.0,
    log_lag_s: float = 300.0,
    room_amp: float = 2.0,
    room_period: float = 2400.0,
    step_k: float = 0.5,
) -> tuple[dict, dict]:
    """The die follows the plate in die_lag_s; the logged DS18B20 follows the die in
    log_lag_s (slower than the die: a negative lag) and reads at step_k (a 9-bit 0.5 K)."""
    acc, rng = base(hours, rate_hz, 2, seed)
    n = acc.shape[0]
    plate = room(n, rate_hz, 22.0, room_amp, room_period, rng, wander_k=0.5)
    die = lag(plate, rate_hz, die_lag_s)
    logged = lag(die, rate_hz, log_lag_s)
    acc[:, 0] += c * (die - 22.0)
    truth = {
        "x": {
            "coupling": c,
            "lag_s": -log_lag_s,
            "channel": "plate",
            "note": "the log lags the die by log_lag_s: lag relative to the log is negative",
        },
        "y": {"coupling": 0.0},
        "step_k": step_k,
        "N": G_NOISE_N,
    }
    return pack(acc, rate_hz, {"plate": ds18b20(logged, rate_hz, 1.0, step_k)}), truth


def relay_step_at_switch(
    hours: float = 4.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    c: float = 1e-3,
    h: float = 2e-4,
    width_k: float = 0.4,
    step: float = 4e-4,
    room_amp: float = 1.5,
    room_period: float = 1800.0,
) -> tuple[dict, dict]:
    """Axis x: a linear coupling (no lag) plus a relay (hysteresis, ±h switching at the
    plate's mean ± width_k), and a bias step placed exactly at the relay's switch nearest
    mid-record."""
    acc, rng = base(hours, rate_hz, 2, seed)
    n = acc.shape[0]
    plate = room(n, rate_hz, 22.0, room_amp, room_period, rng)
    state = np.empty(n)
    s = 1.0 if plate[0] > 22.0 else -1.0
    for i, v in enumerate(plate):
        if s < 0 and v > 22.0 + width_k:
            s = 1.0
        elif s > 0 and v < 22.0 - width_k:
            s = -1.0
        state[i] = s
    switches = np.flatnonzero(np.diff(state) != 0) + 1
    at = int(switches[np.argmin(np.abs(switches - n // 2))])
    acc[:, 0] += c * (plate - 22.0) + h * state
    acc[at:, 0] += step
    truth = {
        "x": {
            "coupling": c,
            "relay_h": h,
            "relay_width_k": width_k,
            "bias_step": step,
            "step_t_s": at / rate_hz,
        },
        "y": {"coupling": 0.0},
        "N": G_NOISE_N,
    }
    return pack(acc, rate_hz, {"plate": ds18b20(plate, rate_hz)}), truth


def remount_warmup(
    hours: float = 4.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    c1: float = 2e-3,
    c2: float = -2e-3,
    lag_s: float = 120.0,
    warm: float = 5e-4,
    warm_t: float = 900.0,
    room_amp: float = 1.0,
    room_period: float = 1500.0,
) -> tuple[dict, dict]:
    """Axis x: a coupling that flips sign at mid-record (the sensor re-mounted) and a warm-up
    A·exp(-t/T) at the start."""
    acc, rng = base(hours, rate_hz, 2, seed)
    n = acc.shape[0]
    t = np.arange(n) / rate_hz
    plate = room(n, rate_hz, 22.0, room_amp, room_period, rng)
    lp = lag(plate, rate_hz, lag_s) - 22.0
    cc = np.where(np.arange(n) < n // 2, c1, c2)
    acc[:, 0] += cc * lp + warm * np.exp(-t / warm_t)
    truth = {
        "x": {
            "coupling_before": c1,
            "coupling_after": c2,
            "change_t_s": (n // 2) / rate_hz,
            "lag_s": lag_s,
            "warmup": warm,
            "warmup_T_s": warm_t,
        },
        "y": {"coupling": 0.0},
        "N": G_NOISE_N,
    }
    return pack(acc, rate_hz, {"plate": ds18b20(plate, rate_hz)}), truth


def coupling_step(
    hours: float = 2.0,
    rate_hz: float = 10.0,
    seed: int = 0,
    c: float = 1e-3,
    lag_s: float = 0.0,
    step: float = 4e-4,
    at_frac: float = 0.3,
    room_amp: float = 1.5,
    room_period: float = 1800.0,
) -> tuple[dict, dict]:
    """Axis x: a temperature coupling c through lag_s on the logged plate, and one bias step
    of `step` at at_frac of the record (a bump to the bench during a cycling room); y null.
    The whole truth is inside explain's candidate set (one lag + a step)."""
    acc, rng = base(hours, rate_hz, 2, seed)
    n = acc.shape[0]
    plate = room(n, rate_hz, 22.0, room_amp, room_period, rng)
    acc[:, 0] += c * (lag(plate, rate_hz, lag_s) - 22.0)
    i = int(at_frac * n)
    acc[i:, 0] += step
    truth = {
        "x": {
            "coupling": c,
            "lag_s": lag_s,
            "channel": "plate",
            "bias_step": step,
            "step_t_s": i / rate_hz,
        },
        "y": {"coupling": 0.0},
        "N": G_NOISE_N,
    }
    return pack(acc, rate_hz, {"plate": ds18b20(plate, rate_hz)}), truth


def faulty_log(kind: str, hours: float = 2.0, rate_hz: float = 10.0, seed: int = 0,
               c: float = 2e-3, lag_s: float = 120.0) -> tuple[dict, dict]:
    """A coupled record (x through lag_s on the plate, y null) whose plate log has a fault the
    docs do not list:

    - ``interleaved``: a second DS18B20 (ambient, 2 K warmer, its own cycle) answers on every
      other reading of the same column (two sensors on one 1-Wire name);
    - ``units``: the logger switches from °C to °F at mid-record;
    - ``clockstep``: the log's clock steps back 600 s at mid-record (readings after it sit
      600 s late on the sample grid: they show the temperature of 10 minutes before);
    - ``late_start_warm``: the log starts 1 h after the acceleration, and the axis has a
      warm-up in that first hour.
    """
    arrays, truth, plate = coupled(hours, rate_hz, seed, c, lag_s, room_amp=1.0,
                                   room_period=1500.0)
    n = plate.size
    t_log = arrays["temperature_c"][:, 0].copy()
    rng = np.random.default_rng(seed + 1000)
    idx = np.flatnonzero(np.isfinite(t_log))
    if kind == "interleaved":
        amb = room(n, rate_hz, 24.0, 2.0, 2700.0, rng)
        odd = idx[1::2]
        t_log[odd] = np.round(amb[odd] / 0.0625) * 0.0625
    elif kind == "units":
        later = idx[idx >= n // 2]
        t_log[later] = np.round((t_log[later] * 1.8 + 32) / 0.1125) * 0.1125
    elif kind == "clockstep":
        shift = int(600 * rate_hz)
        later = idx[idx >= n // 2]
        src = later - shift
        t_log[later] = np.round(plate[src] / 0.0625) * 0.0625
    elif kind == "late_start_warm":
        t_log[: int(3600 * rate_hz)] = np.nan
        t = np.arange(n) / rate_hz
        arrays["accel"][:, 0] += 5e-4 * np.exp(-t / 900.0)
        truth["x"]["warmup"] = 5e-4
        truth["x"]["warmup_T_s"] = 900.0
    else:
        raise ValueError(kind)
    arrays["temperature_c"] = t_log[:, None]
    truth["fault"] = kind
    return arrays, truth


def gm_step(hours: float = 4.0, rate_hz: float = 10.0, seed: int = 0, sigma: float = 1.7e-4,
            t_s: float = 30.0, step: float = 4e-4, at_frac: float = 0.3) -> tuple[dict, dict]:
    """Axis x: a Gauss–Markov process and one bias step; y null; no temperature."""
    arrays, truth = gm_plus_slow_sine(hours, rate_hz, seed, sigma=sigma, t_s=t_s, amp=0.0)
    i = int(at_frac * arrays["accel"].shape[0])
    arrays["accel"][i:, 0] += step
    truth["x"]["bias_step"] = step
    truth["x"]["step_t_s"] = i / rate_hz
    return arrays, truth
