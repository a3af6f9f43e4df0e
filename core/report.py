"""``avard analyze`` as a library: stream a record, fit every channel, and write it out.

A pass over the data (``readers.iter_blocks``) feeds two bounded-memory accumulators per
channel: the fully overlapping Allan variance (``overlapping.OverlappingAllan``, OADEV as
Stable32 and allantools compute it, NIST SP 1065 eq. 12, at octave τ; memory a ring of 2·m_max
running-sum points) and a Welch spectrum used to find sinusoids. A file long enough that the
rings of all its channels would exceed ``PASS_BUDGET_BYTES`` is read once per group of
channels that fit (``oadev_pass_groups``), so only one group's rings are live; the OADEV
then leaves R(n) out and reads a channel again for it only where B1 needs it.
``estimator="cascade"`` gives the service's streaming cascade instead
(``streaming.StreamingAllan``, stride m/8 above m = 8: partially overlapping, a different
estimator with ≥ 98 % of the OADEV's EDF).
Lines found in the spectrum enter the noise fit as fixed components (their
amplitude is measured far more precisely by the spectrum than by the AVAR bump), so they do
not bias N, B or K; then ``fit.fit_noise`` fits the IEEE terms.

Outputs: a text table, the ``--json`` dictionary (shape fixed by issue 4), a kalibr IMU yaml
(written by hand: no yaml dependency) and a csv of the ADEV table. All values SI.
"""

from __future__ import annotations

import itertools
import logging
import math
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core.allan import kernels
from avard.core.allan.noise_id import check_noise_id
from avard.core.allan.scratch import scratch
from avard.core.blas import one_blas_thread
from avard.core.errors import DataError, FitError
from avard.core.io.readers import iter_blocks, load_record
from avard.core.model.terms import SYMBOLS, TERMS, UNITS
from numpy.typing import NDArray

if TYPE_CHECKING:
    from avard.core.allan.overlapping import OverlappingAllan
    from avard.core.model.fit import NoiseFit

# analyze of a file does not import scipy: the line threshold's F quantile and the p-value's
# χ² tail come from core/allan/beta.py and chi2.py (scipy.special cost 0.1–0.2 CPU-s of every
# analyze, ~1 s on a Pi), and the chip filter's model (an ADXL355 record's) from the
# simulator's numpy Butterworth (model.terms._butterworth; scipy.signal was 0.5 CPU-s and
# ~70 MB). What still needs scipy (--psd's intervals) imports it where it is used, after the
# pass over the data: loaded before the pass it would sit under the OADEV's history at the
# peak (measured 190 → 129 MB peak for a 60 h, 3-axis analyze).

__all__ = ["Analysis", "ChannelAnalysis", "WelchAccumulator", "analyze", "analyze_stream",
           "find_lines", "psd_csv"]

ProgressFn = Callable[[int, int | None], None]

log = logging.getLogger(__name__)

#: Estimator names as they appear in the table, the JSON and the csv.
ESTIMATORS = {
    "oadev": "fully overlapping ADEV (OADEV, NIST SP 1065 eq. 12; Stable32 'Overlapping Allan')",
    "cascade": "partially overlapping ADEV (stride m/8 above m = 8; avard's streaming cascade)",
}
#: The estimator as a figure's legend names it.
ESTIMATOR_LABELS = {"oadev": "OADEV", "cascade": "cascade ADEV (stride m/8)"}
#: SI unit of each per-τ array of a channel in ``--json`` ("1": dimensionless).
ADEV_UNITS = {"tau_s": "s", "adev": "m/s^2", "adev_lo": "m/s^2", "adev_hi": "m/s^2",
              "edf": "1", "alpha": "1"}
# OADEV τ grid: octaves while the record holds ≥ 4 non-overlapping intervals (Stable32's
# default range), and while the running-sum rings live at once (2·m_max points per channel)
# fit a quarter of the memory available when analyze starts, at least this much. A fixed
# 96 MiB cut a 60 h, 3-axis record two octaves short of N/4, where rate random walk shows.
# ``analyze`` of a file also uses this much as the rings of one pass: channels whose rings
# do not fit it together are read in further passes (one 60 h axis per pass), which keeps the
# whole analysis of such a record at ~1/10 of the memory of allantools' oadev.
RING_BUDGET_BYTES = 96 << 20
# ``analyze`` of a file reads it once per group of channels whose rings fit this together:
# two 60 h axes (68 MB each) per pass, so a 3-axis record is read twice, not three times
# (the R(n) sums that took another 56 MB per axis are computed only where B1 needs them,
# ``OverlappingAllan(defer_rn=True)``). The whole analysis of such a record then peaks at
# ~180 MB, 1/6 of allantools' oadev of the same axes (``python -m benchmarks analyze``).
PASS_BUDGET_BYTES = 144 << 20


def ring_budget_bytes() -> int:
    """Bytes the OADEV's running-sum history may take (see ``RING_BUDGET_BYTES``)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return max(RING_BUDGET_BYTES, int(line.split()[1]) * 1024 // 4)
    except (OSError, ValueError, IndexError):
        pass
    return RING_BUDGET_BYTES


# ---------------------------------------------------------------------------------------------
# spectrum and sinusoid detection


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
        if k > 0:
            # all the block's segments at once (k, C, L), strided over the channel-major
            # buffer: one window product, one batched FFT per block (contiguous rows into
            # reused buffers: a transform of fresh, page-faulted memory or of one segment at
            # a time measured twice as slow)
            cm = self._cm
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
        # the samples of the next, still incomplete segment move to the front
        rest = total - k * step
        if k > 0:
            self._cm[:, :rest] = self._cm[:, k * step:total]
        self._held = rest

    def gap(self) -> None:
        """A break in the data: the partial segment is dropped, none spans the gap."""
        self._held = 0

    def result(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(f in Hz, PSD (F, C)); empty when no full segment was seen."""
        f = np.fft.rfftfreq(self.L, 1.0 / self.rate)
        if self.n_seg == 0:
            return f, np.full((len(f), self.c), np.nan)
        psd = self._power.T / self.n_seg * self.scale
        psd[1:-1] *= 2.0  # one-sided
        return f, psd


#: Bins each side of a line's main lobe (Hann) and the running-median half width.
LINE_LOBE, LINE_HALF_WIDTH = 2, 32


def welch_nperseg(total: int | None) -> int:
    """analyze's Welch segment: 16384 samples (≈ 0.008 Hz at 125 Hz), fewer for short
    records so that there are ≥ 8 segments."""
    return 1 << 14 if total is None else min(1 << 14, 1 << int(math.log2(total / 8)))


def line_threshold(n_bins: int, n_seg: int, n_bg: NDArray | float, p_false: float = 0.01
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


def find_lines(f: NDArray, psd: NDArray, n_seg: int, *, p_false: float = 0.01,
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
    spectrum at ``p_false`` (Bonferroni over the bins). Amplitude: A = √(2P), P = Σ (PSD −
    background)·Δf over the main lobe (±2 bins). Returns up to ``max_lines`` lines
    {"frequency_hz", "amplitude"} (m/s² for acceleration), strongest first.
    """
    lobe, min_side = LINE_LOBE, 4
    if n_seg < 2 or len(f) < 4 * half_width or not np.all(np.isfinite(psd)):
        return []
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
                lines.append({"frequency_hz": freq, "amplitude": math.sqrt(2.0 * power)})
            k += 3
        else:
            k += 1
    lines.sort(key=lambda d: -d["amplitude"])
    return lines[:max_lines]


# ---------------------------------------------------------------------------------------------
# the analysis


@dataclass
class ChannelAnalysis:
    """One channel: its Allan result (AllanResult, one channel), the fit, the lines found."""

    name: str
    allan: Any
    fit: NoiseFit
    lines: list[dict[str, float]] = field(default_factory=list)
    estimator: str = "oadev"
    psd: Any = None  # psd.ChannelPsd when asked for (analyze(psd=True))

    def to_dict(self) -> dict[str, Any]:
        a = self.allan
        d = {"estimator": self.estimator, "tau_s": _list(a.tau), "adev": _list(a.dev),
             "adev_lo": _list(a.dev_lo), "adev_hi": _list(a.dev_hi), "edf": _list(a.edf),
             "alpha": _list(a.alpha), "units": dict(ADEV_UNITS)}
        if getattr(a, "quantiles", "exact") != "exact":  # said only when not the default
            d["quantiles"] = a.quantiles
        if getattr(a, "noise_id", "avard") != "avard":  # the rule behind alpha, likewise
            d["noise_id"] = a.noise_id
        fd = self.fit.to_dict()
        d["terms"] = fd["terms"]
        d["sinusoids"] = [{"frequency_hz": s["frequency_hz"], "amplitude": s["amplitude"]}
                          for s in self.lines]
        d["fit"] = {k: _num(v) for k, v in fd["fit"].items()}
        if self.psd is not None:
            d["psd"] = self.psd.to_dict()
        return d


@dataclass
class Analysis:
    """The whole ``avard analyze`` result: source, rate (Hz), sample count, channels."""

    source: str
    rate_hz: float
    n_samples: int
    channels: dict[str, ChannelAnalysis]
    meta: dict[str, Any] = field(default_factory=dict)
    estimator: str = "oadev"

    def to_dict(self) -> dict[str, Any]:
        """The ``--json`` shape of issue 4 (SI units; NaN written as null)."""
        d = {"source": self.source, "rate_hz": float(self.rate_hz),
             "n_samples": int(self.n_samples), "estimator": self.estimator,
             "estimator_description": ESTIMATORS[self.estimator],
             "channels": {k: c.to_dict() for k, c in self.channels.items()}}
        rec = self.recording_summary()
        if rec is not None:
            d["recording"] = rec
        if "oadev_cut" in self.meta:
            d["oadev_cut"] = self.meta["oadev_cut"]
        return d

    def recording_summary(self) -> dict[str, Any] | None:
        """For a service recording: its segments (split at every gap record and restart),
        gap records, and what damage cost or duplication repeated, in samples (index ranges);
        None for a file."""
        m = self.meta
        if m.get("format") != "recording":
            return None
        return {"segments": int(m.get("n_segments", 1)), "gap_records": len(m.get("gaps", [])),
                "samples_lost": int(m.get("samples_lost", 0)), "losses": m.get("losses", []),
                "samples_duplicated": int(m.get("samples_duplicated", 0)),
                "duplicates": m.get("duplicates", [])}


def _num(v: Any) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _list(a: Any) -> list[float | None]:
    return [_num(v) for v in np.asarray(a, dtype=float).ravel()]


def _select(names: list[str], channels: Sequence[str] | None) -> list[int]:
    if not channels:
        return list(range(len(names)))
    out = []
    for ch in channels:
        if ch in names:
            out.append(names.index(ch))
        elif ch.isdigit() and int(ch) < len(names):
            out.append(int(ch))
        else:
            raise DataError(f"channel {ch!r} is not in this record; its channels are "
                            f"{', '.join(names)} (or their numbers 0..{len(names) - 1})")
    return sorted(set(out))


#: (accel block (n, C) m/s², temperature block (n, k) °C or None, ends a segment)
RecordBlock = tuple[NDArray[np.float64], NDArray[np.float64] | None, bool]


def record_blocks(path: str, block: int, rate_hz: float | None, *,
                  columns: Sequence[int] | None = None, temperature: bool = True,
                  verify: bool = True) -> tuple[dict[str, Any], Iterator[RecordBlock]]:
    """Metadata and blocks of a record: the one segment iterator of ``avard analyze`` and
    ``avard explain``. Files are one segment, streamed; a recording of the service is loaded
    (``recording.load_recording``) and split where the service split its accumulators
    (``meta["segment_bounds"]``: every gap record, run change and index jump), so nothing is
    averaged across a gap or a restart. ``columns``, ``temperature`` and ``verify`` as for
    ``readers.iter_blocks`` (only those accel columns; no temperatures; no CRC check)."""
    from pathlib import Path

    p = Path(path)
    if p.is_dir() or p.suffix == ".avr":
        rec = load_record(p, rate_hz=rate_hz)
        # the service's own segment breaks (every gap record, run change, index jump)
        cuts = rec.meta.get("segment_bounds") or [0, rec.n_samples]
        meta = {"format": "recording", "n_samples": rec.n_samples, "rate_hz": rec.rate_hz,
                "lsb_mps2": rec.meta.get("lsb_mps2"),
                "names": list(rec.names), "temperature_names": list(rec.temperature_names),
                "source": rec.source, "gaps": rec.meta.get("gaps", []),
                "n_segments": len(cuts) - 1,
                "samples_lost": rec.meta.get("samples_lost", 0),
                "samples_duplicated": rec.meta.get("samples_duplicated", 0),
                "losses": rec.meta.get("losses", []),
                "duplicates": rec.meta.get("duplicates", [])}
        temps = rec.temperature_c if temperature else None
        cols = None if columns is None else list(columns)

        def gen_rec() -> Iterator[RecordBlock]:
            for s0, s1 in itertools.pairwise(cuts):
                for i in range(s0, s1, block):
                    j = min(i + block, s1)
                    a = rec.accel[i:j] if cols is None else rec.accel[i:j, cols]
                    yield a, None if temps is None else temps[i:j], j >= s1

        return meta, gen_rec()
    meta, blocks = iter_blocks(path, block, rate_hz=rate_hz, columns=columns,
                               temperature=temperature, verify=verify)

    def gen() -> Iterator[RecordBlock]:
        for a, t in blocks:
            yield a, t, False

    return meta, gen()


def _segments(path: str, block: int, rate_hz: float | None,
              columns: Sequence[int] | None = None, verify: bool = True
              ) -> tuple[dict[str, Any], Iterator[tuple[NDArray[np.float64], bool]]]:
    """:func:`record_blocks` without the temperatures (what the Allan pass reads)."""
    meta, blocks = record_blocks(path, block, rate_hz, columns=columns, temperature=False,
                                 verify=verify)
    return meta, ((a, end) for a, _t, end in blocks)


def default_filter_corner(meta: dict[str, Any], rate_hz: float) -> float | None:
    """The ADXL355 low-pass corner (ODR/4) when the record says it comes from one: a service
    recording or a simulated record (which carries odr_nominal_hz). Other sensors' filters are
    unknown, and the fit then leaves out the short τ they bend (a data-driven cut)."""
    if meta.get("format") == "recording" or "odr_nominal_hz" in meta:
        return rate_hz / 4.0
    return None


#: A record's blocks: (samples (n, C) in m/s², True where a segment ends).
_Blocks = Iterable[tuple[NDArray[np.float64], bool]]
#: One pass over a record: its channels (numbers in the record), their blocks, and the block
#: columns to take (None: all).
_Pass = tuple[list[int], _Blocks, list[int] | None]
#: One channel's blocks read again (R(n) deferred by the OADEV; see ``_deferred_rn``).
_Reread = Callable[[int], _Blocks]


def analyze(
    path: str,
    *,
    rate_hz: float | None = None,
    channels: Sequence[str] | None = None,
    filter_corner_hz: float | str | None = "auto",
    find_sinusoids: bool = True,
    progress: ProgressFn | None = None,
    block: int = 1 << 16,
    fit_kwargs: dict[str, Any] | None = None,
    estimator: str = "oadev",
    psd: bool = False,
    quantiles: str = "exact",
    noise_id: str = "avard",
) -> Analysis:
    """Read ``path`` once (streamed), compute per-channel AVAR and spectrum, fit the terms.

    ``filter_corner_hz``: "auto" (ADXL355 ODR/4 for avard's own records, else not modelled),
    a number in Hz, or None (not modelled: the bent shortest τ are left out instead).
    ``estimator``: "oadev" (fully overlapping, default) or "cascade" (see ``ESTIMATORS``).
    ``psd``: also give each channel's one-sided PSD with its band and the white density read
    from it, checked against the fit's N (``psd.ChannelPsd``).
    ``quantiles``, ``noise_id``: "stable32" reproduces Stable32's χ² quantiles and its B1
    rule for the noise identification (``edf.chi2_interval``, ``noise_id.NOISE_IDS``).
    """
    check_noise_id(noise_id)
    meta, segments = _segments(path, block, rate_hz)
    if meta.get("n_samples") is None and estimator == "oadev":
        meta = {**meta, "n_samples": _count_rows(path)}
    opts = dict(source=path, filter_corner_hz=filter_corner_hz, find_sinusoids=find_sinusoids,
                progress=progress, fit_kwargs=fit_kwargs, estimator=estimator, psd=psd,
                quantiles=quantiles, noise_id=noise_id)
    sel = _select(list(meta["names"]), channels)
    if estimator != "oadev" or meta.get("format") == "recording":
        # a service recording is loaded whole (``record_blocks``): passes would save nothing
        return _analyze_passes(meta, [(sel, segments, sel)], **opts)
    # A file is read again rather than held: one pass per group of channels whose OADEV
    # histories fit PASS_BUDGET_BYTES together, so only that group's histories are live.
    # The first pass checks an .npz member's CRC, the others skip it. A CSV's first pass takes
    # the blocks already opened (its reader has read the first rows); an .npz reader opens
    # nothing before its first block, so it is simply replaced by one of the group's columns.
    groups = oadev_pass_groups(sel, int(meta["n_samples"]))
    passes: list[_Pass]
    if meta.get("format") == "npz":
        passes = [(groups[0], _lazy_segments(path, block, rate_hz, groups[0], True), None)]
    else:
        passes = [(groups[0], segments, groups[0])]
    for g in groups[1:]:
        passes.append((g, _lazy_segments(path, block, rate_hz, g, False), None))

    def reread(column: int) -> _Blocks:
        return _lazy_segments(path, block, rate_hz, [column], False)

    return _analyze_passes(meta, passes, reread=reread, **opts)


def _lazy_segments(path: str, block: int, rate_hz: float | None, columns: list[int],
                   verify: bool) -> Iterator[tuple[NDArray[np.float64], bool]]:
    """The record's blocks of ``columns`` only, opened when the pass starts (not before, so
    one file handle is open at a time)."""
    yield from _segments(path, block, rate_hz, columns, verify)[1]


def oadev_pass_groups(sel: list[int], n_samples: int) -> list[list[int]]:
    """``sel`` split into groups whose OADEV histories (8 bytes × (2·m_max + PIECE) points per
    channel) fit ``PASS_BUDGET_BYTES`` together, one channel at least: the channels of one
    pass over a file. Short records take every channel in one pass."""
    from avard.core.allan.overlapping import PIECE

    grid = oadev_grid(n_samples, 1)
    per_channel = 8 * (2 * int(grid[-1]) + PIECE)
    size = max(1, PASS_BUDGET_BYTES // per_channel)
    return [sel[i:i + size] for i in range(0, len(sel), size)]


def _count_rows(path: str) -> int:
    """Upper bound on the data rows of a text record (lines after the header), read in 1 MiB
    pieces: the OADEV grid is fixed before the data arrive. An overestimate only adds τ that
    end up without differences, which are dropped."""
    lines = 0
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            lines += chunk.count(b"\n")
    return max(0, lines)


def oadev_grid(n_samples: int, n_channels: int,
               budget_bytes: int | None = None) -> NDArray[np.int64]:
    """Octave m for the OADEV of a record: ≥ 4 non-overlapping intervals (m ≤ N/4, where
    Stable32's tables stop), and a ring of 2·m_max points per channel within
    ``budget_bytes`` (default :func:`ring_budget_bytes`); m = 1 at least."""
    from avard.core.allan.overlapping import PIECE

    budget = ring_budget_bytes() if budget_bytes is None else budget_bytes
    m_max = max(1, n_samples // 4)
    ring_max = budget // (8 * max(1, n_channels)) - PIECE
    m_max = max(1, min(m_max, ring_max // 2))
    return 2 ** np.arange(int(math.log2(m_max)) + 1, dtype=np.int64)


def _with_differences(res: Any) -> Any:
    """The result without the τ that got no difference (NaN variance, n = 0)."""
    from dataclasses import replace

    keep = np.asarray(res.n) > 0
    if keep.all():
        return res
    cut = {k: getattr(res, k)[keep] for k in ("tau", "m", "stride", "var", "n", "edf", "lo",
                                               "hi", "alpha")}
    if res.cov is not None:
        cut["cov"] = res.cov[keep]
    return replace(res, **cut)


@one_blas_thread  # the fit and the spectrum too, not only the Allan pass (core/blas.py)
def analyze_stream(
    meta: dict[str, Any],
    segments: _Blocks,
    *,
    source: str = "stream",
    channels: Sequence[str] | None = None,
    filter_corner_hz: float | str | None = "auto",
    find_sinusoids: bool = True,
    progress: ProgressFn | None = None,
    fit_kwargs: dict[str, Any] | None = None,
    estimator: str = "oadev",
    psd: bool = False,
    quantiles: str = "exact",
    noise_id: str = "avard",
) -> Analysis:
    """``analyze`` on blocks from anywhere (a file reader, the simulator): ``meta`` gives
    ``rate_hz``, ``names`` and, when known, ``n_samples``; ``segments`` yields (block (n, C)
    in m/s², True where a segment ends: no difference or spectrum spans what follows).
    ``estimator="oadev"`` needs ``n_samples`` (an upper bound will do) to fix its τ grid.
    The blocks are read once, every channel at a time (the OADEV history is then 2·m_max
    points for each channel at once; ``analyze`` of a file reads it once per channel group
    instead)."""
    sel = _select(list(meta["names"]), channels)
    return _analyze_passes(meta, [(sel, segments, sel)], source=source,
                           filter_corner_hz=filter_corner_hz, find_sinusoids=find_sinusoids,
                           progress=progress, fit_kwargs=fit_kwargs, estimator=estimator,
                           psd=psd, quantiles=quantiles, noise_id=noise_id)


@dataclass
class _PassResult:
    """What one pass over the blocks gives for its channels."""

    allan: Any  # AllanResult of the pass's channels, τ without differences dropped
    welch: WelchAccumulator | None
    n: int  # samples read


def _one_pass(blocks: _Blocks, take: list[int] | None,
              names: list[str], rate: float, estimator: str, grid: NDArray[np.int64] | None,
              nper: int | None, progress: ProgressFn | None, done: int,
              total: int | None, quantiles: str = "exact",
              n_record: int | None = None, reread: _Reread | None = None,
              noise_id: str = "avard") -> _PassResult:
    """Stream ``blocks`` (their columns ``take``, or all) into the chosen Allan accumulator and
    the Welch spectrum of the channels ``names``; ``done``/``total`` place it in the progress
    of the whole analysis. ``reread(j)``: channel j's blocks again, for the R(n) sums the
    OADEV then leaves out until B1 asks for them (``_deferred_rn``)."""
    from avard.core.allan.overlapping import OverlappingAllan
    from avard.core.allan.streaming import StreamingAllan

    sa: OverlappingAllan | StreamingAllan
    if estimator == "oadev":
        assert grid is not None
        defer = reread is not None and n_record is not None
        sa = OverlappingAllan(len(names), rate, grid, names=names, n_total=n_record,
                              defer_rn=defer)
    else:
        sa = StreamingAllan(len(names), rate, names=names)
    welch = WelchAccumulator(len(names), rate, nper) if nper is not None else None
    n = 0
    for accel, segment_end in blocks:
        a = accel if take is None else accel[:, take]
        sa.update(a)
        if welch is not None:
            welch.update(a)
        n += len(a)
        if segment_end:
            # a gap in the recording: no Allan difference and no spectrum segment spans it
            sa.gap()
            if welch is not None:
                welch.gap()
        if progress is not None:
            progress(done + n, total)
    if isinstance(sa, OverlappingAllan) and reread is not None and n >= 16:
        _deferred_rn(sa, reread, n, noise_id)
    # "stable32": the intervals' χ² quantiles, and the B1 rule, as Stable32's
    res = (_with_differences(sa.result(quantiles=quantiles, noise_id=noise_id)) if n >= 16
           else None)
    return _PassResult(res, welch, n)


def _deferred_rn(sa: OverlappingAllan, reread: _Reread, n: int, noise_id: str = "avard"
                 ) -> None:
    """The R(n) sums ``sa`` (an ``OverlappingAllan(defer_rn=True)`` fed the whole record)
    needs where B1 says PM in its range: each such channel read again into an accumulator of
    those τ alone, which keeps them (the same differences in the same pieces, so the same
    sums as keeping them in the first pass). One channel at a time: a history of 3·m per τ.
    Nothing is read on records without PM noise at the long τ."""
    from avard.core.allan.overlapping import OverlappingAllan

    need = sa.rn_needed(noise_id)
    for ch in sorted({c for chans in need.values() for c in chans}):
        ks = [k for k, chans in need.items() if ch in chans]
        # said, since the progress shown is the passes' and this read comes after them
        log.info("channel %s read again for R(n) at τ = %s s, where B1 says PM",
                 sa.names[ch], ", ".join(f"{m / sa.rate_hz:g}" for m in sa.ms[ks]))
        extra = OverlappingAllan(1, sa.rate_hz, sa.ms[ks])
        got = 0
        for accel, segment_end in reread(ch):
            extra.update(accel)
            got += len(accel)
            if segment_end:
                extra.gap()
        if got != n:
            raise DataError(f"read {got} samples of channel {sa.names[ch]} again for R(n) "
                            f"after {n}; the file changed while it was analysed")
        sums = extra.rn_sums()
        sa.set_rn(ch, {k: r for k, r in zip(ks, sums, strict=True) if r is not None})


def _analyze_passes(
    meta: dict[str, Any],
    passes: Sequence[_Pass],
    *,
    reread: _Reread | None = None,
    source: str,
    filter_corner_hz: float | str | None,
    find_sinusoids: bool,
    progress: ProgressFn | None,
    fit_kwargs: dict[str, Any] | None,
    estimator: str,
    psd: bool,
    quantiles: str = "exact",
    noise_id: str = "avard",
) -> Analysis:
    """The analysis of the channels of ``passes``: each (channel numbers in ``meta["names"]``,
    its blocks, the block columns to take or None for all), read one after another.
    ``progress`` counts the samples read over all passes (the record's length × passes).
    ``reread(column)``, when the record can be read again, gives one column's blocks: the
    OADEV then defers R(n) and reads a column again only where B1 needs it."""
    if estimator not in ESTIMATORS:
        raise DataError(f"estimator {estimator!r} is unknown; use one of {sorted(ESTIMATORS)}")
    rate = float(meta["rate_hz"])
    names = list(meta["names"])
    total = meta.get("n_samples")
    grid = None
    if estimator == "oadev":
        if total is None:
            raise DataError(f"{source}: the record length is unknown, so the OADEV τ grid "
                            "cannot be fixed; give n_samples or use estimator='cascade'")
        width = max(len(chans) for chans, _b, _t in passes)  # channels live at once
        grid = oadev_grid(int(total), width)
        full = oadev_grid(int(total), width, budget_bytes=1 << 62)
        if len(grid) < len(full):
            # said in the table and the JSON: the longest τ the memory here allowed
            meta = {**meta, "oadev_cut": {
                "tau_max_s": float(grid[-1] / rate), "tau_full_s": float(full[-1] / rate),
                "bytes_needed": int(16 * full[-1] * width)}}
    nper = None
    if (find_sinusoids or psd) and (total is None or total >= 1024):
        nper = welch_nperseg(total)
    all_total = None if total is None else int(total) * len(passes)
    results: list[tuple[list[int], _PassResult]] = []
    done = 0
    for chans, blocks, take in passes:
        again = None
        if reread is not None:
            def again(j: int, chans: list[int] = chans) -> _Blocks:
                return reread(chans[j])
        one = _one_pass(blocks, take, [names[i] for i in chans], rate, estimator, grid, nper,
                        progress, done, all_total, quantiles,
                        None if total is None else int(total), again, noise_id)
        if results and one.n != results[0][1].n:
            raise DataError(f"{source}: read {one.n} samples on one pass and "
                            f"{results[0][1].n} on another; the file changed while it was "
                            "analysed")
        done += one.n
        results.append((chans, one))
    n = results[0][1].n
    if n < 16:
        raise DataError(f"{source}: only {n} samples; the Allan variance needs a record of at "
                        "least a few hundred samples")
    corner = (default_filter_corner(meta, rate) if filter_corner_hz == "auto"
              else filter_corner_hz)
    # an ADXL355 record rounds to its LSB after the chip filter: unfiltered white noise the
    # fit holds as a fixed term (simulated records and recordings carry the LSB)
    lsb = meta.get("lsb_mps2")
    lsb = float(lsb) if isinstance(lsb, int | float | np.floating) and lsb > 0 else None
    from avard.core.model.fit import fit_noise

    out: dict[str, ChannelAnalysis] = {}
    for chans, one in results:
        welch = one.welch
        f, spectrum = (welch.result() if welch is not None else (None, None))
        for j, i in enumerate(chans):
            allan = one.allan.channel(j)
            lines = []
            if welch is not None and spectrum is not None and find_sinusoids:
                lines = find_lines(f, spectrum[:, j], welch.n_seg)
            extra = [{"cause": "sinusoid", "params": dict(ln)} for ln in lines]
            kw = dict(fit_kwargs or {})
            if corner is not None and lsb is not None:
                kw.setdefault("rounding_lsb", lsb)
            try:
                fit = fit_noise(allan, filter_corner_hz=corner, extra=extra, **kw)
            except FitError as exc:
                raise FitError(f"{source}, channel {names[i]}: {exc}") from exc
            chan_psd = None
            if psd:
                if welch is None or spectrum is None or welch.n_seg < 1:
                    raise DataError(f"{source}: {n} samples are too few for a spectrum (--psd "
                                    "needs at least 1024)")
                from avard.core.psd import channel_psd, white_density

                chan_psd = channel_psd(f, spectrum[:, j], welch.n_seg, lines=lines)
                chan_psd.white = white_density(chan_psd, fit, rate, filter_corner_hz=corner)
            out[names[i]] = ChannelAnalysis(names[i], allan, fit, lines, estimator, chan_psd)
    # channels in the record's order, whatever the passes
    out = {names[i]: out[names[i]] for i in sorted(i for chans, _r in results for i in chans)}
    return Analysis(source=str(meta.get("source", source)), rate_hz=rate, n_samples=n,
                    channels=out, meta={**meta, "filter_corner_hz": corner},
                    estimator=estimator)


# ---------------------------------------------------------------------------------------------
# text, csv, kalibr


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.4g}"


def format_table(an: Analysis) -> str:
    """Human-readable report: per channel the five terms (value, 68 % interval, SI unit, or
    'absent'), the sinusoids, the τ range used and the fit quality."""
    lines = [f"{an.source}: {an.n_samples} samples at {an.rate_hz:g} Hz "
             f"({an.n_samples / an.rate_hz / 3600:.3g} h). Units SI; intervals 68.3 %."]
    fc = an.meta.get("filter_corner_hz")
    lines.append("sensor low-pass modelled at " + (f"{fc:g} Hz" if fc else
                 "— (not modelled: filter-bent short τ left out)"))
    lines.append(f"Allan deviation: {ESTIMATORS[an.estimator]}, octave τ; intervals from "
                 "Greenhall–Riley EDF with the noise type identified per τ (as Stable32); "
                 "its values per τ (m/s², with interval, EDF, α): --json or --export csv FILE")
    cut = an.meta.get("oadev_cut")
    if cut:
        lines.append(f"OADEV stops at τ = {cut['tau_max_s']:.4g} s, short of N/4 "
                     f"({cut['tau_full_s']:.4g} s): its history would need "
                     f"{cut['bytes_needed'] / 2**20:.0f} MiB, more than a quarter of the free "
                     "memory; --estimator cascade reaches N/4 in kilobytes")
    rec = an.recording_summary()
    if rec is not None:
        line = (f"recording: {rec['segments']} segment(s), split at each of its "
                f"{rec['gap_records']} gap records and at every restart (never averaged across)")
        if rec["samples_lost"]:
            spans = ", ".join(f"[{x['i0']}, {x['i0'] + x['n']})" for x in rec["losses"][:5])
            more = " …" if len(rec["losses"]) > 5 else ""
            line += (f"; {rec['samples_lost']} samples lost to damage at indices "
                     f"{spans}{more}")
        if rec["samples_duplicated"]:
            line += f"; {rec['samples_duplicated']} duplicated samples counted once"
        lines.append(line)
    for name, ch in an.channels.items():
        fit = ch.fit
        lines.append("")
        lines.append(f"channel {name}")
        lines.append(f"  {'term':<24}{'value':>12}  {'68 % interval':<25}{'unit'}")
        for t in TERMS:
            e = fit.terms[t]
            label = f"{t} ({SYMBOLS[t]})"
            if e.present:
                lines.append(f"  {label:<24}{_fmt(e.value):>12}  "
                             f"{'[' + _fmt(e.lo) + ', ' + _fmt(e.hi) + ']':<25}{UNITS[t]}")
            else:
                ub = f"absent (< {_fmt(e.upper)} {UNITS[t]})" if e.upper else "absent"
                lines.append(f"  {label:<24}{ub:>12}")
            if e.note and t == "rate_random_walk":
                lines.append(f"    {e.note}")
        if ch.lines:
            s = ", ".join(f"{ln['frequency_hz']:.4g} Hz × {ln['amplitude']:.3g} m/s²"
                          for ln in ch.lines)
            lines.append(f"  sinusoids: {s}")
        else:
            lines.append("  sinusoids: none found")
        if ch.psd is not None:
            lines.extend(_psd_lines(ch))
        chi = "n/a" if not math.isfinite(fit.chi2_dof) else f"{fit.chi2_dof:.2f}"
        lines.append(f"  fitted τ {fit.tau_min_s:.4g} s … {fit.tau_max_s:.4g} s "
                     f"({fit.n_points} points), χ²/dof = {chi} (dof {fit.dof})")
        if math.isfinite(fit.chi2_dof) and fit.dof > 0:
            from avard.core.allan.chi2 import chi2_sf  # the χ² upper tail, without scipy

            p = float(chi2_sf(fit.chi2_dof * fit.dof, fit.dof))
            if p < 0.001:
                lines.append(f"  note: the five-term model does not describe this curve "
                             f"(p = {p:.1g}); see `avard explain` for what else is in it")
    return "\n".join(lines)


def _psd_lines(ch: ChannelAnalysis) -> list[str]:
    cp = ch.psd
    out = [f"  PSD: one-sided Welch, {cp.n_segments} segments, {len(cp.f)} bins to "
           f"{cp.f[-1]:.4g} Hz, (m/s²)²/Hz with its {cp.ci:.1%} band (--json, --export psd)"]
    w = cp.white
    if w is None:
        out.append("  PSD white density: no white region to read it in")
    else:
        verdict = "agrees with" if w.agrees else "DIFFERS from"
        out.append(f"  PSD white density N = {_fmt(w.value)} [{_fmt(w.lo)}, {_fmt(w.hi)}] "
                   f"m/s²/√Hz ({w.f_lo_hz:.3g}–{w.f_hi_hz:.3g} Hz, {w.n_bins} bins): {verdict}"
                   f" the fit's N [{_fmt(w.fit_lo)}, {_fmt(w.fit_hi)}]")
    return out


def psd_csv(an: Analysis) -> str:
    """The spectra as csv: channel, f_hz, psd, psd_lo, psd_hi ((m/s²)²/Hz, one-sided)."""
    rows = ["channel,f_hz,psd_m2ps4_per_hz,psd_lo,psd_hi"]
    for name, ch in an.channels.items():
        cp = ch.psd
        if cp is None:
            continue
        for k in range(len(cp.f)):
            vals = (cp.f[k], cp.psd[k], cp.lo[k], cp.hi[k])
            rows.append(",".join([name] + [("" if not math.isfinite(v) else f"{v:.9g}")
                                           for v in vals]))
    return "\n".join(rows) + "\n"


def adev_csv(an: Analysis) -> str:
    """The ADEV table as csv: channel, tau_s, adev, adev_lo, adev_hi (m/s²), edf, model (m/s²:
    the fitted model's ADEV), used (1 if the point was in the fit), alpha (noise exponent the
    interval assumes), estimator ("oadev" or "cascade", see ``ESTIMATORS``)."""
    rows = ["channel,tau_s,adev_mps2,adev_lo_mps2,adev_hi_mps2,edf,model_adev_mps2,used,alpha,"
            "estimator"]
    for name, ch in an.channels.items():
        a = ch.allan
        model = np.sqrt(ch.fit.model_avar(a.tau))
        for k in range(len(a.tau)):
            used = int(ch.fit.tau_min_s * (1 - 1e-9) <= a.tau[k] <= ch.fit.tau_max_s * (1 + 1e-9))
            vals = [a.tau[k], a.dev[k], a.dev_lo[k], a.dev_hi[k], a.edf[k], model[k]]
            alpha = a.alpha[k]
            rows.append(",".join([name] + [("" if not math.isfinite(v) else f"{v:.9g}")
                                           for v in vals]
                                 + [str(used), "" if not math.isfinite(alpha) else
                                    str(int(alpha)), ch.estimator]))
    return "\n".join(rows) + "\n"


def kalibr_yaml(an: Analysis, *, rostopic: str = "/imu0") -> str:
    """kalibr's IMU noise file: accelerometer_noise_density = N (m/s²/√Hz), _random_walk = K
    (m/s³/√Hz), update_rate (Hz). kalibr takes one value for all axes: the largest over the
    channels (conservative). An axis without a detected K contributes its upper limit; if no
    channel gives anything, a comment says so and the value is 0."""
    ns = [c.fit.terms["velocity_random_walk"].value for c in an.channels.values()]
    ks = []
    for c in an.channels.values():
        e = c.fit.terms["rate_random_walk"]
        ks.append(e.value if e.present else e.upper)
    n_val = max((v for v in ns if v is not None), default=None)
    k_val = max((v for v in ks if v is not None), default=None)
    if n_val is None:
        raise FitError("no channel has a velocity random walk N; kalibr needs one")
    k_note = ("largest K over the axes" if any(c.fit.terms["rate_random_walk"].present
                                                for c in an.channels.values())
              else "K not detected: the largest 99 % upper limit over the axes")
    out = [
        f"# accelerometer noise from avard analyze of {an.source}",
        f"# channels: {', '.join(an.channels)}; largest value over them; SI units",
        f"accelerometer_noise_density: {n_val:.6e}   # N, m/s^2/sqrt(Hz)",
        f"accelerometer_random_walk: {0.0 if k_val is None else k_val:.6e}   # {k_note}, "
        "m/s^3/sqrt(Hz)",
        f"rostopic: {rostopic}",
        f"update_rate: {an.rate_hz:.6g}   # Hz",
    ]
    return "\n".join(out) + "\n"


def progress_printer(stream: Any = None) -> ProgressFn | None:
    """A progress callback writing to stderr, or None when stderr is not a terminal."""
    stream = stream or sys.stderr
    if not getattr(stream, "isatty", lambda: False)():
        return None
    last = [-1]

    def show(done: int, total: int | None) -> None:
        pct = -1 if not total else int(100 * done / total)
        if pct == last[0] and total:
            return
        last[0] = pct
        msg = f"\ranalyze: {pct:3d} % ({done}/{total} samples read)" if total else \
            f"\ranalyze: {done} samples"
        stream.write(msg)
        if total and done >= total:
            stream.write("\n")
        stream.flush()

    return show
