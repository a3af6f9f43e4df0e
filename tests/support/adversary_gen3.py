"""A third adversary's record generator for `avard explain` (adv26), numpy only.

Written apart from `avard simulate`, core/sim, tests/support/hidden.py, adversary_gen.py and
coverage_gen2.py (those were read only for the .npz layout explain takes: `accel` (N, 3) in
m/s², `rate_hz`, `axes`, `temperature_c` (N, k) with a reading on its row and NaN between,
`temperature_names`). Nothing is imported from core/.

Physics, on a 1 s grid and interpolated to the sample grid:

- room: a thermostat cycle (a clipped sine of period P, so it carries harmonics), a slow
  Ornstein–Uhlenbeck wander (τ 2 h) and a fast one (τ 5 min);
- plate: the room through a first-order lag τ_p; die: the plate through a first-order lag
  L_die (or, class ``order2``, two equal lags in cascade: a critically damped path);
- logged channels: "plate" (a DS18B20 on the plate, its own 15 s lag) and "ambient" (the
  room, 30 s), read every t_read s, + 3 mK noise, rounded to 0.0625 K;
- noise per axis: white (N, m/s/√s), flicker (B, m/s²) as a sum of Gauss–Markov processes
  with time constants an octave apart from 30 s to 4× the record (each of variance
  (ln 2/π)·B², so the Allan plateau is ≈ (2 ln 2/π)·B²; not a Kasdin filter and not FFT
  phases), and optionally a rate random walk (K, m/s²·√s).

Classes outside explain's candidate set (one lag of either sign, two paths, quadratic,
dT/dt, hysteresis, warm-up, steps, excursions, Gauss–Markov, lines), the mechanism on x and
y, z uncoupled:

- ``remount``: one-lag coupling whose coefficient changes at t_s (x: sign flips and size
  changes ×r; y: same sign, ×r with r 2.5–4);
- ``order2``: the die behind the plate through two equal poles (τ2 each);
- ``unlogged``: the axis follows a slow humidity-like drive that is not logged (a sine of
  3–8 h plus an OU wander, through 20 min), the logged temperatures cycle on their own;
- ``multnoise``: the axis's white and flicker noise scaled by (1 + m·d/max|d|), d the die's
  temperature anomaly (a noise level that follows temperature);
- ``cubic``: a·tanh((d/w)³), w = 0.7·max|d|: cubic near the mean, saturating at the swing.

Null classes (no axis feels anything; a false claim is any claimed cause):

- ``clockoff``: the DS18B20 log's timestamps from a clock off by ε (200–2000 ppm, either
  sign) and δ (±30 s): each reading sits on the row its own clock names;
- ``cadence``: the stated rate is off the true one by 1–3 % and the temperature log is held
  (its last reading on every row) at a cadence of 7.3–13.7 s, not a whole number of samples;
- ``faults``: 5–30 readings of 85.0 °C and 5–30 of −127 °C at random, and a 2-hour dropout;
- ``room17``: the room cycles with a 17-minute period at ±0.5–2 K (the plate at a large
  share of it); the sensor is insensitive;
- ``accgap``: a 3-minute gap in the acceleration: spliced out (rows of both acceleration and
  temperature removed, the record continuous by its rows) on even seeds, the last sample
  held for 3 minutes on odd seeds.

Steady couplings under a room whose cycle changes (change28; the coupling never changes, so
a "the coupling changed" line is false there; x and y coupled, z uncoupled): the room's
cycle period jumps (phase-continuous) at t_s from P₁ to P₂, one of them 900–1800 s and the
other 4800–9000 s, in either order, so the temperature's spectrum differs between the parts:

- ``spec2lag``: the die behind the plate through two lags in series (τ_a, τ_b 150–600 s);
- ``specrate``: the die one lag behind the plate, the axis c·(d + τ_r·ḋ) (a one-lag plus
  dT/dt path, τ_r ±(200–800) s).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

DS_STEP = 0.0625
UNEXPLAINED = ("remount", "order2", "unlogged", "multnoise", "cubic")
NULLS = ("clockoff", "cadence", "faults", "room17", "accgap")
STEADY = ("spec2lag", "specrate")
KINDS = UNEXPLAINED + NULLS + STEADY


def lag1(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order low-pass (exact for a drive held over each step), started settled."""
    if tau <= 0:
        return x.copy()
    a = math.exp(-dt / tau)
    y = np.empty_like(x)
    s = float(x[0])
    for i, v in enumerate(x.tolist()):
        s = a * s + (1.0 - a) * v
        y[i] = s
    return y


def ou(rng: np.random.Generator, n: int, dt: float, tau: float, sd: float) -> np.ndarray:
    """Stationary Gauss–Markov process of standard deviation sd, n steps of dt."""
    a = math.exp(-dt / tau)
    e = rng.standard_normal(n) * sd * math.sqrt(1.0 - a * a)
    y = np.empty(n)
    s = rng.standard_normal() * sd
    for i, v in enumerate(e.tolist()):
        s = a * s + v
        y[i] = s
    return y


def flicker_ou(rng: np.random.Generator, t: np.ndarray, b: float, t_rec: float) -> np.ndarray:
    """Flicker of Allan plateau ≈ (2 ln 2/π)·b² as a sum of OU processes an octave apart,
    from two samples to 4× the record (slow ones on a grid of τ/8, interpolated)."""
    out = np.zeros(t.size)
    v = math.log(2.0) / math.pi * b * b
    ts = float(t[1] - t[0])
    tau = 2.0 * ts
    while tau <= 4.0 * t_rec:
        dt = max(ts, tau / 8.0)
        if dt == ts:
            out += ou(rng, t.size, ts, tau, math.sqrt(v))
        else:
            m = math.ceil(t[-1] / dt) + 2
            out += np.interp(t, np.arange(m) * dt, ou(rng, m, dt, tau, math.sqrt(v)))
        tau *= 2.0
    return out


def avar_oct(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan variance of rate samples x at octave m (≥ 8 averages), numpy."""
    c = np.concatenate(([0.0], np.cumsum(x)))
    taus, av = [], []
    m = 1
    while x.size // m >= 8:
        s = (c[2 * m:] - 2 * c[m:-m] + c[: -2 * m]) / m
        taus.append(m * dt)
        av.append(0.5 * float(np.mean(s * s)))
        m *= 2
    return np.array(taus), np.array(av)


def _room(rng: np.random.Generator, tg: np.ndarray, period: float, amp: float) -> np.ndarray:
    ph = rng.uniform(0, 2 * math.pi)
    cyc = np.clip(1.4 * np.sin(2 * math.pi * tg / period + ph), -1.0, 1.0) * amp
    return (21.0 + cyc + ou(rng, tg.size, 1.0, 7200.0, 0.3)
            + ou(rng, tg.size, 1.0, 300.0, 0.03))


def _read(rng, t_true_read: np.ndarray, tg: np.ndarray, src: np.ndarray) -> np.ndarray:
    v = np.interp(t_true_read, tg, src) + 0.003 * rng.standard_normal(t_true_read.size)
    return np.round(v / DS_STEP) * DS_STEP


def oracle(sig: np.ndarray, temp: np.ndarray, noise_av: np.ndarray, t_rec: float) -> dict:
    """The truth signal's best description inside explain's candidate families, fitted to the
    signal itself (no noise) on the 1 s grid against the logged channel: one lag, two lags,
    one lag + dT/dt, one lag + a quadratic (lags 0…3600 s up to record/8, an offset and a
    slope free). The ratio of the best residual's Allan variance to the noise's, at every
    octave with ≥ 8 averages: ≫ 1 means no candidate describes the axis, whatever explain
    does (hysteresis, transients and Gauss–Markov are not tried here)."""
    lags = [lag for lag in (0, 15, 30, 60, 120, 240, 480, 900, 1800, 3600) if lag <= t_rec / 8]
    us = {lag: lag1(temp, 1.0, float(lag)) for lag in lags}
    base = [np.ones_like(temp), np.arange(temp.size) / temp.size]
    fams: dict[str, tuple] = {}

    def fit(name, cols, info):
        a = np.column_stack(base + cols)
        coef, *_ = np.linalg.lstsq(a, sig, rcond=None)
        r = sig - a @ coef
        ss = float(r @ r)
        if name not in fams or ss < fams[name][0]:
            fams[name] = (ss, info, r)

    for i, l1 in enumerate(lags):
        u = us[l1]
        fit("one_lag", [u], {"lag_s": l1})
        fit("rate", [u, np.gradient(u)], {"lag_s": l1})
        fit("quadratic", [u, (u - u.mean()) ** 2], {"lag_s": l1})
        for l2 in lags[i + 1:]:
            fit("two_path", [u, us[l2]], {"lag_s": l1, "lag_2_s": l2})
    out = {}
    for name, (_, info, r) in fams.items():
        _, av = avar_oct(r, 1.0)
        k = min(av.size, noise_av.size)
        ratio = av[:k] / noise_av[:k]
        out[name] = dict(info, resid_over_noise_max=float(ratio.max()),
                         at_s=float(2.0 ** int(np.argmax(ratio))))
    best = min(out, key=lambda k: out[k]["resid_over_noise_max"])
    return {"families": out, "best": best,
            "resid_over_noise_max": out[best]["resid_over_noise_max"]}


def make_record(kind: str, seed: int, hours: float, path: str | Path) -> dict:
    """Write one record to ``path`` (.npz) and its truth to ``path`` + '.truth.json';
    return the truth."""
    if kind not in KINDS:
        raise ValueError(kind)
    rng = np.random.default_rng([26, KINDS.index(kind), seed, int(hours * 10)])
    rate = 10.0 if hours <= 6 else 5.0
    t_rec = hours * 3600.0
    tg = np.arange(int(t_rec) + 2, dtype=float)        # 1 s grid
    n = round(t_rec * rate)
    t = np.arange(n) / rate
    period = 1020.0 if kind == "room17" else float(rng.uniform(1800, 7200))
    amp = float(rng.uniform(0.5, 2.0)) if kind == "room17" else float(rng.uniform(0.4, 1.2))
    room = _room(rng, tg, period, amp)
    spec: dict = {}
    if kind in STEADY:
        # the cycle's period jumps at t_sw (phase continuous): the spectrum changes midway
        t_sw = float(rng.uniform(0.35, 0.65)) * t_rec
        ps = [float(rng.uniform(900, 1800)), float(rng.uniform(4800, 9000))]
        if rng.random() < 0.5:
            ps.reverse()
        ph = np.where(tg < t_sw, tg / ps[0], t_sw / ps[0] + (tg - t_sw) / ps[1])
        cyc = np.clip(1.4 * np.sin(2 * math.pi * ph + rng.uniform(0, 2 * math.pi)),
                      -1.0, 1.0) * amp
        room = _room(rng, tg, 1e12, 0.0) + cyc          # the wander, and the new cycle
        period = ps[0]
        spec = {"room_period_before_s": ps[0], "room_period_after_s": ps[1],
                "spectrum_change_s": t_sw}
    tau_p = float(rng.uniform(300, 900))
    plate = lag1(room, 1.0, tau_p)
    l_die = float(rng.uniform(60, 300))
    die = lag1(plate, 1.0, l_die)
    truth: dict = {"kind": kind, "seed": seed, "hours": hours, "rate_hz": rate,
                   "room_period_s": period, "room_amp_k": amp, "tau_plate_s": tau_p,
                   "die_lag_s": l_die, "axes": {}, **spec}
    noise = {}
    sig_g = {a: np.zeros(tg.size) for a in "xyz"}
    for ax in "xyz":
        nn = float(rng.uniform(1e-4, 2.5e-4))
        bb = float(rng.uniform(5e-6, 3e-5))
        kk = float(rng.uniform(2e-7, 2e-6)) if rng.random() < 0.5 else 0.0
        noise[ax] = (nn, bb, kk)
        truth["axes"][ax] = {"N": nn, "B_approx": bb, "K": kk, "cause": None}
    mult = None
    d = die - die.mean()
    if kind == "remount":
        ts = float(rng.uniform(0.35, 0.65)) * t_rec
        c = float(rng.uniform(5e-4, 2e-3))
        rx = -float(rng.uniform(0.5, 1.5))
        ry = float(rng.uniform(2.5, 4.0))
        for ax, r in (("x", rx), ("y", ry)):
            sig_g[ax] = np.where(tg < ts, c, c * r) * d
            truth["axes"][ax].update(cause="remount", coefficient_before=c,
                                     coefficient_after=c * r, change_s=ts, lag_s=l_die)
    elif kind == "order2":
        tau2 = float(rng.uniform(600, 1800))
        d2 = lag1(lag1(plate, 1.0, tau2), 1.0, tau2)
        d2 = d2 - d2.mean()
        # larger than the other classes: two paths approximate a cascade closely, so only a
        # large coupling leaves the candidate set measurably (the truth file's oracle says)
        c = float(rng.uniform(2e-3, 5e-3))
        for ax, f in (("x", 1.0), ("y", -0.7)):
            sig_g[ax] = c * f * d2
            truth["axes"][ax].update(cause="order2", coefficient=c * f, pole_s=tau2,
                                     poles=2)
    elif kind == "unlogged":
        ph = float(rng.uniform(3, 8)) * 3600.0
        h = np.sin(2 * math.pi * tg / ph + rng.uniform(0, 2 * math.pi))
        h = lag1(h + ou(rng, tg.size, 1.0, 3600.0, 0.5), 1.0, 1200.0)
        h = (h - h.mean()) / max(1e-12, float(np.abs(h - h.mean()).max()))
        g = float(rng.uniform(3e-4, 1e-3))
        for ax, f in (("x", 1.0), ("y", 0.6)):
            sig_g[ax] = g * f * h
            truth["axes"][ax].update(cause="unlogged_drive", amplitude=g * f,
                                     drive_period_s=ph)
    elif kind == "multnoise":
        m = float(rng.uniform(0.6, 0.9))
        mult = 1.0 + m * np.interp(t, tg, d) / float(np.abs(d).max())
        for ax in "xy":
            truth["axes"][ax].update(cause="noise_follows_temperature", depth=m)
    elif kind == "cubic":
        w = 0.7 * float(np.abs(d).max())
        a = float(rng.uniform(5e-4, 1.5e-3))
        for ax, f in (("x", 1.0), ("y", -0.8)):
            sig_g[ax] = a * f * np.tanh((d / w) ** 3)
            truth["axes"][ax].update(cause="cubic_saturating", amplitude=a * f, width_k=w)
    elif kind == "spec2lag":
        ta, tb = float(rng.uniform(150, 600)), float(rng.uniform(150, 600))
        d2 = lag1(lag1(plate, 1.0, ta), 1.0, tb)
        d2 = d2 - d2.mean()
        c = float(rng.uniform(5e-4, 2e-3))
        for ax, f in (("x", 1.0), ("y", -0.7)):
            sig_g[ax] = c * f * d2
            truth["axes"][ax].update(cause="steady_two_lags", coefficient=c * f,
                                     lags_s=[ta, tb])
    elif kind == "specrate":
        tr_ = float(rng.uniform(200, 800)) * (1 if rng.random() < 0.5 else -1)
        c = float(rng.uniform(5e-4, 2e-3))
        dd = np.gradient(d)
        for ax, f in (("x", 1.0), ("y", -0.7)):
            sig_g[ax] = c * f * (d + tr_ * dd)
            truth["axes"][ax].update(cause="steady_lag_rate", coefficient=c * f,
                                     rate_s=tr_, lag_s=l_die)
    accel = np.empty((n, 3))
    offsets = (0.05, -0.03, 9.80665)
    noise_g = {}
    for j, ax in enumerate("xyz"):
        nn, bb, kk = noise[ax]
        wn = rng.standard_normal(n) * nn * math.sqrt(rate)
        fl = flicker_ou(rng, t, bb, t_rec)
        if mult is not None and ax in "xy":
            wn = wn * mult
            fl = fl * mult
        rw = np.cumsum(rng.standard_normal(n)) * kk / math.sqrt(rate) if kk else 0.0
        accel[:, j] = offsets[j] + wn + fl + rw + np.interp(t, tg, sig_g[ax])
        # the noise alone, as 1 s means on the grid, for the oracle's yardstick
        k1 = int(rate)
        nz = (wn + fl + rw)[: (n // k1) * k1].reshape(-1, k1).mean(axis=1)
        noise_g[ax] = nz
    # the logged channels
    t_read = float(rng.choice([1.0, 2.0, 5.0]))
    if kind == "cadence":
        t_read = float(rng.uniform(7.3, 13.7))
    tr = np.arange(0.75, t_rec, t_read)                 # the true time of each reading
    plate_log = _read(rng, tr, tg, lag1(plate, 1.0, 15.0))
    amb_log = _read(rng, tr, tg, lag1(room, 1.0, 30.0))
    rows_t = tr.copy()
    if kind == "clockoff":
        eps = float(rng.uniform(2e-4, 2e-3)) * (1 if rng.random() < 0.5 else -1)
        delta = float(rng.uniform(-30, 30))
        rows_t = tr * (1.0 + eps) + delta
        truth.update(clock_ppm=eps * 1e6, clock_offset_s=delta)
    rows = np.round(rows_t * rate).astype(np.int64)
    ok = (rows >= 0) & (rows < n)
    rows, plate_log, amb_log = rows[ok], plate_log[ok], amb_log[ok]
    rows, first = np.unique(rows, return_index=True)
    plate_log, amb_log = plate_log[first], amb_log[first]
    temp = np.full((n, 2), np.nan)
    temp[rows, 0] = plate_log
    temp[rows, 1] = amb_log
    truth["t_read_s"] = t_read
    stated = rate
    if kind == "faults":
        d0 = float(rng.uniform(0.05, 0.95)) * max(0.0, t_rec - 7200.0)
        i0, i1 = int(d0 * rate), int((d0 + 7200.0) * rate)
        which = int(rng.integers(0, 3))                 # plate, ambient or both
        cols = [0] if which == 0 else [1] if which == 1 else [0, 1]
        temp[i0:i1, cols] = np.nan
        # the faulty readings fall on readings the dropout left (so the truth counts them)
        rr = rows[(rows < i0) | (rows >= i1)]
        k85, k127 = int(rng.integers(5, 31)), int(rng.integers(5, 31))
        pick = rng.choice(rr.size, size=k85 + k127, replace=False)
        col = rng.integers(0, 2, size=pick.size)
        temp[rr[pick[:k85]], col[:k85]] = 85.0
        temp[rr[pick[k85:]], col[k85:]] = -127.0
        truth.update(n_85=k85, n_minus127=k127, dropout_s=[d0, d0 + 7200.0],
                     dropout_channels=[("plate", "ambient")[c] for c in cols])
    if kind == "cadence":
        stated = rate * (1.0 + float(rng.uniform(0.01, 0.03)) * (1 if rng.random() < 0.5
                                                                  else -1))
        # held log: each reading repeated on every row until the next one
        for j in range(2):
            col = temp[:, j]
            idx = np.flatnonzero(np.isfinite(col))
            held = np.full(n, np.nan)
            seg = np.searchsorted(idx, np.arange(n), side="right") - 1
            okr = seg >= 0
            held[okr] = col[idx[seg[okr]]]
            temp[:, j] = held
        truth.update(stated_rate_hz=stated, held_log=True)
    if kind == "accgap":
        g0 = int(float(rng.uniform(0.1, 0.9)) * n)
        g1 = g0 + int(180 * rate)
        if seed % 2 == 0:
            accel = np.concatenate([accel[:g0], accel[g1:]])
            temp = np.concatenate([temp[:g0], temp[g1:]])
            truth["gap"] = {"mode": "spliced", "at_s": g0 / rate, "length_s": 180.0}
        else:
            accel[g0:g1] = accel[g0 - 1]
            truth["gap"] = {"mode": "held", "at_s": g0 / rate, "length_s": 180.0}
    # the oracle's verdict on the unexplained classes: the best candidate's residual
    if kind in UNEXPLAINED and kind != "multnoise":
        tlog = np.interp(tg, tr, lag1(plate, 1.0, 15.0)[np.minimum(tr.astype(int), tg.size - 1)])
        for ax in "xy":
            _, nav = avar_oct(noise_g[ax], 1.0)
            truth["axes"][ax]["oracle"] = oracle(sig_g[ax], tlog, nav, t_rec)
    arrays = {"accel": accel, "rate_hz": np.float64(stated), "axes": np.array(["x", "y", "z"]),
              "temperature_c": temp, "temperature_names": np.array(["plate", "ambient"])}
    np.savez(path, **arrays)
    Path(str(path) + ".truth.json").write_text(json.dumps(truth, indent=1))
    truth["_signals"] = sig_g                           # for the test, not the file
    return truth
