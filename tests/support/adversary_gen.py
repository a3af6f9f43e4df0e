"""An adversary's generator for issues 23 and 24, written apart from the project.

Written from the issue texts and the record format of docs/analysis.md alone (numpy only; it
imports nothing of avard, of ``core/sim`` or of the other generators in ``tests/support``), so
that explain is checked on records whose physics and noise synthesis it was not built on.

Its own physical model:

- **Room**: 21.4 °C plus the record's drive, any of: an HVAC relay (a triangle whose
  half-periods jitter by 12 %), a day/night sinusoid, a compressor (a square wave of its own
  period with a 40 % duty), door openings (a drop with an exponential recovery), and a slow
  Ornstein–Uhlenbeck wander (3 h, 0.04 K).
- **Chain**: plate = lag(room, τ_plate), die = lag(plate, τ_die); the logged DS18B20 =
  lag(plate, τ_sensor) plus 3 mK read noise, read every ``t_read`` s (0.75 s conversion, 1 s
  or 2 s logging) and rounded to 0.0625 °C; a second DS18B20 logs the room through 40 s.
- **Accelerometer** (ADXL355-like): white noise N, flicker B by spectral synthesis (random
  phases, |X(f)| ∝ f^-1/2 on a doubled grid, half kept: not a Kasdin filter), rate random walk
  K by a cumulative sum, 1 g on z, offsets, counts rounded to 3.824e-5 m/s² (±2 g range).
- **Log faults**: 85.0 °C power-on readings, −127 °C, single spikes, a dropout, a stuck run;
  acceleration start-up glitches and shocks.

Noise conventions are the project's documented ones (one-sided PSD
S(f) = 2N² + B²/(πf) + K²/(2π²f²), AVAR = N²/τ + (2 ln 2/π)B² + K²τ/3), so the stated minima
below follow docs/explain.md's derivations: z = 5 standard errors of the GLS amplitude of a
sinusoidal component, σ_a(f) = √(2S(f)/T) per quadrature; warm-up 6·√(2·AVAR(T))/0.40; step
6·min_w √(2·AVAR(w)); drift 5·K·√(1.2/T) (least squares on a random walk); a dT/dt term
beside its coupling (lag 0) the smallest r whose non-centrality against every one-lag reading
reaches 25 on the drive's lines (``rate_min``: docs/log/2026-11-28-cand26.md; one lag reads
c·T + r·dT/dt to first order, so the minimum against zero, 5σ_a/(ωa), was no minimum of the
mechanism).

``make_record(kind, seed, path)`` writes ``path`` (.npz) and ``path`` + ``.truth.json``; the
truth says, per axis, which cause is hidden and its parameters (SI units), and which axes are
null.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

LSB = 3.824e-5  # m/s² per count, ±2 g
G = 9.80665
DS_STEP = 0.0625  # °C
TWO_LN2_PI = 2.0 * math.log(2.0) / math.pi


# --------------------------------------------------------------------------- noise model


def psd(f: float, n: float, b: float, k: float) -> float:
    """One-sided PSD (m/s²)²/Hz of white + flicker + random walk (project's convention)."""
    return 2 * n * n + b * b / (math.pi * f) + k * k / (2 * math.pi**2 * f * f)


def avar(tau: float, n: float, b: float, k: float) -> float:
    return n * n / tau + TWO_LN2_PI * b * b + k * k * tau / 3.0


def sigma_a(f: float, t_rec: float, n: float, b: float, k: float) -> float:
    """Standard error of one quadrature amplitude of a sinusoid at f on a record of t_rec s."""
    return math.sqrt(2.0 * psd(f, n, b, k) / t_rec)


def lag_gain(f: float, tau: float) -> float:
    return 1.0 / math.sqrt(1.0 + (2 * math.pi * f * tau) ** 2)


def drive_lines(drive: dict, tau_plate: float, tau_die: float) -> list[tuple[float, float]]:
    """The room's cycles as lines at the die, (amplitude K, ω rad/s): the HVAC triangle's odd
    harmonics 8A/(π²k²) and the compressor's square wave's (its Fourier series taken
    numerically), up to the 15th, each through the plate's and the die's lags."""
    out = []
    shapes = [(drive["hvac_period"], 8 * drive["hvac_amp"] / math.pi**2
               * np.array([1.0 / (k * k) if k % 2 else 0.0 for k in range(16)]))]
    if "comp_amp" in drive:
        x = np.linspace(0.0, 1.0, 1 << 12, endpoint=False)
        sq = np.where(x < 0.4, drive["comp_amp"], -drive["comp_amp"] * 0.4 / 0.6)
        shapes.append((drive["comp_period"], 2 * np.abs(np.fft.rfft(sq))[:16] / x.size))
    for period, amps in shapes:
        for k in range(1, 16):
            if amps[k] > 0:
                f = k / period
                out.append((float(amps[k]) * lag_gain(f, tau_plate) * lag_gain(f, tau_die),
                            2 * math.pi * f))
    return out


def rate_separation(lines, sig, c: float, r: float) -> float:
    """min over one-lag readings c'·H(ω, L') (L' ≥ 0 a lag 1/(1 + jωL'), L' < 0 the lead-lag
    (1 + 2jωa)/(1 + jωa), a = −L', as docs/explain.md's negative lag) of
    Σ_lines (a/σ_a)²·|c + jωr − c'·H|²: the z² at which a fit tells c·T + r·dT/dt from one
    lag (a brute grid in L', c' by weighted least squares)."""
    a = np.array([x[0] for x in lines])
    w = np.array([x[1] for x in lines])
    q = (a / np.array(sig)) ** 2
    G = c + 1j * w * r
    top = 1e3 * max(abs(r / c), float(np.max(1.0 / w)))
    Ls = np.geomspace(0.5, top, 3000)
    H = np.vstack([1.0 / (1 + 1j * np.outer(Ls, w)),
                   (1 + 2j * np.outer(Ls, w)) / (1 + 1j * np.outer(Ls, w)),
                   np.ones((1, w.size))])
    cp = np.sum(q * np.real(G * H.conj()), axis=1) / np.sum(q * np.abs(H) ** 2, axis=1)
    return float(np.min(np.sum(q * np.abs(G - cp[:, None] * H) ** 2, axis=1)))


def rate_min(lines, sig, c: float, r0: float, lead: bool) -> float:
    """The smallest r > 0 (r/c > 0 if ``lead``) with ``rate_separation`` ≥ 25, from the
    minimum against zero ``r0`` up (bisection); inf past 1e4·r0 (one line and a lag)."""
    sgn = 1.0 if lead == (c > 0) else -1.0
    lo, hi = 0.0, r0
    while rate_separation(lines, sig, c, sgn * hi) < 25.0:
        lo, hi = hi, 2 * hi
        if hi > 1e4 * r0:
            return math.inf
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rate_separation(lines, sig, c, sgn * mid) < 25.0 else (lo, mid)
    return hi


# ------------------------------------------------------- the minima as explain's fit sees them
# (docs/log/2026-11-28-cand26b.md): the fit regresses Allan covariances at the octave τ from
# the logged channel's rounding floor up; a line's weight there is W(f) = Σ_k ν_k·g(fτ_k)/r_k
# (g(x) = sin⁴(πx)/(πx)², a unit sinusoid's AVAR; r_k the one-lag residual's AVAR, the noise
# and the readings' rounding through the coupling; ν_k its EDF by NIST SP 1065's simple
# formulas), the closest one-lag reading is the one the fit picks in W, and the size of what
# it leaves is estimated to a variance Σ W²σ_a²|ΔY|²/(Σ W|ΔY|²)²: the stated minimum is the
# size where that estimate's z is 5.

def g_allan(x):
    px = np.pi * np.asarray(x, dtype=float)
    return np.sin(px) ** 4 / px**2


def rounding_time(lines) -> float:
    """(amplitude K, ω) lines of the logged channel: DS_STEP over its rms slope, ≥ 1 s."""
    slope = math.sqrt(sum((w * a) ** 2 / 2 for a, w in lines))
    return max(DS_STEP / slope, 1.0) if slope > 0 else math.inf


def rounding_floor(lines, rate: float, t_rec: float) -> float:
    """The first octave τ (2ʲ/rate) where the logged channel's AVAR reaches 10× its
    rounding's (DS_STEP²/12)·t_c/τ."""
    tc = rounding_time(lines)
    tau = 1.0 / rate
    while 2 * tau <= t_rec:
        v = sum(a * a * float(g_allan(tau * w / (2 * math.pi))) for a, w in lines)
        if v >= 10 * DS_STEP**2 / 12 * tc / tau:
            return tau
        tau *= 2
    return math.inf


def fit_weights(freqs, t_rec: float, nbk, floor: float, c2tc: float) -> np.ndarray:
    n, b, k = nbk
    f = np.asarray(freqs, dtype=float)
    out = np.zeros(f.size)
    tau = floor
    while math.isfinite(tau) and 2 * tau <= t_rec:
        x = t_rec / tau
        parts = ((n * n + c2tc) / tau, TWO_LN2_PI * b * b, k * k * tau / 3)
        nus = (1.5 * x - 2.0, 5 * x * x / (4 * (x + 3)), x - 3 + 4 / x)
        den = sum(p * p / max(v, 1.0) for p, v in zip(parts, nus, strict=True))
        nu = max(sum(parts) ** 2 / den, 1.0)
        out += nu * g_allan(f * tau) / sum(parts)
        tau *= 2
    return out


def sep_fit(w, U, Y, W, s2) -> float:
    """z² of the fit's estimate of Y − c'H(ω, L')U, the one-lag reading the fit picks in W (a
    brute grid in L' of either sign, c' by W-weighted least squares)."""
    w = np.asarray(w, dtype=float)
    top = 1e3 * float(np.max(1.0 / w))
    Ls = np.geomspace(0.5, top, 3000)
    H = np.vstack([1.0 / (1 + 1j * np.outer(Ls, w)),
                   (1 + 2j * np.outer(Ls, w)) / (1 + 1j * np.outer(Ls, w)),
                   np.ones((1, w.size))]) * U
    cp = np.sum(W * np.real(Y * H.conj()), axis=1) / np.sum(W * np.abs(H) ** 2, axis=1)
    d2 = np.abs(Y - cp[:, None] * H) ** 2
    i = int(np.argmin(np.sum(W * d2, axis=1)))
    return float(np.sum(W * d2[i]) ** 2 / np.sum(W * W * s2 * d2[i]))


def size_at_z5(lam, start: float) -> float:
    lo, hi = 0.0, start
    while lam(hi) < 25.0:
        lo, hi = hi, 2 * hi
        if hi > 1e4 * start:
            return math.inf
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lam(mid) < 25.0 else (lo, mid)
    return hi


def rate_min_fit(lines, t_rec: float, nbk, c: float, lead: bool, floor: float,
                 c2tc: float) -> float:
    """The smallest r (r/c > 0 if ``lead``) the fit tells from one lag at z = 5."""
    a = np.array([x[0] for x in lines])
    w = np.array([x[1] for x in lines])
    f = w / (2 * math.pi)
    W = fit_weights(f, t_rec, nbk, floor, c2tc)
    s2 = np.array([sigma_a(x, t_rec, *nbk) ** 2 for x in f])
    sgn = 1.0 if lead == (c > 0) else -1.0
    start = 5 / math.sqrt(float(np.sum((a * w) ** 2 / s2)))
    return size_at_z5(lambda r: sep_fit(w, a + 0j, (c + 1j * w * sgn * r) * a, W, s2), start)


def relay_harmonics(U: np.ndarray, width: float) -> np.ndarray:
    """Complex harmonics 1…len(U) of a ±1 relay switching once the periodic drive (harmonics
    ``U``, K) has moved ``width`` back from its last extreme (``play``'s 2·half-width)."""
    m = 1 << 12
    th = np.arange(2 * m) / m
    ks = np.arange(1, U.size + 1)
    u = np.real(np.exp(2j * np.pi * np.outer(th, ks)) @ U)
    out = play(u, width / 2)
    return (2 * np.fft.fft(out[m:]) / m)[1:U.size + 1]


def triangle_at_die(period: float, amp: float, tau_plate: float, tau_die: float,
                    k_max: int = 39) -> np.ndarray:
    """The HVAC triangle's complex harmonics 1…k_max at the die (8A/(π²k²)·(−1)^((k−1)/2)·
    sin kωt, through the plate's and the die's lags)."""
    out = np.zeros(k_max, dtype=complex)
    for k in range(1, k_max + 1, 2):
        w = 2 * math.pi * k / period
        out[k - 1] = (8 * amp / (math.pi**2 * k * k) * (-1) ** ((k - 1) // 2) * -1j
                      / complex(1, w * tau_plate) / complex(1, w * tau_die))
    return out


def hyst_min_fit(U: np.ndarray, period: float, t_rec: float, nbk, c: float, width: float,
                 floor: float, c2tc: float, rounding_noise: bool = True) -> float:
    """The smallest h the fit tells c·T + h·relay from one lag at z = 5. The estimate's noise
    is the accelerometer's and (``rounding_noise``) the readings' rounding through the
    coupling, white of N² = c2tc: the one-lag column is built on the rounded readings, so it
    is in the residual as it is in the weights (hyst29; without it, the sizes before)."""
    R = relay_harmonics(U, width)
    f = np.arange(1, U.size + 1) / period
    W = fit_weights(f, t_rec, nbk, floor, c2tc)
    n, b, k = nbk
    ne = math.sqrt(n * n + c2tc) if rounding_noise else n
    s2 = np.array([sigma_a(x, t_rec, ne, b, k) ** 2 for x in f])
    start = 5 / math.sqrt(float(np.sum(np.abs(R) ** 2 / s2)))
    return size_at_z5(lambda h: sep_fit(2 * math.pi * f, U, c * U + h * R, W, s2), start)


# --------------------------------------------------------------------------- synthesis


def first_order(x: np.ndarray, dt: float, tau: float, y0: float | None = None) -> np.ndarray:
    """Exact first-order lag of a piecewise-linear input (the chain runs on a 1 s grid)."""
    if tau <= 0:
        return x.copy()
    a = math.exp(-dt / tau)
    y = np.empty_like(x)
    prev = x[0] if y0 is None else y0
    # first-order hold: y[k] = a y[k-1] + (1-a) x[k] + (a - (1-a) tau/dt ... ) slope term
    c1 = 1.0 - a
    cs = tau / dt * (1.0 - a) - a  # weight of the slope (x[k] - x[k-1])
    xs = x.tolist()
    out = y  # alias
    xprev = xs[0]
    for i, xi in enumerate(xs):
        prev = a * prev + c1 * xi - cs * (xi - xprev)
        xprev = xi
        out[i] = prev
    return out


def flicker(rng: np.random.Generator, n: int, rate: float, b: float) -> np.ndarray:
    """Flicker with one-sided PSD B²/(πf) by spectral synthesis on a doubled grid."""
    if b <= 0:
        return np.zeros(n)
    m = 2 * n
    f = np.fft.rfftfreq(m, 1.0 / rate)
    amp = np.zeros_like(f)
    amp[1:] = np.sqrt(b * b / (math.pi * f[1:]))
    # one-sided S(f) with df = rate/m: a bin's variance S·df split into two quadratures
    spec = (
        amp
        * np.sqrt(rate * m / 4.0)
        * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    )
    x = np.fft.irfft(spec, m)[:n]
    return x


def ou(rng: np.random.Generator, n: int, dt: float, tau: float, sd: float) -> np.ndarray:
    a = math.exp(-dt / tau)
    e = rng.standard_normal(n) * sd * math.sqrt(1 - a * a)
    out = np.empty(n)
    prev = rng.standard_normal() * sd
    for i in range(n):
        prev = a * prev + e[i]
        out[i] = prev
    return out


def triangle_jitter(
    rng: np.random.Generator, t: np.ndarray, period: float, amp: float, jitter: float = 0.12
) -> np.ndarray:
    """An HVAC relay's room swing: linear ramps between ±amp, half-periods jittered."""
    edges = [-rng.uniform(0, period / 2)]
    while edges[-1] < t[-1]:
        edges.append(edges[-1] + period / 2 * max(0.3, 1 + jitter * rng.standard_normal()))
    edges_a = np.array(edges)
    levels = np.where(np.arange(edges_a.size) % 2 == 0, -amp, amp)
    return np.interp(t, edges_a, levels)


def square(t: np.ndarray, period: float, amp: float, duty: float, phase: float) -> np.ndarray:
    return np.where(((t / period + phase) % 1.0) < duty, amp, -amp * duty / (1 - duty))


def play(u: np.ndarray, width: float) -> np.ndarray:
    """Relay (sign of a play operator of half-width ``width``): +1 after rising by it."""
    out = np.empty(u.size)
    s = 1.0
    lo = hi = float(u[0])
    for i, ui in enumerate(u.tolist()):
        if s > 0:
            hi = max(hi, ui)
            if ui < hi - 2 * width:
                s, lo = -1.0, ui
        else:
            lo = min(lo, ui)
            if ui > lo + 2 * width:
                s, hi = 1.0, ui
        out[i] = s
    return out


# --------------------------------------------------------------------------- the record


@dataclass
class Spec:
    kind: str
    hours: float
    rate: float
    noise: dict[str, tuple[float, float, float]]  # axis -> (N, B, K)
    drive: dict[str, float] = field(default_factory=dict)
    tau_plate: float = 1100.0
    tau_die: float = 45.0
    tau_sensor: float = 45.0
    t_read: float = 1.0
    faults: bool = False


def _noise(
    rng: np.random.Generator, n: int, rate: float, nbk: tuple[float, float, float]
) -> np.ndarray:
    nn, b, k = nbk
    x = rng.standard_normal(n) * nn * math.sqrt(rate)
    x += flicker(rng, n, rate, b)
    if k > 0:
        x += np.cumsum(rng.standard_normal(n)) * k / math.sqrt(rate)
    return x


def _room(rng: np.random.Generator, ts: np.ndarray, drive: dict[str, float]) -> np.ndarray:
    room = 21.4 + ou(rng, ts.size, 1.0, 10800.0, drive.get("wander", 0.04))
    if "hvac_amp" in drive:
        room += triangle_jitter(rng, ts, drive["hvac_period"], drive["hvac_amp"])
    if "day_amp" in drive:
        room += drive["day_amp"] * np.sin(2 * math.pi * ts / 86400.0 + rng.uniform(0, 6.28))
    if "comp_amp" in drive:
        room += square(ts, drive["comp_period"], drive["comp_amp"], 0.4, rng.uniform())
    for t0 in drive.get("doors", []):
        m = ts >= t0
        room[m] -= 0.8 * np.exp(-(ts[m] - t0) / 600.0) * (1 - np.exp(-(ts[m] - t0) / 20.0))
    return room


def die_amplitude(spec: Spec, f0: float, room_amp: float) -> float:
    """Amplitude at the die of a room sinusoid of amplitude room_amp at f0."""
    return room_amp * lag_gain(f0, spec.tau_plate) * lag_gain(f0, spec.tau_die)


def synthesize(spec: Spec, seed: int | list[int], effects) -> tuple[dict, dict]:
    """Return (npz arrays, thermal truth). ``effects(t, temps) -> {axis: signal}``."""
    rng = np.random.default_rng(seed)
    n = round(spec.hours * 3600 * spec.rate)
    t = np.arange(n) / spec.rate
    ts = np.arange(0.0, t[-1] + 2.0, 1.0)  # thermal grid, 1 s
    room = _room(rng, ts, spec.drive)
    plate = first_order(room, 1.0, spec.tau_plate, y0=room[:600].mean())
    die = first_order(plate, 1.0, spec.tau_die, y0=plate[0])
    sens = first_order(plate, 1.0, spec.tau_sensor, y0=plate[0])
    amb = first_order(room, 1.0, 40.0, y0=room[0])
    temps = {"room": room, "plate": plate, "die": die, "sensor": sens, "ts": ts}
    die_t = np.interp(t, ts, die)
    signals = effects(t, die_t, temps, rng)
    accel = np.empty((n, 3))
    offsets = (0.031, -0.017, G + 0.044)
    for j, ax in enumerate("xyz"):
        accel[:, j] = offsets[j] + _noise(rng, n, spec.rate, spec.noise[ax]) + signals.get(ax, 0.0)
    accel = np.round(accel / LSB) * LSB
    # DS18B20 reads: every t_read s (jittered to the sample grid), 3 mK noise, 0.0625 °C
    step = max(1, round(spec.t_read * spec.rate))
    idx = np.arange(int(0.75 * spec.rate) + 1, n, step)
    temp = np.full((n, 2), np.nan)
    for j, src in enumerate((sens, amb)):
        v = np.interp(t[idx] - 0.375, ts, src) + 0.003 * rng.standard_normal(idx.size)
        temp[idx, j] = np.round(v / DS_STEP) * DS_STEP
    faults: dict[str, list] = {}
    if spec.faults:
        faults = _inject_faults(rng, accel, temp, idx, spec)
    arrays = {
        "accel": accel,
        "rate_hz": np.float64(spec.rate),
        "axes": np.array(["x", "y", "z"]),
        "temperature_c": temp,
        "temperature_names": np.array(["plate", "ambient"]),
    }
    return arrays, faults


def _inject_faults(rng, accel, temp, idx, spec) -> dict[str, list]:
    n = accel.shape[0]
    rate = spec.rate
    out: dict[str, list] = {
        "power_on_85_s": [],
        "read_error_s": [],
        "spike_s": [],
        "dropout_s": [],
        "stuck_s": [],
        "accel_glitch_s": [],
    }
    # a dropout of 20 min on the plate log (a record of under 3 h gets 8 min)
    dur = int((1200.0 if spec.hours >= 3 else 480.0) * rate)
    s0 = int(rng.uniform(0.3, 0.55) * n)
    temp[s0 : s0 + dur, 0] = np.nan
    out["dropout_s"].append([s0 / rate, (s0 + dur) / rate])
    # a stuck run of 40 min on the ambient log (the last value repeated), cut at the record's
    # end: the screen's rule needs 30 min, so a shorter one is not a fault it can see
    s1 = int(rng.uniform(0.6, 0.75) * n)
    e1 = min(s1 + int(2400 * rate), n)
    col = temp[:, 1]
    last = col[s1 - 10 * int(rate) : s1][~np.isnan(col[s1 - 10 * int(rate) : s1])][-1]
    m = ~np.isnan(col[s1:e1])
    col[s1:e1][m] = last
    out["stuck_s"].append([s1 / rate, e1 / rate])
    # single faulty readings: outside the dropout and the stuck run, apart from each other
    ridx = idx[(idx > n * 0.05) & (idx < n * 0.95)]
    ridx = ridx[
        ((ridx < s0 - 5 * rate) | (ridx > s0 + dur + 5 * rate))
        & ((ridx < s1 - 5 * rate) | (ridx > e1))
    ]
    picks = rng.choice(ridx, 7, replace=False)
    while np.min(np.diff(np.sort(picks))) < 10 * rate:
        picks = rng.choice(ridx, 7, replace=False)
    for i in picks[:3]:
        temp[i, 0] = 85.0
        out["power_on_85_s"].append(i / rate)
    for i in picks[3:5]:
        temp[i, int(rng.integers(0, 2))] = -127.0
        out["read_error_s"].append(i / rate)
    for i in picks[5:]:
        temp[i, 0] += 2.5
        out["spike_s"].append(i / rate)
    # acceleration: a 3-sample start-up glitch and one shock
    accel[1:4, :] += 0.6
    k = int(rng.uniform(0.2, 0.8) * n)
    accel[k, 0] += 0.4
    out["accel_glitch_s"] = [1 / rate, k / rate]
    return out


# --------------------------------------------------------------------------- classes

DEFAULT_NOISE = {
    "x": (1.4e-4, 1.6e-5, 1.5e-6),
    "y": (1.7e-4, 2.2e-5, 2.5e-6),
    "z": (2.0e-4, 2.0e-5, 1.0e-6),
}

KINDS = (
    "null_faulty",
    "null_insensitive",
    "faulty_coupled",
    "compound",
    "neglag",
    "twopath",
    "quadratic",
    "dtdt",
    "hysteresis",
    "typical24",
    "pump",
    "drift",
)


def _fit_view(drive: dict, spec: Spec, rate: float, t_rec: float, c: float
              ) -> tuple[float, float]:
    """(the logged plate channel's rounding floor, s; c²·(DS_STEP²/12)·t_c, its rounding's
    white AVAR coefficient through the coupling) from the drive's lines at that sensor."""
    logged = drive_lines(drive, spec.tau_plate, spec.tau_sensor)
    return (rounding_floor(logged, rate, t_rec),
            c * c * DS_STEP**2 / 12 * rounding_time(logged))


def _die_swing(temps: dict) -> tuple[float, np.ndarray]:
    """Amplitude of the die's cycling (√2 × sd of the die minus its 2 h running mean)."""
    die = temps["die"]
    w = 7200
    if die.size > 2 * w:
        c = np.concatenate(([0.0], np.cumsum(die)))
        trend = (c[w:] - c[:-w]) / w  # mean of die[i:i+w]
        resid = die[w // 2 : w // 2 + trend.size] - trend
    else:
        resid = die - die.mean()
    return math.sqrt(2.0) * float(resid.std()), die


def make_record(
    kind: str,
    seed: int,
    path: str | Path,
    hours: float | None = None,
    factor: float = 3.0,
    logged: tuple[str, ...] = ("plate", "ambient"),
    pump_band_hz: float = 0.1,
    dtdt_minimum: str = "one_lag",
    hysteresis_minimum: str = "harmonics",
) -> dict:
    """Write one record of class ``kind`` and its truth file; return the truth. ``factor``:
    the hidden effect's size in its stated minima (the pump's amplitude in units of
    2e-4/3 m/s²); ``logged``: the DS18B20 channels the record holds (plate, ambient);
    ``pump_band_hz``: how far the pump's line sweeps (linearly, from 3.05 Hz).
    ``dtdt_minimum``: what the dT/dt class's r is a multiple of: the minimum against one lag
    as explain's fit sees the drive's lines ("fit", from the logged plate's rounding floor
    up, cand26b), against one lag on every line ("one_lag", cand26's) or against zero
    ("zero", the sizes before: a term one lag reads to first order where c < 0).
    ``hysteresis_minimum``: the relay's h against one lag as the fit sees the lines ("fit",
    its noise the accelerometer's and the readings' rounding through the coupling, hyst29;
    "fit_accel": the accelerometer's alone, cand26b's sizes) or its harmonics 3–9 on the
    whole spectrum ("harmonics", the sizes before).
    The defaults are the stated minima docs/explain.md gives (dT/dt against one lag on every
    line, cand26; hysteresis on its harmonics): cand26b's "fit" minima are measured (its log)
    and not yet the stated ones, as the benchmark's rows are not tied to them.

    The ambient sensor reads the room through 40 s, the die is the room through the plate's
    and the die's lags: ``truth["ambient_equivalent_lag_s"]`` is the one lag that channel
    would need at low frequency (τ_plate + τ_die − 40 s)."""
    # every class draws its own noise: the null axes of two classes at one seed are not one
    ki = KINDS.index(kind)
    rng0 = np.random.default_rng([seed, ki, 7919])
    path = Path(path)
    noise = dict(DEFAULT_NOISE)
    rate = float(rng0.choice([8.0, 10.0, 12.5]))
    hvac = {
        "hvac_period": float(rng0.uniform(1300, 2300)),
        "hvac_amp": float(rng0.uniform(0.5, 0.9)),
    }
    drive: dict = dict(hvac)
    h = hours
    spec_kw: dict = {}
    truth: dict = {"kind": kind, "seed": seed, "axes": {}}
    faults = kind in ("null_faulty", "faulty_coupled", "null_insensitive")
    if kind == "null_insensitive":
        drive.update(hvac_amp=1.5, comp_amp=0.3, comp_period=float(rng0.uniform(700, 1000)))
    if kind in ("twopath", "dtdt") and rng0.uniform() < 0.5:
        drive.update(comp_amp=0.25, comp_period=float(rng0.uniform(600, 1100)))
    if kind == "typical24":
        drive.update(day_amp=1.2)
        h = h or 24.0
    if kind == "neglag":
        spec_kw.update(tau_die=50.0, tau_sensor=150.0)
    if kind == "faulty_coupled":
        spec_kw.update(tau_sensor=45.0)
    if kind == "compound":
        drive = {"hvac_period": 1800.0, "hvac_amp": 0.3}
    if kind == "pump":
        rate = 10.0
    h = h or {"compound": float(rng0.choice([1.0, 6.0, 24.0]))}.get(kind, 4.0)
    spec = Spec(
        kind=kind,
        hours=h,
        rate=rate,
        noise=noise,
        drive=drive,
        faults=faults,
        t_read=float(rng0.choice([1.0, 2.0])),
        **spec_kw,
    )
    t_rec = h * 3600.0
    f0 = 1.0 / drive["hvac_period"]
    nx = noise["x"]

    def effects(t, die_t, temps, rng):
        a_die, _ = _die_swing(temps)
        truth["die_amplitude_k"] = a_die
        s0 = sigma_a(f0, t_rec, *nx)
        sig: dict[str, np.ndarray] = {}
        u = die_t - float(die_t.mean())
        c_min = 5 * s0 / max(a_die, 1e-6)
        if kind in ("faulty_coupled", "neglag", "quadratic", "dtdt", "hysteresis", "twopath"):
            c = factor * c_min * float(rng.choice([-1.0, 1.0]))
            sig["x"] = c * u
            truth["axes"]["x"] = {
                "cause": "temperature",
                "coefficient_mps2_per_k": c,
                "lag_s": spec.tau_die - spec.tau_sensor,
                "min": c_min,
            }
        if kind == "neglag":
            truth["axes"]["x"]["mechanism"] = "negative lag"
        if kind == "quadratic":
            q_min = 5 * sigma_a(2 * f0, t_rec, *nx) * 2 / a_die**2
            q = factor * q_min
            sig["x"] = sig["x"] + q * (u**2 - float(np.mean(u**2)))
            truth["axes"]["x"].update(mechanism="quadratic", q_mps2_per_k2=q, q_min=q_min)
        if kind == "dtdt":
            w = 2 * math.pi * f0
            # against zero (the minimum before, kept in the truth), and against every one-lag
            # reading beside the record's coupling (the stated minimum): r > 0, so a lead
            # where c > 0 and a lag where c < 0
            r_zero = 5 * s0 / (w * a_die)
            lines = drive_lines(drive, spec.tau_plate, spec.tau_die)
            sl = [sigma_a(wl / (2 * math.pi), t_rec, *nx) for _, wl in lines]
            c_x = truth["axes"]["x"]["coefficient_mps2_per_k"]
            if dtdt_minimum == "zero":
                r_min = r_zero
            elif dtdt_minimum == "one_lag":  # every line counted (cand26's)
                r_min = rate_min(lines, sl, c_x, r_zero, lead=c_x > 0)
            else:  # as explain's fit sees the lines, from the logged plate's rounding floor
                floor, c2tc = _fit_view(drive, spec, rate, t_rec, c_x)
                r_min = rate_min_fit(lines, t_rec, nx, c_x, c_x > 0, floor, c2tc)
            r = factor * r_min
            dudt = np.gradient(die_t, t)
            sig["x"] = sig["x"] + r * dudt
            truth["axes"]["x"].update(mechanism="dT/dt", r_mps2_per_k_per_s=r, r_min=r_min,
                                      r_min_zero=r_zero)
        if kind == "hysteresis":
            inv = sum(
                (4 / (math.pi * k)) ** 2 / sigma_a(k * f0, t_rec, *nx) ** 2 for k in (3, 5, 7, 9)
            )
            width = 0.25 * a_die
            if hysteresis_minimum == "harmonics":  # harmonics 3–9, the whole spectrum
                h_min = 5 / math.sqrt(inv)
            else:  # against one lag, as explain's fit sees the lines (cand26b)
                c_x = truth["axes"]["x"]["coefficient_mps2_per_k"]
                floor, c2tc = _fit_view(drive, spec, rate, t_rec, c_x)
                U = triangle_at_die(drive["hvac_period"], drive["hvac_amp"], spec.tau_plate,
                                    spec.tau_die)
                h_min = hyst_min_fit(U, drive["hvac_period"], t_rec, nx, c_x, 2 * width,
                                     floor, c2tc, rounding_noise=hysteresis_minimum == "fit")
            hh = factor * h_min
            sig["x"] = sig["x"] + hh * play(die_t, width)
            truth["axes"]["x"].update(mechanism="hysteresis", h_mps2=hh, width_k=width, h_min=h_min)
        if kind == "twopath":
            l2 = 1500.0
            slow = np.interp(
                t, temps["ts"], first_order(temps["room"], 1.0, l2, y0=temps["room"][:600].mean())
            )
            slow -= slow.mean()
            # lags-known minimum of c2 on the HVAC line: its part orthogonal to the die path
            g = abs(1 / complex(1, 2 * math.pi * f0 * l2) - 1)
            room_amp = a_die / (lag_gain(f0, spec.tau_plate) * lag_gain(f0, spec.tau_die))
            c2_min = 5 * s0 / (room_amp * g)
            c2 = factor * c2_min
            sig["x"] = sig["x"] + c2 * slow
            truth["axes"]["x"].update(
                mechanism="two paths", c2_mps2_per_k=c2, lag2_s=l2, c2_min=c2_min
            )
        if kind == "typical24":
            c = 2e-4
            sig["x"] = c * u
            truth["axes"]["x"] = {
                "cause": "temperature",
                "coefficient_mps2_per_k": c,
                "lag_s": 0.0,
                "min": c_min,
            }
        if kind == "compound":
            T = float(rng.uniform(600, 1500))
            wmin = 6 * math.sqrt(2 * avar(T, *nx)) / 0.40
            # windows of at least record/100: docs/explain.md's step minima (1 h … 24 h) come
            # out of 6·min_w √(2·AVAR(w)) only so (its steps sit on a grid of 100 times)
            smin = 6 * min(
                math.sqrt(2 * avar(w_, *nx)) for w_ in np.geomspace(t_rec / 100, t_rec / 4, 30)
            )
            wsz = factor * wmin * float(rng.choice([-1.0, 1.0]))
            ssz = factor * smin
            t1, t2 = sorted(rng.uniform(0.2, 0.8, 2) * t_rec)
            if t2 - t1 < 0.15 * t_rec:
                t2 = min(t1 + 0.15 * t_rec, 0.9 * t_rec)
            # the excursion in the widest stretch between the steps and the record's ends
            gaps = [(0.1 * t_rec, t1), (t1, t2), (t2, 0.95 * t_rec)]
            lo, hi = max(gaps, key=lambda ab: ab[1] - ab[0])
            dur = min(max(0.05 * t_rec, 600.0), 0.5 * (hi - lo))
            e0 = float(lo + 0.25 * (hi - lo))
            e1 = e0 + dur
            sig["x"] = (
                wsz * np.exp(-t / T)
                + ssz * (t >= t1)
                - ssz * (t >= t2)
                + 1.5 * ssz * ((t >= e0) & (t < e1))
            )
            truth["axes"]["x"] = {
                "cause": "compound",
                "warmup": {"size": wsz, "time_constant_s": T, "min": wmin},
                "steps": [{"t_s": t1, "size": ssz}, {"t_s": t2, "size": -ssz}],
                "excursion": {"start_s": e0, "end_s": e1, "size": 1.5 * ssz},
                "step_min": smin,
            }
        if kind == "pump":
            f_a, f_b = 3.05, 3.05 + pump_band_hz
            ph = 2 * math.pi * (f_a * t + (f_b - f_a) * t**2 / (2 * t[-1]))
            amp = 30 * noise["x"][0] / math.sqrt(t_rec)
            amp = max(amp, 2e-4) * factor / 3.0
            sig["x"] = amp * np.sin(ph)
            truth["axes"]["x"] = {
                "cause": "periodic",
                "frequency_lo_hz": f_a,
                "frequency_hi_hz": f_b,
                "amplitude": amp,
            }
        if kind == "drift":
            kx = nx[2]
            d_min = 5 * kx * math.sqrt(1.2 / t_rec)
            d = factor * d_min
            sig["x"] = d * (t - t_rec / 2)
            truth["axes"]["x"] = {"cause": "drift", "rate_mps3": d, "min": d_min}
        return sig

    arrays, fl = synthesize(spec, [seed, ki], effects)
    truth.update(
        hours=h,
        rate_hz=rate,
        noise=noise,
        drive=drive,
        tau_plate=spec.tau_plate,
        tau_die=spec.tau_die,
        tau_sensor=spec.tau_sensor,
        t_read=spec.t_read,
        faults=fl,
        ambient_equivalent_lag_s=spec.tau_plate + spec.tau_die - 40.0,
    )
    keep = [i for i, name in enumerate(("plate", "ambient")) if name in logged]
    arrays["temperature_c"] = arrays["temperature_c"][:, keep]
    arrays["temperature_names"] = arrays["temperature_names"][keep]
    for ax in "xyz":
        truth["axes"].setdefault(ax, {"cause": None})
    np.savez(path, **arrays)
    Path(str(path) + ".truth.json").write_text(json.dumps(truth, indent=1, default=float))
    return truth


if __name__ == "__main__":  # pragma: no cover - manual use
    import sys

    k, s, p = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    hrs = float(sys.argv[4]) if len(sys.argv) > 4 else None
    print(json.dumps(make_record(k, s, p, hrs), default=float)[:400])
