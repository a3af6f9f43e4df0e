"""The ADXL355 + DS18B20 sensor simulator: streamed, seeded, memory independent of duration.

    sim = SensorSimulator(make_config("quiet-lab"), seed=1)
    chunk = sim.next(65536)          # SimChunk: accel, counts, temp_c, chip_temp_c, index0

What one sample is made of, in the order the chip would see it (all in m/s², SI time):

1. white noise, per-sample σ = N·√fs (one-sided PSD 2N², so AVAR = N²/τ), together with the
   fastest flicker components (one ARMA stream, see ``noise_gen.FastNoise``). N is the white
   level of the *output*, as a datasheet or an Allan analysis of a record reports it: the
   rounding in step 6 adds white noise of LSB²/12 per sample, so the analog white noise is
   drawn with σ² = N²·fs − LSB²/12 (``analog_white_sigma``);
2. bias instability as a sum of Gauss–Markov processes spaced in log time constant,
   a Gauss–Markov term, rate random walk (AVAR K²τ/3), rate ramp (R·t), sinusoids, Poisson
   bias steps, a warm-up transient, and the temperature coupling (``thermal``), on a pyramid of
   grids from full rate to ≈1 s (``noise_gen.Level``);
3. gravity component and 0 g offset;
4. the ADXL355 digital low-pass: 2nd-order Butterworth at ODR/4 (the datasheet gives only the
   corner; ``avard.core.model.terms.lowpass_white_avar`` models the same filter), run at the
   real ODR
   (nominal × (1 + ppm)), which is the rate every time constant above is converted with;
5. the quantization noise term Q (white phase noise of σ = Q: AVAR 3Q²/τ², IEEE 952 C.7);
6. rounding to the 20-bit LSB of the range (3.9 µg at ±2 g) with clipping at ±2^19.

``SimChunk.accel`` is the signal before rounding; ``counts`` are what the chip's FIFO holds.
Random streams are spawned per component from the seed, so adding a term never reshuffles
the others, and chunk boundaries never change a number.
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np
from avard.core.sim.linear_filter import ModalFilter, butterworth_lowpass_zpk
from avard.core.sim.noise_gen import (
    AR1Bank,
    FastNoise,
    Source,
    build_pyramid,
    flicker_ladder,
    lerp,
    level_for,
    reinject_interpolation_loss,
)
from avard.core.sim.presets import PRESETS, SimConfig, make_config
from avard.core.sim.thermal import ThermalSource, ds18b20_readings
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "PRESETS",
    "SensorSimulator",
    "SimChunk",
    "SimConfig",
    "adxl355_lowpass_sos",
    "adxl355_lowpass_zpk",
    "ds18b20_readings",
    "make_config",
    "simulate_record",
]

COUNTS_MAX = (1 << 19) - 1
COUNTS_MIN = -(1 << 19)


def adxl355_lowpass_zpk() -> tuple[NDArray, NDArray, float]:
    """The ADXL355 output low-pass in sample units: 2nd-order Butterworth at ODR/4 (the corner
    is half the Nyquist frequency at any ODR), unit DC gain, as (zeros, poles, gain)."""
    return butterworth_lowpass_zpk(2, 0.5)


def adxl355_lowpass_sos() -> NDArray[np.float64]:
    """The same filter as one second-order section [b0, b1, b2, 1, a1, a2] (for
    ``scipy.signal.sosfilt`` in tests and analyses)."""
    zeros, poles, gain = adxl355_lowpass_zpk()
    b = gain * np.real(np.poly(zeros))
    a = np.real(np.poly(poles))
    return np.concatenate([b, a])[None, :]


def analog_white_sigma(n: ArrayLike, rate_hz: float, lsb: float) -> NDArray[np.float64]:
    """Per-sample σ of the white noise before the filter and the rounding, per axis, such
    that the quantized output has white level N (m/s/√s).

    Rounding a signal whose noise spans at least half an LSB adds an error that is uniform on
    ±LSB/2 and independent of the signal (Sheppard; Widrow & Kollár ch. 4): white noise of
    variance LSB²/12 per sample, N_q² = LSB²/(12·fs) in Allan terms. On the paper's X and Y
    axes that is 0.35 % of N² (N 0.17 % high if ignored). It is subtracted where the
    requested per-sample σ is at least LSB/2; below that rounding is not an additive white
    term and N is taken as the analog level unchanged."""
    sigma = np.asarray(n, dtype=float) * math.sqrt(rate_hz)
    var_q = lsb * lsb / 12.0
    return np.where(sigma >= 0.5 * lsb, np.sqrt(np.maximum(sigma**2 - var_q, 0.0)), sigma)


class SimChunk:
    """``n`` consecutive samples starting at sample ``index0``.

    accel (n, 3) m/s² before rounding; counts (n, 3) int32 raw 20-bit (C-ordered); temp_c
    (n, 2) true plate and ambient temperatures (°C); chip_temp_c (n,) die temperature (°C).
    accel and temp_c are column-major views (time runs fastest inside the simulator). The
    temperatures are interpolated from the ≈1 s thermal grid when first asked for;
    :meth:`temperatures_at` gives them at a few samples only (what a DS18B20 needs).
    """

    __slots__ = ("__dict__", "_coarse", "_q", "_start", "accel", "counts", "index0")

    def __init__(self, accel: NDArray[np.float64], counts: NDArray[np.int32], index0: int,
                 coarse: NDArray[np.float64], q: int, start: int) -> None:
        self.accel = accel
        self.counts = counts
        self.index0 = index0
        self._coarse, self._q, self._start = coarse, q, start   # thermal grid (3, K)

    def __len__(self) -> int:
        return len(self.counts)

    @cached_property
    def _temps(self) -> NDArray[np.float64]:
        out = np.empty((3, len(self.counts)))
        if len(self.counts):
            lerp(self._coarse, self._q, self._start, out)
        return out

    @property
    def temp_c(self) -> NDArray[np.float64]:
        return self._temps[:2].T

    @property
    def chip_temp_c(self) -> NDArray[np.float64]:
        return self._temps[2]

    def temperatures_at(self, rel: NDArray[np.int64]) -> NDArray[np.float64]:
        """(len(rel), 3) plate, ambient and die temperature (°C) at samples index0 + rel."""
        f = np.asarray(rel, dtype=np.int64) + self._start
        k = f // self._q
        w = ((f - k * self._q) / self._q)[:, None]
        c = self._coarse.T
        return c[k] * (1.0 - w) + c[np.minimum(k + 1, len(c) - 1)] * w


class _Sinusoids:
    """A·sin(2πf·t + φ) on one axis each, t = index/fs: a function of the index only."""

    def __init__(self, sines: tuple, dt: float) -> None:
        self.sines = sines
        self.dt = dt
        self.i = 0

    def next_values(self, m: int) -> NDArray[np.float64]:
        out = np.zeros((3, m))
        t = np.arange(self.i, self.i + m) * self.dt
        self.i += m
        for axis, amp, freq, phase in self.sines:
            out[int(axis)] += amp * np.sin(2.0 * math.pi * freq * t + phase)
        return out


class _BiasSteps:
    """Bias steps at Poisson times (rate λ per hour over all axes, axis drawn uniformly),
    amplitude N(0, σ²). Events are drawn in time order from their own stream."""

    def __init__(self, rate_per_h: float, sigma: float, dt: float,
                 rng: np.random.Generator) -> None:
        self.mean_gap = 3600.0 / rate_per_h / dt    # samples between steps
        self.sigma = sigma
        self.rng = rng
        self.i = 0
        self.level = np.zeros(3)
        self.next_event = self._draw_gap(0.0)

    def _draw_gap(self, after: float) -> float:
        return after + self.rng.exponential(self.mean_gap)

    def next_values(self, m: int) -> NDArray[np.float64]:
        out = np.empty((3, m))
        start, end = self.i, self.i + m
        pos = start
        while self.next_event < end:
            k = max(math.ceil(self.next_event), pos)
            out[:, pos - start : k - start] = self.level[:, None]
            pos = k
            axis = int(self.rng.integers(3))
            self.level = self.level.copy()
            self.level[axis] += self.sigma * self.rng.standard_normal()
            self.next_event = self._draw_gap(self.next_event)
        out[:, pos - start :] = self.level[:, None]
        self.i = end
        return out


class SensorSimulator:
    """Streams simulated ADXL355 samples (see the module docstring for the signal chain).

    ``next(n)`` returns the next n samples; the state is carried, so any split of a record into
    chunks gives identical numbers for the same seed, and memory depends on n only.
    """

    def __init__(self, config: SimConfig, seed: int | None = None) -> None:
        self.config = config
        self.seed = seed
        self.rate_hz = config.rate_hz
        self.dt = 1.0 / self.rate_hz
        self.lsb = config.lsb_mps2
        self.index = 0
        entropy = np.random.SeedSequence(seed).entropy

        def seq(*key: int) -> np.random.SeedSequence:
            # one fixed stream per component and grid level, keyed by number (not by order)
            return np.random.SeedSequence(entropy, spawn_key=key)

        fs, dt, c = self.rate_hz, self.dt, config
        h_slow = max(FAST_MAX_H * 2, 2 ** round(math.log2(fs)))   # ≈ 1 s grid
        self._h_slow = h_slow
        levels: dict[int, list[Source]] = {}

        # Gauss–Markov components: the flicker ladder and the per-axis GM term
        # default: the fastest member at one sample; flicker_ladder refits the variances of
        # the lowest members to the sampled 1/f level (AVAR flat from m = 2 up, before the
        # chip filter), which a ladder cut at any tmin is not
        tmin = c.flicker_tmin_s if c.flicker_tmin_s is not None else dt
        ladder = flicker_ladder(c.bias_instability, tmin, c.flicker_tmax_s, c.flicker_per_decade,
                                dt_s=dt)
        if REINJECT:
            steps = [0.0 if (h := level_for(T, fs, h_slow)) <= FAST_MAX_H else h * dt
                     for T, _ in ladder]
            ladder = reinject_interpolation_loss(ladder, steps)
        gm_term = [(T, np.where(np.arange(3) == a, s, 0.0))
                   for a, (T, s) in enumerate(zip(c.gm_tau_s, c.gm_sigma_mps2, strict=True))]
        fast: list[tuple[float, NDArray]] = []
        for stream, entries in ((1, ladder), (2, gm_term)):
            by_level: dict[int, list] = {}
            for T, sig in entries:
                if not np.any(sig > 0):
                    continue
                h = level_for(T, fs, h_slow)
                # the fastest share the white stream: one ARMA filter instead of more draws
                (fast if h <= FAST_MAX_H else by_level.setdefault(h, [])).append((T, sig))
            for h, group in sorted(by_level.items()):
                levels.setdefault(h, []).append(AR1Bank(group, h * dt, seq(stream, h)))
        sigma_w = analog_white_sigma(c.velocity_random_walk, fs, self.lsb)
        levels.setdefault(1, []).insert(0, FastNoise(sigma_w, fast, dt, seq(0)))
        # rate random walk on a ≈50 ms grid: increments K·√Δ (discrete AVAR K²τ/3 + O(Δ²/τ))
        if any(k > 0 for k in c.rate_random_walk):
            h_rw = 2 ** max(0, math.floor(math.log2(max(1.0, RW_STEP_S * fs))))
            h_rw = min(h_slow, max(FAST_MAX_H * 2, h_rw))
            step = h_rw * dt
            levels.setdefault(h_rw, []).append(
                AR1Bank([(math.inf, np.asarray(c.rate_random_walk) * math.sqrt(step))], step,
                        seq(3)))
        self._thermal = ThermalSource(c, h_slow * dt, np.random.default_rng(seq(4)))
        levels.setdefault(h_slow, []).append(self._thermal)
        if c.sinusoids:
            levels[1].append(_Sinusoids(c.sinusoids, dt))
        if c.bias_step_rate_per_h > 0 and c.bias_step_sigma_mps2 > 0:
            levels[1].append(_BiasSteps(c.bias_step_rate_per_h, c.bias_step_sigma_mps2, dt,
                                        np.random.default_rng(seq(5))))
        self._top = build_pyramid(levels, 3)
        self._q = np.asarray(c.quantization, dtype=float)
        self._q_rngs = [np.random.default_rng(s) for s in seq(6).spawn(3)]
        self._q_prev = self._q * np.array([r.standard_normal() for r in self._q_rngs])
        self._dc = np.asarray(c.gravity_mps2) + np.asarray(c.offset_mps2)
        self._chip_filter = ModalFilter.from_zpk(*adxl355_lowpass_zpk(), channels=3)
        self._started = False
        # Samples are computed in blocks of _block aligned to sample 0 (see SIM_BLOCK) and
        # served from here: accel (3, ·) and counts (·, 3) from sample _buf_i0, the slow
        # grid's temperatures (3, ·) from grid point _coarse_j0.
        self._block = max(SIM_BLOCK, h_slow)
        self._buf_i0 = 0
        self._acc = np.zeros((3, 0))
        self._cnt = np.zeros((0, 3), dtype=np.int32)
        self._coarse = np.zeros((3, 0))
        self._coarse_j0 = 0

    def next(self, n: int) -> SimChunk:
        """The next ``n`` samples (n ≥ 0)."""
        n = int(n)
        if n < 0:
            raise ValueError("n must be >= 0")
        i0 = self.index
        if n == 0:
            empty = np.zeros((0, 3))
            return SimChunk(empty, empty.astype(np.int32), i0, np.zeros((3, 1)), 1, 0)
        gen_end = self._buf_i0 + self._cnt.shape[0]
        if gen_end < i0 + n:
            blocks = []
            while gen_end < i0 + n:
                blocks.append(self._generate(gen_end, self._block))
                gen_end += self._block
            self._acc = np.concatenate([self._acc, *(b[0] for b in blocks)], axis=1)
            self._cnt = np.concatenate([self._cnt, *(b[1] for b in blocks)])
            # consecutive blocks share their boundary grid point
            grids = [self._coarse[:, :-1], *(b[2][:, :-1] for b in blocks[:-1]), blocks[-1][2]]
            if not self._coarse.shape[1]:
                self._coarse_j0 = self._buf_i0 // self._h_slow
            self._coarse = np.concatenate(grids, axis=1)
        a = i0 - self._buf_i0
        accel, counts = self._acc[:, a : a + n], self._cnt[a : a + n]
        h = self._h_slow
        c0, c1 = i0 // h, (i0 + n - 1) // h + 1
        coarse = self._coarse[:, c0 - self._coarse_j0 : c1 - self._coarse_j0 + 1]
        self.index += n
        # keep what has not been served (the grid from the point before the next sample)
        self._acc, self._cnt = self._acc[:, a + n :], self._cnt[a + n :]
        self._buf_i0 = self.index
        keep = self.index // h
        self._coarse = self._coarse[:, keep - self._coarse_j0 :]
        self._coarse_j0 = keep
        # accel and temp_c are (n, k) views of channel-major arrays (Fortran-ordered)
        return SimChunk(accel.T, counts, i0, coarse, h, i0 - c0 * h)

    def _generate(self, i0: int, n: int) -> tuple[NDArray, NDArray[np.int32], NDArray]:
        """Samples i0 … i0+n−1: accel (3, n) m/s², counts (n, 3), and the slow grid's
        temperatures (3, ·) from grid point i0 // h_slow to the one after the last sample."""
        tot = self._top.totals(i0, i0 + n - 1)          # (3, n), time contiguous
        x = tot + self._dc[:, None]
        # temperatures straight from the slow grid (generated by now: the pyramid looks ahead)
        h = self._h_slow
        coarse = self._thermal.temps(i0 // h, (i0 + n - 1) // h + 1).copy()
        if not self._started:
            # start the filter in its steady state for the first sample (no start-up ringing)
            self._chip_filter.steady(x[:, 0])
            self._started = True
        accel = self._chip_filter.run(x)
        if np.any(self._q > 0):
            # y = Δx/τ0 of white phase noise x of σ = Q (one stream per axis)
            e = np.stack([r.standard_normal(n) for r in self._q_rngs]) * self._q[:, None]
            d = np.diff(e, axis=1, prepend=self._q_prev[:, None])
            accel += d * self.rate_hz
            self._q_prev = e[:, -1].copy()
        # (n, 3) C-ordered counts straight from the channel-major signal (one strided pass)
        scaled = np.multiply(accel.T, 1.0 / self.lsb, order="C")
        np.rint(scaled, out=scaled)
        np.clip(scaled, COUNTS_MIN, COUNTS_MAX, out=scaled)
        return accel, scaled.astype(np.int32), coarse

    def counts_source(self, n: int) -> NDArray[np.int32]:
        """``source(n)`` for the ADXL355 emulator: the next n samples as raw counts."""
        return self.next(n).counts


#: Samples computed at a time, aligned to sample 0, whatever ``next`` is asked for: the
#: vectorised filters (linear_filter) round differently for different lengths, so fixed blocks
#: keep any split of a record bit for bit equal to the whole. It is also the look-ahead that
#: makes the emulator's per-drain calls cheap (131 s at 125 Hz, 4 s at 4 kHz), and long
#: enough that numpy's per-call cost is small (a quarter less CPU than 4096 on long records).
SIM_BLOCK = 16384

#: Grid step of the rate random walk (s, rounded down to a power-of-two number of samples):
#: linear interpolation makes the walk smooth below it, where its AVAR is negligible anyway.
RW_STEP_S = 0.05

#: Gauss–Markov processes that would sit on grids up to this step join the white stream.
FAST_MAX_H = 4
REINJECT = True


def simulate_record(config: SimConfig, hours: float, seed: int | None,
                    *, chunk: int = 1 << 17) -> dict[str, object]:
    """A whole record in memory, as the .npz of issue 4: ``accel`` (N, 3) m/s² (the rounded
    counts × LSB, what the sensor reports), ``rate_hz`` (the real ODR), ``axes``,
    ``temperature_c`` (N, 2) DS18B20 readings aligned to samples (NaN between readings),
    ``temperature_names``. Use :func:`avard.core.sim.sim_io.write_npz` for long records."""
    from avard.core.sim.sim_io import iter_record_blocks, record_meta

    n_total = n_samples(config, hours)
    accel = np.empty((n_total, 3))
    temp = np.empty((n_total, 2))
    for i0, a, t in iter_record_blocks(config, n_total, seed, chunk=chunk):
        accel[i0 : i0 + len(a)] = a
        temp[i0 : i0 + len(t)] = t
    return {"accel": accel, "temperature_c": temp, **record_meta(config, seed)}


def n_samples(config: SimConfig, hours: float) -> int:
    """Number of samples in ``hours`` at the real ODR."""
    return round(float(hours) * 3600.0 * config.rate_hz)
