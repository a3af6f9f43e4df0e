"""Streaming noise generators on a multi-rate grid pyramid.

Every process here is generated sequentially, point by point in time, from its own random
stream, with its filter state carried between calls: asking for 1000 points and then 1000 more
gives bit for bit the same numbers as asking for 2000 at once, and memory does not grow with the
length of the record.

Slow processes are cheap to generate at a coarse step and interpolate. A :class:`Level` holds
the processes of one grid step h (in samples, a power of two); its points are the sum of its own
sources plus the next coarser level linearly interpolated onto its grid. A Gauss–Markov process
of time constant T lives on the coarsest level with h·dt ≤ T/``GM_POINTS_PER_TAU``, so the
interpolation only smooths it where its own AVAR contribution is small.

References: first-order Gauss–Markov and random walk as AR(1) (IEEE Std 952-1997 Annex C);
flicker (bias instability) as a sum of Gauss–Markov processes evenly spaced in log time constant
(the PSD of the sum, ∫ 4σ²T/(1 + (2πfT)²) dlnT with σ² = (B²/π) per unit ln T, is B²/(πf),
the one-sided PSD whose AVAR floor is (2 ln 2/π)·B², NIST SP 1065 Table 5).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from avard.core.model.nnls import nnls
from avard.core.sim.linear_filter import ModalFilter, first_order_scan
from numpy.typing import NDArray

#: A Gauss–Markov process gets at least this many grid points per time constant.
GM_POINTS_PER_TAU = 8.0


class Source(Protocol):
    """Anything that yields the next ``m`` grid points of its (m, C) contribution."""

    def next_values(self, m: int) -> NDArray[np.float64]: ...


#: Lowest ladder members whose variances are refitted to the discrete 1/f level (see below).
END_RUNGS = 3
#: Averaging factors (samples) over which the short end of the ladder is made flat.
END_FIT_M = (2, 1024)


def ar1_avar(t_s: float, dt_s: float, m: int) -> float:
    """Allan variance at τ = m·dt of a sampled stationary AR(1) of unit variance and
    autocorrelation e^(−k·dt/T) (T = 0: white). Exact: σ²(m) = (1/m²) Σ_{k=1}^{2m−1} c_k·(ρ_k − 1)
    with c_k the autocorrelation of the Allan kernel (+1 × m, −1 × m): 2m − 3k for k ≤ m,
    −(2m − k) above; written with ρ_k − 1 = expm1(−k·dt/T) so nothing cancels for T ≫ m·dt."""
    k = np.arange(1, 2 * m, dtype=float)
    c = np.where(k <= m, 2 * m - 3 * k, -(2 * m - k))
    rho_m1 = np.full_like(k, -1.0) if t_s <= 0 else np.expm1(-k * dt_s / t_s)
    return float(np.dot(c, rho_m1) / (m * m))


def flicker_ladder(
    b: Sequence[float], tmin_s: float, tmax_s: float, per_decade: float,
    dt_s: float | None = None,
) -> list[tuple[float, NDArray[np.float64]]]:
    """Gauss–Markov components (T, σ per axis) whose sum is flicker noise of bias instability B.

    Time constants T_k = tmin·r^k with r = 10^(1/per_decade) up to tmax; each carries variance
    σ_k² = (B²/π)·ln r, the discrete version of a density B²/π per unit ln T. The AVAR floor
    is then (2 ln 2/π)·B² = (0.6643·B)² for τ well inside [tmin, tmax] (IEEE 952 eq. C.14).

    The short end needs care when the members are sampled every ``dt_s`` (pass it): a member
    of T ≈ dt is almost white, and a sampled AR(1) is not the continuous process it stands for
    (its low-frequency level is σ²(1+φ)/(1−φ)·dt, not 2σ²T; at T = dt/π that is 1.7× too much),
    while the 1/f density below tmin, missing from the sum, acts like white noise at every
    τ ≫ tmin. Both errors fall off as 1/m and 1/m², which is why the plain ladder from
    1/(π·ODR) was 12 % high at m = 4 and 2.4 % at m = 16 before the chip filter. So with
    ``dt_s`` given (and tmin ≤ 2·dt), the variances of the lowest :data:`END_RUNGS` members are
    refitted (non-negative least squares, relative error) so that the exact sampled AVAR of the
    whole sum (:func:`ar1_avar`) is (2 ln 2/π)·B² at every m in :data:`END_FIT_M`: an end
    correction that absorbs the missing tail and the sampling of the fast members. With
    tmin = dt (the default) the sum is then within 0.2 % of the floor from m = 2 up (4.5 % high
    at m = 1, where one AR(1) per decade cannot follow and the chip filter dominates anyway).
    """
    r = 10.0 ** (1.0 / per_decade)
    n = max(1, math.ceil(math.log(tmax_s / tmin_s) / math.log(r)) + 1)
    sigma: NDArray[np.float64] = (np.asarray(b, dtype=float)
                                  * math.sqrt(math.log(r) / math.pi))
    ts = [tmin_s * r**k for k in range(n)]
    scale = np.ones(n)
    if dt_s is not None and tmin_s <= 2.0 * dt_s and n > END_RUNGS:
        scale[:END_RUNGS] = _end_correction(ts, dt_s, math.log(r) / math.pi)
    return [(float(t), sigma * math.sqrt(float(f)))
            for t, f in zip(ts, scale, strict=True)]


def _end_correction(ts: Sequence[float], dt_s: float, w: float) -> NDArray[np.float64]:
    """Variance factors of the lowest END_RUNGS members (see :func:`flicker_ladder`)."""
    m_lo, m_hi = END_FIT_M
    m_hi = max(m_lo + 1, min(m_hi, int(ts[-1] / dt_s / 100.0)))
    ms = np.unique(np.round(np.geomspace(m_lo, m_hi, 30)).astype(int))
    target = 2.0 * math.log(2.0) / math.pi
    a = np.array([[w * ar1_avar(t, dt_s, int(m)) / target for t in ts] for m in ms])
    rest = a[:, END_RUNGS:].sum(axis=1)
    return nnls(a[:, :END_RUNGS], 1.0 - rest)[0]


def reinject_interpolation_loss(
    ladder: list[tuple[float, NDArray[np.float64]]], steps_s: Sequence[float]
) -> list[tuple[float, NDArray[np.float64]]]:
    """Give back what grid interpolation takes from the flicker ladder.

    A Gauss–Markov process of time constant T sampled every Δ and linearly interpolated keeps
    on average (2 + φ)/3 of its variance (φ = e^(−Δ/T)); the lost σ²(1 − φ)/3 is its
    spectrum above the grid's Nyquist frequency, i.e. time scales ≈ Δ/π. That variance is
    added to the ladder member whose time constant is nearest Δ/π (which lives on a finer
    grid), so the sum keeps the 1/f level at short τ. ``steps_s[k]`` is member k's grid step
    (0 for members generated at full rate, which lose nothing).
    """
    t = np.array([T for T, _ in ladder])
    var = [np.asarray(s, dtype=float) ** 2 for _, s in ladder]
    add = [np.zeros_like(v) for v in var]
    for k, (T, _) in enumerate(ladder):
        step = steps_s[k]
        if step <= 0:
            continue
        lost = var[k] * (1.0 - math.exp(-step / T)) / 3.0
        j = int(np.argmin(np.abs(np.log(t / (step / math.pi)))))
        add[j] = add[j] + lost
    return [(T, np.sqrt(v + a)) for (T, _), v, a in zip(ladder, var, add, strict=True)]


def level_for(tau_s: float, rate_hz: float, h_max: int) -> int:
    """Grid step (samples, power of two) for a process of time constant ``tau_s``."""
    points = tau_s * rate_hz / GM_POINTS_PER_TAU
    if points < 2.0:
        return 1
    return int(min(h_max, 2 ** math.floor(math.log2(points))))


class AR1Bank:
    """Independent first-order autoregressions x[j] = φ x[j−1] + c·w[j] on one grid.

    Each entry is (T, σ (3,)): a stationary Gauss–Markov process of standard deviation σ and
    time constant T (φ = e^(−Δ/T), c = σ√(1−φ²)), or, with T = inf, a random walk with
    increments σ·w (φ = 1, start at 0). The state starts from the stationary distribution, so
    the record has no start-up transient. Every (process, axis) has its own random stream, so
    draws stay contiguous in time whatever the chunk size. Output layout (3, m). All
    processes run as one vectorised recurrence (linear_filter.first_order_scan).
    """

    def __init__(self, entries: Sequence[tuple[float, NDArray]], step_s: float,
                 seed: np.random.SeedSequence) -> None:
        children = seed.spawn(len(entries))
        self.rngs = [[np.random.default_rng(s) for s in ch.spawn(3)] for ch in children]
        self.scale = np.array([np.asarray(s, dtype=float) for _, s in entries]).reshape(-1, 3)
        phis, gains, prev = [], [], []
        for (T, _), rngs in zip(entries, self.rngs, strict=True):
            if math.isinf(T):
                phi, gain, x0 = 1.0, 1.0, np.zeros(3)
            else:
                phi = math.exp(-step_s / T)
                gain = math.sqrt(-math.expm1(-2.0 * step_s / T))  # √(1−φ²), exact for tiny Δ/T
                x0 = np.array([r.standard_normal() for r in rngs])
            phis.append(phi)
            gains.append(gain)
            prev.append(x0)
        self.phi = np.array(phis).reshape(-1, 1)       # (P, 1) against (P, 3)
        self.gain = np.array(gains).reshape(-1, 1, 1)
        self.prev = np.array(prev).reshape(-1, 3)      # x[−1] of every (process, axis)

    def next_values(self, m: int) -> NDArray[np.float64]:
        w = np.empty((len(self.rngs), 3, m))
        for p, rngs in enumerate(self.rngs):
            for a, r in enumerate(rngs):
                r.standard_normal(out=w[p, a])
        w *= self.gain
        x = first_order_scan(w, self.phi, self.prev)    # x[j] = φ·x[j−1] + c·w[j]
        if m:
            self.prev = x[:, :, -1].copy()
        return np.einsum("pa,pam->am", self.scale, x)


def white_plus_ar1_filter(
    sigma_w: float, phis: Sequence[float], sigmas: Sequence[float]
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """One ARMA(p, p) filter whose output has the law of white noise (σ_w) plus p independent
    stationary AR(1) processes x_k[j] = φ_k x_k[j−1] + σ_k√(1−φ_k²)·w_k[j].

    The sum's spectrum is S(z) = σ_w² + Σ c_k²/((1−φ_k z⁻¹)(1−φ_k z)); over the common
    denominator its numerator z^p·N(z) is a palindromic polynomial P(z) of degree 2p whose roots
    come in pairs (r, 1/r). Keeping the roots inside the unit circle gives the minimum-phase
    spectral factor N(z) = g²·Π(1 − r_i z⁻¹)(1 − r_i z), g² = P(1)/Π(1 − r_i)².
    Returns (g, zeros r_i, poles φ_k): y = g·Π(1 − r_i z⁻¹)/Π(1 − φ_k z⁻¹)·w.
    """
    phis = [float(f) for f, s in zip(phis, sigmas, strict=True) if s > 0]
    sigmas = [float(s) for s in sigmas if s > 0]
    if not phis:
        return float(sigma_w), np.zeros(0), np.zeros(0)
    ones = np.poly1d([1.0])

    def a_of(fs: Sequence[float]) -> np.poly1d:      # Π (z − φ)
        return np.poly1d(np.poly(fs)) if fs else ones

    def abar_of(fs: Sequence[float]) -> np.poly1d:   # Π (1 − φ z)
        out = ones
        for f in fs:
            out = out * np.poly1d([-f, 1.0])
        return out

    z = np.poly1d([1.0, 0.0])
    P = sigma_w**2 * a_of(phis) * abar_of(phis)
    for k, (f, s) in enumerate(zip(phis, sigmas, strict=True)):
        rest = phis[:k] + phis[k + 1 :]
        P = P + (s * s * (1.0 - f * f)) * z * a_of(rest) * abar_of(rest)
    roots = np.roots(P.coeffs)
    inside = np.sort_complex(roots[np.abs(roots) < 1.0])
    zeros = np.real_if_close(inside, tol=1e6)
    g2 = float(np.real(P(1.0) / np.prod((1.0 - inside) ** 2)))
    return math.sqrt(g2), np.asarray(zeros), np.asarray(phis)


class FastNoise:
    """White noise of per-sample σ_w plus the full-rate Gauss–Markov processes (T_k, σ_k),
    all from one white stream per axis through :func:`white_plus_ar1_filter` (the same
    Gaussian process as the independent sum, at the cost of one random draw per sample).
    The filter state is warmed up on its own stream, so the record starts stationary.
    Output layout (3, m). The filter runs in modal form (linear_filter.ModalFilter).
    """

    def __init__(self, sigma_w: NDArray, gms: Sequence[tuple[float, NDArray]], step_s: float,
                 seed: np.random.SeedSequence) -> None:
        # equal time constants are one process of the summed variance (the modal form needs
        # distinct poles)
        merged: dict[float, NDArray] = {}
        for T, s in gms:
            merged[T] = np.sqrt(merged.get(T, 0.0) ** 2 + np.asarray(s, dtype=float) ** 2)
        gms = list(merged.items())
        seeds = seed.spawn(4)
        self.rngs = [np.random.default_rng(s) for s in seeds[:3]]
        warm = np.random.default_rng(seeds[3])
        phis = [math.exp(-step_s / T) for T, _ in gms]
        slowest = max([T for T, _ in gms], default=step_s)
        n_warm = int(40 * slowest / step_s) + 64       # φ^n_warm < e^−40: stationary
        self.filters: list[ModalFilter] = []
        for a in range(3):
            g, zeros, poles = white_plus_ar1_filter(
                float(sigma_w[a]), phis, [float(s[a]) for _, s in gms])
            f = ModalFilter.from_zpk(zeros, poles, g)
            f.run(warm.standard_normal(n_warm)[None, :])
            self.filters.append(f)

    def next_values(self, m: int) -> NDArray[np.float64]:
        out = np.empty((3, m))
        for a, (f, rng) in enumerate(zip(self.filters, self.rngs, strict=True)):
            rng.standard_normal(out=out[a])
            out[a] = f.run(out[a][None, :])[0]
        return out


class Level:
    """One grid of step ``h`` samples: own sources plus the coarser level interpolated.

    Arrays are channel-major, (C, m): time is the contiguous axis. :meth:`totals` returns
    points j0..j1 (inclusive) and generates what is missing, in order, exactly once. Requests
    only move forward (j0 never goes back more than one point before the end of the previous
    request), so only the last two points are kept between calls.
    """

    h: int  # this grid's step, in samples of the finest grid

    def __init__(self, h: int, n_columns: int, sources: list[Source],
                 coarser: Level | None) -> None:
        if coarser is not None and coarser.h % h:
            raise ValueError("grid steps must nest (powers of two)")
        self.h = h
        self.columns = n_columns
        self.sources = sources
        self.coarser = coarser
        self.buf = np.zeros((n_columns, 0))
        self.buf_j0 = 0

    @property
    def next_j(self) -> int:
        return self.buf_j0 + self.buf.shape[1]

    def _generate(self, out: NDArray[np.float64]) -> None:
        """Fill ``out`` (C, m) with the next m points."""
        m = out.shape[1]
        j_start = self.next_j
        if self.coarser is not None:
            q = self.coarser.h // self.h
            j_end = j_start + m - 1
            c0, c1 = j_start // q, j_end // q + 1
            lerp(self.coarser.totals(c0, c1), q, j_start - c0 * q, out)
        else:
            out[:] = 0.0
        for src in self.sources:
            v = src.next_values(m)
            out[: v.shape[0]] += v

    def totals(self, j0: int, j1: int) -> NDArray[np.float64]:
        """Points j0..j1 (C, j1−j0+1). The result may be a view: use it before the next call."""
        if j0 < self.buf_j0:
            raise RuntimeError("simulator grid asked to go back in time")  # a bug, not a user error
        if j1 >= self.next_j:
            k = self.buf.shape[1]
            grown = np.empty((self.columns, j1 - self.buf_j0 + 1))
            grown[:, :k] = self.buf
            self._generate_into(grown, k)
            self.buf = grown
        out = self.buf[:, j0 - self.buf_j0 : j1 - self.buf_j0 + 1]
        keep = max(self.buf_j0, j1 - 1)
        self.buf = self.buf[:, keep - self.buf_j0 :].copy()
        self.buf_j0 = keep
        return out

    def _generate_into(self, grown: NDArray[np.float64], k: int) -> None:
        # next_j must still describe the old buffer while generating
        self._generate(grown[:, k:])


def lerp(coarse: NDArray[np.float64], q: int, start: int, out: NDArray[np.float64]) -> None:
    """Linear interpolation of coarse points (C, K), spaced q fine points apart with the first
    at fine offset 0, at fine offsets start … start+m−1, written into ``out`` (C, m).

    Whole coarse intervals are filled in place through a (C, n, q) view of ``out`` (two passes,
    no gathers, no temporaries of the fine size); the partial first and last intervals apart.
    """
    m = out.shape[1]
    if q == 1:
        out[:] = coarse[:, start : start + m]
        return
    w = np.arange(q) / q
    d = np.diff(coarse, axis=1)
    end = start + m                       # fine offsets [start, end)
    first_full = -(-start // q)           # first interval that starts inside the range
    last_full = end // q                  # intervals [first_full, last_full) are whole
    if first_full >= last_full:           # the range sits inside one or two intervals
        f = np.arange(start, end)
        k = f // q
        out[:] = coarse[:, k] + d[:, k] * w[f - k * q]
        return
    head = first_full * q - start
    if head:
        i = first_full - 1
        out[:, :head] = coarse[:, i, None] + d[:, i, None] * w[q - head :]
    n_full = last_full - first_full
    body = out[:, head : head + n_full * q].reshape(out.shape[0], n_full, q)
    np.multiply(d[:, first_full:last_full, None], w, out=body)
    body += coarse[:, first_full:last_full, None]
    tail = end - last_full * q
    if tail:
        out[:, m - tail :] = coarse[:, last_full, None] + d[:, last_full, None] * w[:tail]


def build_pyramid(levels: dict[int, list[Source]], n_columns: int) -> Level:
    """Link one :class:`Level` per grid step (coarsest last) and return the finest (h = 1)."""
    coarser: Level | None = None
    for h in sorted(set(levels) | {1}, reverse=True):
        coarser = Level(h, n_columns, levels.get(h, []), coarser)
    assert coarser is not None
    return coarser
