"""Sample index ↔ CLOCK_MONOTONIC: a running fit that measures the chip's real output rate.

The ADXL355's internal clock is off by up to a few thousand ppm (datasheet: nominal 4 kHz
spans 3.8–4.2 kHz), so time must never be ``index / nominal ODR``. Every FIFO drain is stamped
with CLOCK_MONOTONIC just before FIFO_ENTRIES is read; the newest set it counted was produced
within one sample period before that stamp. :class:`TimeBase` fits

    t_mono = a_k + b · index        (b = 1 / real ODR, one intercept a_k per gap-free segment)

by least squares with a common slope across segments (an overrun loses an unknown number of
samples, which shifts the intercept but not the rate). The accumulators are exponentially
weighted (``memory_s``) so the fit follows the slow, temperature-driven drift of the chip's
oscillator, and numerically stable (running means and co-moments, Welford/West).

Each sample's time is the fitted output time, moved back by half a period (the stamp lags the
newest sample by U(0, T), mean T/2) and by the low-pass filter's group delay (datasheet: 1.5 to
2.5 samples), so that it says when the acceleration happened:

    t(i) = a_k + b · i − (½ + group_delay_samples) · b
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from avard.daemon.hw.adxl355 import Drain


class Clock(Protocol):
    """What the driver needs from a clock (seconds)."""

    def monotonic(self) -> float: ...

    def realtime(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...


class SystemClock:
    """The host's CLOCK_MONOTONIC and CLOCK_REALTIME."""

    @staticmethod
    def monotonic() -> float:
        return time.clock_gettime(time.CLOCK_MONOTONIC)

    @staticmethod
    def realtime() -> float:
        return time.clock_gettime(time.CLOCK_REALTIME)

    @staticmethod
    def sleep(seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


#: A CLOCK_MONOTONIC/CLOCK_REALTIME pair read within this is tight enough to stop retrying.
CLOCK_PAIR_TIGHT_S = 50e-6
CLOCK_PAIR_TRIES = 3


def read_clock_pair(clock: Any) -> tuple[float, float, float]:
    """(t_mono, t_real, u): CLOCK_MONOTONIC now, CLOCK_REALTIME at that moment, and the
    uncertainty of the pair (s). Read as monotonic, realtime, monotonic: realtime was read
    within that window, so the pair is its middle ± half the window. A thread pre-empted
    between two reads made a window of 0.1 s, and the realtime offset looked 0.1 s off
    (a spurious clock_step pair); the read is retried and the narrowest window's offset kept,
    and a step is judged against ``u`` (TimeBase.realtime_step). ``t_mono`` is the last read,
    the one closest to what the caller does next."""
    best_off, best_u = 0.0, float("inf")
    m2 = 0.0
    for _ in range(CLOCK_PAIR_TRIES):
        m1 = clock.monotonic()
        r = clock.realtime()
        m2 = clock.monotonic()
        u = 0.5 * (m2 - m1)
        if u < best_u:
            best_off, best_u = r - 0.5 * (m1 + m2), u
        if m2 - m1 <= CLOCK_PAIR_TIGHT_S:
            break
    return m2, m2 + best_off, best_u


@dataclass(frozen=True)
class RateEstimate:
    """The fitted output rate. ``odr_hz`` ± ``odr_u_hz`` (1σ, from the fit residuals);
    ``ppm`` = (odr / nominal − 1)·10⁶ ± ``ppm_u``; ``jitter_s`` the residual RMS, s."""

    odr_hz: float
    odr_u_hz: float
    ppm: float
    ppm_u: float
    nominal_hz: float
    jitter_s: float
    n_points: int


class _Segment:
    """Weighted running means and co-moments of (index, time) for one gap-free segment.

    Values are kept relative to the segment's first point so that sums of squares of
    10⁹-sized indices never meet float rounding."""

    __slots__ = ("c_xx", "c_xy", "c_yy", "n", "w", "x0", "x_mean", "y0", "y_mean")

    def __init__(self, x0: float, y0: float) -> None:
        self.x0, self.y0 = x0, y0
        self.w = 0.0
        self.n = 0
        self.x_mean = self.y_mean = 0.0
        self.c_xx = self.c_xy = self.c_yy = 0.0

    def decay(self, f: float) -> None:
        self.w *= f
        self.c_xx *= f
        self.c_xy *= f
        self.c_yy *= f

    def add(self, x: float, y: float, w: float = 1.0) -> None:
        dx, dy = x - self.x0, y - self.y0
        self.w += w
        self.n += 1
        ex = dx - self.x_mean
        ey = dy - self.y_mean
        self.x_mean += ex * w / self.w
        self.y_mean += ey * w / self.w
        self.c_xx += w * ex * (dx - self.x_mean)
        self.c_xy += w * ex * (dy - self.y_mean)
        self.c_yy += w * ey * (dy - self.y_mean)


class TimeBase:
    """Running fit of sample index against CLOCK_MONOTONIC (see the module docstring).

    ``update(last_index, t_mono, gap=...)`` after every drain that returned sets:
    ``last_index`` is the index of the newest set read, ``t_mono`` the drain's stamp.
    ``gap=True`` starts a new segment (an overrun, a restart): the rate is kept, the intercept
    is refitted. Until two points exist the nominal rate is used.
    """

    def __init__(self, nominal_odr_hz: float, *, group_delay_samples: float = 0.0,
                 memory_s: float | None = 3600.0, min_span_s: float = 1.0) -> None:
        if nominal_odr_hz <= 0:
            raise ValueError("nominal_odr_hz must be positive")
        self.nominal_odr_hz = float(nominal_odr_hz)
        self.group_delay_samples = float(group_delay_samples)
        self.memory_s = memory_s
        self.min_span_s = float(min_span_s)
        self._seg: _Segment | None = None
        # Pooled within-segment co-moments of closed segments (already decayed).
        self._old_xx = self._old_xy = self._old_yy = 0.0
        self._old_w = 0.0
        self._old_segments = 0
        self._first_index: float | None = None
        self._last_index = 0.0
        self._last_t: float | None = None
        self._last_real_offset: float | None = None
        self._last_real_u = 0.0
        self._pending_gap = False
        self.n_points = 0

    # -- feeding ----------------------------------------------------------------------------
    def update(self, last_index: int, t_mono: float, *, gap: bool = False,
               exact: bool = True) -> bool:
        """Add the pair (index of the newest set read, drain stamp); returns whether it was
        used. ``exact=False`` (``Drain.complete`` false: the FIFO was full, so a newer set may
        have been left in the sync buffer) skips the point but keeps ``gap`` for the next."""
        gap = gap or self._pending_gap
        if not exact and self._seg is not None:  # the very first point is used regardless
            self._pending_gap = gap
            return False
        self._pending_gap = False
        if self._last_t is not None and self.memory_s:
            f = math.exp(-max(t_mono - self._last_t, 0.0) / self.memory_s)
            if self._seg is not None:
                self._seg.decay(f)
            self._old_xx *= f
            self._old_xy *= f
            self._old_yy *= f
            self._old_w *= f
        if self._seg is None or gap:
            if self._seg is not None and self._seg.n >= 2:
                self._old_xx += self._seg.c_xx
                self._old_xy += self._seg.c_xy
                self._old_yy += self._seg.c_yy
                self._old_w += self._seg.w
                self._old_segments += 1
            self._seg = _Segment(float(last_index), float(t_mono))
        self._seg.add(float(last_index), float(t_mono))
        if self._first_index is None:
            self._first_index = float(last_index)
        self._last_index = float(last_index)
        self._last_t = t_mono
        self.n_points += 1
        return True

    def add_drain(self, drain: Drain) -> bool:
        """Feed one :class:`~avard.daemon.hw.adxl355.Drain`; returns whether it was used.

        A drain with ``overrun`` starts a new segment. A drain that is not ``complete`` (the
        FIFO was full, so its newest set may still sit in the sync buffer, or ``max_sets``
        left sets behind) does not give a tight index ↔ stamp pair and is skipped, as is an
        empty one; a gap they carry is kept for the next point."""
        if drain.n_sets == 0:
            self._pending_gap = self._pending_gap or bool(drain.overrun)
            return False
        return self.update(drain.last_index, drain.t_mono, gap=bool(drain.overrun),
                           exact=bool(drain.complete))

    def realtime_step(self, t_mono: float, t_real: float, threshold_s: float = 0.05,
                      u_s: float = 0.0) -> float | None:
        """Track CLOCK_REALTIME − CLOCK_MONOTONIC; return the step in s when it jumped by more
        than ``threshold_s`` plus the uncertainties of this read and the previous one
        (``u_s``: :func:`read_clock_pair`) since the last call (an NTP step or a date
        change), else None. Steps are events: sample order and times stay on the monotonic
        clock."""
        off = t_real - t_mono
        prev, prev_u = self._last_real_offset, self._last_real_u
        self._last_real_offset, self._last_real_u = off, float(u_s)
        if prev is not None and abs(off - prev) > threshold_s + u_s + prev_u:
            return off - prev
        return None

    # -- results ----------------------------------------------------------------------------
    def _sums(self) -> tuple[float, float, float, float]:
        """Pooled within-segment co-moments and the effective number of points (sum of
        the exponential weights)."""
        sxx, sxy, syy, w = self._old_xx, self._old_xy, self._old_yy, self._old_w
        if self._seg is not None:
            sxx += self._seg.c_xx
            sxy += self._seg.c_xy
            syy += self._seg.c_yy
            w += self._seg.w
        return sxx, sxy, syy, w

    @property
    def period_s(self) -> float:
        """Fitted sample period b, s (nominal until the fit has a span of ``min_span_s``)."""
        sxx, sxy, _, _ = self._sums()
        b = sxy / sxx if sxx > 0 else 0.0
        first = self._first_index if self._first_index is not None else 0.0
        span_s = (self._last_index - first) / self.nominal_odr_hz
        if self.n_points < 3 or b <= 0 or span_s < self.min_span_s:
            return 1.0 / self.nominal_odr_hz
        return b

    @property
    def odr_hz(self) -> float:
        """Fitted output data rate, Hz."""
        return 1.0 / self.period_s

    @property
    def ppm(self) -> float:
        """Fitted rate's offset from nominal, ppm (see :meth:`rate` for its uncertainty)."""
        return (self.odr_hz / self.nominal_odr_hz - 1.0) * 1e6

    def rate(self) -> RateEstimate:
        """The fitted rate with its 1σ uncertainty (ordinary least-squares standard error of
        the slope, s_b = s / √Sxx with s² the residual variance, pooled over segments)."""
        sxx, sxy, syy, w = self._sums()
        b = self.period_s
        n_seg = self._old_segments + (1 if self._seg is not None else 0)
        dof = w - n_seg - 1
        if sxx > 0 and dof > 0 and b != 1.0 / self.nominal_odr_hz:
            resid = max(syy - sxy * sxy / sxx, 0.0)
            s2 = resid / dof
            u_b = math.sqrt(s2 / sxx)
            jitter = math.sqrt(s2)
        else:
            u_b = math.nan
            jitter = math.nan
        odr = 1.0 / b
        odr_u = odr * u_b / b if math.isfinite(u_b) else math.nan
        return RateEstimate(
            odr_hz=odr, odr_u_hz=odr_u,
            ppm=(odr / self.nominal_odr_hz - 1.0) * 1e6,
            ppm_u=odr_u / self.nominal_odr_hz * 1e6 if math.isfinite(odr_u) else math.nan,
            nominal_hz=self.nominal_odr_hz, jitter_s=jitter, n_points=self.n_points)

    def time_of(self, index: float) -> float:
        """CLOCK_MONOTONIC time, s, at which sample ``index`` (of the current segment) was
        measured: fit, minus half a period (stamp lag), minus the filter group delay."""
        seg = self._seg
        if seg is None:
            raise ValueError("TimeBase has no drain yet: call update() first")
        b = self.period_s
        # Relative to the segment's centroid, so that 10¹⁰-sized indices lose no precision.
        di = (float(index) - seg.x0) - seg.x_mean
        return seg.y0 + seg.y_mean + b * (di - 0.5 - self.group_delay_samples)

    def timestamps(self, index0: int, n: int) -> np.ndarray:
        """CLOCK_MONOTONIC times, s, of samples ``index0 … index0 + n − 1`` (float64)."""
        b = self.period_s
        return self.time_of(index0) + b * np.arange(n, dtype=np.float64)
