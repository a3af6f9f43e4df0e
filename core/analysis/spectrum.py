"""The Welch spectrum of ``avard analyze`` and its sinusoid (line) finder: a streaming
Welch accumulator, its segment length, and the F-test threshold a line must pass."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan import kernels
from avard.core.allan.scratch import scratch
from avard.core.errors import DataError
from numpy.typing import NDArray

if TYPE_CHECKING:
    pass

# ---------------------------------------------------------------------------------------------
# spectrum and sinusoid detection


#: Segments are transformed at once as many as a block of this many new samples brings:
#: two of analyze's one-worker blocks (whose segments all go in one batch, as before), so a
#: parallel chunk's four-block reads keep the transform buffers of two. A transform has a
#: fixed cost (its plan, the window and mean passes' Python), so batches of one block each
#: would cost the chunks more than the two-block buffers do.
SEGMENT_BATCH = 1 << 17


@dataclass(frozen=True)
class WelchPart:
    """A stretch's Welch power sums: Σ |X|² per channel and bin over its ``n_seg``
    segments (what ``WelchAccumulator`` adds up; no samples)."""

    power: NDArray[np.float64]
    n_seg: int


class WelchAccumulator:
    """Streaming Welch PSD (Hann window, 50 % overlap, mean removed per segment), one-sided
    density in (unit)²/Hz. Memory: one segment per channel, and the segments of one block
    while it is transformed."""

    def __init__(self, n_channels: int, rate_hz: float, nperseg: int) -> None:
        if int(nperseg) < 2 or int(nperseg) % 2:
            # 50 % overlap and the segment means from half-segment sums need an even length
            raise DataError(f"Welch segment of {nperseg} samples: use an even length ≥ 2")
        self.c = n_channels
        self.rate = float(rate_hz)
        self.L = int(nperseg)
        self.win = np.hanning(self.L + 1)[:-1]  # periodic Hann
        self.scale = 1.0 / (self.rate * np.sum(self.win**2))
        # The segment mean is removed in the spectrum: a periodic Hann window's transform is
        # nonzero only at bins 0 and ±1, so (x − μ)·w and x·w transform alike except there,
        # by μ·W₀ and μ·W₁ (one pass fewer over every sample than subtracting μ first).
        self._w01 = np.fft.rfft(self.win)[:2].real.copy()
        self._power = np.zeros((n_channels, self.L // 2 + 1))  # Σ |X|² per channel and bin
        self.n_seg = 0
        # channel-major samples not yet in a full segment, then the block: each sample is
        # transposed once, and every segment is a contiguous row of it
        self._cm = np.zeros((n_channels, 0))
        self._held = 0
        self._ref: NDArray[np.float64] | None = None

    def update(self, block: NDArray) -> None:
        a = np.asarray(block, dtype=float).reshape(-1, self.c)
        if len(a) == 0:
            return
        if self._ref is None:
            # a per-channel constant (the first sample) taken off every sample: the segment
            # means to remove are then the signal's wander, not 9.81 m/s² of gravity
            self._ref = a[0].copy()
        held, total = self._held, self._held + len(a)
        if self._cm.shape[1] < total:
            grown = np.empty((self.c, max(total, 2 * self._cm.shape[1])))
            grown[:, :held] = self._cm[:, :held]
            self._cm = grown
        np.subtract(a.T, self._ref[:, None], out=self._cm[:, held:total])
        step = self.L // 2
        k = (total - self.L) // step + 1 if total >= self.L else 0
        # the block's segments in batches, each the most a block of SEGMENT_BATCH new
        # samples brings (a longer block's would otherwise all sit in the transform buffers)
        batch = SEGMENT_BATCH // step + 1
        for b in range(0, k, batch):
            self._segments(b * step, min(batch, k - b))
        # the samples of the next, still incomplete segment move to the front
        rest = total - k * step
        if k > 0:
            self._cm[:, :rest] = self._cm[:, k * step:total]
        self._held = rest

    def _segments(self, first: int, k: int) -> None:
        """The power of the k segments starting at sample ``first`` of the channel-major
        buffer, added up."""
        step = self.L // 2
        if k > 0:
            # the segments at once (k, C, L), strided over the channel-major
            # buffer: one window product, one batched FFT per block (contiguous rows into
            # reused buffers: a transform of fresh, page-faulted memory or of one segment at
            # a time measured twice as slow)
            cm = self._cm[:, first:]
            rows, cols = cm.strides
            segs = np.lib.stride_tricks.as_strided(cm, (k, self.c, self.L),
                                                   (step * cols, rows, cols), writeable=False)
            nf = self.L // 2 + 1
            seg = scratch("welch.seg", k * self.c, self.L, np.float64).reshape(k, self.c, -1)
            np.multiply(segs, self.win, out=seg)
            spec = scratch("welch.spec", k * self.c, nf, np.complex128).reshape(k, self.c, -1)
            np.fft.rfft(seg, axis=2, out=spec)
            # segment means from half-segment sums (each sample summed once, not twice)
            halves = cm[:, :(k + 1) * step].reshape(self.c, k + 1, step).sum(axis=2)
            mean = ((halves[:, :-1] + halves[:, 1:]) / self.L).T  # (k, C)
            spec[:, :, 0] -= mean * self._w01[0]
            spec[:, :, 1] -= mean * self._w01[1]
            kern = kernels.compiled()
            if kern is not None:  # Σ over the segments of re² + im², one pass
                kern.power_sum(spec.reshape(-1).view(np.float64), k, self._power.reshape(-1))
            else:
                parts = spec.view(np.float64)  # (k, C, 2F): re, im pairs
                np.square(parts, out=parts)
                self._power += parts.sum(axis=0).reshape(self.c, nf, 2).sum(axis=2)
            self.n_seg += k

    def gap(self) -> None:
        """A break in the data: the partial segment is dropped, none spans the gap."""
        self._held = 0

    def part(self) -> WelchPart:
        """The segments' power sums so far (a chunk's share of an exact parallel analysis)."""
        return WelchPart(self._power.copy(), self.n_seg)

    def add(self, part: WelchPart) -> None:
        """Add the segments of another stretch of the same channels (``part()`` of an
        accumulator at the same rate and segment length)."""
        if part.power.shape != self._power.shape:
            raise DataError(f"a Welch part of shape {part.power.shape} does not add to "
                            f"{self._power.shape}")
        self._power += part.power
        self.n_seg += part.n_seg

    def result(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(f in Hz, PSD (F, C)); empty when no full segment was seen."""
        f = np.fft.rfftfreq(self.L, 1.0 / self.rate).astype(np.float64, copy=False)
        if self.n_seg == 0:
            return f, np.full((len(f), self.c), np.nan)
        psd: NDArray[np.float64] = self._power.T / self.n_seg * self.scale
        psd[1:-1] *= 2.0  # one-sided
        return f, psd


#: Bins each side of a line's main lobe (Hann) and the running-median half width.
LINE_LOBE, LINE_HALF_WIDTH = 2, 32


def welch_nperseg(total: int | None) -> int:
    """analyze's Welch segment: 16384 samples (≈ 0.008 Hz at 125 Hz), fewer for short
    records so that there are ≥ 8 segments."""
    return 1 << 14 if total is None else min(1 << 14, 1 << int(math.log2(total / 8)))


def line_threshold(n_bins: int, n_seg: float, n_bg: NDArray | float, p_false: float = 0.01
                   ) -> NDArray[np.float64]:
    """The bin/background ratio a line must exceed (``find_lines``' test): bins are
    χ²(ν)/ν with ν ≈ 1.8·segments, the background a median of ``n_bg`` bins carrying about
    2/π of their degrees of freedom, so the ratio is F(ν, ν_bg); Bonferroni over ``n_bins``
    keeps one false line per spectrum at ``p_false``."""
    from avard.core.allan.beta import f_isf_array  # not scipy: see the note above

    nu = max(2.0, 1.8 * n_seg)
    nu_bg = np.maximum(2.0, np.asarray(n_bg, dtype=float) * nu * 2.0 / math.pi)
    # the F(ν, ν_bg) upper quantile
    return f_isf_array(p_false / n_bins, nu, nu_bg)


#: Rebinnings (adjacent bins averaged) at which a second search looks for a disturbance whose
#: power is spread over a band wider than the fine search's background window (a pump swept
#: over many bins raises that window's median as much as the bin it tests, so no bin of the
#: band stands out) — the coarser spectrum's window reaches the background outside the band.
BROAD_REBIN = (8, 64)
#: The share of the false-line probability each broad rebinning is given (the fine search
#: keeps all of its own: its lines are the ones the rest of avard models).
BROAD_P_SHARE = 0.1


def hann_neighbour_factor(m: int) -> float:
    """How many times the variance of a mean of m adjacent bins of a Hann-windowed
    periodogram exceeds that of m independent ones: the window's spectral kernel is
    (−¼, ½, −¼), so a bin's Fourier amplitude correlates −2/3 with its neighbour's and 1/6
    with the next one's, and their powers 4/9 and 1/36 (a mean of m bins has the degrees
    of freedom of m over this many independent bins: 1.82 at m = 8, 1.94 for large m)."""
    return 1.0 + 2.0 * (4.0 / 9.0) * (m - 1) / m + 2.0 * (1.0 / 36.0) * max(m - 2, 0) / m


def find_lines(f: NDArray, psd: NDArray, n_seg: float, *, p_false: float = 0.01,
               max_lines: int = 8, half_width: int = LINE_HALF_WIDTH
               ) -> list[dict[str, float]]:
    """Sinusoids in a Welch PSD of one channel: bins standing above the local background by
    more than chance allows.

    Background: the median of the bins within ±``half_width`` of each bin, leaving out the
    bin's own main lobe (±2 bins), divided by the median/mean ratio of the averaged
    periodogram's χ² distribution. The window is always symmetric: near 0 Hz it shrinks to
    the bins available on both sides (DC excluded). A one-sided or padded window there is
    biased low on a red spectrum (flicker, random walk), and with thousands of averaged
    segments that bias alone passes the test: a 60 h record's 1/f rise at 0.05 Hz read as two
    lines; at Nyquist the un-doubled last bin does the same. The median of a symmetric window
    is unbiased for any monotonic background. Bins with fewer than 4 background bins on each
    side are not tested (the lowest and highest 7).
    Test: each bin is χ²(ν)/ν × background with ν ≈ 1.8·segments (Hann, 50 % overlap; Welch
    1967), the background an estimate with ≈ (2/π)·ν per bin it is the median of, so the
    ratio is F(ν, ν_bg)-distributed; the threshold keeps the chance of one false line per
    spectrum at ``p_false`` (Bonferroni over the bins). Beside it a broad search
    (``_broad_lines``, ``BROAD_REBIN``) finds a disturbance swept over more bins than the
    window, at ``BROAD_P_SHARE`` of ``p_false`` per rebinning (so 1.2·``p_false`` in all).
    Amplitude: A = √(2P), P = Σ (PSD − background)·Δf over the main lobe (±2 bins).
    Returns up to ``max_lines`` lines {"frequency_hz", "amplitude"} (m/s² for
    acceleration), strongest first.
    """
    if n_seg < 2 or len(f) < 4 * half_width or not np.all(np.isfinite(psd)):
        return []
    lines = _find_at(f, psd, n_seg, p_false, half_width)
    lines += _broad_lines(f, psd, n_seg, p_false, half_width, lines)
    lines.sort(key=lambda d: -d["amplitude"])
    for ln in lines:
        del ln["bin"]
    return lines[:max_lines]


def _find_at(f: NDArray, psd: NDArray, n_seg: float, p_false: float, half_width: int
             ) -> list[dict[str, float]]:
    """``find_lines``' search at the spectrum's own resolution (which checks the spectrum
    is long enough, averaged and finite): the lines with their group marks (``_group``) and
    the bin each was found at."""
    lobe, min_side = LINE_LOBE, 4
    from avard.core.allan.chi2 import chi2_ppf

    nu = max(2.0, 1.8 * n_seg)
    med_ratio = float(chi2_ppf(0.5, nu)) / nu
    ring = np.ones(2 * half_width + 1, dtype=bool)
    ring[half_width - lobe:half_width + lobe + 1] = False
    # median of the ring around every bin whose full window fits (np.median averages the two
    # middle values of the even count; a single rank would be biased on a sloping spectrum)
    bg = np.full(len(f), np.nan)
    win = np.lib.stride_tricks.sliding_window_view(psd, 2 * half_width + 1)
    bg[half_width:len(f) - half_width] = np.median(win[:, ring], axis=1)
    n_bg = np.full(len(f), 2.0 * (half_width - lobe))
    # bins near either end: the widest symmetric window that fits between the bin and DC or
    # Nyquist (both excluded: DC is emptied by the mean removal, Nyquist is not doubled)
    first = lobe + min_side + 1
    last = len(f) - 1 - first
    for k in [*range(first, half_width + 1), *range(len(f) - 1 - half_width, last + 1)]:
        w = min(k - 1, len(f) - 2 - k, half_width)
        sides = np.r_[psd[k - w:k - lobe], psd[k + lobe + 1:k + w + 1]]
        bg[k] = np.median(sides)
        n_bg[k] = len(sides)
    bg[:first] = bg[first]          # only used for the main lobe of a line at the first bin
    bg[last + 1:] = bg[last]
    bg /= med_ratio
    # The background is itself an estimate: a median of n_bg bins carries about 2/π of their
    # degrees of freedom, so bin/background is F(ν, ν_bg)-distributed, not χ²(ν)/ν. That
    # matters where the window is short (low bins) and few segments were averaged.
    thr = line_threshold(len(f), n_seg, n_bg, p_false)
    ratio = psd / np.where(bg > 0, bg, np.inf)
    df = f[1] - f[0]
    lines = []
    k = first
    while k <= last:
        if ratio[k] > thr[k] and ratio[k] >= ratio[k - 1] and ratio[k] >= ratio[k + 1]:
            sl = slice(k - 2, k + 3)
            excess = np.clip(psd[sl] - bg[sl], 0.0, None)
            power = float(np.sum(excess) * df)
            if power > 0:
                freq = float(np.sum(excess * f[sl]) / np.sum(excess))
                lo, hi = _amplitude_interval(power, excess, bg[sl], nu, df)
                lines.append({"frequency_hz": freq, "amplitude": math.sqrt(2.0 * power),
                              "amplitude_lo": lo, "amplitude_hi": hi, "bin": float(k)})
            k += 3
        else:
            k += 1
    _group(lines, f, psd, nu, med_ratio)
    return lines


def _side_background(psd: NDArray, k1: int, k2: int, med_ratio: float) -> float:
    """The mean background level under a band [k1, k2) of bins: the median of as many bins
    again (at least ``WIDE_HALF_WIDTH``) either side of it, DC and Nyquist left out, over
    the median/mean ratio of a bin's χ²(ν)/ν. A window centred on the band would hold the
    band itself, whose raised bins lift its median (a band of a third of the window read
    the amplitude a few % low)."""
    w = max(k2 - k1, WIDE_HALF_WIDTH)
    side = np.r_[psd[max(1, k1 - w):max(1, k1)], psd[min(len(psd) - 1, k2):
                                                     min(len(psd) - 1, k2 + w)]]
    if len(side) == 0:
        return math.nan
    return float(np.median(side)) / med_ratio


def _band_edges(f: NDArray, psd: NDArray, lo_hz: float, hi_hz: float, m: int,
                med_ratio: float) -> tuple[float, float, float]:
    """A broad disturbance's band on the fine spectrum and the background beside it
    (``_side_background``): where the PSD's running mean over ``m`` bins crosses half way
    from the background to the band's mean level. The coarse bins place the edges only to
    within one of them, and a band swept at a steady rate is flat, so its half-level points
    are its ends."""
    df = float(f[1] - f[0])
    k_lo = max(1, int(np.searchsorted(f, lo_hz)) - m)
    k_hi = min(len(f) - 1, int(np.searchsorted(f, hi_hz)) + m)
    bg = _side_background(psd, k_lo, k_hi, med_ratio)
    inner = psd[int(np.searchsorted(f, lo_hz)):int(np.searchsorted(f, hi_hz)) + 1]
    level = float(np.mean(inner)) if len(inner) else bg
    if k_hi - k_lo < 2 * m or not level > bg:
        return lo_hz, hi_hz, bg
    run = np.convolve(psd[k_lo:k_hi], np.ones(m) / m, mode="same")
    above = np.flatnonzero(run > bg + 0.5 * (level - bg))
    if len(above) == 0:
        return lo_hz, hi_hz, bg
    return float(f[k_lo + above[0]] - 0.5 * df), float(f[k_lo + above[-1]] + 0.5 * df), bg


def _broad_lines(f: NDArray, psd: NDArray, n_seg: float, p_false: float, half_width: int,
                 fine: list[dict[str, float]]) -> list[dict[str, float]]:
    """Disturbances spread over more bins than the fine search's window sees: the search of
    ``_find_at`` on the spectrum averaged over ``BROAD_REBIN`` adjacent bins (DC and Nyquist
    left out), degrees of freedom scaled by m / ``hann_neighbour_factor(m)``, each rebinning at
    ``BROAD_P_SHARE`` of the false-line probability. A broad group is kept only where no line
    of a finer search lies within its band (or main lobe): what the fine search found it
    describes better. Each kept group is one line of its own: a drifting disturbance over
    the band it raises (``_band_edges``), its amplitude from the band's whole power above
    the background on the fine spectrum (the coarse lines' lobes would count the band's
    power in pieces, each a little high)."""
    out: list[dict[str, float]] = []
    taken: list[tuple[float, float]] = []
    for ln in fine:
        lo_hz, hi_hz = ln.get("band_lo_hz", math.nan), ln.get("band_hi_hz", math.nan)
        if not (math.isfinite(lo_hz) and math.isfinite(hi_hz)):
            lo_hz = hi_hz = ln["frequency_hz"]
        taken.append((lo_hz, hi_hz))
    from avard.core.allan.chi2 import chi2_ppf

    df = float(f[1] - f[0])
    nu = max(2.0, 1.8 * n_seg)
    med_ratio = float(chi2_ppf(0.5, nu)) / nu
    group_base = 1000.0   # each rebinning's groups apart from the fine search's and each other
    for m in BROAD_REBIN:
        n_c = (len(f) - 2) // m
        if n_c < 4 * half_width:
            break
        sl = slice(1, 1 + n_c * m)
        f_c = f[sl].reshape(n_c, m).mean(axis=1)
        psd_c = psd[sl].reshape(n_c, m).mean(axis=1)
        found = _find_at(f_c, psd_c, n_seg * m / hann_neighbour_factor(m), p_false * BROAD_P_SHARE,
                         half_width)
        df_c = float(f_c[1] - f_c[0])
        # one broad line per cluster of the coarse search (a band, or a line), keeping the
        # coarse grouping's marks: a swept fundamental and its swept harmonic are two bands
        # of one disturbance, not one band over both
        by: dict[tuple[float, float], list[dict[str, float]]] = {}
        for ln in found:
            by.setdefault((ln["group"], ln["group_frequency_hz"]), []).append(ln)
        for members in by.values():
            lo_hz = min(ln["band_lo_hz"] if math.isfinite(ln["band_lo_hz"])
                        else ln["frequency_hz"] - LINE_LOBE * df_c for ln in members)
            hi_hz = max(ln["band_hi_hz"] if math.isfinite(ln["band_hi_hz"])
                        else ln["frequency_hz"] + LINE_LOBE * df_c for ln in members)
            if any(a <= hi_hz + df_c and b >= lo_hz - df_c for a, b in taken):
                continue
            lo_hz, hi_hz, bg = _band_edges(f, psd, lo_hz, hi_hz, m, med_ratio)
            taken.append((lo_hz, hi_hz))
            k1 = max(1, int(np.searchsorted(f, lo_hz)) - LINE_LOBE)
            k2 = min(len(f) - 1, int(np.searchsorted(f, hi_hz)) + LINE_LOBE + 1)
            if not math.isfinite(bg) or k2 <= k1:
                continue
            raised = psd[k1:k2] - bg
            power = max(float(np.sum(raised)) * df, 0.0)
            excess = np.clip(raised, 0.0, None)
            if power <= 0 or not np.sum(excess) > 0:
                continue
            a_lo, a_hi = _amplitude_interval(power, excess, np.full(len(excess), bg), nu, df)
            fc = float(np.sum(excess * f[k1:k2]) / np.sum(excess))
            a = math.sqrt(2.0 * power)
            out.append({"frequency_hz": fc, "amplitude": a, "amplitude_lo": a_lo,
                        "amplitude_hi": a_hi, "bin": 0.0, "group": group_base + members[0]["group"],
                        "harmonic": members[0]["harmonic"],
                        "modulation_hz": members[0]["modulation_hz"],
                        "group_frequency_hz": fc, "group_amplitude": a,
                        "group_amplitude_lo": a_lo, "group_amplitude_hi": a_hi,
                        "band_lo_hz": lo_hz, "band_hi_hz": hi_hz,
                        "sweep_lo_hz": lo_hz, "sweep_hi_hz": hi_hz,
                        "members": float(len(members))})
        group_base += 1000.0
    return out


#: Neighbouring Hann bins share about half their noise: the variance of a sum over a line's
#: main lobe is this many times the sum of the bins' variances.
LOBE_CORRELATION = 2.0


def _amplitude_interval(power: float, excess: NDArray, bg: NDArray, nu: float, df: float
                        ) -> tuple[float, float]:
    """68 % interval of a line's amplitude √(2P) from the variance of its power P = Σ
    excess·Δf over the main lobe: a bin of the averaged periodogram holding a line of power
    density e over noise b has variance (b² + 2·e·b)·2/ν (the noise alone, and its product
    with the line), the lobe's bins correlated (``LOBE_CORRELATION``)."""
    var = float(np.sum((bg**2 + 2.0 * excess * bg) * 2.0 / nu)) * LOBE_CORRELATION * df**2
    sd = math.sqrt(max(var, 0.0))
    return math.sqrt(2.0 * max(power - sd, 0.0)), math.sqrt(2.0 * (power + sd))


#: The most harmonics of a fundamental looked for, and how near (bins, times the harmonic's
#: number for a drifting fundamental's spread) a line must be to count as one.
MAX_HARMONIC, HARMONIC_TOL_BINS = 10, 2.5
#: Bins either side of a line left out when asking whether the PSD between two lines is raised
#: (a drifting line): the main lobe and the first skirt of the Hann window.
LEAK_BINS = LINE_LOBE + 4
#: The wide background a drifting line's band is measured against: ±this many bins.
WIDE_HALF_WIDTH = 8 * LINE_HALF_WIDTH


@dataclass(frozen=True)
class LineGroup:
    """One periodic disturbance: a line with its harmonics and sidebands, or a drifting line
    (its power spread over a band). ``frequency_hz``: the fundamental (a drifting one: the
    power-weighted centre of its band); ``amplitude`` (m/s² for acceleration) with its 68 %
    interval: the fundamental's, or for a drifting line the amplitude of its whole band's
    power; ``band_hz``: where a drifting line's power lies (None for a steady one);
    ``harmonics``: the harmonic numbers found (1 the fundamental); ``modulation_hz``: the
    sidebands' offset (None without sidebands); ``members``: how many lines of the finder
    it gathers."""

    frequency_hz: float
    amplitude: float
    amplitude_lo: float
    amplitude_hi: float
    band_hz: tuple[float, float] | None
    harmonics: tuple[int, ...]
    modulation_hz: float | None
    members: int

    @property
    def kind(self) -> str:
        parts = []
        if self.band_hz is not None:
            parts.append("drifting")
        if len(self.harmonics) > 1:
            parts.append("with harmonics")
        if self.modulation_hz is not None:
            parts.append("modulated")
        return ", ".join(parts) or "steady line"


#: Bins per step when a drifting line's band is grown outwards from a line.
BAND_STEP = 8


def _hann_skirt(x: float) -> float:
    """Power of a periodic-Hann-windowed line x bins from it, relative to its peak (at worst,
    the line between bins): (sinc(x)/(1 − x²))²."""
    return (math.sin(math.pi * x) / (math.pi * x * (1.0 - x * x))) ** 2 if x > 1 else 1.0


def _band(k: int, psd: NDArray, wide: Callable[[int], float], thr: float
          ) -> tuple[int, int] | None:
    """The bins [lo, hi] over which the line at bin k's power spreads (a drifting line), or
    None for a steady one: outwards from where the Hann skirt of a steady line this strong
    falls below 5 % of the background, steps of ``BAND_STEP`` bins whose mean stays above
    ``thr`` times the wide background; a band needs a whole step raised on one side."""
    peak = psd[k] / max(wide(k), 1e-300)
    x0 = LEAK_BINS
    while x0 < 4 * WIDE_HALF_WIDTH and peak * _hann_skirt(x0 + 0.5) > 0.05:
        x0 += 1
    hi = k + x0
    while hi + BAND_STEP < len(psd) - 1 and float(
            np.mean(psd[hi + 1:hi + 1 + BAND_STEP])) > thr * wide(hi + BAND_STEP // 2):
        hi += BAND_STEP
    lo = k - x0
    while lo - BAND_STEP > 1 and float(
            np.mean(psd[lo - BAND_STEP:lo])) > thr * wide(lo - BAND_STEP // 2):
        lo -= BAND_STEP
    if hi == k + x0 and lo == k - x0:
        return None
    return (lo if lo < k - x0 else k, hi if hi > k + x0 else k)


def _group(lines: list[dict[str, float]], f: NDArray, psd: NDArray, nu: float,
           med_ratio: float) -> None:
    """Mark which lines are one periodic disturbance (``line_groups`` reads the marks back).

    1. Drifting: a line whose PSD stays raised beyond its Hann skirt (``_band``), and
       neighbouring lines whose PSD between them (``LEAK_BINS`` clear of each) stays above the
       wide
       background (median of ±``WIDE_HALF_WIDTH`` bins) by 3 standard errors of a mean of
       those bins are one line moving over a band; its amplitude is that of the band's
       power above the wide background.
    2. Harmonics: from the lowest frequency up, a line (or band) with found lines at k·f
       (k ≤ ``MAX_HARMONIC``, within ``HARMONIC_TOL_BINS``·k bins, wider by a band's spread).
    3. Sidebands: two lines at fc ± fm, equally far within the same tolerance, around a
       line or harmonic already placed, are its modulation; then a lone line at ±fm of a
       member of a group with that modulation is one of its sidebands."""
    if not lines:
        return
    df = float(f[1] - f[0])
    order = sorted(range(len(lines)), key=lambda i: lines[i]["bin"])
    wide_cache: dict[int, float] = {}

    def wide(k: int) -> float:
        if k not in wide_cache:
            lo, hi = max(1, k - WIDE_HALF_WIDTH), min(len(psd) - 1, k + WIDE_HALF_WIDTH + 1)
            wide_cache[k] = float(np.median(psd[lo:hi])) / med_ratio
        return wide_cache[k]

    # 1. drifting bands: each line's band (``_band``), lines inside one band together, and
    # neighbours whose PSD between them stays raised
    thr8 = 1.0 + 3.0 * math.sqrt(2.0 / (nu * BAND_STEP))
    bands = {i: _band(int(lines[i]["bin"]), psd, wide, thr8) for i in order}
    clusters: list[list[int]] = []
    spans: list[tuple[int, int] | None] = []
    for i in order:
        k = int(lines[i]["bin"])
        if clusters:
            j = clusters[-1][-1]
            k1 = int(lines[j]["bin"])
            span = spans[-1]
            # clear of both lines' main lobes and near leakage: a strong steady line's
            # Hann skirt would otherwise join it to a sideband a few bins away
            between = psd[k1 + LEAK_BINS + 1:k - LEAK_BINS]
            m = len(between)
            own = bands[i]
            # either band holds the other's line: a later line's band grown back over an
            # earlier line (a pump swept over 0.02 Hz was a drifting line and, inside its
            # band, a "steady" one)
            joined = (span is not None and span[0] <= k <= span[1]) or (
                own is not None and own[0] <= k1) or (
                m > 0 and float(np.mean(between))
                > wide((k1 + k) // 2) * (1.0 + 3.0 * math.sqrt(2.0 / (nu * m))))
            if joined:
                clusters[-1].append(i)
                lo_k = min(x for x in (span[0] if span else k1, own[0] if own else k))
                hi_k = max(x for x in (span[1] if span else k, own[1] if own else k))
                spans[-1] = (lo_k, hi_k)
                continue
        clusters.append([i])
        spans.append(bands[i])
    reps: list[dict[str, float]] = []
    for c, span in zip(clusters, spans, strict=True):
        if span is None and len(c) == 1:
            ln = lines[c[0]]
            reps.append({"f": ln["frequency_hz"], "a": ln["amplitude"], "lo": ln["amplitude_lo"],
                         "hi": ln["amplitude_hi"], "spread": 0.0, "band_lo": math.nan,
                         "band_hi": math.nan, "members": 1.0})
            continue
        k1 = min(int(lines[c[0]]["bin"]) - LINE_LOBE, span[0] if span else len(psd))
        k2 = max(int(lines[c[-1]]["bin"]) + LINE_LOBE, span[1] if span else 0) + 1
        b = _side_background(psd, k1, k2, med_ratio)
        if not math.isfinite(b):
            b = wide((k1 + k2) // 2)
        excess = np.clip(psd[k1:k2] - b, 0.0, None)
        power = max(float(np.sum(psd[k1:k2] - b)) * df, 0.0)
        lo, hi = _amplitude_interval(power, excess, np.full(len(excess), b), nu, df)
        fc = float(np.sum(excess * f[k1:k2]) / max(np.sum(excess), 1e-300))
        reps.append({"f": fc, "a": math.sqrt(2.0 * power), "lo": lo, "hi": hi,
                     "spread": float(f[k2 - 1] - f[k1]) / 2.0,
                     "band_lo": float(f[k1 + LINE_LOBE]),
                     "band_hi": float(f[k2 - 1 - LINE_LOBE]), "members": float(len(c))})
    # 2. harmonics, 3. sidebands: over the representatives, lowest frequency first
    group = [-1] * len(reps)
    role = [0.0] * len(reps)
    n_groups = 0
    for i, r in enumerate(reps):
        if group[i] >= 0:
            continue
        group[i], role[i] = n_groups, 1.0
        for k in range(2, MAX_HARMONIC + 1):
            tol = HARMONIC_TOL_BINS * df * k + k * r["spread"]
            near = [j for j in range(len(reps)) if group[j] < 0
                    and abs(reps[j]["f"] - k * r["f"]) <= tol]
            if near:
                j = min(near, key=lambda j: abs(reps[j]["f"] - k * r["f"]))
                group[j], role[j] = n_groups, float(k)
        n_groups += 1
    mod: dict[int, list[float]] = {}
    for ctr in [i for i in range(len(reps)) if role[i] >= 1]:
        fc = reps[ctr]["f"]
        free = [j for j in range(len(reps)) if role[j] == 1.0 and group[j] != group[ctr]
                and sum(group[x] == group[j] for x in range(len(reps))) == 1]
        tol = HARMONIC_TOL_BINS * df
        for lo_j in [j for j in free if reps[j]["f"] < fc]:
            fm = fc - reps[lo_j]["f"]
            ups = [j for j in free if j != lo_j and abs(reps[j]["f"] - fc - fm) <= tol]
            if ups and role[lo_j] == 1.0:
                up = ups[0]
                for j in (lo_j, up):
                    group[j], role[j] = group[ctr], -1.0
                mod.setdefault(group[ctr], []).append(0.5 * (fm + reps[up]["f"] - fc))
                free = [j for j in free if j not in (lo_j, up)]
    # a lone sideband (its partner below the finder's threshold) at a known modulation's
    # offset from a member of that group
    for j in range(len(reps)):
        if role[j] != 1.0 or sum(group[x] == group[j] for x in range(len(reps))) != 1:
            continue
        for g_id, fms in mod.items():
            fm = float(np.mean(fms))
            if any(role[c] >= 1 and group[c] == g_id
                   and abs(abs(reps[j]["f"] - reps[c]["f"]) - fm) <= HARMONIC_TOL_BINS * df
                   for c in range(len(reps))):
                group[j], role[j] = g_id, -1.0
                break
    # the marks, on every line of a representative
    for ci, c in enumerate(clusters):
        for i in c:
            lines[i]["group"] = float(group[ci])
            lines[i]["harmonic"] = role[ci]
            lines[i]["modulation_hz"] = float(np.mean(mod[group[ci]])) if group[ci] in mod \
                else 0.0
            r = reps[ci]
            lines[i].update({"group_frequency_hz": r["f"], "group_amplitude": r["a"],
                             "group_amplitude_lo": r["lo"], "group_amplitude_hi": r["hi"],
                             "band_lo_hz": r["band_lo"], "band_hi_hz": r["band_hi"],
                             "members": r["members"]})


def line_groups(lines: list[dict[str, float]]) -> list[LineGroup]:
    """The periodic disturbances of a channel from ``find_lines``' marks: one per group, its
    fundamental (harmonic 1) giving frequency and amplitude; strongest first. Lines without
    marks (found before the grouping existed) are one group each."""
    by: dict[float, list[dict[str, float]]] = {}
    for n, ln in enumerate(lines):
        by.setdefault(ln.get("group", -1.0 - n), []).append(ln)
    out = []
    for members in by.values():
        fund = [m for m in members if m.get("harmonic", 1.0) == 1.0] or members
        m0 = fund[0]
        a = m0.get("group_amplitude", m0["amplitude"])
        band = (m0.get("band_lo_hz", math.nan), m0.get("band_hi_hz", math.nan))
        harm = sorted({int(m.get("harmonic", 1.0)) for m in members
                       if m.get("harmonic", 1.0) >= 1.0})
        fm = m0.get("modulation_hz", 0.0)
        out.append(LineGroup(
            m0.get("group_frequency_hz", m0["frequency_hz"]), a,
            m0.get("group_amplitude_lo", m0.get("amplitude_lo", math.nan)),
            m0.get("group_amplitude_hi", m0.get("amplitude_hi", math.nan)),
            band if all(math.isfinite(x) for x in band) else None, tuple(harm),
            fm if fm > 0 else None, len(members)))
    out.sort(key=lambda g: -g.amplitude)
    return out


def line_components(lines: list[dict[str, float]]) -> list[dict[str, float]]:
    """The lines of ``find_lines`` as the sinusoid components a fit models: each line the
    finder placed as a steady line at its frequency, and the power of a drifting
    disturbance that its lines do not hold as one line swept over its band
    (``sweep_lo_hz``/``sweep_hi_hz``, ``terms.swept_sinusoid_avar``). A line of the broad
    search is all band. The finder's lines inside a band hold only their main lobes' share
    of its power; the rest, modelled by nobody, went to the noise terms (a quantization
    term made of a swept pump). It is added only where it exceeds the standard error of
    the band's power: a wandering line whose power stays in its lobe (a real ADIS16405's
    0.56 Hz) is its lines, not a sweep."""
    out: list[dict[str, float]] = []
    clusters: dict[tuple[float, float], list[dict[str, float]]] = {}
    for ln in lines:
        lo, hi = ln.get("band_lo_hz", math.nan), ln.get("band_hi_hz", math.nan)
        if "sweep_lo_hz" in ln:
            out.append({k: ln[k] for k in ("frequency_hz", "amplitude", "sweep_lo_hz",
                                           "sweep_hi_hz")})
            continue
        out.append(dict(ln))
        if math.isfinite(lo) and math.isfinite(hi) and lo < hi:
            key = (ln.get("group", math.nan), ln.get("group_frequency_hz", math.nan))
            clusters.setdefault(key, []).append(ln)
    for members in clusters.values():
        m0 = members[0]
        a, a_lo, a_hi = (m0.get("group_amplitude", math.nan),
                         m0.get("group_amplitude_lo", math.nan),
                         m0.get("group_amplitude_hi", math.nan))
        rest = 0.5 * a * a - sum(0.5 * ln["amplitude"] ** 2 for ln in members)
        se = 0.25 * (a_hi * a_hi - a_lo * a_lo)
        if math.isfinite(rest) and math.isfinite(se) and rest > se:
            out.append({"frequency_hz": m0["group_frequency_hz"],
                        "amplitude": math.sqrt(2.0 * rest),
                        "sweep_lo_hz": m0["band_lo_hz"], "sweep_hi_hz": m0["band_hi_hz"]})
    return out
